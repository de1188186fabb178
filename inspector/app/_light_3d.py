"""Light 3D: plain lighting for pages that draw WebGL without a GPU.

The 3D view lights the arms with an environment map. Drawn in software (SwiftShader, llvmpipe) it
makes every frame of the view several times slower, and while a frame is drawn the page answers
nothing: slider keys reached the server after ~2 s instead of ~70 ms. Each page looks at its own
WebGL renderer once and, when it is a software one, ticks the panel's "Light 3D" box (the user can
untick it); the server then turns that page's environment map off.

The script rides in the panel title's HTML (see ``._page_script``).
"""

from __future__ import annotations

import json

from ._page_script import page_script_html

LIGHT_3D_LABEL = "Light 3D"
LIGHT_3D_HINT = ("Plain lighting, no environment map: the 3D view draws several times quicker in a "
                 "browser without a GPU (ticked by itself there)")
# viser's built-in environment map is this preset's image (potsdamer_platz_1k).
DEFAULT_HDRI = "city"

# Ticks the box once per connection (a reconnect is a new client, its box unticked): a user who
# unticks it keeps it so.
SOFTWARE_GL_JS = r"""
let renderer = '';
try {
  const gl = document.createElement('canvas').getContext('webgl');
  const info = gl && gl.getExtension('WEBGL_debug_renderer_info');
  renderer = info ? String(gl.getParameter(info.UNMASKED_RENDERER_WEBGL)) : '';
  const lose = gl && gl.getExtension('WEBGL_lose_context');
  if (lose) lose.loseContext();
} catch (e) {}
if (!/swiftshader|llvmpipe|softpipe|software/i.test(renderer)) return;
let ticked = null;
setInterval(() => {
  const client = document.querySelector('[data-inspector-client]')?.dataset.inspectorClient;
  if (!client || client === ticked) return;
  const label = [...document.querySelectorAll('label[for]')].find((l) => l.textContent.trim() === __LABEL__);
  const box = label && document.getElementById(label.htmlFor);
  if (!box) return;
  if (!box.checked) box.click();
  ticked = client;
}, 500);
""".replace("__LABEL__", json.dumps(LIGHT_3D_LABEL))

LIGHT_3D_HTML = page_script_html("light_3d", SOFTWARE_GL_JS)


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
