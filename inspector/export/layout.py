"""What goes where in an exported recording: entity paths, colours, and the one default blueprint.

Entity tree::

    /description                      TextDocument (markdown, static)
    /world/gt_arm/...                 GT arm from the URDF (opaque), frames "gt/<link>"
    /world/pred_arm/...               predicted arm (translucent), frames "pred/<link>"
    /world/ee_path/{gt,pred}          tool-point paths (LineStrips3D, static)
    /world/ee/{gt,pred}               tool point now (Points3D over time)
    /world/chunk_trail                the current chunk's whole predicted horizon
    /world/limit_violations           tool point wherever a joint is past its limit (static)
    /tf/{gt,pred}/<joint>             joint transforms over time (send_columns)
    /video/<view>/{imagined,gt}       AssetVideo + VideoFrameReference
    /plots/drift/...                  time-aligned, best-match, DTW drift, speed mismatch, path error
    /plots/joint_error/<joint>        prediction - GT per joint
    /plots/joints/<joint>/...         predicted, GT, limits, limit-violation markers
    /plots/ee_error_mm, /plots/psnr/<view>, /plots/chunk_rmse
    /plots/gt_time/<view>/{video,joints,split,no_match}, /plots/lag/<view>   video-action agreement
    /plots/markers/episode_end
    /events                           TextLog at chunk boundaries and the episode's end

Timelines: ``time`` (duration, s), ``frame`` (imagined frame), ``chunk``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
import rerun as rr
import rerun.blueprint as rrb

from ..analysis.timeline import RolloutTimeline
from ..units import JOINT_NAMES

TIME, FRAME, CHUNK = "time", "frame", "chunk"

DESCRIPTION = "description"
WORLD = "world"
WORLD_FRAME = "tf#/world"  # the implicit frame of /world, which the 3D view looks from
ARM_KEYS = ("gt", "pred")
EVENTS = "events"
PLOTS = "plots"
MARKERS = f"{PLOTS}/markers"


def arm_root(arm: str) -> str:
    """Entity of an arm's URDF tree (``UrdfTree`` puts it at ``<prefix>/<robot name>``)."""
    return f"{WORLD}/{arm_robot_name(arm)}"


def arm_robot_name(arm: str) -> str:
    return f"{arm}_arm"


def arm_frame_prefix(arm: str) -> str:
    return f"{arm}/"


def joint_transform_path(arm: str, joint: str) -> str:
    return f"tf/{arm}/{joint}"


def ee_path(arm: str) -> str:
    return f"{WORLD}/ee_path/{arm}"


def ee_now(arm: str) -> str:
    return f"{WORLD}/ee/{arm}"


CHUNK_TRAIL = f"{WORLD}/chunk_trail"
LIMITS_3D = f"{WORLD}/limit_violations"


def video_path(view: str, source: str) -> str:
    """``source``: ``"imagined"`` or ``"gt"``."""
    return f"video/{view}/{source}"


# Colours (RGBA). GT keeps the URDF's printed-part yellow; the prediction is translucent blue.
GT_RGBA = (235, 160, 30, 255)
PRED_RGBA = (60, 130, 255, 255)
PRED_MESH_RGBA = {"printed": (0.25, 0.55, 1.0, 0.45), "servo": (0.08, 0.2, 0.5, 0.45)}
PRED_MESH_DEFAULT = (0.25, 0.55, 1.0, 0.45)
LIMIT_RGBA = (230, 40, 40, 255)
NO_MATCH_RGBA = (150, 150, 150, 255)  # a frame without a video-action lag
JOINT_RGBA = {
    "shoulder_pan": (31, 119, 180, 255),
    "shoulder_lift": (255, 127, 14, 255),
    "elbow_flex": (44, 160, 44, 255),
    "wrist_flex": (214, 39, 40, 255),
    "wrist_roll": (148, 103, 189, 255),
    "gripper": (140, 86, 75, 255),
}
VIEW_RGBA = [(31, 119, 180, 255), (44, 160, 44, 255), (214, 39, 40, 255), (148, 103, 189, 255)]

# name, entity, colour of each drift series
DRIFT_SERIES = (
    ("time_aligned_drift", f"{PLOTS}/drift/time_aligned", "time-aligned drift", (214, 39, 40, 255)),
    ("best_match_drift", f"{PLOTS}/drift/best_match", "best-match drift", (31, 119, 180, 255)),
    ("dtw_drift", f"{PLOTS}/drift/dtw", "DTW drift", (148, 103, 189, 255)),
    ("speed_mismatch", f"{PLOTS}/drift/speed_mismatch", "speed mismatch", (255, 127, 14, 255)),
    ("path_error", f"{PLOTS}/drift/path_error", "path error", (44, 160, 44, 255)),
)
JOINT_ERROR = f"{PLOTS}/joint_error"
EE_ERROR = f"{PLOTS}/ee_error_mm"
CHUNK_RMSE = f"{PLOTS}/chunk_rmse"


def joint_plot(joint: str, series: str) -> str:
    """``series``: pred, gt, lower_limit, upper_limit, limit_violation."""
    return f"{PLOTS}/joints/{joint}/{series}"


def psnr_path(view: str) -> str:
    return f"{PLOTS}/psnr/{view}"


def gt_time_path(view: str, series: str) -> str:
    """``series``: ``video`` (the video's GT time), ``joints`` (the joints'), ``split`` (the chunk
    from which they part), ``no_match`` (frames without a lag)."""
    return f"{PLOTS}/gt_time/{view}/{series}"


def lag_path(view: str) -> str:
    return f"{PLOTS}/lag/{view}"


def step_indexes(tl: RolloutTimeline, steps: npt.ArrayLike,
                 chunks: npt.ArrayLike | None = None) -> list[rr.TimeColumn]:
    """``time`` / ``frame`` / ``chunk`` columns for timeline steps (``chunks`` overrides the chunk)."""
    steps = np.asarray(steps, dtype=np.int64)
    frames = [tl.frame_index(int(s)) for s in steps]
    chunk = tl.step_chunk[steps] if chunks is None else np.asarray(chunks, dtype=np.int64)
    return [
        rr.TimeColumn(TIME, duration=tl.t_s[steps]),
        rr.TimeColumn(FRAME, sequence=frames),
        rr.TimeColumn(CHUNK, sequence=chunk),
    ]


@dataclass
class Contents:
    """What a recording holds, which decides the blueprint's panels.

    Attributes:
        views: camera views, each with ``(has_imagined, has_gt)``.
        gt_joints: the GT arm, drift and error plots exist.
        psnr_views: views with a PSNR series.
        agreement_views: views with video-action agreement series (GT times and lag).
        pred_name, gt_name: the arms' names in titles.
        chunks: the rollout has several chunks.
        eye: the 3D view's camera (position, look target) [m].
        joints: the rollout has joints; a video-only one has no 3D view and no joint plots.
        cameras: views with a camera in the scene (:mod:`inspector.export.cameras`): their frames
            are shown through it, with the arms projected into them.
    """

    views: dict[str, tuple[bool, bool]] = field(default_factory=dict)
    gt_joints: bool = False
    psnr_views: list[str] = field(default_factory=list)
    agreement_views: list[str] = field(default_factory=list)
    pred_name: str = "predicted"  # what the two arms are ("commanded" / "measured" for an episode)
    gt_name: str = "GT"
    chunks: bool = True  # more than one chunk (else no chunk RMSE plot)
    # the 3D view's eye: (position, look target) [m], fitted to everything drawn
    eye: tuple[tuple[float, float, float], tuple[float, float, float]] = ((0.55, -0.45, 0.4), (0.15, 0.0, 0.1))
    joints: bool = True
    cameras: list[str] = field(default_factory=list)


def _frames_view(view: str, source: str, name: str, through_camera: bool) -> rrb.Spatial2DView:
    """A view of one video: its frames alone, or, for a view with a camera, the frames under the
    camera (``/world/cameras/<view>/<source>``) with the arms of the scene projected into them."""
    if not through_camera:
        return rrb.Spatial2DView(name=name, origin=f"/{video_path(view, source)}")
    return rrb.Spatial2DView(name=name, origin=f"/{WORLD}/cameras/{view}",
                             contents=[f"+ $origin/{source}", f"+ /{WORLD}/**", f"- /{WORLD}/cameras/**",
                                       f"+ $origin/{source}"])


def build_blueprint(contents: Contents) -> rrb.Blueprint:
    """The recording's default layout: 3D arms and plots on the left, video pairs and notes right."""
    markers = f"/{MARKERS}/**"
    plots: list[rrb.View | rrb.Container] = []
    if contents.gt_joints:
        plots.append(rrb.TimeSeriesView(name="Drift", origin=f"/{PLOTS}/drift",
                                        contents=["$origin/**", markers]))
        plots.append(rrb.TimeSeriesView(name=f"Joint error ({contents.pred_name} - {contents.gt_name})",
                                        origin=f"/{JOINT_ERROR}",
                                        contents=["$origin/**", markers]))
        plots.append(rrb.TimeSeriesView(name="End-effector error [mm]", origin=f"/{EE_ERROR}",
                                        contents=["$origin", markers]))
    # two columns: three narrow plots a row cut the joint names short ("should...")
    plots += [] if not contents.joints else [rrb.Grid(*[rrb.TimeSeriesView(name=j, origin=f"/{PLOTS}/joints/{j}",
                                               contents=["$origin/**", markers],
                                               plot_legend=rrb.PlotLegend(visible=False))
                            for j in JOINT_NAMES], grid_columns=2, name="Joints")]
    if contents.psnr_views:
        plots.append(rrb.TimeSeriesView(name="Video PSNR [dB]", origin=f"/{PLOTS}/psnr",
                                        contents=["$origin/**", markers]))
    if contents.agreement_views:
        plots.append(rrb.TimeSeriesView(name="GT time: video vs joints [s]", origin=f"/{PLOTS}/gt_time",
                                        contents=["$origin/**", markers]))
        if contents.gt_joints:
            plots.append(rrb.TimeSeriesView(name="Video-action lag [s]", origin=f"/{PLOTS}/lag",
                                            contents=["$origin/**", markers]))
    if contents.gt_joints and contents.chunks:
        plots.append(rrb.TimeSeriesView(name="Chunk RMSE", origin=f"/{CHUNK_RMSE}",
                                        contents=["$origin", markers]))
    if contents.chunks:  # the sanity measures of chained rollouts (inspector/export/sanity_series.py)
        plots.append(rrb.TimeSeriesView(name="Chunk seams [deg]", origin=f"/{PLOTS}/seams",
                                        contents=["$origin/**", markers]))
        if contents.psnr_views:
            plots.append(rrb.TimeSeriesView(name="Video degradation (x chunk 0)", origin=f"/{PLOTS}/video_degradation",
                                            contents=["$origin/**", markers]))

    title = (f"Arms: {contents.gt_name} (opaque) vs {contents.pred_name} (translucent)" if contents.gt_joints
             else f"Arm: {contents.pred_name} (no GT joints)")
    scene = rrb.Spatial3DView(
        name=title, origin=f"/{WORLD}",
        contents=["$origin/**"],
        eye_controls=rrb.EyeControls3D(position=contents.eye[0], look_target=contents.eye[1],
                                       eye_up=(0.0, 0.0, 1.0)),
    )
    pairs = [
        rrb.Horizontal(*[_frames_view(view, src, f"{view} {label}", view in contents.cameras)
                         for src, label, present in (("imagined", "imagined", has[0]),
                                                     ("gt", "GT" if has[0] else "camera", has[1]))
                         if present], name=view)
        for view, has in contents.views.items()
    ]
    right: list[rrb.View | rrb.Container] = [*pairs, rrb.TextDocumentView(name="About", origin=f"/{DESCRIPTION}")]
    left = (rrb.Vertical(scene, rrb.Tabs(*plots, name="Plots"), row_shares=[3, 2]) if contents.joints
            else rrb.Vertical(rrb.Tabs(*plots, name="Plots")))  # video only: no arm to show in 3D
    layout = rrb.Horizontal(
        left,
        rrb.Vertical(*right, row_shares=[*([2] * len(pairs)), 2]),
        column_shares=[3, 2],
    )
    return rrb.Blueprint(
        layout,
        rrb.TimePanel(timeline=TIME, state="expanded"),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        auto_views=False,
    )
