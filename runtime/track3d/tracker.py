"""The Track3D loop (paper section IV): 2D tracker -> frustum -> 3D box estimator -> 2D-3D fusion.

    t = Track3D.create(camera, tracker="kcf", estimator="baseline")
    t.init(image, box2d, category)          # optionally points=... for an initial 3D box
    out = t.update(image, points)           # -> TrackResult(box2d, box2d_raw, box3d, status, ...)

Per frame: the 2D tracker gives A_2d; the frustum proposal takes the cloud's points whose
projection falls in A_2d (1 <= z <= 45 m); the estimator turns them into a 3D box; fusion
reports A = 0.3 A_proj + 0.7 A_2d and hands it back to the 2D tracker as its state for the
next frame (``correct(box)`` when the tracker has it: SiamFC moves its search centre and
size, OpenCV trackers ignore it by default, see trackers2d).

Nothing in the loop raises on bad sensor data: a lost 2D target is status "lost"; a frustum
too thin to estimate from (fewer than `min_points` points, or all of them within 1 cm of each
other, e.g. a quantised or stuck cloud) or an estimate that is not a finite box of positive size
is status "no_points", as is a frustum the estimator refuses (ValueError, e.g. points spanning
more than A3BoxNet answers for); the 3D box then keeps the last estimate (nan before the first one).
With ``depth_range_m`` (the depth sensor's maximum range, e.g. an AMCW ToF camera's unambiguous
range) a body whose returns stop at that range and cover less of it than the 2D box shows is
boxed from the image and its front face instead of by the estimator, and one whose returns
reach that range while covering the outline keeps the estimator's box made at least as deep as
the image's, and one whose returns had reached it and now give none (wholly past it) has its
last box carried by the 2D box instead of held (track3d.range_cut.carry_box; still "no_points"; at
the image border by the side of the 2D box in view, CARRY_AT_BORDER).
Each result also carries the 2D tracker's confidence (`score`, 0..1 or None), how many frames
the 3D box has been held (`held_frames`); after `lost_after` consecutive frames without a usable
estimate (or with a score below `min_score`) the status is "lost", except that a frame which a
2D tracker judging its own loss (a bool `lost` attribute, EdgeTrack) says it tracks is not bad
for want of points where the depth range can explain them: a body past a ToF camera's range is
in view, not lost (a frustum without a single return that the range cannot explain is the box on
empty space, and EMPTY_LOST_AFTER such frames in a row are "lost"). Conversely, when such
a tracker says "lost" but at least `evidence_points` depth returns remain in the frustum of the
last box (a sliver of the body at the image border), the frame is "no_points" (boxes held,
`num_points` the returns), not "lost"; it still counts towards `lost_after`. `skip()` / `update(None,
points)` coasts over a dropped frame. `get_state()` / `set_state()` checkpoint the tracker as
plain data; `describe()` says what it runs (names, options, model files with sha256).
Caller errors raise ValueError (the checks live in track3d.frames): update() or skip() before
init(), an image that is not (H, W, 3) uint8 or not the camera's size, a cloud that is not
(N, 3), a category that is not an integer in -1 .. categories - 1, an init box that is not
finite, has no positive size, does not overlap the image or is more than 10x the image.
"""
from __future__ import annotations

import time
import warnings
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np

from .body_views import BodyViews, BodyViewsParams, hold_back_face
from .dark_side import check_sun, dark_side_box, phase_deg, reach_dark_side
from .camera import Camera
from .estimators import BoxEstimator, create_estimator
from .first_box import FIRST_BOX_FADE, check_fade, with_first_depth
from .frames import (MAX_COORD_M, check_category, check_cloud, check_image, check_init_box, check_init_box3d,
                     is_integer)
from .frustum import Z_MAX, Z_MIN, extract_frustum_bounds
from .boxes import clip_box2d, fit_measured_faces, hold_cut_extent
from .sensor_options import (BODY_VIEWS, CONTAIN_SLACK_PX, DARK_SIDE, DROP_STRAY, EDGE_PAD, FIND_DEPTH_SLACK,
                             FIND_DEPTH_SIZE, FIND_MIN_RETURNS, FIND_SIZE_RATIO,
                             FRONT_FILTER,
                             FRONT_QUANTILE, FRUSTUM_MARGIN, FUSION_COVER, OUTLINE_SHARE, OUTLINE_SHARE_PHASE,
                             SECTION_LIMBS, SILHOUETTE, check_depth_sensor, sensor_options)
# the names this module exported before the tables moved to track3d.sensor_options: still
# importable from here, for callers of earlier releases
from .sensor_options import (DEPTH_SENSORS, frustum_margin_for, fusion_weight_for, measured_faces_for,
                             section_limbs_for, section_weight_for)
from .silhouette import contain, find_body, past_border, silhouette_box
from .fusion import WEIGHT_2D, WEIGHT_3D, fuse, fuse_section, limb_depths
from .range_cut import (CAP_FUSION_COVERAGE, DEPTH_RATIO, MAX_DEPTH_RATIO, MIN_COVERAGE, box_at_range, box_from_view,
                        carry_box, cut_ratio, deepen_to_view, lateral_coverage, reaches_range)
from .trackers2d import Tracker2D, create_tracker
from .unmatched_texture import trim_unmatched
from .stray_returns import drop_stray

__all__ = ["Track3D", "TrackResult", "cut_box", "measured_bounds", "STATUSES", "TRACKING", "NO_POINTS", "LOST", "STAGES",
           "MIN_POINTS",
           # from track3d.sensor_options, as before it existed
           "FRUSTUM_MARGIN", "frustum_margin_for", "fusion_weight_for", "section_weight_for", "section_limbs_for",
           "measured_faces_for", "sensor_options", "DEPTH_SENSORS", "check_depth_sensor"]

TRACKING, NO_POINTS, LOST = "tracking", "no_points", "lost"
STATUSES = (TRACKING, NO_POINTS, LOST)
STAGES = ("track2d", "frustum", "box3d", "fusion", "total")
MIN_POINTS = 16          # the fewest frustum points A3BoxNet was trained on
DEFAULT_TRACKER = "edgetrack"  # from_default's 2D tracker (faster and more accurate in 2D than SiamFC-edge)
MIN_SPREAD_M = 0.01      # a frustum whose points all lie within 1 cm holds no shape
LOST_AFTER = 10          # consecutive frames without a usable estimate (or below min_score) -> lost
# A 2D tracker that judges its own loss (EdgeTrack) says "lost" on the slivers of a body at the
# image border too (7-11,000 pixels of it in view). When at least this many depth returns remain
# in the frustum of the last box, the body is in view: the frame is held ("no_points"), not lost.
# On the held-out calibration sets the frames after an exit had 0 returns there (stereo: up to
# 32 false matches), the false "lost" flags 55 or more on 14 of 21 (Track3D's lost precision
# 0.86 -> 0.93 pooled over nine sets, recall unchanged). 0: off.
# A held frame whose 3D box was measured from the body's outline there (Track3D._held_outline)
# is not a bad frame either: the body is in view and measured. Counted bad, a body held at the
# border for 30 frames turned "lost" after LOST_AFTER while its 3D box followed it. EdgeTrack one
# pass, 300-frame calibration sets with images (ideal seed 13, ToF seed 37, flash-LiDAR seed 41;
# `track3d-sim generate --preset small --seed S --train 0 --test 12 --test-unseen 12 --frames 300
# --sensors X`), "lost" on absent frames / "lost" reported / absent frames, test and held-out
# shapes: ideal 20/45/20 -> 20/29/20 and 62/118/66 -> 62/66/66, ToF 34/36/34 -> 34/34/34 and
# 59/72/87 -> 59/70/87, flash-LiDAR 70/134/84 -> 70/81/84 and 34/39/34 -> 34/37/34 (lost
# precision pooled 0.63 -> 0.88, recall unchanged); boxes and AO_3d unchanged; the 60-frame
# accuracy set (27 + 27) and the stereo sets (no outline there) unchanged.
# With stereo depth the outline is the lit part (`outline_contain`): a held frame whose 3D box was
# measured from the frustum of the last box moved to hold the lit outline (Track3D._held_lit) is
# not a bad frame either. Counted bad, a README stereo long watch (seed 47, test 0005) turned
# "lost" for 65 frames while 17,000 returns showed the body in the last box (EdgeTrack had drifted
# off a half-lit body; lost precision 0.13 over the split). Stereo calibration sets with images
# (60-frame seeds 3, 9, 21 and 300-frame seed 43, 12 + 12 each), EdgeTrack one pass: lost on absent
# frames / reported / absent frames over the 300-frame set 33/36/36 -> 33/34/36 test and
# 105/138/106 -> 105/117/106 held-out shapes, the 60-frame sets unchanged; AO_3d pooled over the 96
# sequences 0.7071 -> 0.7072 (held frames counted good without the measured box: the same flags,
# 0.7071).
EVIDENCE_POINTS = 48
MIN_CLOUD_CAP = 1000   # the least max_cloud_points: a thinner cloud would not box a body
# A frame EdgeTrack calls lost while the depth's outline at its last box holds the body in view
# (at least RESUME_SHARE of that box's area in the image, not cut by the image border on one side
# only, returns short of the sensor's range) is not held with the last 2D box: with
# `resume_outline` the loop goes on from the outline as from the tracker's box (the tracker is
# corrected onto it) and the frame is tracked. EdgeTrack called a large body lost for 55 frames
# while the flash LiDAR's outline followed it and NanoTrack v2 kept it (300-frame calibration set,
# flash-LiDAR seed 41, test 0008: held 2D box, IoU_2d 0.96 -> 0.44; AO_3d 0.748 -> 0.782, NanoTrack
# 0.790). An outline cut on one side only is a body coming into view or leaving it: resumed there
# (ToF seed 37, held-out 0008, a body coming back in at the left border), the frames fed the loop's
# running depth extent and views a partial body's, and the box stayed 0.3-0.4 m too deep for 80
# frames (-0.073); cut on both sides, the body is larger than the view along that axis (seed 41's
# spans the image's height). EdgeTrack one pass, 300-frame calibration sets with images, AO_3d
# test / held-out shapes: ideal seed 13 0.9255 -> 0.9275, 0.8826 -> 0.8838, flash-LiDAR seed 41
# 0.8803 -> 0.8831, 0.8628 -> 0.8628, ToF seed 37 0.7635 -> 0.7635, 0.7564 -> 0.7564 (3 sequences
# up by +0.015 to +0.034, none down; pooled over 72 0.8452 -> 0.8462). The 60-frame ideal accuracy
# set (27 + 27) did not move. A smaller outline is a sliver of a body at the border: corrected
# onto it, EdgeTrack did not re-acquire the body when it came back whole (EVIDENCE_POINTS'
# notes), so that frame stays held.
# Stereo (the outline is the lit part, `outline_contain`): the frame goes on from the last box
# moved onto the lit outline when that outline passes the same tests. EdgeTrack called a half-lit
# body lost and its held 2D box stayed put for 74 frames (README stereo long watch, test 0005:
# IoU_2d 0.53-0.81 while the body moved on; 0.91-0.99 resumed). Chosen on the stereo calibration
# sets (300-frame seed 43 and 60-frame seed 3, 12 + 12 each), EdgeTrack one pass: AO_3d 0.7428 ->
# 0.7428 test, 0.7035 -> 0.7037 held-out shapes (2 sequences up by 0.001-0.002, none down), the
# 60-frame set level.
RESUME_SHARE = 0.5


# A frame a 2D tracker judging its own loss says it tracks, with no depth return at all in its
# frustum, is not bad for want of points only when the depth sensor's range can explain the
# empty frustum: the sensor has one and the last 3D box reaches EMPTY_RANGE_SHARE of it along its
# centre ray, or there is no 3D box yet (a body past a ToF camera's range from the start). Else
# the box is on empty space (EdgeTrack held a box on the sky for 9-12 frames after a body's exit)
# and EMPTY_LOST_AFTER such frames in a row are "lost". EdgeTrack one pass on the calibration sets
# with images (300 frames: ideal seed 13, ToF seed 37, flash-LiDAR seed 41; 60 frames: the ideal
# accuracy set, stereo seeds 3 and 9; 12 + 12 or 27 + 27 sequences each), "lost" on absent frames /
# "lost" reported / absent frames pooled over the twelve splits 388 / 437 / 463 -> 414 / 464 /
# 463: recall 0.84 -> 0.89, precision 0.888 -> 0.892, boxes and AO_3d unchanged (flash-LiDAR test
# 70 / 81 -> 82 / 93, stereo seed 3 test 19 / 19 -> 25 / 25; one false flag more, stereo seed 9).
# Without the range test (an empty frustum never excused) ToF bodies past the range from the
# start were "lost": ToF test 34 / 34 -> 34 / 105. At 10 frames (LOST_AFTER) instead of 3 the
# absent stretches were mostly over first.
EMPTY_LOST_AFTER = 3
EMPTY_RANGE_SHARE = 0.8

# A body carried past the depth range that reaches the image border (its 2D box there spans the
# part in view) follows the side of the 2D box not at the border, its depth kept (range_cut.carry_box
# with the boxes' border sides), frame to frame from the last clear pair; the next clear frame is
# carried from that pair again, as before. It had been held where it was, while the 2D box slid
# off the image (ToF calibration seed 1203, held-out 0001: 5 m behind the body in 4 frames).
# Measured on the ToF calibration sets of seeds 1203 / 3 / 9 (12 + 12 x 60 frames, oracle 2D boxes
# and EdgeTrack, one pass, both splits: twelve AO_3d; no parameter): mean 0.7892 -> 0.7916, no row
# down, no sequence down by more than 0.002; held-out shapes EdgeTrack 0.7478 -> 0.7535 / 0.7897 ->
# 0.7908 / 0.8113 -> 0.8113, oracle 0.7490 -> 0.7577 / 0.8035 -> 0.8068 / 0.8264 -> 0.8288.
# Carrying the border frames on to the clear ones (the chain unbroken) lost that (EdgeTrack held-out
# seed 1203 0.7478 -> 0.7337: a border box's wrong side moved the box for good).
CARRY_AT_BORDER = True
# A body carried past the depth range (range_cut.carry_box) is carried from the last estimate
# whose returns reached the range; a 2D box at the image border with less than this share of the
# area of the last such box clear of the border is a sliver of the body, not its size in the
# image, and is not carried from (the clear one is kept).
CARRY_SLIVER = 0.5
# A body carried from a pair at the image border (its 2D box there larger than a sliver) to a clear
# 2D box had its depth scaled by the cut box's size, as if that were the body's in the image: a
# held-out body of the README's ToF long watch (0008), wholly past the range when it came back
# into view, was carried 28.1 m away for 35.0 m. The pair's box now moves across the line of sight
# with the side not at the border, and its depth scales from the size the body's 2D box would have
# had there: the last clear one's, by its depth over the pair's, or the cut box's own where larger
# (a tracker that keeps its box's size at the border; `_carry_area`, `_carry_area_z`; none known:
# the depth is kept; range_cut.carry_box's `last_whole`). Measured in docs/runtime.md.
CARRY_CUT_FROM_CLEAR = True
# A held frame measured from the outline (the 2D tracker calls the body lost, the depth holds it
# there: a sliver at the image border) is measured as a tracked frame is: its returns go into the
# past views and a views model is given them. Before, a views model ran there without its views
# and the views missed the frame, so a tracker that judges its loss (EdgeTrack) and one that does
# not (NanoTrack v2, tracking on) left the same outline with different 3D boxes (README flash-LiDAR
# test 0003 at the top border: 12.93 vs 12.74 m wide, then apart for the rest of the sequence).
HELD_VIEWS = True
# A body that gives no return in the caller's first 2D box, with a depth range known (a ToF
# camera's 30 m), is past the range from the start: it had no 3D box at all (every frame empty,
# AO_3d 0 over the sequence; ToF calibration seed 9, test 0005, a body 16 m long centred at 32 m).
# It is boxed at the range (range_cut.box_at_range: the nearest it can be) and carried by the 2D
# box as a body gone past it is; its first returns replace that box. Status stays "no_points".
BOX_AT_RANGE = True
# Inside the loop a lost 2D tracker that judges its own loss takes a candidate only at this
# score or above (its `reacquire_threshold`, raised to this, never lowered; None: the tracker's
# own). Right after an exit its wide search is mostly pad and empty sky, whose edge scored
# 0.74-0.88 on held-out sequences; the frames a hesitant re-acquisition leaves lost while the
# body is back are held by the depth check above. On the nine calibration sets, Track3D's lost
# precision / recall 0.932 / 0.868 -> 0.941 / 0.945, AO_3d level (EdgeTrack alone in 2D keeps
# its lost threshold: without the depth it would stay lost on returning bodies).
REACQUIRE_THRESHOLD = 0.9
# The hidden depth of the body (the reported box's extent along the line of sight, its front
# face kept) is averaged over frames: the estimator guesses it afresh from each frame's view while
# the body turns slowly (degrees per second), so frame-to-frame differences are mostly its noise.
# new = s * previous + (1 - s) * this frame's; 0 = off. Only for an amodal estimator's box (a
# plug-in's box is reported as it is). Measured one pass on held-out train-like sequences,
# EdgeTrack + A3BoxNet, AO_3d at s = 0 / 0.5 / 0.7 / 0.85: ideal seeds 3 / 4 0.8891 / 0.8922 /
# 0.8915 / 0.8882, 0.8687 / 0.8713 / 0.8690 / 0.8620; ToF seeds 3 / 5 0.7238 / 0.7263 / 0.7252 /
# 0.7206, 0.7481 / 0.7521 / 0.7539 / 0.7562; stereo seeds 3 / 5 0.6878 / 0.6930 / 0.6916 /
# 0.6876, 0.6027 / 0.6089 / 0.6069 / 0.6020; confirmed on ideal seed 7 (24 sequences) 0.8884 /
# 0.8909 and flash-LiDAR seeds 3 / 5 0.8662 / 0.8698, 0.8101 / 0.8128 (s = 0 / 0.5). Averaging
# the centre depth too (the front face with it) lags the approach: ideal seed 3 0.870 at 0.5;
# the whole size: 0.882.
DEPTH_SMOOTHING = 0.5
# A body cut by the image border: on an image axis where the 2D box touches the border and the
# returns span less than this fraction of the body's extent in the last view that saw it whole
# (2D box off every border, not cut by the depth range), the reported box takes that extent from
# the face it sees, the other image axis at least its whole extent about the whole view's middle
# (moved the least to hold the returns), and the front face the nearer of the returns' and the
# whole view's, the back at least the whole depth behind it (boxes.hold_cut_extent). The returns
# of a sliver span the sliver, and A3BoxNet shown a sliver boxes a sliver (its open face was the
# estimate's guess before). Only with measured faces. Cut frames are 11-26% of the calibration
# sets' frames with IoU_3d 0.66-0.82 against 0.88-0.91 whole. One pass on held-out sequences, EdgeTrack + A3BoxNet, AO_3d with the image axes only at
# 0.6 / 0.8 / 0.9 (off: first): ideal seed 3 0.8909 / 0.8941 / 0.8953 / 0.8966, seed 7 0.8870 /
# 0.8905 / 0.8915 / 0.8907, flash-LiDAR seed 5 0.8112 / 0.8139 / 0.8143 / 0.8143, ToF seed 5
# 0.7466 / 0.7488 / 0.7494 / 0.7498; without the fraction (every cut frame held) a body slightly
# cut for a whole sequence kept its first frame's size (flash-LiDAR seed 5, sequence 0003: 0.831
# -> 0.735). The depth rule added at 0.8: seeds 3 / 7 0.8953 -> 0.8951, 0.8915 -> 0.8927,
# flash-LiDAR / ToF seed 5 0.8143 -> 0.8177, 0.7494 -> 0.7528 (the whole view's depth and centre
# instead: 0.8918, 0.8864, 0.8176, 0.7501); the whole view's middle on the other axis then
# +0.0002 to +0.0012 on all nine calibration sets (docs/runtime.md has every number). An axis at
# both borders (a body larger than the view) is held too: it shrank to the view (a 7.6 m body at
# 7 m, accuracy set held-out shapes 0023: AO_3d 0.509 -> 0.586). With the body's past views
# (BODY_VIEWS) the extent held across the view is theirs now, carried into the frame as the body
# turned (`_views_extent`). Without measured faces (stereo) the same hold applies to the box after
# the reverse fusion, its own faces in place of the returns': the 2D box's cross-section spans the
# part in view as the returns do (ground-truth 2D boxes of the README's held-out stereo split at
# the true depth: 0.9 / 1.6 m short in width / height on its cut frames, 14% of them). One pass,
# EdgeTrack, stereo depth maps, AO_3d without / with it: calibration seeds 3 / 43 0.6816 / 0.6868,
# 0.7280 / 0.7303, 0.7439 / 0.7464, 0.7043 / 0.7102; seed 53 0.6770 / 0.6830, 0.7341 / 0.7363
# (every split up, ACE_3d lower on all). 0: off.
HOLD_CUT_SIZE = 0.8


def cut_box(box2d: np.ndarray, margin: float) -> np.ndarray:
    """The box [x, y, w, h] a frustum is cut with: `box2d` widened by `margin` of its size (half on
    each side); `box2d` itself at margin 0 (track3d.sensor_options.FRUSTUM_MARGIN, frustum_margin_for)."""
    if margin > 0.0:
        grow = box2d[2:] * margin
        return np.concatenate([box2d[:2] - grow / 2.0, box2d[2:] + grow])
    return box2d


def measured_bounds(pts: np.ndarray, bounds: np.ndarray, front_quantile: float) -> np.ndarray:
    """The frustum's bounds (2, 3) as the loop measures the body with them: the least depth is the
    `front_quantile` quantile of the returns' (track3d.sensor_options.FRONT_QUANTILE,
    front_quantile_for; 0: the nearest)."""
    if front_quantile <= 0.0 or len(pts) < 2:
        return bounds
    k = int(front_quantile * (len(pts) - 1))
    out = np.array(bounds, dtype=np.float64)
    out[0, 2] = np.partition(pts[:, 2], k)[k]
    return out



STATE_VERSION = 1


def _judges_loss(tracker2d) -> bool:
    """Whether the 2D tracker says itself when it has lost the target (a bool `lost` attribute,
    as EdgeTrack's): then its "ok" outranks an empty frustum."""
    return isinstance(getattr(tracker2d, "lost", None), (bool, np.bool_))


def _tracker_score(tracker2d) -> float | None:
    """The 2D tracker's optional `score` attribute as a float in 0..1, or None."""
    s = getattr(tracker2d, "score", None)
    if s is None or isinstance(s, bool):
        return None
    try:
        s = float(s)
    except (TypeError, ValueError):
        return None
    return min(max(s, 0.0), 1.0) if np.isfinite(s) else None


@dataclass
class TrackResult:
    """One frame's output. box2d (4,) float64 is the reported box (fused when fusion is on),
    clipped to the image as the labels are (a box wholly outside it is reported as it is);
    box2d_raw (4,) the 2D tracker's own box, unclipped; box3d (6,) float64 [cx, cy, cz, sx, sy, sz];
    status one of STATUSES: "tracking" (a new 3D estimate), "no_points" (boxes held: no usable
    estimate, a dropped frame, or a 2D loss with the body still in the depth of the last box;
    a body gone past the depth sensor's range has its 3D box carried by the 2D box),
    "lost"; num_points the frustum size; ms per-stage milliseconds (STAGES);
    score the 2D tracker's confidence in 0..1 for this frame (None when it has none);
    held_frames how many frames since the estimator last gave a box (0: on this frame; a held
    box may still be measured from the depth's outline or carried by the 2D box past the depth
    range, and is NaN before any 3D box); ``lost`` is True once the tracker has decided the target
    is lost."""

    box2d: np.ndarray
    box2d_raw: np.ndarray
    box3d: np.ndarray
    status: str
    num_points: int
    ms: dict[str, float] = field(default_factory=dict)
    score: float | None = None
    held_frames: int = 0

    @property
    def ok(self) -> bool:
        return self.status == TRACKING

    @property
    def lost(self) -> bool:
        return self.status == LOST


def _valid_box2d(b: np.ndarray) -> bool:
    return bool(np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0)


def _built_in(part) -> bool:
    """Whether a tracker or estimator is one of track3d's own (a protocol break is a plug-in's to hear of)."""
    return type(part).__module__.split(".")[0] == "track3d"


def _is_flag(ok) -> bool:
    """A 2D tracker's `ok`: a bool or the integers 0 / 1, as Python, numpy or a 0-d array / tensor
    of one (`score > threshold` on an array); not a string, a box or a list."""
    if isinstance(ok, (str, bytes)):
        return False
    try:
        a = np.asarray(ok)
    except Exception:   # an object numpy cannot take
        return False
    return a.ndim == 0 and (a.dtype == np.bool_ or (a.dtype.kind in "iu" and int(a) in (0, 1)))


def _read_only(image: np.ndarray) -> np.ndarray:
    """A read-only view of `image` for the 2D tracker: a plug-in that drew into the frame had
    changed the caller's array and the overlay (a plug-in walkthrough); writing now raises."""
    view = image.view()
    view.flags.writeable = False
    return view


class Track3D:
    """The 3D tracker: one 2D tracker, one 3D box estimator, the camera of the point clouds."""

    def __init__(self, camera: Camera, tracker2d: Tracker2D, estimator: BoxEstimator, fusion: bool = True,
                 weight_3d: float = WEIGHT_3D, z_range: tuple[float, float] = (Z_MIN, Z_MAX),
                 min_points: int = MIN_POINTS, lost_after: int = LOST_AFTER, min_score: float = 0.0,
                 frustum_margin: float = FRUSTUM_MARGIN, depth_range_m: float | None = None,
                 weight_2d: float = WEIGHT_2D, section_limbs: tuple[float, float, float] | None = SECTION_LIMBS,
                 measured_faces: bool = True,
                 depth_smoothing: float = DEPTH_SMOOTHING, evidence_points: int = EVIDENCE_POINTS,
                 reacquire_threshold: float | None = REACQUIRE_THRESHOLD, hold_cut_size: float = HOLD_CUT_SIZE,
                 edge_pad: float = EDGE_PAD, front_quantile: float = FRONT_QUANTILE,
                 front_filter: tuple[float, float] | None = FRONT_FILTER,
                 silhouette: float = SILHOUETTE, outline_share: float = OUTLINE_SHARE,
                 outline_share_phase: float = OUTLINE_SHARE_PHASE, outline_contain: bool = False,
                 dark_side: float = DARK_SIDE, fusion_cover: float = FUSION_COVER, texture_trim: bool = False,
                 resume_outline: bool = False,
                 body_views: bool | BodyViewsParams = BODY_VIEWS, first_box_fade: float = FIRST_BOX_FADE,
                 drop_stray: bool = DROP_STRAY, max_cloud_points: int | None = None):
        if not isinstance(camera, Camera):
            raise TypeError(f"camera must be a track3d.Camera, got {type(camera).__name__}")
        if not 0.0 <= float(weight_3d) <= 1.0:
            raise ValueError(f"weight_3d must be in [0, 1], got {weight_3d}")
        z0, z1 = (float(z) for z in z_range)
        if not (0.0 <= z0 < z1):
            raise ValueError(f"z_range must be (near, far) with 0 <= near < far, got {z_range}")
        if int(min_points) < 1:
            raise ValueError(f"min_points must be >= 1, got {min_points}")
        if isinstance(evidence_points, bool) or int(evidence_points) != evidence_points or int(evidence_points) < 0:
            raise ValueError(f"evidence_points must be an integer >= 0 (0: off), got {evidence_points!r}")
        self.evidence_points = int(evidence_points)
        if reacquire_threshold is not None and not 0.0 < float(reacquire_threshold) <= 1.0:
            raise ValueError(f"reacquire_threshold must be in (0, 1] or None, got {reacquire_threshold!r}")
        self.reacquire_threshold = None if reacquire_threshold is None else float(reacquire_threshold)
        if not 0.0 <= float(frustum_margin) <= 1.0:
            raise ValueError(f"frustum_margin must be in [0, 1] (a fraction of the 2D box), got {frustum_margin}")
        self.frustum_margin = float(frustum_margin)
        if not 0.0 <= float(weight_2d) <= 1.0:
            raise ValueError(f"weight_2d must be in [0, 1], got {weight_2d}")
        self.weight_2d = float(weight_2d)
        if measured_faces not in (True, False):
            raise ValueError(f"measured_faces must be True or False, got {measured_faces!r}")
        self.measured_faces = bool(measured_faces)
        # only an amodal estimator's box (a guess of the whole body) gets its seen faces measured
        # and its hidden depth averaged over frames
        amodal = bool(getattr(estimator, "amodal", False))
        self._fit_faces = self.measured_faces and amodal
        if not 0.0 <= float(depth_smoothing) < 1.0:
            raise ValueError(f"depth_smoothing must be in [0, 1) (0: off), got {depth_smoothing}")
        self.depth_smoothing = float(depth_smoothing)
        self._smooth_depth = amodal and self.depth_smoothing > 0.0
        self._depth_avg = float("nan")   # the averaged depth extent (m), nan before the first box
        if not 0.0 <= float(hold_cut_size) <= 1.0:
            raise ValueError(f"hold_cut_size must be in [0, 1] (0: off), got {hold_cut_size}")
        self.hold_cut_size = float(hold_cut_size)
        # with measured faces the returns' extent is held; without them (stereo) the cross-section
        # the 2D box gives (weight_2d), which a border cuts as it cuts the returns
        self._hold_cut = self.hold_cut_size > 0.0 and (self._fit_faces or self.weight_2d > 0.0)
        if not (np.isfinite(float(edge_pad)) and 0.0 <= float(edge_pad) <= 10.0):
            raise ValueError(f"edge_pad must be in [0, 10] pixels (0: off), got {edge_pad}")
        self.edge_pad = float(edge_pad)
        if not (np.isfinite(float(front_quantile)) and 0.0 <= float(front_quantile) <= 0.1):
            raise ValueError(f"front_quantile must be in [0, 0.1] (0: the nearest return), got {front_quantile}")
        self.front_quantile = float(front_quantile)
        if front_filter is not None:
            try:
                fa, fb = (float(v) for v in front_filter)
            except (TypeError, ValueError):
                raise ValueError(f"front_filter must be (alpha, beta) or None, got {front_filter!r}") from None
            if not (0.0 < fa <= 1.0 and 0.0 <= fb <= 1.0):
                raise ValueError(f"front_filter must be (alpha, beta) with 0 < alpha <= 1, 0 <= beta <= 1, "
                                 f"got {front_filter!r}")
            front_filter = (fa, fb)
        self.front_filter: tuple[float, float] | None = front_filter
        if section_limbs is not None:
            try:
                lp, ls, lq = (float(v) for v in section_limbs)
            except (TypeError, ValueError):
                raise ValueError(f"section_limbs must be (band px, band share, quantile) or None, "
                                 f"got {section_limbs!r}") from None
            if not (0.0 <= lp <= 100.0 and 0.0 <= ls < 0.5 and max(lp, ls) > 0.0 and 0.0 <= lq <= 1.0):
                raise ValueError(f"section_limbs must be (band px, band share, quantile) with 0 <= px <= 100, "
                                 f"0 <= share < 0.5, not both 0, 0 <= quantile <= 1, got {section_limbs!r}")
            section_limbs = (lp, ls, lq)
        self.section_limbs: tuple[float, float, float] | None = section_limbs
        self._front = (float("nan"), 0.0)   # the filter's front face (m) and its rate (m a frame)
        if not (np.isfinite(float(silhouette)) and 0.0 <= float(silhouette) <= 4.0):
            raise ValueError(f"silhouette must be in [0, 4] (the search region's growth; 0: off), got {silhouette}")
        self.silhouette = float(silhouette)
        if not (np.isfinite(float(outline_share)) and 0.0 <= float(outline_share) <= 1.0):
            raise ValueError(f"outline_share must be in [0, 1] (0: off), got {outline_share}")
        self.outline_share = float(outline_share)
        if not (np.isfinite(float(outline_share_phase)) and 0.0 <= float(outline_share_phase) <= 180.0):
            raise ValueError(f"outline_share_phase must be in [0, 180] degrees (180: always), got {outline_share_phase}")
        self.outline_share_phase = float(outline_share_phase)
        if not isinstance(outline_contain, (bool, np.bool_)):
            raise ValueError(f"outline_contain must be True or False, got {outline_contain!r}")
        self.outline_contain = bool(outline_contain)
        if not isinstance(texture_trim, (bool, np.bool_)):
            raise ValueError(f"texture_trim must be True or False, got {texture_trim!r}")
        self.texture_trim = bool(texture_trim)
        if not isinstance(drop_stray, (bool, np.bool_)):
            raise ValueError(f"drop_stray must be True or False, got {drop_stray!r}")
        self.drop_stray = bool(drop_stray)
        # the loop's time grows with the cloud (~65 ns a return past the body's own, mostly the
        # false-alarm rule's sort of the frustum): a sensor of more returns than a frame's budget
        # holds is thinned to at most this many, every k-th return (None: all; docs/runtime.md)
        if max_cloud_points is not None and (isinstance(max_cloud_points, bool)
                                             or not isinstance(max_cloud_points, (int, np.integer))
                                             or max_cloud_points < MIN_CLOUD_CAP):
            raise ValueError(f"max_cloud_points must be None (all) or an integer >= {MIN_CLOUD_CAP}, "
                             f"got {max_cloud_points!r}")
        self.max_cloud_points = None if max_cloud_points is None else int(max_cloud_points)
        if not isinstance(resume_outline, (bool, np.bool_)):
            raise ValueError(f"resume_outline must be True or False, got {resume_outline!r}")
        self.resume_outline = bool(resume_outline)
        if not (np.isfinite(float(dark_side)) and 0.0 <= float(dark_side) <= 2.0):
            raise ValueError(f"dark_side must be in [0, 2] (0: off), got {dark_side}")
        self.dark_side = float(dark_side)
        if not (np.isfinite(float(fusion_cover)) and 0.0 <= float(fusion_cover) <= 1.0):
            raise ValueError(f"fusion_cover must be in [0, 1] (0: off), got {fusion_cover}")
        self.fusion_cover = float(fusion_cover)
        self.sun: np.ndarray | None = None   # unit (3,) toward the sun, camera frame (set_sun)
        if not isinstance(body_views, (bool, np.bool_, BodyViewsParams)):
            raise ValueError(f"body_views must be True, False or a BodyViewsParams, got {body_views!r}")
        self.first_box_fade = check_fade(first_box_fade)
        self._first = None   # the first 3D box, when init() was given one (track3d.first_box)
        self.body_views = isinstance(body_views, BodyViewsParams) or bool(body_views)
        # the past views only push an amodal estimator's guessed back face
        self._views = (BodyViews(camera, body_views if isinstance(body_views, BodyViewsParams) else None)
                       if self.body_views and amodal else None)
        self._pad = (self.edge_pad / camera.fx, self.edge_pad / camera.fy)
        self._whole_box: np.ndarray | None = None   # the reported box of the last whole view (6,)
        self._depth_ratio = float("nan")   # size z / mean(size x, y) of the last whole view's box within the depth range
        self._small_cap = False   # this frame's returns: a cap past the range smaller than CAP_FUSION_COVERAGE
        # the 2D box of the last estimate whose returns reached the range (not a sliver of the body at
        # the image border: CARRY_SLIVER) and its 3D box (6,): what a body gone wholly past the range
        # is carried from (range_cut.carry_box)
        self._carry_from: np.ndarray | None = None
        # the pair (2D box, 3D box) of the last frame carried at the image border (CARRY_AT_BORDER);
        # None off the border
        self._border_from: np.ndarray | None = None
        self._border_box: np.ndarray | None = None
        self._carry_box: np.ndarray | None = None
        self._carry_area = float("nan")   # area (px^2) of the last such 2D box clear of the image border
        self._carry_area_z = float("nan")   # the centre depth (m) of the 3D box that went with it
        if depth_range_m is not None and not (np.isfinite(float(depth_range_m)) and float(depth_range_m) > 0.0):
            raise ValueError(f"depth_range_m must be a positive number of metres or None (unlimited), got {depth_range_m}")
        # the depth sensor's maximum range: a body reaching past it is boxed from the image (range_cut)
        self.depth_range_m = None if depth_range_m is None else float(depth_range_m)
        self.camera = camera
        self.tracker2d = tracker2d
        self.estimator = estimator
        if not isinstance(fusion, (bool, np.bool_)):   # "no" had read as True
            raise ValueError(f"fusion must be True or False, got {fusion!r}")
        self.fusion = bool(fusion)
        self.weight_3d = float(weight_3d)
        self.z_range = (z0, z1)
        if not is_integer(min_points):
            raise ValueError(f"min_points must be an integer >= 1, got {min_points!r}")
        self.min_points = int(min_points)
        if not is_integer(lost_after) or int(lost_after) < 1:   # 2.5 had been taken as 2
            raise ValueError(f"lost_after must be an integer >= 1, got {lost_after!r}")
        if not 0.0 <= float(min_score) <= 1.0:
            raise ValueError(f"min_score must be in [0, 1], got {min_score}")
        self.lost_after = int(lost_after)
        self.min_score = float(min_score)
        self.bad_frames = 0       # consecutive frames without a usable estimate or with a low score
        self.held_frames = 0      # frames since the 3D box was last estimated
        self._empty_frames = 0    # consecutive frames on empty space the depth range cannot explain
        self.tracker_name: str | None = None      # registry names when built by `create`
        self.estimator_name: str | None = None
        self.tracker_options: dict = {}
        self.estimator_options: dict = {}
        self._size = (camera.width, camera.height)
        self._M = camera.M
        self._correct = getattr(tracker2d, "correct", None)
        # False for the null estimator ("none"): 2D only, the loop skips frustum, estimate, fusion.
        self.needs_points = bool(getattr(estimator, "needs_points", True))
        # the loop's re-acquisition threshold, for a tracker that judges its loss and has one, when
        # the depth check can hold what a hesitant re-acquisition leaves lost
        own = getattr(tracker2d, "reacquire_threshold", None)
        if (self.reacquire_threshold is not None and isinstance(own, float) and _judges_loss(tracker2d)
                and self.needs_points and self.evidence_points):
            tracker2d.reacquire_threshold = max(own, self.reacquire_threshold)
        # an estimator whose estimate() takes bounds= gets the frustum pass's [min; max] (A3BoxNet)
        self._estimator_takes_bounds = bool(getattr(estimator, "takes_bounds", False))
        # ... and phase_deg= (the phase angle at the 2D box, with the sun known)
        self._estimator_takes_phase = bool(getattr(estimator, "takes_phase", False))
        # ... and past= (the body's past views in this frame, BodyViews.past_points: a model trained
        # with them, track3d.boxnet.PAST_VIEWS); the views are then updated before the estimate
        self._estimator_takes_past = bool(getattr(estimator, "takes_past", False))
        self.category = -1
        self.box2d = np.full(4, np.nan)
        self.box3d = np.full(6, np.nan)
        self._started = False     # init() (or set_state of a started tracker) has run

    def __repr__(self) -> str:
        return (f"Track3D({self.tracker2d!r}, {self.estimator!r}, fusion={self.fusion}, "
                f"weight_3d={self.weight_3d})")

    # --- construction by names -----------------------------------------------------------------
    @classmethod
    def create(cls, camera: Camera, tracker: str = "kcf", estimator: str = "baseline",
               tracker_options: dict | None = None, estimator_options: dict | None = None,
               threads: int | None = None, **options) -> "Track3D":
        """Build from registry names; `options` go to Track3D (fusion, weight_3d, z_range,
        min_points, lost_after, min_score, frustum_margin, depth_range_m, weight_2d, section_limbs,
        measured_faces, depth_smoothing, evidence_points, reacquire_threshold, hold_cut_size, edge_pad,
        front_quantile, front_filter, silhouette, outline_share, outline_share_phase, outline_contain,
        texture_trim, resume_outline, dark_side, fusion_cover, body_views, first_box_fade, drop_stray,
        max_cloud_points).
        threads: the CPU threads of each part that runs a model (a `threads` option of its factory,
        unless its own options give one; track3d.threads.check_threads); parts without one
        (OpenCV's trackers, the baseline box) run on the calling thread."""
        from .estimators import estimator_factory
        from .plugins import takes_option
        from .trackers2d import tracker_factory

        topts, eopts = dict(tracker_options or {}), dict(estimator_options or {})
        if threads is not None:   # `Track3D.create(..., threads=1)` had been a TypeError of __init__
            from .threads import check_threads

            threads = check_threads(threads)
            for opts, factory in ((topts, tracker_factory(tracker)), (eopts, estimator_factory(estimator))):
                if "threads" not in opts and takes_option(factory, "threads"):
                    opts["threads"] = threads
        t = cls(camera, create_tracker(tracker, **topts), create_estimator(estimator, **eopts), **options)
        t.tracker_name, t.estimator_name = str(tracker).lower(), str(estimator).lower()
        t.tracker_options, t.estimator_options = topts, eopts
        return t

    @classmethod
    def from_default(cls, camera: Camera, threads: int = 1, precision: str = "fp32", engine: str = "onnxruntime",
                     depth_sensor: str | None = None, **options) -> "Track3D":
        """The shipped models: EdgeTrack + A3BoxNet, on `threads` CPU threads (the paper's SiamFC:
        ``Track3D.create(camera, "siamfc-edge", "a3boxnet")``).

        depth_sensor: the kind of depth the clouds come from ("ideal", "tof", "flash-lidar",
        "stereo", or None: unknown): the loop options chosen for it (`sensor_options`) and its
        A3BoxNet (track3d.boxnet.SENSOR_MODELS); `options` override the former.

        precision / engine: "fp32" | "int8" | "bf16" | "auto" and "onnxruntime" | "openvino" |
        "auto" (track3d.onnxmodel; "auto": the fastest variant this CPU allows, see describe()).
        Raises ValueError for an unknown depth_sensor name, TrackerUnavailable / EstimatorUnavailable
        when the models are not shipped.
        """
        depth_sensor = check_depth_sensor(depth_sensor)
        arith = {"threads": threads, "precision": precision, "engine": engine}
        options = {**(sensor_options(depth_sensor) if depth_sensor is not None else {}), **options}
        sensor = {} if depth_sensor is None else {"depth_sensor": depth_sensor}
        return cls.create(camera, DEFAULT_TRACKER, "a3boxnet", arith, {**arith, **sensor}, **options)

    # --- the loop --------------------------------------------------------------------------------
    def _cut_box(self, box2d: np.ndarray) -> np.ndarray:
        """The box a frustum is cut with: `box2d` widened by ``frustum_margin`` of its size."""
        return cut_box(box2d, self.frustum_margin)

    def _frustum(self, points, box2d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(frustum points, their (2, 3) [min; max]) from one C++ pass; the points are finite.
        The cut uses the 2D box widened by ``frustum_margin`` (see FRUSTUM_MARGIN); with
        ``drop_stray`` a depth sensor's false alarms are left out (track3d.stray_returns).
        points: a cloud (N, 3) or a callable box2d -> cloud (e.g. track3d.stereo.StereoCloud.bind,
        which computes depth only around the box)."""
        box2d = self._cut_box(box2d)
        if callable(points):
            points = points(box2d.copy())
        pts, bounds = extract_frustum_bounds(points, box2d, self._M, *self.z_range)
        # a depth sensor's false alarms are no part of the body (DROP_STRAY)
        return drop_stray(pts, bounds, self._M) if self.drop_stray else (pts, bounds)

    def _measured(self, pts: np.ndarray, bounds: np.ndarray) -> np.ndarray:
        """The frustum's bounds (2, 3) as the loop measures the body with them: the least depth is
        the `front_quantile` quantile of the returns' (FRONT_QUANTILE). The estimator gets the true
        bounds (they enclose its points)."""
        return measured_bounds(pts, bounds, self.front_quantile)

    def _update_views(self, pts: np.ndarray, bounds: np.ndarray, seen: np.ndarray
                      ) -> tuple[float | None, float | None]:
        """This frame's returns into the past views (`bounds` as measured, `_measured`) -> the
        back face's bounds (far, limit) they give (track3d.body_views)."""
        # returns that stop at the sensor's range outline a cap, not the body: no carving
        cut_by_range = reaches_range(bounds, seen, self.camera, self.depth_range_m)
        whole = not cut_by_range and not any(self._border_sides(seen))
        far = self._views.update(pts, self._cut_box(seen), float(bounds[0][2]), carve=not cut_by_range, whole=whole)
        return far, self._views.limit

    def _estimate(self, pts: np.ndarray, bounds: np.ndarray, box2d: np.ndarray,
                  past: np.ndarray | None = None) -> np.ndarray | None:
        """The estimator's box for the frustum `pts` (its [min; max] `bounds`) cut with `box2d`;
        `past`: the body's past views in this frame, for an estimator that takes them."""
        # The checks use the frustum pass's bounds: no second pass over a large frustum.
        if len(pts) < self.min_points:
            return None
        lo, hi = bounds
        if (hi - lo).max() < MIN_SPREAD_M or lo.min() < -MAX_COORD_M or hi.max() > MAX_COORD_M:
            return None
        extra = {}
        if self._estimator_takes_bounds:
            extra["bounds"] = bounds
        if self._estimator_takes_phase and self.sun is not None:
            # a model of its own for bodies lit from behind (track3d.boxnet.BACKLIT_MODELS)
            extra["phase_deg"] = phase_deg(box2d, self.sun, self.camera)
        if self._estimator_takes_past:
            extra["past"] = past
        try:
            b = self.estimator.estimate(pts, self.category, **extra)
            b = np.asarray(b, dtype=np.float64).reshape(-1)
        except ValueError:  # points outside the estimator's domain (e.g. A3BoxNet's extent)
            return None
        # a box behind the camera or past any coordinate the loop takes in is no estimate (a plug-in's
        # [0, 0, -20, 1, 1, 1] had been reported as tracking, and a 1e12 m box bent the fused 2D box)
        if b.shape != (6,) or not np.all(np.isfinite(b)) or np.any(b[3:] <= 0.0) or b[2] <= 0.0 \
                or np.any(np.abs(b) > MAX_COORD_M):
            if not _built_in(self.estimator):   # the baseline's box of a flat cap is no box, and no mistake
                self._say_once("box3d", f"the box estimator {self._name3d!r} returned "
                                        f"{np.array2string(b, precision=3, threshold=8)}: not a box in front of the "
                                        "camera ((6,) [cx, cy, cz, sx, sy, sz], finite, sizes > 0, cz > 0, within "
                                        f"{MAX_COORD_M:g} m): taken as no estimate")
            return None
        return b

    def _reported_box(self, est: np.ndarray, bounds: np.ndarray, box2d: np.ndarray,
                      pts: np.ndarray | None = None) -> tuple[np.ndarray, bool, bool]:
        """The reported 3D box: `est`, or the box from the image when the body reaches past the
        depth sensor's range and its returns cover less than the outline (track3d.range_cut; as deep
        for its width as range_cut.cut_ratio makes of the body's last whole view's box), else `est` with the faces the sensor sees taken
        from the returns (`measured_faces`, boxes.fit_measured_faces) and its cross-section fused
        with the 2D box by `weight_2d` (fusion.fuse_section; each side at the limb's depth the
        frustum's returns `pts` give, `section_limbs`). The 2D fusion keeps `est`: the
        returns' cap, inside the body's outline, holds a 2D box that would otherwise grow with nothing to check it
        (measured one pass, EdgeTrack, held-out ToF sequences, AO_3d without the rule / with it
        fusing the image box / fusing `est`: seed 3 0.651 / 0.694 / 0.701, seed 5 0.674 / 0.702 /
        0.710; seed 5 sequence 0004 0.19 / 0.08 / 0.33), unless the cap covers less than
        range_cut.CAP_FUSION_COVERAGE of the 2D box (`_small_cap`): then the 2D box stands. Also says whether the view was whole
        (the 2D box off every image border, the body not cut by the depth range) and whether the
        returns reached the range. When the returns reach the range but cover the outline, the
        box's back face goes at least as far as the image's box's (range_cut.deepen_to_view)
        with the depth-to-width ratio of the last whole view's box (off the image border, returns
        within the range; 1 before one)."""
        reach = reaches_range(bounds, box2d, self.camera, self.depth_range_m)
        coverage = lateral_coverage(bounds, box2d, self.camera) if reach else 1.0
        self._small_cap = coverage < CAP_FUSION_COVERAGE
        if coverage < MIN_COVERAGE:
            b = box_from_view(box2d, self.camera, float(bounds[0][2]), cut_ratio(self._depth_ratio))
            if b is not None:
                return b, False, True
        sides = self._border_sides(box2d)
        if self._fit_faces:
            est = fit_measured_faces(est, bounds, sides, self._pad)
            if self._hold_cut and any(sides) and self._whole_box is not None:
                est = hold_cut_extent(est, bounds, sides, self._whole_box, self.hold_cut_size,
                                      self._views_extent())
        limbs = None
        if self.section_limbs is not None and self.weight_2d > 0.0 and pts is not None:
            band_px, band_share, quantile = self.section_limbs
            limbs = limb_depths(pts, box2d, self.camera, (band_px, band_share), quantile)
            limbs[np.array(sides)] = np.nan   # a side at the image border is not the body's limb
        box = fuse_section(est, box2d, self.camera, self.weight_2d, limbs) if self.weight_2d > 0.0 else est
        if not self._fit_faces and self._hold_cut and any(sides) and self._whole_box is not None:
            # the cross-section of a 2D box cut by the image border spans the part in view
            box = hold_cut_extent(box, np.stack([box[:3] - box[3:] / 2.0, box[:3] + box[3:] / 2.0]), sides,
                                  self._whole_box, self.hold_cut_size)
        if reach:   # the outline is seen, the depth stops at the range: the body goes on past it
            ratio = self._depth_ratio if np.isfinite(self._depth_ratio) else DEPTH_RATIO
            return deepen_to_view(box, box2d, self.camera, float(bounds[0][2]), ratio), False, True
        return box, not any(sides), False

    def _views_extent(self) -> np.ndarray | None:
        """The extent (3,) a cut body keeps: the last whole view's, on the first
        BodyViewsParams.cut_extent axes the past views' now (the body has turned since it was
        last seen whole); None without views that saw it whole."""
        ext = None if self._views is None else self._views.extent
        k = 0 if self._views is None else self._views.params.cut_extent
        if ext is None or k == 0 or self._whole_box is None:
            return None
        size = self._whole_box[3:].copy()
        size[:k] = ext[:k]
        return size

    def _border_sides(self, box2d: np.ndarray) -> tuple[bool, bool, bool, bool]:
        """Whether the 2D box [x, y, w, h] touches the image's left, top, right, bottom border: the
        body may go on past the view on that side."""
        x, y, w, h = (float(v) for v in box2d)
        W, H = self._size
        return x <= 0.5, y <= 0.5, x + w >= W - 0.5, y + h >= H - 0.5

    def _report(self, est: np.ndarray, bounds: np.ndarray, box2d: np.ndarray,
                far: float | None = None, limit: float | None = None, pts: np.ndarray | None = None) -> np.ndarray:
        """This frame's reported box (`_reported_box`), its back face at least at `far` (the past
        views' farthest depth, track3d.body_views) and, when the returns are within the depth
        range, at most at `limit` (the farthest the past views leave possible, never nearer than `far`),
        with its depth extent replaced by the
        running average (DEPTH_SMOOTHING), its front face where it was; updates the average and,
        after a whole view, the size a cut body keeps (HOLD_CUT_SIZE)."""
        box, whole, reached = self._reported_box(est, bounds, box2d, pts)
        # returns that reach the range say nothing of where the body ends: no upper bound then,
        # but the views saw as far as `far` (ToF calibration sets, oracle 2D boxes, AO_3d test /
        # held-out: seed 23 300 frames 0.8037 -> 0.8121 / 0.8224 -> 0.8226, seed 3 60 frames
        # 0.7603 -> 0.7653 / 0.7787 -> 0.7787)
        box = hold_back_face(box, far, None if reached else limit)
        if whole:   # a box from a whole view within the range: the body's own depth-to-width ratio
            # (not from a view cut by the image border, whose width is the part in view: a held-out
            # ToF calibration body cut at the top border lent its cut box's 1.3 to the box from
            # the image and lost 0.033 AO_3d; track3d.range_cut.CUT_RATIO_WEIGHT)
            self._depth_ratio = float(min(box[5] / max((box[3] + box[4]) / 2.0, 1e-6), MAX_DEPTH_RATIO))
        if self._smooth_depth:
            s = self.depth_smoothing
            avg = box[5] if not np.isfinite(self._depth_avg) else s * self._depth_avg + (1.0 - s) * box[5]
            self._depth_avg = float(avg)
            box = np.array(box, dtype=np.float64)
            box[2] = box[2] - box[5] / 2.0 + avg / 2.0
            box[5] = avg
        if whole and self._hold_cut:
            self._whole_box = np.array(box, dtype=np.float64)
        if self.front_filter is not None:
            box = self._filter_front(box)
        if not reached:
            self._carry_from = self._carry_box = None
            self._carry_area = self._carry_area_z = float("nan")
        else:
            # a 2D box at the image border may be a sliver of the body: a body that left the view
            # beyond the range and came back wholly past it was carried from a sliver's box, 8 m
            # too near (README ToF long-watch held-out 0008). A border box with less than
            # CARRY_SLIVER of the last clear box's area leaves the pair as it was; a tracker whose
            # box keeps its size at the border (SiamFC) still carries from its latest box
            clear = not any(self._border_sides(box2d))
            area = float(box2d[2] * box2d[3])
            if clear:
                self._carry_area, self._carry_area_z = area, float(box[2])
            if clear or not area < CARRY_SLIVER * self._carry_area:   # (nan: no clear box yet)
                self._carry_from, self._carry_box = np.array(box2d, dtype=np.float64), np.array(box, dtype=np.float64)
        self._border_from = self._border_box = None
        return box if self._first is None else with_first_depth(box, self._first, self.first_box_fade)

    def _filter_front(self, box: np.ndarray) -> np.ndarray:
        """`box` moved along the line of sight (its size kept) to put its front face at the
        alpha-beta filter's (FRONT_FILTER), the filter updated with this front face."""
        a, b = self.front_filter
        front = float(box[2] - box[5] / 2.0)
        x, v = self._front
        if not (np.isfinite(front) and np.isfinite(x)):
            x, v = front, 0.0
        else:
            guess = x + v
            miss = front - guess
            x, v = guess + a * miss, v + b * miss
        self._front = (x, v)
        if not np.isfinite(front):
            return box
        out = np.array(box, dtype=np.float64)
        out[2] = x + out[5] / 2.0
        return out

    def set_sun(self, direction) -> None:
        """The sun's direction: 3 numbers toward the sun in the camera frame (x right, y down, z
        forward; any length > 0), or None (unknown). With `dark_side` > 0 and a lit outline read
        (stereo), the 2D box reaches past the outline's side away from the sun (track3d.dark_side).
        Kept across init() (a property of the scene, not of the target); part of get_state()."""
        self.sun = check_sun(direction)

    def init(self, image: np.ndarray, box2d: np.ndarray, category: int = -1,
             points: np.ndarray | Callable[[np.ndarray], np.ndarray] | None = None,
             box3d: np.ndarray | None = None) -> None:
        """Start on `image` with the target in `box2d` [x, y, w, h]; category: coarse category.

        points: the frame's cloud (N, 3) or a callable box2d -> cloud (as in `update`), optional;
        when given the first 3D box is estimated from its frustum so that a later empty frustum
        has a box to keep.
        box3d: the body's 3D box in this frame, (6,) [cx, cy, cz, sx, sy, sz] camera frame, metres,
        optional (3D single-object tracking's start): it is the first box, and its depth extent
        holds the reported boxes' while the body has not turned (track3d.first_box,
        `first_box_fade`).
        """
        b = check_init_box(box2d, self._size)
        first = None if box3d is None else check_init_box3d(box3d)
        category = check_category(category, getattr(self.estimator, "num_categories", None))
        image = self.camera.undistort_image(check_image(image, self._size))
        points = self._thinned(check_cloud(points, needed=False)) if self.needs_points else None
        if callable(points):
            # called (for the box _frustum would cut) before anything changes: a callable that fails
            # had left the tracker started
            points = check_cloud(points(self._cut_box(b).copy()), needed=True)
        if points is not None and self.needs_points:
            self._check_units(points, b)
        self.category = category
        self.tracker2d.init(_read_only(image), b)
        self.box2d = b.copy()
        self.box3d = np.full(6, np.nan)
        self.bad_frames = 0
        self.held_frames = 0
        self._empty_frames = 0
        self._depth_avg = float("nan")
        self._whole_box = None
        self._depth_ratio = float("nan")
        self._carry_from = self._carry_box = None
        self._border_from = self._border_box = None
        self._carry_area = self._carry_area_z = float("nan")
        self._front = (float("nan"), 0.0)
        self._first = first
        if self._views is not None:
            self._views.reset()
        self._started = True
        if points is not None and self.needs_points:
            pts, bounds = self._frustum(points, b)
            est = self._estimate(pts, bounds, b)
            if est is not None:
                self.box3d = self._report(est, self._measured(pts, bounds), b, pts=pts)
            elif (BOX_AT_RANGE and len(pts) == 0 and self.depth_range_m is not None
                  and not any(self._border_sides(b))):
                # the caller's box is on the body and the sensor returns nothing there: the body is
                # past the range. Boxed at the range and carried by the 2D box as a body gone past it
                at = box_at_range(b, self.camera, self.depth_range_m)
                if at is not None:
                    self.box3d = at
                    self._carry_from, self._carry_box = b.copy(), at.copy()
                    self._carry_area, self._carry_area_z = float(b[2] * b[3]), float(at[2])
        if first is not None:
            self.box3d = first.copy()
            if self._carry_box is not None:   # past the range: carried from the known box, not the guess
                self._carry_box = first.copy()

    def _judge(self, r: TrackResult, estimated: bool, seen: bool = False, empty: bool = False) -> TrackResult:
        """Count held and bad frames; after `lost_after` bad frames in a row the target is lost.
        `seen`: a 2D tracker that judges its own loss tracked the target in this frame, so a frame
        without points is not bad (held-out ToF sequences: 43 of 82 "lost" reports came from a
        body past the camera's 30 m range, tracked in 2D all along), unless the frustum was
        `empty` (no return at all) where the depth range cannot explain it: then it is bad, and
        EMPTY_LOST_AFTER such frames in a row are lost."""
        if seen and empty and not self._range_explains_empty():
            seen = False
            self._empty_frames += 1
        else:
            self._empty_frames = 0
        self.held_frames = 0 if estimated else self.held_frames + 1
        low = r.score is not None and r.score < self.min_score
        good = r.status == TRACKING or (seen and r.status == NO_POINTS)
        self.bad_frames = 0 if (good and not low) else self.bad_frames + 1
        r.held_frames = self.held_frames
        if self.bad_frames >= self.lost_after or self._empty_frames >= EMPTY_LOST_AFTER:
            r.status = LOST
        return r

    def _range_explains_empty(self) -> bool:
        """Whether a frustum without returns may be the body past the depth sensor's range: the
        sensor has one and the last 3D box reaches EMPTY_RANGE_SHARE of it (or there is no box)."""
        if self.depth_range_m is None:
            return False
        b = self.box3d
        if not (np.all(np.isfinite(b)) and b[2] > 0.0):
            return True
        far = (b[2] + b[5] / 2.0) * float(np.sqrt(1.0 + (b[0] / b[2]) ** 2 + (b[1] / b[2]) ** 2))
        return far >= EMPTY_RANGE_SHARE * self.depth_range_m

    @property
    def _name2d(self) -> str:
        """The 2D tracker's registry name, or its class's: what a message calls it."""
        return self.tracker_name or type(self.tracker2d).__name__

    @property
    def _name3d(self) -> str:
        return self.estimator_name or type(self.estimator).__name__

    def _protocol_broken(self, res) -> str:
        """The one line naming a 2D tracker whose update() broke the (ok, box) protocol."""
        got = " ".join(repr(res).split())
        return (f"the 2D tracker {self._name2d!r} returned {got:.80} from update(image); "
                "the protocol is (ok: bool, box: [x, y, w, h])")

    def _say_once(self, what: str, message: str) -> None:
        """A plug-in that breaks its protocol in a way the loop survives (a 2D box that is no box,
        a score outside 0..1, a 3D box that is no box): one warning per kind and tracker, never
        silent (a plug-in walkthrough: each had been taken as "lost" / clamped / no estimate)."""
        said = self.__dict__.setdefault("_said", set())
        if what not in said:
            said.add(what)
            warnings.warn(message, RuntimeWarning, stacklevel=3)

    def _score(self) -> float | None:
        """The 2D tracker's score (_tracker_score), with one warning when it gives one outside 0..1."""
        s = getattr(self.tracker2d, "score", None)
        got = _tracker_score(self.tracker2d)
        if s is not None and not isinstance(s, bool) and (got is None or got != s):
            self._say_once("score", f"the 2D tracker {self._name2d!r} has score {s!r}, "
                                    f"not a number in 0..1: taken as {got}")
        return got

    def _thinned(self, points):
        """`points` with at most `max_cloud_points` returns (every k-th, k the least that fits), or
        as they are (no cap, a callable, None)."""
        cap = self.max_cloud_points
        if cap is None or not isinstance(points, np.ndarray) or len(points) <= cap:
            return points
        return np.ascontiguousarray(points[:: -(-len(points) // cap)])

    def _check_started(self, call: str) -> None:
        if not self._started:
            raise ValueError(f"Track3D.{call} before init(): start the tracker with init(image, box2d) first")

    def skip(self) -> TrackResult:
        """A dropped frame: no image, no update of the 2D tracker; the last boxes coast.

        Status "no_points" (no new estimate; counts towards `lost_after`), or "lost" once
        `lost_after` bad frames have passed. ``update(None, points)`` does the same.
        Before init(): ValueError (there is no box to coast), as for update()."""
        self._check_started("skip()")
        r = TrackResult(self._shown(self.box2d), self.box2d.copy(), self.box3d.copy(), NO_POINTS, 0,
                        dict.fromkeys(STAGES, 0.0), None)
        return self._judge(r, estimated=False)

    def update(self, image: np.ndarray | None,
               points: np.ndarray | Callable[[np.ndarray], np.ndarray] | None) -> TrackResult:
        """Track into the next frame: image (H, W, 3) uint8 RGB, points (N, 3) float32 cloud, or a
        callable box2d -> (N, 3) cloud that the loop calls with the 2D tracker's box (a stereo
        camera computes depth only there: `track3d.stereo.StereoCloud.bind`; its time counts in
        the "frustum" stage). None: the depth did not arrive this frame (a sensor fault): the 2D
        tracker runs, the status is no_points and the last 3D box is kept (with the null estimator,
        "none", the cloud is not used). An empty (0, 3) cloud is the sensor seeing nothing: also
        no_points, but to a range sensor in space a view without returns is a view without the body,
        so EMPTY_LOST_AFTER such frames in a row, unexplained by the sensor's range, are "lost". A
        cloud that breaks the contract (another shape, not numbers) is refused with ValueError
        before any state moves.

        image None: a dropped frame, see :meth:`skip`. Before init(): ValueError (it used to
        answer "lost" with nan boxes, which a caller could take for a real loss)."""
        self._check_started("update()")
        if image is None:
            return self.skip()
        ms: dict[str, float] = dict.fromkeys(STAGES, 0.0)
        t0 = time.perf_counter()
        image = self.camera.undistort_image(check_image(image, self._size))
        # None: the depth did not arrive (a sensor fault), unlike an empty cloud, which is the
        # sensor seeing nothing (a body that left the view: EMPTY_LOST_AFTER)
        points = check_cloud(points, needed=False) if self.needs_points else points
        points = self._thinned(points)
        res = self.tracker2d.update(_read_only(image))
        own = None   # the tracker's own box when the loop went on from another (the depth's body)
        try:
            ok, raw = res
            shape = np.shape(raw)
            # a copy: a tracker that returns its own array and moves it in correct() had its fused
            # box recorded as its own (a plug-in walkthrough)
            raw = np.array(raw, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):  # a plug-in's bug, named as such (not numpy's message)
            raise ValueError(self._protocol_broken(res)) from None
        if not _is_flag(ok) or (ok and shape not in ((4,), (1, 4))):
            # ok="no" had counted as found, a (2, 2) array as a box
            raise ValueError(self._protocol_broken(res))
        if ok and not _valid_box2d(raw):
            self._say_once("box2d", f"the 2D tracker {self._name2d!r} returned ok=True with "
                                    f"{raw.tolist()}, not a box (a non-finite value or a size <= 0): taken as lost")
        t1 = time.perf_counter()
        ms["track2d"] = (t1 - t0) * 1e3
        if not ok or raw.shape != (4,) or not _valid_box2d(raw):
            # Lost in 2D: report the last box (a held frame: the outline its 3D box was measured from),
            # keep the last 3D estimate.
            raw = raw if raw.shape == (4,) and _valid_box2d(raw) else self.box2d.copy()
            status, n, asked, measured, whole = LOST, 0, False, False, None
            held = None   # the outline a held frame's 3D box was measured from: its reported 2D box
            if (self.evidence_points and self.needs_points and points is not None
                    and _judges_loss(self.tracker2d) and _valid_box2d(self.box2d)):
                # the body may still be in view (a sliver at the border): ask the depth, in the
                # frustum of the last box; held, not lost, when it answers
                n, asked = int(len(self._frustum(points, self.box2d.copy())[0])), True
                status = NO_POINTS if n >= self.evidence_points else LOST
                if status == NO_POINTS and self.silhouette > 0.0 and not callable(points):
                    # the returns' outline at the last box, read once for both rules
                    sil = silhouette_box(points, self.box2d, self._M, self._size, self.z_range, self.silhouette,
                                         lone_out=self.drop_stray)
                    whole = self._resumed_outline(points, sil[0]) if self.resume_outline else None
                    measured = whole is None and self._held_outline(points, sil)
                    held = sil[0] if measured else None
                elif status == NO_POINTS and self.outline_contain and not callable(points):
                    whole, measured = self._held_lit(points, image)
                ms["frustum"] = (time.perf_counter() - t0) * 1e3 - ms["track2d"]
            body = whole
            if body is None and status == LOST:
                found = self._body_in_view(points, n if asked else None)
                if found is not None and self._inside(found):
                    body = found
                elif found is not None and self._measure_held(points, found):
                    # at the border: a held frame on the body there (`_body_in_view`)
                    held, status, measured = found, NO_POINTS, True
            if body is None:
                ms["total"] = (time.perf_counter() - t0) * 1e3
                r = TrackResult(self._shown(self.box2d if held is None else held), raw, self.box3d.copy(), status,
                                n, ms, self._score())
                # a 3D box measured from the body's outline in the depth is the body in view: not
                # a bad frame (EVIDENCE_POINTS' notes)
                return self._judge(r, estimated=False, seen=measured)
            own, raw = raw, body   # the depth shows the body whole elsewhere: the loop goes on from it

        if not self.needs_points:   # 2D only: the tracker's box is the answer, no 3D box
            self.box2d = raw.copy()
            ms["total"] = (time.perf_counter() - t0) * 1e3
            r = TrackResult(self._shown(raw), raw.copy(), self.box3d.copy(), TRACKING, 0, ms,
                            self._score())
            return self._judge(r, estimated=False)
        if points is None:
            # the depth did not arrive: the 2D tracker's box, the last 3D box held; a frame the 2D
            # tracker says it tracked is not bad (the tracker judging its own loss), as one past
            # the depth range is not, and no evidence of empty space either
            self.box2d = raw.copy()
            ms["total"] = (time.perf_counter() - t0) * 1e3
            r = TrackResult(self._shown(raw), raw.copy(), self.box3d.copy(), NO_POINTS, 0, ms,
                            self._score())
            return self._judge(r, estimated=False, seen=_judges_loss(self.tracker2d))
        lit = None   # the outline where it is off (stereo: the lit part), for containment and the share
        dark = None  # that outline reaching into the body's dark side (track3d.dark_side), with the sun known
        wants_lit = self.silhouette == 0.0 and (self.outline_contain or (self.outline_share > 0.0 and self.fusion))
        windowed = callable(points)   # a cloud of the box's window only: no whole view to search
        if wants_lit and callable(points):
            # a cloud computed around the box (stereo from the pair: the box and the matcher's
            # margin): the one call the frustum would make, made first so the outline can be read
            points = points(self._cut_box(raw).copy())
        seen, cloud = raw, points
        cut = None   # (frustum points, bounds) of `seen`, when already cut
        if wants_lit and not callable(points):
            lit, near, _ = silhouette_box(points, raw, self._M, self._size, self.z_range, SILHOUETTE,
                                          lone_out=self.drop_stray)
            if lit is not None:
                lit = past_border(lit, raw, self._size)
                if self.outline_contain:
                    seen = self._contain(raw, lit, near, image)
                if self.dark_side > 0.0 and self.sun is not None:
                    dark = dark_side_box(lit, self.sun, self.camera, self.dark_side)
                    seen = reach_dark_side(seen, dark, self.sun, self.camera)
            elif self.outline_contain and not windowed:
                # no returns near the tracker's box: the body, if in view, is elsewhere (a tracker
                # left on the sky by a body that went out of view and came back); the whole
                # view's depth finds it, if it holds enough returns to be a body, not noise
                body, found = self._find_body(points, raw, FIND_MIN_RETURNS)
                if found is not None:
                    seen = lit = body
                    cut = found   # the frustum of the box the loop goes on from, cut once
        if self.silhouette > 0.0 and not callable(points):
            outline, near, region = silhouette_box(points, raw, self._M, self._size, self.z_range, self.silhouette,
                                                   lone_out=self.drop_stray)
            if outline is None:
                # no returns at the tracker's box: the body, if in view, is elsewhere (a fast swing
                # the 2D search did not follow); the depth finds it
                seen, cut = self._find_body(points, raw)
                if seen is None:
                    seen = raw
            else:
                seen = past_border(outline, raw, self._size)
                cloud = self._region_cloud(seen, near, region, points)
        pts, bounds = cut if cut is not None else self._frustum(cloud, seen)
        if seen is not raw and reaches_range(bounds, seen, self.camera, self.depth_range_m):
            # returns stopped by the sensor's range outline a cap, not the body: the range cut
            # (_reported_box) needs the image's box
            seen = raw
            pts, bounds = self._frustum(points, seen)
        start = seen   # the box the 2D fusion starts from
        # returns on a few of the box's pixels (stereo: a body mostly in shadow, depth only where
        # the images have texture) outline a sliver of the body, not its extent in the image
        sparse = self.fusion_cover > 0.0 and len(pts) < self.fusion_cover * float(seen[2]) * float(seen[3])
        if self.outline_share > 0.0 and lit is not None and self.fusion and not sparse and not self._crescent(seen):
            start = self.outline_share * lit + (1.0 - self.outline_share) * seen
        t2 = time.perf_counter()
        ms["frustum"] = (t2 - t1) * 1e3
        views = past = measured = None
        if self._estimator_takes_past and self._views is not None and len(pts) >= self.min_points:
            # the views first: the estimator sees them beside this frame's returns
            measured = self._measured(pts, bounds)   # kept for the report: a partition of the returns' depths
            views = self._update_views(pts, measured, seen)
            past = self._views.past_points(pts)
        est = self._estimate(pts, bounds, seen, past)
        status = TRACKING
        if est is None:
            status = NO_POINTS
            carried = (self._carry_from is not None and self._carry_box is not None
                       and np.all(np.isfinite(self._carry_box)))
            if carried and not any(self._border_sides(seen)):
                # a body that had reached the range and now returns nothing is past it, still in
                # view: its box follows the image's (range_cut.carry_box); from a pair at the image
                # border, whose box may be only the part in view, the depth goes by the body's size
                # (CARRY_CUT_FROM_CLEAR)
                rule = CARRY_CUT_FROM_CLEAR
                self.box3d = carry_box(self._carry_box, self._carry_from, seen, self.camera,
                                       last_sides=self._border_sides(self._carry_from) if rule else None,
                                       last_whole=(self._carry_area, self._carry_area_z) if rule else None)
                self._carry_from, self._carry_box = np.array(seen, dtype=np.float64), self.box3d.copy()
                self._carry_area, self._carry_area_z = float(seen[2] * seen[3]), float(self.box3d[2])
                self._border_from = self._border_box = None
            elif carried and CARRY_AT_BORDER:
                # at the image border: the side in view follows the body (CARRY_AT_BORDER)
                if self._border_from is None:
                    self._border_from, self._border_box = self._carry_from.copy(), self._carry_box.copy()
                self.box3d = carry_box(self._border_box, self._border_from, seen, self.camera,
                                       last_sides=self._border_sides(self._border_from), sides=self._border_sides(seen))
                self._border_from, self._border_box = np.array(seen, dtype=np.float64), self.box3d.copy()
        else:
            bounds = self._measured(pts, bounds) if measured is None else measured
            far = limit = None
            if views is not None:
                far, limit = views
            elif self._views is not None:
                far, limit = self._update_views(pts, bounds, seen)
            self.box3d = self._report(est, bounds, seen, far, limit, pts)
        t3 = time.perf_counter()
        ms["box3d"] = (t3 - t2) * 1e3
        # without fusion the reported 2D box is the 2D tracker's own (the outline only feeds the 3D box)
        box = seen if self.fusion else raw
        if self.fusion and est is not None:
            # a cap of a body past the range is not its extent in the image (CAP_FUSION_COVERAGE)
            box = np.array(start, dtype=np.float64) if self._small_cap or sparse else fuse(start, est, self.camera,
                                                                                           self.weight_3d)
            if self._correct is not None:
                self._correct(box)
            if dark is not None:
                # the lit outline's share of `start` and the fusion pulled the dark side back in;
                # pushed out again after the tracker's correction (before it, the calibration
                # sets' mean AO_3d at 0.1 was 0.7191 instead of 0.7201: DARK_SIDE's notes)
                box = reach_dark_side(box, dark, self.sun, self.camera)
        self.box2d = box.copy()
        t4 = time.perf_counter()
        ms["fusion"] = (t4 - t3) * 1e3
        ms["total"] = (t4 - t0) * 1e3
        r = TrackResult(self._shown(box), (raw if own is None else own).copy(), self.box3d.copy(), status,
                        int(len(pts)), ms,
                        self._score())
        return self._judge(r, estimated=est is not None, seen=_judges_loss(self.tracker2d),
                           empty=est is None and len(pts) == 0)

    def _check_units(self, points: np.ndarray, box2d: np.ndarray) -> None:
        """ValueError when the first box's returns all lie 10x or more outside `z_range`: a cloud
        in millimetres, centimetres or kilometres (a millimetre cloud had left the first 3D box NaN
        and every frame "no_points", then "lost", with the 2D tracker sure of the body). Returns
        just past the range (a body still far) are no error: the 3D box starts when it comes in."""
        if len(self._frustum(points, box2d)[0]):
            return
        z0, z1 = self.z_range
        seen = extract_frustum_bounds(points, self._cut_box(box2d), self._M, 0.0, MAX_COORD_M)[0]
        if len(seen) < max(self.min_points, 1):
            return
        z = float(np.median(seen[:, 2]))
        if z > 10.0 * z1 or z < z0 / 10.0:
            raise ValueError(f"the cloud's {len(seen)} returns in the first box lie at a median depth of {z:.4g}, "
                             f"far outside the loop's depth range [{z0:g}, {z1:g}] m: is the cloud in metres? "
                             f"(Track3D(z_range=...) for another range)")

    def _crescent(self, box2d: np.ndarray) -> bool:
        """Whether the sun is known and lies past `outline_share_phase` at the box: the lit outline
        is then a crescent, not the body's size (OUTLINE_SHARE_PHASE)."""
        return (self.sun is not None and self.outline_share_phase < 180.0
                and phase_deg(box2d, self.sun, self.camera) > self.outline_share_phase)

    def _body_in_view(self, points, at_last: int | None) -> np.ndarray | None:
        """For a frame the 2D tracker calls lost with no returns left at its last box (`at_last`:
        the returns counted in its frustum, None: not counted yet): the box [x, y, w, h] of the
        body in the whole view's depth (`silhouette.find_body`), or None. With the body's outline
        on (a range sensor against empty space) a body in the depth is the body.

        The caller takes two cases apart. A body whole inside the image (`_inside`): the loop goes
        on from it (a lost EdgeTrack whose template no longer matched a body swinging back into
        view stayed lost while the depth showed it whole: accuracy set test 0005, 15 frames). A
        body at the image border: a held frame, its 3D box measured from that outline and the
        outline reported, the tracker left as it was (corrected onto a sliver, it did not
        re-acquire the body when it came back whole: held-out 0011). Without the held frame a
        body that left at the border and came back there was missed: EdgeTrack, not calling the
        loss at once, drifted onto the sky and the loop kept the last 3D box for 7 frames (ideal
        long watch, test 0005)."""
        if (not self.silhouette > 0.0 or points is None or callable(points) or not self.needs_points
                or not _judges_loss(self.tracker2d) or not _valid_box2d(self.box2d)):
            return None
        if at_last is None:
            at_last = len(self._frustum(points, self.box2d.copy())[0])
        if at_last > 0:   # returns at the last box: the depth-held rule's case, not a body elsewhere
            return None
        return self._find_body(points, self.box2d)[0]

    def _find_body(self, points: np.ndarray, near: np.ndarray, min_returns: int | None = None
                   ) -> tuple[np.ndarray | None, tuple[np.ndarray, np.ndarray] | None]:
        """The body the whole view's depth shows (`silhouette.find_body`, the one nearest `near`)
        when it holds at least `min_returns` returns (None: FIND_MIN_RETURNS with `drop_stray`,
        else any; a few false alarms or stereo's stray matches are no body) and continues the
        track: the median depth of its returns within the last 3D box's depth span widened by
        FIND_DEPTH_SLACK of its range (another body in view is not the target), its size across
        the line of sight the last box's within FIND_SIZE_RATIO (a binary's other body). -> (its box
        [x, y, w, h], its frustum (points, bounds)), or (None, None). Without a 3D box yet the
        depth is not checked."""
        body = find_body(points, near, self._M, self._size, self.z_range, self.drop_stray)
        if body is None:
            return None, None
        cut = self._frustum(points, body)
        if min_returns is None:
            min_returns = FIND_MIN_RETURNS if self.drop_stray else 1
        if len(cut[0]) < min_returns:
            return None, None
        b = self.box3d
        if len(cut[0]) and np.all(np.isfinite(b)):
            z = float(np.median(cut[0][:, 2]))
            slack = FIND_DEPTH_SLACK * float(b[2])
            if not b[2] - b[5] / 2.0 - slack <= z <= b[2] + b[5] / 2.0 + slack:
                return None, None
            if not self._like_in_size(body, z):
                return None, None
        return body, cut

    def _like_in_size(self, body: np.ndarray, z: float) -> bool:
        """Whether the body found at `body` [x, y, w, h] (median depth z m) can be the body of the
        last 3D box: its larger side at that depth at most FIND_SIZE_RATIO times the box's larger
        side across the line of sight, or FIND_DEPTH_SIZE times its depth extent (a 3:1 body lost
        end-on and found side-on shows the long axis the box held along the line of sight; that
        extent is the box network's guess, so it gets a tighter factor), and at least the box's
        middle extent over FIND_SIZE_RATIO (a smaller one cut by the image border passes: part of
        the target coming back into view)."""
        b = self.box3d
        found = max(float(body[2]) * z / self.camera.fx, float(body[3]) * z / self.camera.fy)
        ext = np.asarray(b[3:6], dtype=np.float64)
        if not (np.isfinite(found) and np.all(np.isfinite(ext))) or max(ext) <= 0.0:
            return True
        if found > FIND_SIZE_RATIO * max(ext[0], ext[1]) and found > FIND_DEPTH_SIZE * ext[2]:
            return False
        return found * FIND_SIZE_RATIO >= float(np.median(ext)) or any(self._border_sides(body))

    def _inside(self, box: np.ndarray) -> bool:
        """Whether `box` lies inside the image, off its border by more than half a pixel."""
        W, H = self._size
        return bool(box[0] > 0.5 and box[1] > 0.5 and box[0] + box[2] < W - 0.5 and box[1] + box[3] < H - 0.5)

    def _resumed_outline(self, points: np.ndarray, outline: np.ndarray | None) -> np.ndarray | None:
        """For a frame the 2D tracker calls lost while the depth holds the body at its last box
        (`resume_outline`): the returns' outline there when it holds at least RESUME_SHARE of the
        last box's area in the image, is not cut by the image border on one side only and its
        returns do not reach the sensor's range (the body in view, not a sliver at the border, a
        body coming in or a cap); the loop goes on from it as from the tracker's box. None: the
        frame is held (`_held_outline`). `outline`: silhouette_box's at the last box."""
        if outline is None:
            return None
        W, H = self._size
        a, b = clip_box2d(outline, W, H), clip_box2d(self.box2d, W, H)
        if not a[2] * a[3] >= RESUME_SHARE * b[2] * b[3] > 0.0:
            return None
        left, top, right, bottom = self._border_sides(outline)
        if left != right or top != bottom:
            return None   # cut on one side: coming into view or leaving it, not a body larger than the view
        if reaches_range(self._frustum(points, outline)[1], outline, self.camera, self.depth_range_m):
            return None
        return outline

    def _shown(self, box: np.ndarray) -> np.ndarray:
        """The reported 2D box: `box` clipped to the image, as the labels are (docs/dataset.md:
        the visible silhouette's box). The loop keeps the whole box (a body coming into view
        goes on past the border; the 2D tracker is corrected with it). A box wholly outside the
        image is reported as it is (clipping would leave no box)."""
        b = np.array(box, dtype=np.float64)
        W, H = self._size
        if b[0] >= 0 and b[1] >= 0 and b[0] + b[2] <= W and b[1] + b[3] <= H:
            return b   # inside: as it is (x + w - x need not give w back in floats)
        c = clip_box2d(b, W, H)
        return c if c[2] > 0 and c[3] > 0 else b

    def _region_cloud(self, box: np.ndarray, near: np.ndarray, region: np.ndarray,
                      points: np.ndarray) -> np.ndarray:
        """The search region's returns `near` when the region holds `box` widened by the frustum
        margin (no second pass over the whole cloud), else the whole cloud `points`."""
        grow = box[2:] * self.frustum_margin / 2.0
        if (box[0] - grow[0] >= region[0] and box[1] - grow[1] >= region[1]
                and box[0] + box[2] + grow[0] <= region[0] + region[2]
                and box[1] + box[3] + grow[1] <= region[1] + region[3]):
            return near
        return points

    def _held_outline(self, points: np.ndarray, sil: tuple) -> bool:
        """A frame the 2D tracker calls lost while the depth holds the body at its last box (a
        sliver at the image border): the 3D box from the returns' outline there; True when it was
        measured. The frame reports that outline as its 2D box (the sliver in view, as the label
        is: the last box, reported before, was 0.13-0.34 IoU_2d on a body leaving the view), but the
        loop's own box and the tracker stay as they were: corrected onto a sliver, the tracker did
        not re-acquire the body when it came back whole. `sil`: silhouette_box's (outline, search
        points, search region) at the last box."""
        outline, near, region = sil
        if outline is None:
            return False
        return self._measure_held(self._region_cloud(outline, near, region, points), outline)

    def _held_lit(self, points: np.ndarray, image: np.ndarray) -> tuple[np.ndarray | None, bool]:
        """`_held_outline` where the outline is the lit part (stereo, `outline_contain`): the last
        box moved to hold the lit outline there. With `resume_outline` and the lit outline a body
        in view (`_resumed_outline`'s tests), (that box, False): the loop goes on from it as from
        the tracker's box. Otherwise (None, measured): the 3D box from its frustum, measured True
        when it was; the 2D box and the tracker stay as they were."""
        lit, near, _ = silhouette_box(points, self.box2d, self._M, self._size, self.z_range, SILHOUETTE,
                                      lone_out=self.drop_stray)
        if lit is None:
            return None, False
        box = self._contain(self.box2d, past_border(lit, self.box2d, self._size), near, image)
        if self.resume_outline and self._resumed_outline(points, lit) is not None:
            return box, False
        return None, self._measure_held(points, box)

    def _contain(self, box: np.ndarray, lit: np.ndarray, near: np.ndarray, image: np.ndarray) -> np.ndarray:
        """`box` moved to hold the lit outline `lit` (`silhouette.contain`), then, with
        `texture_trim`, pulled in off texture the returns `near` (the outline's) did not match
        (`unmatched_texture.trim_unmatched`; the right camera's blind band at the left border
        from the nearest return's disparity)."""
        box = contain(box, lit, CONTAIN_SLACK_PX)
        if not self.texture_trim or not len(near):
            return box
        z = float(near[:, 2].min())
        if self.camera.baseline_m is None:   # clouds of a pair the camera does not describe: no band known
            blind = 0.0
        else:
            blind = self.camera.fx * self.camera.baseline_m / z if z > 0.0 else float(self._size[0])
        return trim_unmatched(box, lit, image, len(near), blind)

    def _measure_held(self, cloud: np.ndarray, box: np.ndarray) -> bool:
        """A held frame's 3D box from the frustum of `box` in `cloud`; False (the box held as it
        was) when the returns reach the depth range or give no estimate."""
        pts, bounds = self._frustum(cloud, box)
        if reaches_range(bounds, box, self.camera, self.depth_range_m):
            return False
        far = limit = past = None
        measured = self._measured(pts, bounds)
        if self._views is not None and len(pts) >= self.min_points:
            # as a tracked frame: the returns into the past views, and a views model given them
            # (HELD_VIEWS)
            far, limit = self._update_views(pts, measured, box) if HELD_VIEWS else (None, None)
            if self._estimator_takes_past and HELD_VIEWS:
                past = self._views.past_points(pts)
        est = self._estimate(pts, bounds, box, past)
        if est is None:
            return False
        self.box3d = self._report(est, measured, box, far, limit, pts)
        return True

    # --- checkpoints and self-description ------------------------------------------------------
    def get_state(self) -> dict:
        """The tracker's state as plain data (dicts, lists, str, numbers; arrays base64-coded by
        ``track3d.state.to_plain``): picklable and JSON-able, no onnxruntime objects.

        ``set_state`` on a fresh Track3D of the same configuration restores it. What the 2D
        tracker restores depends on it: SiamFC and the oracle their full state (bit-identical
        continuation); OpenCV trackers their last frame and box (a re-initialisation there).
        A tracker or estimator without ``get_state`` cannot be checkpointed (ValueError) unless
        it is stateless (an estimator without the method is taken as stateless).
        """
        from .state import to_plain

        get2d = getattr(self.tracker2d, "get_state", None)
        if get2d is None:
            raise ValueError(f"the 2D tracker {self._name2d!r} has no get_state(): it cannot be checkpointed")
        get3d = getattr(self.estimator, "get_state", None)
        return to_plain({
            "version": STATE_VERSION, "tracker": self.tracker_name or type(self.tracker2d).__name__,
            "estimator": self.estimator_name or type(self.estimator).__name__,
            "camera": self.camera.to_dict(),
            "category": self.category, "box2d": self.box2d, "box3d": self.box3d,
            "bad_frames": self.bad_frames, "held_frames": self.held_frames, "empty_frames": self._empty_frames,
            "depth_avg": self._depth_avg if np.isfinite(self._depth_avg) else None,
            "whole_box": None if self._whole_box is None else self._whole_box.tolist(),
            "depth_ratio": self._depth_ratio if np.isfinite(self._depth_ratio) else None,
            "carry_from": None if self._carry_from is None else self._carry_from.tolist(),
            "carry_box": None if self._carry_box is None else self._carry_box.tolist(),
            "carry_area": self._carry_area if np.isfinite(self._carry_area) else None,
            "carry_area_z": self._carry_area_z if np.isfinite(self._carry_area_z) else None,
            "border_from": None if self._border_from is None else self._border_from.tolist(),
            "border_box": None if self._border_box is None else self._border_box.tolist(),
            "tracker2d": get2d(), "estimator_state": get3d() if get3d is not None else None,
            "body_views": None if self._views is None else self._views.get_state(),
            "sun": None if self.sun is None else self.sun.tolist(),
            "front": list(self._front) if np.isfinite(self._front[0]) else None,
            "first_box": None if self._first is None else self._first.tolist(),
            "config": self._config_key(),
        })

    def _config_key(self) -> dict:
        """What a state continues bit for bit only on: the model files (name: sha256 prefix) and a
        digest of the loop's options (describe()'s, and the first box's fade). Threads and the
        parts' other options are left out: they change no output, or change the models."""
        import hashlib
        import json

        d = self.describe()
        opts = json.dumps({**d["options"], "first_box_fade": self.first_box_fade}, sort_keys=True, default=str)
        return {"models": sorted(f"{m.get('file')}:{str(m.get('sha256'))[:16]}" for m in d["models"]),
                "options": hashlib.sha256(opts.encode()).hexdigest()[:16]}

    def set_state(self, state: dict) -> None:
        """Restore a :meth:`get_state` of a Track3D built with the same names, model files, loop
        options and camera (the state's `config` key; a state from before the key is taken as is).

        A damaged state (a field missing, of the wrong type, not finite, a box of no size, a
        part's state its own ``set_state`` refuses) raises ValueError with one line and leaves
        the tracker as it was."""
        from .state import damaged, from_plain, read_box, read_float, read_int

        st = from_plain(state)
        if not isinstance(st, dict) or st.get("version") != STATE_VERSION:
            raise ValueError(f"not a Track3D state of version {STATE_VERSION}")
        mine = (self.tracker_name or type(self.tracker2d).__name__, self.estimator_name or type(self.estimator).__name__)
        if (st.get("tracker"), st.get("estimator")) != mine:
            raise ValueError(f"state of {st.get('tracker')!r:.40}+{st.get('estimator')!r:.40} cannot restore a "
                             f"{mine[0]}+{mine[1]} tracker")
        set2d = getattr(self.tracker2d, "set_state", None)
        if set2d is None:
            raise ValueError(f"the 2D tracker {self._name2d!r} has no set_state()")
        # another model file or other loop options would go on from the state, but not as the
        # tracker that wrote it (a stereo model's state had restored into the ideal-depth loop);
        # states written before the key are taken as they are
        if "config" in st:
            theirs, ours = st["config"], self._config_key()
            if not (isinstance(theirs, dict) and isinstance(theirs.get("models"), list)
                    and all(isinstance(m, str) for m in theirs["models"]) and isinstance(theirs.get("options"), str)):
                raise ValueError(f"Track3D state damaged: config must hold models (a list of names) and options "
                                 f"(a digest), got {theirs!r:.80}")
            if theirs["models"] != ours["models"]:
                other = sorted(set(theirs["models"]) ^ set(ours["models"]))
                raise ValueError(f"state of other model files cannot restore this tracker (differ: "
                                 f"{', '.join(x.split(':')[0] for x in other)[:120]})")
            if theirs["options"] != ours["options"]:
                raise ValueError("state of other loop options cannot restore this tracker (describe()['options'] "
                                 "or first_box_fade differ)")

        def box_or_none(key: str, n: int):
            v = st.get(key)
            return None if v is None else read_box(v, key, n)

        def number_or_nan(key: str, lo: float):
            v = st.get(key)
            return float("nan") if v is None else read_float(v, key, lo=lo)

        # Read every field before changing anything: a damaged state leaves the tracker as it was.
        # Boxes are in the state's image: another camera's would land in the wrong place.
        # (States written before the camera was recorded have none and are taken as they are.)
        if "camera" in st:
            with damaged("Track3D"):
                cam = Camera.from_dict(st["camera"])
            if cam != self.camera:
                raise ValueError(f"state of a {cam.width}x{cam.height} camera cannot restore a tracker of another "
                                 f"camera ({self.camera.width}x{self.camera.height} or other intrinsics)")
        with damaged("Track3D"):
            category = check_category(st["category"], getattr(self.estimator, "num_categories", None))
            box2d = read_box(st["box2d"], "box2d", 4, unset_ok=True, empty_ok=True)
            box3d = read_box(st["box3d"], "box3d", 6, unset_ok=True)
            bad, held = read_int(st["bad_frames"], "bad_frames"), read_int(st["held_frames"], "held_frames")
            empty = read_int(st.get("empty_frames", 0), "empty_frames")   # 0: an older state
            depth_avg = number_or_nan("depth_avg", 0.0)   # None: no box yet, or a state from before the average
            whole_box = box_or_none("whole_box", 6)   # None: no whole view yet, or a state from before it
            depth_ratio = number_or_nan("depth_ratio", 0.0)   # None: no box within the range yet, or an older state
            carry_from = box_or_none("carry_from", 4)   # None: the last box's returns were within the range, or older
            carry_box = st.get("carry_box", st["box3d"])   # an older state carried its last box
            carry_area = number_or_nan("carry_area", 0.0)   # None: no clear box reached the range yet, or older
            carry_area_z = number_or_nan("carry_area_z", 0.0)   # None: as carry_area, or a state from before it
            carry_box = None if carry_from is None or carry_box is None else read_box(carry_box, "carry_box", 6)
            border_from, border_box = st.get("border_from"), st.get("border_box")   # None: not at the border
            if border_from is None or border_box is None:
                border_from = border_box = None
            else:
                border_from, border_box = read_box(border_from, "border_from", 4), read_box(border_box, "border_box", 6)
            tracker2d, estimator_state = st["tracker2d"], st.get("estimator_state")
            if not isinstance(tracker2d, dict):
                raise ValueError(f"tracker2d must be a dict, got {type(tracker2d).__name__}")
            set3d = getattr(self.estimator, "set_state", None)
            if estimator_state is not None and set3d is None:
                raise ValueError(f"the estimator {self.estimator_name or type(self.estimator).__name__} keeps no "
                                 f"state, but the state holds one")
            sun = check_sun(st.get("sun"))   # None: unknown, or a state from before the sun
            front = st.get("front")   # None: no filtered front face yet, or an older state
            if front is None:
                front = (float("nan"), 0.0)
            else:
                if not isinstance(front, list) or len(front) != 2:
                    raise ValueError(f"front must be two numbers, got {front!r:.40}")
                front = (read_float(front[0], "front"), read_float(front[1], "front rate"))
            first = st.get("first_box")   # None: started without a 3D box, or an older state
            first = None if first is None else check_init_box3d(first)
            views = None
            if self._views is not None and st.get("body_views") is not None:
                views = BodyViews(self.camera, self._views.params)
                views.set_state(st["body_views"])
        # The parts last, each refusing a damaged state of its own without a change; the
        # estimator's is put back if the 2D tracker then refuses.
        before3d = self.estimator.get_state() if estimator_state is not None else None
        if estimator_state is not None:
            with damaged(f"{self.estimator_name or type(self.estimator).__name__} estimator"):
                set3d(estimator_state)
        try:
            with damaged(f"{mine[0]} 2D tracker"):
                set2d(tracker2d)
        except ValueError:
            if before3d is not None:
                set3d(before3d)
            raise
        self.category, self.box2d, self.box3d = category, box2d, box3d
        self.bad_frames, self.held_frames, self._depth_avg = bad, held, depth_avg
        self._empty_frames = empty
        self._whole_box = whole_box
        self._depth_ratio = depth_ratio
        self._carry_from, self._carry_box, self._carry_area = carry_from, carry_box, carry_area
        self._carry_area_z = carry_area_z
        self._border_from, self._border_box = border_from, border_box
        self.sun = sun
        self._front = front
        self._first = first
        if self._views is not None:   # a state without views (an older one, or views off): they start over
            if views is None:
                self._views.reset()
            else:
                self._views = views
        self._started = bool(np.isfinite(box2d).all())   # the state of a started tracker

    def __getstate__(self):
        # pickle / copy would stop inside onnxruntime ("cannot pickle InferenceSession"), a
        # message that does not say what to do instead.
        raise TypeError("a Track3D holds onnxruntime sessions and OpenCV trackers and cannot be pickled: "
                        "checkpoint it with state = t.get_state() (plain data) and t2.set_state(state)")

    def describe(self) -> dict:
        """What this tracker is, as a plain dict: names, options, and every ONNX model file it
        runs (path name, sha256, kind, metadata version). Result folders record it."""
        models = []
        for part in (self.tracker2d, self.estimator):
            models += _models_of(part)
        return {
            "tracker": self.tracker_name or type(self.tracker2d).__name__,
            "estimator": self.estimator_name or type(self.estimator).__name__,
            "tracker_options": _plain_options(self.tracker_options),
            "estimator_options": _plain_options(self.estimator_options),
            "options": {"fusion": self.fusion, "weight_3d": self.weight_3d, "z_range": list(self.z_range),
                        "frustum_margin": self.frustum_margin, "depth_range_m": self.depth_range_m,
                        "weight_2d": self.weight_2d, "measured_faces": self.measured_faces,
                        "depth_smoothing": self.depth_smoothing, "min_points": self.min_points,
                        "lost_after": self.lost_after, "min_score": self.min_score,
                        "evidence_points": self.evidence_points,
                        "reacquire_threshold": self.reacquire_threshold,
                        "hold_cut_size": self.hold_cut_size, "edge_pad": self.edge_pad,
                        # only when on: the records of runs with the nearest return stay as they were
                        **({"front_quantile": self.front_quantile} if self.front_quantile > 0.0 else {}),
                        **({"front_filter": list(self.front_filter)} if self.front_filter is not None else {}),
                        # only when on: the records of runs without it stay as they were
                        **({"section_limbs": list(self.section_limbs)} if self.section_limbs is not None else {}),
                        "silhouette": self.silhouette, "outline_share": self.outline_share,
                        # only when on: the records of runs without it stay as they were
                        **({"outline_share_phase": self.outline_share_phase}
                           if self.outline_share_phase < OUTLINE_SHARE_PHASE else {}),
                        "outline_contain": self.outline_contain,
                        **({"texture_trim": True} if self.texture_trim else {}),
                        **({"resume_outline": True} if self.resume_outline else {}),
                        # only when on: the records of runs without it stay as they were
                        **({"dark_side": self.dark_side} if self.dark_side > 0.0 else {}),
                        **({"fusion_cover": self.fusion_cover} if self.fusion_cover > 0.0 else {}),
                        # only when on: the records of runs without the views stay as they were
                        **({"body_views": asdict(self._views.params)} if self._views is not None else {}),
                        **({"drop_stray": True} if self.drop_stray else {}),
                        **({"max_cloud_points": self.max_cloud_points} if self.max_cloud_points else {}),
                        # acts only with a first 3D box (init(box3d=)); named when not the default
                        **({"first_box_fade": self.first_box_fade} if self.first_box_fade != FIRST_BOX_FADE else {})},
            "models": models,
        }


def _plain_options(o: dict) -> dict:
    """Options as JSON-able values; arrays (e.g. the oracle's ground truth) become a short note."""
    out = {}
    for k, v in o.items():
        if isinstance(v, np.ndarray):
            out[k] = f"<array {v.shape}>"
        elif isinstance(v, (str, int, float, bool)) or v is None:
            out[k] = v
        else:
            out[k] = str(v)
    return out


_SHA: dict = {}


def _models_of(part) -> list[dict]:
    """The OnnxModel attributes of a tracker or estimator, described (sha256 cached per file)."""
    from .onnxmodel import OnnxModel, models_of

    out = []
    for attr, v in models_of(part).items():
        if isinstance(v, OnnxModel):   # files to describe (a stand-in has none)
            import hashlib

            f = getattr(v, "file", v.path)  # the variant that runs (fp32, int8 twin ...)
            key = (str(f), f.stat().st_mtime_ns)
            if key not in _SHA:
                _SHA[key] = hashlib.sha256(f.read_bytes()).hexdigest()
            out.append({"role": attr, "file": f.name, "sha256": _SHA[key], "kind": v.meta.get("kind"),
                        "version": v.meta.get("version"), "engine": v.engine, "precision": v.precision,
                        "threads": v.threads, "reason": v.choice.get("reason")})
    return out
