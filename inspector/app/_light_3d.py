"""Light 3D: plain lighting for pages that draw WebGL without a GPU.

The 3D view lights the arms with an environment map. Drawn in software (SwiftShader, llvmpipe) it
makes every frame of the view several times slower, and while a frame is drawn the page answers
nothing: slider keys reached the server after ~2 s instead of ~70 ms. Merely setting the map up
(prefiltering its image for every roughness) took such a page ~6.5 s of CPU as it loaded.

So every page starts plainly lit, the panel's "Light 3D" box ticked, and the environment map is
sent only to a page that asks for it: each page looks at its own WebGL renderer once and, when it
is a hardware one, unticks the box (the user can tick it again); the server then turns that page's
environment map on. A page in software, or with no WebGL at all, never sets the map up.

The script rides in the panel title's HTML (see ``._page_script``).
"""

from __future__ import annotations

import json

from ._page_script import page_script_html

LIGHT_3D_LABEL = "Light 3D"
LIGHT_3D_HINT = ("Plain lighting, no environment map: the 3D view draws several times quicker in a "
                 "browser without a GPU (unticked by itself where the page has one)")
# viser's built-in environment map is this preset's image (potsdamer_platz_1k).
DEFAULT_HDRI = "city"

# Unticks the box once per connection where the page has a GPU (a reconnect is a new client, its box
# ticked again): a user who ticks it again keeps it so.
RENDERER_CHECK_JS = r"""
let renderer = null;
try {
  const gl = document.createElement('canvas').getContext('webgl');
  if (gl) {
    const info = gl.getExtension('WEBGL_debug_renderer_info');
    renderer = String(gl.getParameter(info ? info.UNMASKED_RENDERER_WEBGL : gl.RENDERER));
    const lose = gl.getExtension('WEBGL_lose_context');
    if (lose) lose.loseContext();
  }
} catch (e) {}
const kind = renderer === null ? 'none' : /swiftshader|llvmpipe|softpipe|software/i.test(renderer) ? 'software' : 'gpu';
document.documentElement.dataset.inspectorWebgl = kind;  // what the page found (devtools, tests)
if (kind !== 'gpu') return;
let unticked = null;
setInterval(() => {
  const client = document.querySelector('[data-inspector-client]')?.dataset.inspectorClient;
  if (!client || client === unticked) return;
  const label = [...document.querySelectorAll('label[for]')].find((l) => l.textContent.trim() === __LABEL__);
  const box = label && document.getElementById(label.htmlFor);
  if (!box) return;
  if (box.checked) box.click();
  unticked = client;
}, 500);
""".replace("__LABEL__", json.dumps(LIGHT_3D_LABEL))

LIGHT_3D_HTML = page_script_html("light_3d", RENDERER_CHECK_JS)


# What lights the arms instead: a sky-to-table hemisphere light costs next to nothing to draw.
HEMISPHERE_NODE = "/lights/light_3d"
SKY_RGB, TABLE_RGB, HEMISPHERE_INTENSITY = (255, 255, 255), (150, 140, 125), 1.6


def apply_light_3d(client, light: bool):
    """Light ``client``'s scene plainly (``light``) or with viser's default environment map;
    returns the hemisphere light's handle (shown only for plain lighting)."""
    client.scene.configure_environment_map(hdri=None if light else DEFAULT_HDRI)
    # re-adding a node of the same name replaces it
    return client.scene.add_light_hemisphere(HEMISPHERE_NODE, sky_color=SKY_RGB, ground_color=TABLE_RGB,
                                      intensity=HEMISPHERE_INTENSITY, position=(0.0, 0.0, 1.0), visible=light)
