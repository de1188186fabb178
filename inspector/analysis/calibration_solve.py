"""A fixed camera from clicks: known 3D points of the arm and the pixels they were seen at.

The solve (:func:`solve_fixed_camera`), in three steps:

1. **A starting pose** that needs no good geometry: the clicks of an arm are often close to one
   plane (a pick moves the arm in a vertical plane), where a linear solve (the DLT) falls apart
   under a few pixels of noise. So cameras are placed around the points instead (24 directions on
   a sphere, 4 rolls each, at the distance the points' spread in pixels suggests for the
   field-of-view guess), each pose refined with a robust loss (soft L1, so one wild click cannot
   drag it), and the best kept.
2. **RANSAC** against a bad click (Fischler & Bolles, 1981): minimal samples of 6 points each
   refit the pose and focal length from that start; the fit that reprojects the most points
   within :data:`RANSAC_THRESHOLD_PX` wins (ties: the smaller summed error).
3. **Refinement** by nonlinear least squares (``scipy.optimize.least_squares``, Levenberg-Marquardt)
   of the pose (a rotation vector and a translation) and the focal length (square pixels) on the
   winner's points, minimising the reprojection error in pixels. The principal point stays at the
   image centre unless asked for (``fit_principal_point``; then with a weak prior at the centre,
   :data:`PRINCIPAL_POINT_PRIOR` of the image side): clicks on an arm seen from one side leave it
   nearly undetermined, and freeing it doubles the position error on the demo. A point whose
   residual is past ``reject_px`` is left out and the rest refitted, until none is.

The reprojection error reported is the root mean square of the used points' pixel distances.
No lens distortion is fitted.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from ..robot.camera import Camera, intrinsics_from_fovy

MIN_POINTS = 6  # a 3x4 projection has 11 degrees of freedom: 6 points give 12 equations
RANSAC_THRESHOLD_PX = 12.0  # a hypothesis' inlier: reprojected this close, in its own DLT camera
PRINCIPAL_POINT_PRIOR = 0.1  # sd of the principal point's prior, as a fraction of the image side
DEFAULT_FOVY_DEG = 55.0  # a typical USB camera's vertical field of view; refined by the solve


@dataclass
class CalibrationResult:
    """A solved camera and how well it explains the clicks.

    Attributes:
        camera: the fixed camera (``T_base_camera``, OpenCV axes).
        reprojection_error_px: root mean square pixel distance over the points used [px].
        used: indices (into the input) of the points used.
        rejected: indices of the points left out (past ``reject_px``, or outside RANSAC's consensus).
        residuals_px: (N,) pixel distance of every input point under ``camera`` (NaN behind it).
    """

    camera: Camera
    reprojection_error_px: float
    used: list[int]
    rejected: list[int]
    residuals_px: npt.NDArray[np.float64] = field(repr=False)


class CalibrationFailed(ValueError):
    """The points do not determine a camera (too few, degenerate, or no consensus)."""


def solve_fixed_camera(points_base: npt.ArrayLike, uv: npt.ArrayLike, width: int, height: int,
                       fovy_guess_deg: float = DEFAULT_FOVY_DEG, reject_px: float = 10.0,
                       fit_principal_point: bool = False, seed: int = 0) -> CalibrationResult:
    """Solve a fixed camera from 3D points [m, base frame] and their pixels [px].

    Args:
        points_base: (N, 3) the arm's named points at the clicked frames (FK of the GT joints).
        uv: (N, 2) where they were clicked (OpenCV pixel centres).
        width, height: the image size [px].
        fovy_guess_deg: vertical field of view to start from [deg].
        reject_px: a point farther than this from its reprojection is left out [px].
        fit_principal_point: fit the principal point too (default: held at the image centre,
            where a camera's usually lies within a few pixels; clicks on an arm seldom pin it down).
        seed: RANSAC's random seed (the result depends only on the inputs and it).

    Raises:
        CalibrationFailed: fewer than :data:`MIN_POINTS` points, or fewer left after rejection,
            or points that determine no camera (all on one plane or line).
    """
    X = np.asarray(points_base, np.float64).reshape(-1, 3)
    x = np.asarray(uv, np.float64).reshape(-1, 2)
    n = len(X)
    if n < MIN_POINTS:
        raise CalibrationFailed(f"{n} points: at least {MIN_POINTS} are needed")
    K0 = intrinsics_from_fovy(fovy_guess_deg, width, height)
    start = _starting_pose(X, x, K0)
    inliers, params = _ransac(start, X, x, np.random.default_rng(seed))
    if inliers.sum() < MIN_POINTS:
        raise CalibrationFailed(f"no camera explains {MIN_POINTS} of the {n} points within "
                                f"{RANSAC_THRESHOLD_PX:g} px (too many bad clicks, or the points lie on a line)")
    while True:
        params = _refine(params, X[inliers], x[inliers], width, height, fit_principal_point)
        residuals = _residuals_px(params, X, x)
        worst = np.where(inliers, np.nan_to_num(residuals, nan=np.inf), -np.inf)
        if worst.max() <= reject_px:
            break
        inliers[int(np.argmax(worst))] = False  # the worst point out, then refit
        if inliers.sum() < MIN_POINTS:
            raise CalibrationFailed(f"fewer than {MIN_POINTS} points left within {reject_px:g} px of the "
                                    "solved camera")
    camera = _camera(params, width, height)
    used = np.flatnonzero(inliers)
    rms = float(np.sqrt(np.mean(residuals[used] ** 2)))
    return CalibrationResult(camera, rms, used.tolist(), np.flatnonzero(~inliers).tolist(), residuals)


# ---------------------------------------------------------------------------------------------
# A starting pose and RANSAC

N_DIRECTIONS, N_ROLLS = 24, 4
RANSAC_SAMPLES = 60


def _starting_pose(X: npt.NDArray[np.float64], x: npt.NDArray[np.float64], K: npt.NDArray[np.float64]
                   ) -> npt.NDArray[np.float64]:
    """[rotation vector, translation, f, cx, cy] (world to camera) of the best of the cameras
    placed around the points, each refined robustly with ``K``'s intrinsics held."""
    from scipy.optimize import least_squares

    centre = X.mean(axis=0)
    spread_3d = float(np.sqrt(((X - centre) ** 2).sum(axis=1).mean()))
    spread_2d = float(np.sqrt(((x - x.mean(axis=0)) ** 2).sum(axis=1).mean()))
    distance = K[0, 0] * max(spread_3d, 1e-3) / max(spread_2d, 1.0)
    intrinsics = np.array([K[0, 0], K[0, 2], K[1, 2]])
    best, best_cost = None, np.inf
    for direction in _sphere(N_DIRECTIONS):
        for roll in range(N_ROLLS):
            R = _look_at(centre + distance * direction, centre, roll * np.pi / 2)
            pose = np.r_[_rotvec(R), -R @ (centre + distance * direction)]
            fit = least_squares(lambda p: (_project(np.r_[p, intrinsics], X) - x).ravel(), pose,
                                loss="soft_l1", f_scale=RANSAC_THRESHOLD_PX / 2, max_nfev=200)
            if fit.cost < best_cost and _in_front(np.r_[fit.x, intrinsics], X):
                best, best_cost = fit.x, fit.cost
    if best is None:
        raise CalibrationFailed("no camera in front of the points explains them")
    return np.r_[best, intrinsics]


def _ransac(start: npt.NDArray[np.float64], X: npt.NDArray[np.float64], x: npt.NDArray[np.float64],
            rng: np.random.Generator) -> tuple[npt.NDArray[np.bool_], npt.NDArray[np.float64]]:
    """(inliers, params): the largest consensus set of :data:`RANSAC_SAMPLES` minimal samples,
    each refitting the pose and focal length from ``start``; the sample's params come with it."""
    from scipy.optimize import least_squares

    n = len(X)
    principal = start[7:9]
    best, best_params, best_cost = np.zeros(n, bool), start, np.inf
    for _ in range(RANSAC_SAMPLES if n > MIN_POINTS else 1):
        sample = rng.choice(n, MIN_POINTS, replace=False)
        fit = least_squares(lambda p: (_project(np.r_[p, principal], X[sample]) - x[sample]).ravel(),
                            start[:7], max_nfev=200)
        params = np.r_[fit.x, principal]
        error = np.nan_to_num(_residuals_px(params, X, x), nan=np.inf)
        inliers = error <= RANSAC_THRESHOLD_PX
        cost = np.minimum(error, RANSAC_THRESHOLD_PX).sum()
        if inliers.sum() > best.sum() or (inliers.sum() == best.sum() and cost < best_cost):
            best, best_params, best_cost = inliers, params, cost
    return best, best_params


def _sphere(n: int) -> npt.NDArray[np.float64]:
    """(n, 3) unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5 ** 0.5) * i
    r = np.sqrt(1 - z * z)
    return np.c_[r * np.cos(phi), r * np.sin(phi), z]


def _look_at(eye: npt.NDArray[np.float64], target: npt.NDArray[np.float64], roll: float) -> npt.NDArray[np.float64]:
    """(3, 3) world-to-camera rotation (OpenCV axes) of a camera at ``eye`` looking at ``target``,
    turned by ``roll`` [rad] about its axis from upright (world z up in the image)."""
    forward = (target - eye) / np.linalg.norm(target - eye)
    up = np.array([0.0, 0.0, 1.0]) if abs(forward[2]) < 0.99 else np.array([1.0, 0.0, 0.0])
    right = np.cross(forward, up)
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    c, s = math.cos(roll), math.sin(roll)
    return np.array([c * right + s * down, -s * right + c * down, forward])


def _in_front(params: npt.NDArray[np.float64], X: npt.NDArray[np.float64]) -> bool:
    return bool(np.median((X @ _rotation(params[:3]).T + params[3:6])[:, 2]) > 0)


# ---------------------------------------------------------------------------------------------
# The nonlinear refinement


def _refine(params: npt.NDArray[np.float64], X: npt.NDArray[np.float64], x: npt.NDArray[np.float64],
            width: int, height: int, fit_principal_point: bool) -> npt.NDArray[np.float64]:
    """Least squares of the pose and focal length (and the principal point, with its prior)."""
    from scipy.optimize import least_squares

    centre = np.array([(width - 1) / 2, (height - 1) / 2])
    prior_sd = PRINCIPAL_POINT_PRIOR * np.array([width, height])
    scale = np.r_[np.full(3, 0.1), np.full(3, 0.05), params[6] * 0.1, prior_sd]
    if not fit_principal_point:
        def held(p: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
            return (_project(np.r_[p, centre], X) - x).ravel()
        fit = least_squares(held, params[:7], method="lm", x_scale=scale[:7], max_nfev=2000)
        return np.r_[fit.x, centre]

    def residuals(p: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
        return np.r_[(_project(p, X) - x).ravel(), (p[7:9] - centre) / prior_sd]

    fit = least_squares(residuals, params, method="lm", x_scale=scale, max_nfev=2000)
    return np.asarray(fit.x, np.float64)


def _project(p: npt.NDArray[np.float64], X: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    p_cam = X @ _rotation(p[:3]).T + p[3:6]
    z = np.where(np.abs(p_cam[:, 2]) < 1e-9, 1e-9, p_cam[:, 2])
    return p_cam[:, :2] / z[:, None] * p[6] + p[7:9]


def _residuals_px(p: npt.NDArray[np.float64], X: npt.NDArray[np.float64], x: npt.NDArray[np.float64]
                  ) -> npt.NDArray[np.float64]:
    """Pixel distance of each point's reprojection; NaN for a point behind the camera."""
    p_cam = X @ _rotation(p[:3]).T + p[3:6]
    error = np.linalg.norm(_project(p, X) - x, axis=1)
    return np.where(p_cam[:, 2] > 0, error, np.nan)


def _camera(p: npt.NDArray[np.float64], width: int, height: int) -> Camera:
    R_camera_base = _rotation(p[:3])
    T = np.eye(4)
    T[:3, :3] = R_camera_base.T
    T[:3, 3] = -R_camera_base.T @ p[3:6]
    K = np.array([[p[6], 0.0, p[7]], [0.0, p[6], p[8]], [0.0, 0.0, 1.0]])
    return Camera(width, height, K, T_base_camera=T, source="inspector calibrate")


def _rotation(r: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    """Rodrigues: (3,) rotation vector [rad] -> (3, 3)."""
    theta = float(np.linalg.norm(r))
    if theta < 1e-12:
        return np.eye(3)
    k = r / theta
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * Kx + (1 - math.cos(theta)) * Kx @ Kx


def _rotvec(R: npt.NDArray[np.float64]) -> npt.NDArray[np.float64]:
    from scipy.spatial.transform import Rotation

    return np.asarray(Rotation.from_matrix(R).as_rotvec(), np.float64)


__all__ = ["CalibrationFailed", "CalibrationResult", "DEFAULT_FOVY_DEG", "MIN_POINTS", "solve_fixed_camera"]
