"""The demo's scripted tasks as joint-space waypoints: pick a cube up and set it down, put it in the
bowl, stack it on the other cube, each as a careful operator would move (hover, straight down,
grasp, lift, carry, lower, release, retreat), with grasp poses solved by IK on the scene's model
(:meth:`inspector.demo.scene.DemoScene.solve_grasp`); and the object layouts of the three tasks.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from .scene import DemoScene
from .scene_mjcf import BOWL_FLOOR, CUBE_HALF, CUBES, Layout
from .waypoints import GRIPPER_CLOSED, GRIPPER_OPEN, REST_POSE, Waypoint

# Heights [m] of the grasp point between the pads above a cube's centre: the pads pinch the
# cube's upper half; "hover" is where the arm pauses before going straight down.
GRASP_ABOVE_CENTRE = 0.008
HOVER_ABOVE_CENTRE = 0.075
CARRY_HEIGHT = 0.12  # [m] of the grasp point above the table while carrying
RELEASE_DROP = 0.004  # [m] a placed cube is let go this far above where it will rest


def tangential_yaw(xy: Sequence[float]) -> float:
    """Cube yaw [rad] whose faces square up with an arm reaching from the base to ``xy``."""
    return float(np.arctan2(xy[1], xy[0]))


def default_layouts() -> dict[str, Layout]:
    """The object layouts of the three demo tasks; cubes square to the arm's reach."""
    pick = Layout(red_cube=(0.23, -0.06), blue_cube=(0.25, 0.10), bowl=(0.12, 0.19))
    bowl = Layout(red_cube=(0.24, -0.09), blue_cube=(0.28, 0.06), bowl=(0.16, 0.16))
    stack = Layout(red_cube=(0.20, -0.11), blue_cube=(0.25, 0.07), bowl=(0.10, 0.20))
    return {
        name: replace(lay, red_yaw=tangential_yaw(lay.red_cube), blue_yaw=tangential_yaw(lay.blue_cube))
        for name, lay in (("pick", pick), ("place_in_bowl", bowl), ("stack", stack))
    }


class _Planner:
    """Grasp-point targets -> joint poses, with one approach tilt per vertical line.

    Keeping the tilt fixed along a descent keeps the jaws' attitude fixed while they go down,
    as a careful operator would; the least tilt that reaches the top of the line is used.
    """

    def __init__(self, scene: DemoScene):
        self.scene = scene
        self.seed: npt.NDArray[np.float64] | None = None

    def vertical_line(
        self, xy: Sequence[float], heights: Sequence[float] | npt.NDArray[np.float64], jaw_yaw: float, gripper: float
    ) -> list[npt.NDArray[np.float64]]:
        """Poses (dataset units) with the grasp point at ``xy`` and each height [m], top first."""
        for tilt_deg in range(0, 61, 5):
            try:
                poses, seed = [], self.seed
                for z in sorted(heights, reverse=True):
                    seed = self.scene.solve_grasp((*xy, z), jaw_yaw, gripper, np.deg2rad(tilt_deg), seed)
                    poses.append(seed)
            except ValueError:
                continue
            self.seed = poses[-1]
            order = np.argsort(np.argsort(-np.asarray(heights)))  # back to the caller's order
            return [poses[i] for i in order]
        raise ValueError(f"no grasp pose reaches {list(xy)} at heights {list(heights)}")

    def descent(self, xy: Sequence[float], z_top: float, z_bottom: float, jaw_yaw: float,
                gripper: float, n: int = 4) -> npt.NDArray[np.float64]:
        """(n, 6) IK samples strictly between two heights: a straight vertical path between them."""
        heights = np.linspace(z_top, z_bottom, n + 2)[1:-1]
        return np.array(self.vertical_line(xy, heights, jaw_yaw, gripper))


def _jaw_yaw_for(cube_yaw: float, xy: Sequence[float]) -> float:
    """The cube face direction (cube_yaw + k * 90 deg) closest to the arm's tangential direction.

    The jaws then close across the arm's reach, where the wrist can tilt about the jaw axis.
    """
    tangential = tangential_yaw(xy) + np.pi / 2
    k = np.round((tangential - cube_yaw) / (np.pi / 2))
    return float(cube_yaw + k * np.pi / 2)


def pick_and_place_motion(
    scene: DemoScene,
    cube_xy: Sequence[float],
    cube_yaw: float,
    place_xy: Sequence[float],
    place_centre_z: float,
    show_s: float = 0.0,
    speed: float = 1.0,
) -> list[Waypoint]:
    """Rest -> hover -> descend -> grasp -> lift -> carry -> lower -> release -> retreat -> rest.

    Args:
        scene: the scene whose model solves the IK.
        cube_xy: (2,) the cube's centre on the table [m].
        cube_yaw: the cube's yaw [rad].
        place_xy: (2,) where the cube's centre goes [m].
        place_centre_z: height of the cube's centre where it will rest [m].
        show_s: pause with the cube lifted [s].
        speed: time scale of every move (2 = twice as fast).

    Returns:
        Waypoints in dataset units, 16-19 s in all at speed 1.
    """
    plan = _Planner(scene)
    pick_yaw = _jaw_yaw_for(cube_yaw, cube_xy)
    # The cube turns with the gripper: place it with the jaws across the arm's reach again.
    place_yaw = pick_yaw + (tangential_yaw(place_xy) - tangential_yaw(cube_xy))
    grasp_z, hover_z = CUBE_HALF + GRASP_ABOVE_CENTRE, CUBE_HALF + HOVER_ABOVE_CENTRE
    hover, grasp = plan.vertical_line(cube_xy, (hover_z, grasp_z), pick_yaw, GRIPPER_OPEN)
    down = plan.descent(cube_xy, hover_z, grasp_z, pick_yaw, GRIPPER_OPEN)
    up = plan.descent(cube_xy, grasp_z, CARRY_HEIGHT, pick_yaw, GRIPPER_CLOSED)
    (lifted,) = plan.vertical_line(cube_xy, (CARRY_HEIGHT,), pick_yaw, GRIPPER_CLOSED)
    release_z = place_centre_z + GRASP_ABOVE_CENTRE + RELEASE_DROP
    above_place, release = plan.vertical_line(place_xy, (CARRY_HEIGHT, release_z), place_yaw, GRIPPER_CLOSED)
    lower = plan.descent(place_xy, CARRY_HEIGHT, release_z, place_yaw, GRIPPER_CLOSED)
    retreat_z = release_z + HOVER_ABOVE_CENTRE - GRASP_ABOVE_CENTRE
    (retreat,) = plan.vertical_line(place_xy, (retreat_z,), place_yaw, GRIPPER_OPEN)
    rise = plan.descent(place_xy, release_z, retreat_z, place_yaw, GRIPPER_OPEN)
    gripped = lambda q, g: np.r_[q[:5], g]  # noqa: E731 - same arm pose, other gripper value

    s = 1.0 / speed
    return [
        Waypoint(REST_POSE, hold_s=1.0 * s, phase="rest"),
        Waypoint(hover, 2.4 * s, 0.3 * s, "reach"),
        Waypoint(grasp, 1.4 * s, 0.2 * s, "descend", via=down),
        Waypoint(gripped(grasp, GRIPPER_CLOSED), 0.8 * s, 0.4 * s, "grasp"),
        Waypoint(lifted, 1.4 * s, show_s * s, "lift", via=up),
        Waypoint(above_place, 2.0 * s, 0.2 * s, "carry"),
        Waypoint(release, 1.4 * s, 0.2 * s, "lower", via=lower),
        Waypoint(gripped(release, GRIPPER_OPEN), 0.6 * s, 0.3 * s, "release"),
        Waypoint(retreat, 1.0 * s, 0.0, "retreat", via=rise),
        Waypoint(REST_POSE, 2.4 * s, 1.0 * s, "return"),
    ]


def pick_motion(
    scene: DemoScene,
    layout: Layout | None = None,
    cube: str = "red_cube",
    put_down_xy: Sequence[float] | None = None,
) -> list[Waypoint]:
    """Pick up ``cube``, hold it up for a moment, set it down at ``put_down_xy``, return to rest.

    ``put_down_xy`` defaults to 7 cm nearer the arm's centre line than where the cube was.
    """
    layout = layout or scene.layout
    xy, yaw = _cube_xy_yaw(layout, cube)
    if put_down_xy is None:
        put_down_xy = (xy[0] - 0.02, xy[1] - np.sign(xy[1]) * 0.07)
    return pick_and_place_motion(scene, xy, yaw, put_down_xy, CUBE_HALF, show_s=1.5)


def place_in_bowl_motion(
    scene: DemoScene, layout: Layout | None = None, cube: str = "red_cube"
) -> list[Waypoint]:
    """Pick up ``cube`` and drop it into the bowl."""
    layout = layout or scene.layout
    xy, yaw = _cube_xy_yaw(layout, cube)
    # Let go a little above the bowl's floor: it falls the last centimetre, as a real one would.
    return pick_and_place_motion(scene, xy, yaw, layout.bowl, BOWL_FLOOR + CUBE_HALF + 0.01)


def stack_motion(
    scene: DemoScene, layout: Layout | None = None, cube: str = "red_cube", onto: str = "blue_cube"
) -> list[Waypoint]:
    """Pick up ``cube`` and stack it on ``onto``."""
    layout = layout or scene.layout
    xy, yaw = _cube_xy_yaw(layout, cube)
    onto_xy, _ = _cube_xy_yaw(layout, onto)
    return pick_and_place_motion(scene, xy, yaw, onto_xy, 3 * CUBE_HALF)


def _cube_xy_yaw(layout: Layout, cube: str) -> tuple[tuple[float, float], float]:
    if cube == "red_cube":
        return layout.red_cube, layout.red_yaw
    if cube == "blue_cube":
        return layout.blue_cube, layout.blue_yaw
    raise ValueError(f"unknown cube {cube!r}; cubes: {list(CUBES)}")
