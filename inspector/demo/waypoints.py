"""Joint-space waypoints and the smooth command through them: a minimum-jerk move between poses
(rest to rest, as a teleoperator's hand roughly moves), holds, and named phases kept per frame; and
the poses and gripper values the scripted motions start from and use.

Pure numpy (no MuJoCo): :meth:`inspector.demo.scene.DemoScene.simulate_episode` follows these, and
:mod:`inspector.demo.motions` writes them. All joint values are in dataset units (degrees, gripper
0..100), :data:`inspector.units.JOINT_NAMES` order.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

# Gripper values (0..100, 0 closed) used by the scripts: open wide enough to straddle a cube
# (pads ~60 mm apart), and the command below which the grasp weld may engage.
GRIPPER_OPEN = 50.0
GRIPPER_CLOSED = 0.0
GRIPPER_GRASP_BELOW = 15.0

# A folded rest pose close to a real SO-101's (dataset units: degrees, gripper 0..100).
REST_POSE: npt.NDArray[np.float64] = np.array([0.0, -99.0, 86.0, 68.0, 0.0, 2.0])
# Arm raised and open, looking at the table: the start of every scripted motion.
READY_POSE: npt.NDArray[np.float64] = np.array([0.0, -60.0, 55.0, 70.0, 0.0, 40.0])


@dataclass
class Waypoint:
    """A joint pose to reach, and how.

    Attributes:
        q: (6,) joint pose, dataset units (degrees, gripper 0..100), JOINT_NAMES order.
        move_s: seconds to get here from the previous waypoint (ignored for the first one).
        hold_s: seconds to stay here afterwards.
        phase: name of the motion that ends here (``"reach"``, ``"grasp"``...), kept per frame.
        via: (N, 6) poses the move passes through on the way (e.g. IK samples of a straight
            vertical descent), evenly spaced in path parameter; None for a straight joint-space move.
    """

    q: npt.NDArray[np.float64]
    move_s: float = 1.0
    hold_s: float = 0.0
    phase: str = ""
    via: npt.NDArray[np.float64] | None = None


def _min_jerk(tau: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Minimum-jerk time scaling: 0 -> 1 with zero velocity and acceleration at both ends."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


def _along_path(path: npt.NDArray[np.float64], s: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Points at path parameters ``s`` in [0, 1] on the polyline ``path`` (N, 6) -> (len(s), 6)."""
    x = s * (len(path) - 1)
    i = np.minimum(x.astype(int), len(path) - 2)
    f = (x - i)[:, None]
    return path[i] * (1.0 - f) + path[i + 1] * f


def waypoint_duration(waypoints: Sequence[Waypoint]) -> float:
    """Total time [s] of a waypoint list: the first hold, then every move and hold."""
    return waypoints[0].hold_s + sum(w.move_s + w.hold_s for w in waypoints[1:])


def commanded_trajectory(
    waypoints: Sequence[Waypoint], fps: float = 30.0
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.float64], npt.NDArray[np.str_]]:
    """Sample the smooth command through ``waypoints`` at ``fps``.

    Every move follows a minimum-jerk profile (rest to rest), as a human teleoperator's hand
    roughly does; holds keep the pose.

    Returns:
        (times, q, phase): (T,) [s] from 0, (T, 6) dataset units, (T,) phase names.
    """
    if not waypoints:
        raise ValueError("no waypoints")
    n = int(np.floor(waypoint_duration(waypoints) * fps + 1e-9)) + 1
    times = np.arange(n) / fps
    q = np.empty((n, 6))
    phase = np.empty(n, dtype=object)
    first = waypoints[0]
    q[:] = first.q
    phase[:] = first.phase
    t0, prev = first.hold_s, np.asarray(first.q, float)
    for w in waypoints[1:]:
        target = np.asarray(w.q, float)
        path = np.vstack([prev, *(() if w.via is None else np.asarray(w.via, float)), target])
        moving = (times >= t0) & (times < t0 + w.move_s)
        q[moving] = _along_path(path, _min_jerk((times[moving] - t0) / w.move_s))
        after = times >= t0 + w.move_s
        q[after] = target
        phase[times >= t0] = w.phase
        t0, prev = t0 + w.move_s + w.hold_s, target
    return times, q, phase.astype(str)
