"""2D trackers behind one small protocol (OpenCV style) and a registry of them by name.

The protocol (:class:`Tracker2D`)::

    tracker.init(image, box)            # image (H, W, 3) uint8 RGB, box (4,) [x, y, w, h]
    ok, box = tracker.update(image)     # ok: bool, box: (4,) float64
    tracker.correct(box)                # optional: adopt a new state box (e.g. the fused one)

Built-in names (:func:`available_trackers`):

- ``"oracle"``: replays the ground truth, ``create_tracker("oracle", gt=seq.gt2d)``; scores a
  box estimator alone (the paper's A3BoxNet row). It knows its frame index: ``seek(i)`` before
  ``init`` says which frame the init image is (the evaluation does this); without ``seek`` the
  init box is looked up among the ground-truth rows. Each ``update`` advances one frame.
- ``"kcf"``, ``"csrt"``, ``"mosse"``, ``"mil"``, ``"medianflow"``, ``"boosting"``:
  OpenCV's classic trackers (opencv-contrib-python-headless, some under ``cv2.legacy``).
  OpenCV only ever gets integer boxes inside the image of at least ``MIN_SIDE[name]`` pixels
  (measured with OpenCV 5.0: Boosting segfaults in ``update`` after an ``init`` with a
  fractional box touching the image border; MIL and Boosting never return from ``init`` on a
  box under 5 px); a smaller box starts the tracker 'lost'. TLD is not registered: it takes
  seconds per frame on small boxes (11 s for one update on 3x3 px) and reports boxes far
  outside the image, which no input check can make safe.
- ``"nano"``: OpenCV's NanoTrack with ``backbone=`` / ``neckhead=`` ONNX paths (default: the
  peer models in the folder named by ``$TRACK3D_NANOTRACK_DIR``; benchmarks only, never shipped).
- ``"siamfc"``, ``"siamfc-edge"``: this project's SiamFC (``track3d.siamfc``), loaded lazily.
- ``"edgetrack"``: the fast edge tracker (``track3d.edgetrack``); ``model=<dir>/<name>`` picks an
  exported pair instead of the shipped one; it exposes ``score`` (0..1) and reports ok=False when lost.

OpenCV trackers cannot take a new state box without relearning their appearance model, so
their ``correct`` does nothing by default (the fused box is reported but the OpenCV tracker
follows its own estimate); ``correct="reinit"`` re-initialises them on the current frame
with the corrected box instead.
"""
from __future__ import annotations

import importlib
import os
from contextlib import contextmanager
from pathlib import Path
from typing import Callable, Iterator, Protocol, runtime_checkable

import cv2
import numpy as np

from .frames import check_image
from .state import damaged, read_array, read_flag, read_int

__all__ = [
    "Tracker2D", "OpenCVTracker", "OracleTracker", "TrackerUnavailable", "MIN_SIDE",
    "create_tracker", "tracker_factory", "available_trackers", "register_tracker", "NANOTRACK_ENV", "nanotrack_dir",
]

# runtime/track3d/trackers2d.py -> the repository root is two folders up from the package.
# NanoTrack v2 is a peer's model, never shipped: its folder (nanotrack_backbone_sim.onnx,
# nanotrack_head_sim.onnx) comes from this environment variable or the factory's options.
NANOTRACK_ENV = "TRACK3D_NANOTRACK_DIR"


def nanotrack_dir() -> Path | None:
    """The NanoTrack peer-model folder named by $TRACK3D_NANOTRACK_DIR, or None."""
    d = os.environ.get(NANOTRACK_ENV)
    return Path(d) if d else None


class TrackerUnavailable(RuntimeError):
    """A registered tracker cannot be built here (a missing model file or module)."""


@runtime_checkable
class Tracker2D(Protocol):
    """What the Track3D loop needs from a 2D tracker (OpenCV's API, RGB images)."""

    def init(self, image: np.ndarray, box: np.ndarray) -> None:
        """Start tracking the target in `box` [x, y, w, h] of `image` (H, W, 3) uint8 RGB."""

    def update(self, image: np.ndarray) -> tuple[bool, np.ndarray]:
        """Track into the next frame: (found, box (4,) float64 [x, y, w, h])."""


def _as_box(box) -> np.ndarray:
    b = np.asarray(box, dtype=np.float64).reshape(-1)
    if b.shape != (4,):
        raise ValueError(f"a 2D box is [x, y, w, h], got shape {np.shape(box)}")
    return b


# --- the oracle ---------------------------------------------------------------------------------

class OracleTracker:
    """Replays ground-truth boxes: gt (T, 4); absent (T,) bool frames report ok=False."""

    def __init__(self, gt: np.ndarray, absent: np.ndarray | None = None):
        self.gt = np.asarray(gt, dtype=np.float64).reshape(-1, 4)
        self.absent = np.zeros(len(self.gt), bool) if absent is None else np.asarray(absent, bool)
        if len(self.absent) != len(self.gt):
            raise ValueError("oracle: absent flags and ground truth differ in length")
        self.frame = -1           # index of the frame last seen
        self._next_init: int | None = None

    def seek(self, frame: int) -> None:
        """Say which frame the next ``init`` image is (0-based)."""
        if not 0 <= int(frame) < len(self.gt):
            raise IndexError(f"oracle: frame {frame} outside 0..{len(self.gt) - 1}")
        self._next_init = int(frame)

    def init(self, image: np.ndarray, box: np.ndarray) -> None:
        b = _as_box(box)
        if self._next_init is not None:
            self.frame, self._next_init = self._next_init, None
            return
        # No seek: find the frame whose label is this box, first from the current position on.
        match = np.flatnonzero(np.all(np.isclose(self.gt, b, atol=1e-6), axis=1))
        if len(match) == 0:
            raise ValueError("oracle: the init box is no ground-truth row; call seek(frame) first")
        later = match[match > self.frame]
        self.frame = int(later[0] if len(later) else match[0])

    def update(self, image: np.ndarray) -> tuple[bool, np.ndarray]:
        self.frame += 1
        if self.frame >= len(self.gt):
            return False, np.full(4, np.nan)
        b = self.gt[self.frame].copy()
        ok = bool(not self.absent[self.frame] and np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0)
        return ok, b

    def correct(self, box: np.ndarray) -> None:
        """The oracle follows the ground truth whatever the fused box is."""

    def get_state(self) -> dict:
        """The frame position (the ground truth itself is configuration, given at construction)."""
        return {"frame": int(self.frame)}

    def set_state(self, state: dict) -> None:
        with damaged("oracle"):
            frame = read_int(state["frame"], "frame", lo=-1)
        self.frame, self._next_init = frame, None


# --- OpenCV adapters ----------------------------------------------------------------------------

def _cv_constructor(candidates) -> tuple[Callable[[], object], bool] | None:
    """First existing constructor among (dotted name, legacy?) pairs, e.g. ('legacy.TrackerKCF_create', True)."""
    for name, legacy in candidates:
        obj = cv2
        for part in name.split("."):
            obj = getattr(obj, part, None)
            if obj is None:
                break
        if obj is not None:
            return obj, legacy
    return None


class OpenCVTracker:
    """Adapter for a cv2 tracker: RGB in (converted to BGR as OpenCV expects), float64 boxes out.

    Boxes given to OpenCV are clipped to the image and rounded outwards to integer pixels
    (fractional boxes at the border crash Boosting); a box wholly outside the image, or with a
    side under ``min_side`` pixels after clipping (MIL and Boosting hang on those), starts the
    tracker 'lost'. OpenCV exceptions in ``update`` become ``ok=False``.
    """

    def __init__(self, name: str, make: Callable[[], object], legacy: bool, correct: str = "none",
                 min_side: int = 1):
        if correct not in ("none", "reinit"):
            raise ValueError(f"correct must be 'none' or 'reinit', got {correct!r}")
        self.name = name
        self._make = make
        self._legacy = legacy     # legacy trackers take float Rect2d, the new API int Rect
        self.correct_mode = correct
        self.min_side = max(1, int(min_side))
        self._tracker = None
        self._last_bgr: np.ndarray | None = None
        self._box = np.full(4, np.nan)

    def __repr__(self) -> str:
        return f"OpenCVTracker({self.name!r}, correct={self.correct_mode!r})"

    def _cv_box(self, box: np.ndarray, shape) -> tuple | None:
        h_img, w_img = shape[:2]
        x0 = np.clip(box[0], 0, w_img)
        y0 = np.clip(box[1], 0, h_img)
        x1 = np.clip(box[0] + box[2], 0, w_img)
        y1 = np.clip(box[1] + box[3], 0, h_img)
        if not np.all(np.isfinite([x0, y0, x1, y1])) or x1 - x0 < 1 or y1 - y0 < 1:
            return None
        # Integer pixels, rounded outwards, still inside the image (x1 <= w_img after the clip).
        xi, yi = int(np.floor(x0)), int(np.floor(y0))
        wi, hi = int(np.ceil(x1)) - xi, int(np.ceil(y1)) - yi
        if wi < self.min_side or hi < self.min_side:
            return None
        if self._legacy:  # legacy trackers take a Rect2d: the same integer values as floats
            return (float(xi), float(yi), float(wi), float(hi))
        return (xi, yi, wi, hi)

    def _start(self, bgr: np.ndarray, box: np.ndarray) -> None:
        self._box = box.copy()
        cvbox = self._cv_box(box, bgr.shape)
        self._tracker = None
        if cvbox is None:
            return
        tracker = self._make()
        try:
            r = tracker.init(bgr, cvbox)
        except cv2.error:
            return
        if r is False:  # legacy init returns a bool, the new API None
            return
        self._tracker = tracker

    def init(self, image: np.ndarray, box: np.ndarray) -> None:
        bgr = cv2.cvtColor(check_image(image), cv2.COLOR_RGB2BGR)
        self._last_bgr = bgr
        self._start(bgr, _as_box(box))

    def update(self, image: np.ndarray) -> tuple[bool, np.ndarray]:
        bgr = cv2.cvtColor(check_image(image), cv2.COLOR_RGB2BGR)
        self._last_bgr = bgr
        if self._tracker is None:
            return False, self._box.copy()
        try:
            ok, box = self._tracker.update(bgr)
        except cv2.error:
            return False, self._box.copy()
        b = np.asarray(box, dtype=np.float64).reshape(-1)
        if not ok or b.shape != (4,) or not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
            return False, self._box.copy()
        self._box = b
        return True, b.copy()

    def correct(self, box: np.ndarray) -> None:
        """Adopt `box` as the state: re-init on the current frame when correct='reinit', else nothing."""
        if self.correct_mode == "reinit" and self._last_bgr is not None:
            self._start(self._last_bgr, _as_box(box))

    def get_state(self) -> dict:
        """OpenCV keeps its learned model private: the state is the last frame and box, and
        ``set_state`` re-initialises a fresh tracker on them (the appearance model restarts
        from that frame; two restorations of one state continue identically)."""
        if self._last_bgr is None:
            return {"initialised": False}
        return {"initialised": True, "restore": "reinit", "image_bgr": self._last_bgr.copy(),
                "box": self._box.copy(), "running": self._tracker is not None}

    def set_state(self, state: dict) -> None:
        """Restore a `get_state()`: a re-initialisation on its frame and box; a damaged one raises
        ValueError (one line) and leaves the tracker as it was."""
        with damaged(f"OpenCV {self.name}"):
            if read_flag(state.get("initialised"), "initialised"):
                bgr = read_array(state["image_bgr"], "image_bgr", (-1, -1, 3), np.uint8)
                if bgr.shape[0] < 1 or bgr.shape[1] < 1:
                    raise ValueError(f"image_bgr of shape {bgr.shape}")
                box = read_array(state["box"], "box", (4,), finite=False)   # as init() took it
                running = read_flag(state.get("running", True), "running")
        self._tracker, self._last_bgr = None, None
        if not state["initialised"]:
            return
        self._last_bgr = bgr
        if running:
            self._start(bgr, box)
        self._box = box.copy()


_OPENCV = {  # name -> constructors to try in order, with "is it the legacy API" (Rect2d boxes)
    "kcf": (("TrackerKCF_create", False), ("legacy.TrackerKCF_create", True)),
    "csrt": (("TrackerCSRT_create", False), ("legacy.TrackerCSRT_create", True)),
    "mil": (("TrackerMIL_create", False), ("legacy.TrackerMIL_create", True)),
    "mosse": (("legacy.TrackerMOSSE_create", True),),
    "medianflow": (("legacy.TrackerMedianFlow_create", True),),
    "boosting": (("legacy.TrackerBoosting_create", True),),
    # "tld" is deliberately absent: see the module docstring.
}
# The smallest box side OpenCV gets, per tracker: MIL and Boosting never return from init on
# boxes under 5 px (measured: 3x3 and 4x4 hang, 5x5 and 4x40 do not); 8 leaves a margin.
MIN_SIDE = {"mil": 8, "boosting": 8}


def _opencv(name: str) -> Callable[..., OpenCVTracker]:
    def factory(correct: str = "none", threads: int = 1) -> OpenCVTracker:
        # threads: OpenCV's own pool is set process-wide (track3d.threads.set_threads); accepted
        # here so that every factory takes the same `threads` option
        found = _cv_constructor(_OPENCV[name])
        if found is None:
            raise TrackerUnavailable(f"this OpenCV build ({cv2.__version__}) has no {name} tracker "
                                     "(install opencv-contrib-python-headless)")
        return OpenCVTracker(name, found[0], found[1], correct, MIN_SIDE.get(name, 1))

    return factory


@contextmanager
def opencv_log_level(level: int) -> Iterator[None]:
    """OpenCV's log level set to `level` inside the block, restored after it."""
    before = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(level)
    try:
        yield
    finally:
        cv2.utils.logging.setLogLevel(before)


def _nano(backbone: str | Path | None = None, neckhead: str | Path | None = None,
          correct: str = "none", threads: int = 1) -> OpenCVTracker:
    """NanoTrack v2 through OpenCV (peer model, for benchmarks only: never shipped)."""
    d = nanotrack_dir()
    if (not backbone or not neckhead) and d is None:
        raise TrackerUnavailable(f"NanoTrack needs its peer models: set {NANOTRACK_ENV} to their folder "
                                 "(nanotrack_backbone_sim.onnx, nanotrack_head_sim.onnx) or pass backbone= and neckhead=")
    backbone = Path(backbone) if backbone else d / "nanotrack_backbone_sim.onnx"
    neckhead = Path(neckhead) if neckhead else d / "nanotrack_head_sim.onnx"
    for p in (backbone, neckhead):
        if not p.is_file():
            raise TrackerUnavailable(f"NanoTrack model file {p} not found (pass backbone= and neckhead=)")
    if not hasattr(cv2, "TrackerNano_create"):
        raise TrackerUnavailable(f"this OpenCV build ({cv2.__version__}) has no TrackerNano")

    def make():
        params = cv2.TrackerNano_Params()
        params.backbone = str(backbone)
        params.neckhead = str(neckhead)
        # OpenCV's NanoTrack asks its DNN engine for a target the new graph engine ignores and
        # warns about it on stderr at every creation (twice per sequence, dozens of lines per run)
        with opencv_log_level(cv2.utils.logging.LOG_LEVEL_ERROR):
            return cv2.TrackerNano_create(params)

    return OpenCVTracker("nano", make, False, correct)


def _siamfc(variant: str) -> Callable[..., Tracker2D]:
    def factory(**options) -> Tracker2D:
        try:
            mod = importlib.import_module("track3d.siamfc")
            create = getattr(mod, "create")
        except (ImportError, AttributeError) as e:
            raise TrackerUnavailable(f"SiamFC model not available: track3d.siamfc cannot be loaded ({e})") from None
        from .onnxmodel import ModelError   # loaded with track3d.siamfc above

        try:
            return create(variant=variant, **options)
        except (FileNotFoundError, OSError, ModelError) as e:   # e.g. no shipped model yet
            raise TrackerUnavailable(f"SiamFC model not available: {e}") from None

    return factory


def _edgetrack(**options) -> Tracker2D:
    """EdgeTrack (track3d.edgetrack): the shipped model, or model=<dir>/<name> of an exported pair."""
    from .onnxmodel import ModelError
    try:
        from .edgetrack import create
        return create(**options)
    except (ModelError, FileNotFoundError) as e:
        raise TrackerUnavailable(f"EdgeTrack model not available: {e}") from None


_REGISTRY: dict[str, Callable[..., Tracker2D]] = {
    "oracle": OracleTracker,
    **{name: _opencv(name) for name in _OPENCV},
    "nano": _nano,
    "siamfc": _siamfc("faithful"),
    "siamfc-edge": _siamfc("edge"),
    "edgetrack": _edgetrack,
}


_BUILT_IN = frozenset(_REGISTRY)


def register_tracker(name: str, factory: Callable[..., Tracker2D], replace: bool = False) -> None:
    """Add a tracker: ``factory(**options)`` returns a :class:`Tracker2D`. A built-in name is
    refused unless `replace` (a plug-in named "EdgeTrack" had silently run in its place and
    written under its results' name)."""
    from .plugins import check_registration

    check_registration("tracker", name, factory, _BUILT_IN, replace)
    _REGISTRY[name.lower()] = factory


def _load_plugins() -> None:
    from .plugins import TRACKER_GROUP, load_entry_points

    load_entry_points(TRACKER_GROUP, register_tracker)


# what a registered tracker needs beyond the package (`track3d trackers` says it next to the names)
TRACKER_NEEDS = {"nano": f"the peer NanoTrack v2 models (not shipped): set {NANOTRACK_ENV} to their folder"}


def available_trackers() -> list[str]:
    """Registered tracker names, plug-ins included (some may still need model files to be built)."""
    _load_plugins()
    return sorted(_REGISTRY)


def tracker_factory(name: str) -> Callable[..., Tracker2D]:
    """The factory registered as `name` (plug-ins loaded when it is not yet known); ValueError
    listing the names there are."""
    factory = _REGISTRY.get(str(name).lower())
    if factory is None:
        _load_plugins()
        factory = _REGISTRY.get(str(name).lower())
    if factory is None:
        raise ValueError(f"unknown 2D tracker {name!r}; available: {', '.join(available_trackers())} "
                         "(a plug-in: --plugin MODULE or an entry point in the track3d.trackers group)")
    return factory


def create_tracker(name: str, **options) -> Tracker2D:
    """Build the tracker registered as `name` with its options (e.g. ``gt=`` for "oracle")."""
    factory = tracker_factory(name)
    from .plugins import call_factory, check_built

    return check_built("2D tracker", name, call_factory("2D tracker", name, factory, options), ("init", "update"))
