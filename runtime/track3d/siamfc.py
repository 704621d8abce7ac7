"""SiamFC 2D tracker on onnxruntime (no torch): the runtime half of paper §IV-A.

Two ONNX graphs (written by `track3d-train siamfc export`):
    <name>_exemplar.onnx  uint8 (1, 127, 127, 3) RGB crop -> exemplar feature (1, C, k, k), once per init
    <name>_search.onnx    uint8 (S, N, N, 3) RGB crops + exemplar feature -> responses (S, R, R)

Per frame: S crops of the search region around the last centre (one per scale, mean-colour
padding, one bilinear warp each, `track3d.resample`), one ORT call, cubic upsampling of the
responses, scale penalty, cosine window, scale damping (Bertinetto et al. 2016). Every size and
hyper-parameter comes from the models' metadata (key 'track3d'), so a new model needs no code
change; keyword overrides to `create` / `SiamFCTracker` win over the metadata.

Shipped: `siamfc_edge_*` (default, quarter-width AlexNet, fast) and `siamfc_faithful_*`
(full AlexNet of the paper).
"""
from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np

from .frames import MAX_BOX_SCALE, MIN_BOX_SIDE, check_image, check_init_box
from .onnxmodel import check_pair, load_model, model_pair, shipped_model
from .resample import warp_axis_aligned
from .state import damaged, read_array, read_flag, read_float, read_int, read_kernel

__all__ = ["SiamFCTracker", "create", "crop_square", "model_paths", "VARIANT_FILES", "TUNABLE"]

VARIANT_FILES = {"edge": "siamfc_edge", "faithful": "siamfc_faithful"}
TUNABLE = ("instance_size", "scale_num", "scale_step", "scale_penalty", "scale_lr", "window_influence",
           "response_up", "context_amount")


def crop_square(image: np.ndarray, center: np.ndarray, size: float, out_size: int,
                border: tuple) -> np.ndarray:
    """Square patch of side `size` image pixels centred at `center` (x, y, continuous pixel
    coordinates: pixel i spans [i, i+1)), resized to out_size x out_size; outside the image the
    patch is filled with `border` (the mean colour). One bilinear warp (`track3d.resample`: the
    arithmetic of OpenCV 5.0's warpAffine, fixed whatever OpenCV is installed)."""
    s = out_size / max(float(size), 1e-6)
    tx = out_size / 2.0 - 0.5 - s * (center[0] - 0.5)
    ty = out_size / 2.0 - 0.5 - s * (center[1] - 0.5)
    if s < 0.5:  # shrinking by more than 2: box halvings first, which a bilinear warp lacks
        return _crop_resize(image, center, size, out_size, border)
    return warp_axis_aligned(image, (s, s), (tx, ty), (out_size, out_size), border)


def _crop_resize(image, center, size, out_size, border):
    """The downscaling path (out_size / size < 0.5): only the part inside the image is resized,
    halved by 2 x 2 box means while the remaining factor is below 1/2, then resized bilinearly,
    and framed by the border colour. Padding the full-resolution patch first (copyMakeBorder) and
    area-resizing it cost 1.3-3.6 ms per frame for near, large targets on this CPU."""
    h, w = image.shape[:2]
    x0 = int(round(center[0] - size / 2.0))
    y0 = int(round(center[1] - size / 2.0))
    n = max(int(round(size)), 1)
    ix0, iy0, ix1, iy1 = max(0, x0), max(0, y0), min(w, x0 + n), min(h, y0 + n)
    fill = tuple(float(round(c)) for c in border[:3])
    s = out_size / n
    ox0, oy0 = int(round((ix0 - x0) * s)), int(round((iy0 - y0) * s))
    ox1, oy1 = min(int(round((ix1 - x0) * s)), out_size), min(int(round((iy1 - y0) * s)), out_size)
    if ix1 <= ix0 or iy1 <= iy0 or ox1 <= ox0 or oy1 <= oy0:    # the crop lies outside the image
        return np.full((out_size, out_size, 3), fill, dtype=image.dtype)
    patch = image[iy0:iy1, ix0:ix1]
    k = 1.0
    while s * k < 0.5 and min(patch.shape[:2]) >= 4:
        # a 2 x 2 box mean (OpenCV's integer area fast path): 0.06 ms on a 640 x 480 frame where
        # the 5 x 5 Gaussian pyramid took 0.10; both remove what the bilinear step would alias
        ph, pw = patch.shape[0] // 2, patch.shape[1] // 2
        patch = cv2.resize(patch[:2 * ph, :2 * pw], (pw, ph), interpolation=cv2.INTER_AREA)
        k *= 2.0
    # the halvings left a factor in [0.5, 1): bilinear there (area at such non-integer factors
    # cost 0.31 ms of the 0.50 on a 640 x 480 patch, bilinear 0.04 ms, measured)
    inner = cv2.resize(patch, (ox1 - ox0, oy1 - oy0), interpolation=cv2.INTER_LINEAR)
    # framed by OpenCV in one call: numpy's broadcast fill of a (n, n, 3) canvas took 0.05 ms
    return cv2.copyMakeBorder(inner, oy0, out_size - oy1, ox0, out_size - ox1, cv2.BORDER_CONSTANT, value=fill)


def model_paths(variant: str = "edge") -> tuple[Path, Path]:
    """(exemplar, search) paths of a shipped variant."""
    if variant not in VARIANT_FILES:
        raise ValueError(f"unknown SiamFC variant {variant!r} (known: {', '.join(VARIANT_FILES)})")
    stem = VARIANT_FILES[variant]
    return shipped_model(f"{stem}_exemplar.onnx"), shipped_model(f"{stem}_search.onnx")


class SiamFCTracker:
    """SiamFC behind the Tracker2D seam: init(image, box), update(image) -> (ok, box), correct(box).

    Images are (H, W, 3) uint8 RGB; boxes [x, y, w, h] pixels. After update, `peak` holds the
    peak of the raw response of the chosen scale (a logit) and `score` the confidence in 0..1:
    peak / ref_peak clipped to [0, 1], ref_peak being the peak of the exemplar on its own init
    frame (one extra search-branch call in `init`): 1 = as good a match as the target on the
    frame it was taken from. The sigmoid of the logit saturates (measured: 12.5 on the target,
    9 on pure noise, both > 0.999), the ratio keeps them apart (~0.9 vs ~0.6). None before the
    first update; `timings_ms` holds the stage times.
    `get_state()` / `set_state(state)` save and restore everything the next update depends on
    (exemplar feature, centre, sizes, mean colour), so a restored tracker continues bit-identically.
    """

    def __init__(self, exemplar_model: str | Path, search_model: str | Path, threads: int = 1,
                 precision: str = "fp32", engine: str = "onnxruntime", **overrides):
        # precision / engine: "fp32" | "int8" | "bf16" | "auto", "onnxruntime" | "openvino" | "auto"
        # (track3d.onnxmodel); each graph makes its own choice (see .exemplar.choice / .search.choice)
        # each model a path or a model object (onnxmodel.load_model)
        self.exemplar = load_model(exemplar_model, threads, "siamfc-exemplar", precision=precision, engine=engine)
        self.search = load_model(search_model, threads, "siamfc-search", precision=precision, engine=engine)
        # an exemplar graph of another export makes features the search graph was not trained on
        check_pair(self.exemplar, self.search, "track3d-train siamfc export")
        meta = self.search.meta
        self.meta = meta
        unknown = set(overrides) - set(TUNABLE)
        if unknown:
            raise TypeError(f"unknown SiamFC options: {', '.join(sorted(unknown))} (tunable: {', '.join(TUNABLE)})")
        hp = dict(meta.get("tracking", {}))
        hp["instance_size"] = meta["instance_size"]
        hp.update({k: v for k, v in overrides.items() if v is not None})
        self.exemplar_size = int(meta["exemplar_size"])
        self.total_stride = int(meta["total_stride"])
        self.instance_size = int(hp["instance_size"])
        self.scale_num = int(hp["scale_num"])
        self.scale_step = float(hp["scale_step"])
        self.scale_penalty = float(hp["scale_penalty"])
        self.scale_lr = float(hp["scale_lr"])
        self.window_influence = float(hp["window_influence"])
        self.response_up = int(hp["response_up"])
        self.context_amount = float(hp["context_amount"])
        if self.instance_size < self.exemplar_size or (self.instance_size - self.exemplar_size) % self.total_stride:
            raise ValueError(f"instance_size {self.instance_size} must be exemplar_size {self.exemplar_size} "
                             f"+ a multiple of the stride {self.total_stride}")
        if self.scale_num < 1:
            raise ValueError("scale_num must be >= 1")
        self.response_size = (self.instance_size - self.exemplar_size) // self.total_stride + 1
        self.upscale_size = self.response_up * (self.response_size - 1) + 1
        hann = np.hanning(self.upscale_size)
        win = np.outer(hann, hann)
        self.window = (win / win.sum()).astype(np.float32)
        half = (self.scale_num - 1) / 2.0
        self.scale_factors = self.scale_step ** np.linspace(-half, half, self.scale_num)
        self.penalties = np.where(np.arange(self.scale_num) == self.scale_num // 2, 1.0, self.scale_penalty)
        if self.scale_num % 2 == 0:  # no exact centre scale: penalise none
            self.penalties[:] = 1.0
        self._kernel = None
        self.peak = float("nan")
        self.ref_peak = float("nan")
        self.score: float | None = None
        self._max_side = float("inf")
        self.timings_ms: dict[str, float] = {}

    # -- state -------------------------------------------------------------------------------
    def _set_box(self, box) -> None:
        b = np.asarray(box, dtype=np.float64).reshape(4)
        if not np.all(np.isfinite(b)) or b[2] <= 0 or b[3] <= 0:
            raise ValueError(f"box must be finite with positive size, got {b.tolist()}")
        # the centre held within MAX_BOX_SCALE x the image of it, as the size is: a corrected box
        # at y = 1e200 had made the next crop's map degenerate (a ValueError out of update)
        self.center = np.clip(b[:2] + b[2:] / 2.0, -self._max_side, self._max_side)
        # A (fused) state box larger than MAX_BOX_SCALE x the image is capped there: beyond,
        # the crops overflow and the tracker would follow nothing. Below MIN_BOX_SIDE the crop
        # size (a product of the sides) underflows to 0.
        self.target_sz = np.clip(b[2:], MIN_BOX_SIDE, self._max_side)
        ctx = self.context_amount * self.target_sz.sum()
        self.z_sz = math.sqrt(float(np.prod(self.target_sz + ctx)))
        self.x_sz = self.z_sz * self.instance_size / self.exemplar_size
        self._min_sz = max(2.0, 0.2 * float(self.target_sz.min()))

    def init(self, image: np.ndarray, box) -> None:
        """Start on `image` with the target in `box`; ValueError for a box that is not finite,
        not of positive size, does not overlap the image or is absurdly large (track3d.frames)."""
        image = check_image(image)
        b = check_init_box(box, (image.shape[1], image.shape[0]))
        self._image_hw = image.shape[:2]
        self._max_side = MAX_BOX_SCALE * max(image.shape[:2])
        self._set_box(b)
        self.avg_color = tuple(float(c) for c in cv2.mean(image)[:3])
        z = crop_square(image, self.center, self.z_sz, self.exemplar_size, self.avg_color)
        self._kernel = self.exemplar.run({"exemplar": z[None]})[0]
        self.base_target_sz = self.target_sz.copy()
        # The reference for `score`: the exemplar against its own frame (centre scale, all S crops
        # so that the search graph sees its usual batch).
        crops = np.stack([crop_square(image, self.center, self.x_sz * f, self.instance_size, self.avg_color)
                          for f in self.scale_factors])
        ref = self.search.run({"search": crops, "exemplar_feature": self._kernel})[0]
        self.ref_peak = float(np.max(ref[self.scale_num // 2])) if np.all(np.isfinite(ref)) else float("nan")
        self.peak, self.score = float("nan"), None

    def correct(self, box) -> None:
        """Adopt a new state box (e.g. the 2D-3D fused box): centre and size, same appearance."""
        if self._kernel is None:
            raise RuntimeError("correct() before init()")
        self._set_box(box)

    @property
    def box(self) -> np.ndarray:
        return np.concatenate([self.center - self.target_sz / 2.0, self.target_sz])

    def update(self, image: np.ndarray) -> tuple[bool, np.ndarray]:
        if self._kernel is None:
            raise RuntimeError("update() before init()")
        image = check_image(image)
        t0 = _now()
        self.center = np.clip(self.center, -self._max_side, self._max_side)   # a restored state too (_set_box)
        crops = np.empty((self.scale_num, self.instance_size, self.instance_size, 3), np.uint8)
        for i, f in enumerate(self.scale_factors):
            crops[i] = crop_square(image, self.center, self.x_sz * f, self.instance_size, self.avg_color)
        t1 = _now()
        responses = self.search.run({"search": crops, "exemplar_feature": self._kernel})[0]
        t2 = _now()
        if not np.all(np.isfinite(responses)):
            self.peak, self.score = float("nan"), 0.0
            return False, self.box
        n = self.upscale_size
        if self.scale_num == 1:
            best = 0
            resp = cv2.resize(responses[0], (n, n), interpolation=cv2.INTER_CUBIC)
        else:
            peaks = responses.reshape(self.scale_num, -1).max(axis=1) * self.penalties
            best = int(np.argmax(peaks))
            resp = cv2.resize(responses[best], (n, n), interpolation=cv2.INTER_CUBIC)
            resp *= self.penalties[best]
        self.peak = float(responses[best].max())
        self.score = self._confidence(self.peak)
        resp -= resp.min()
        resp /= resp.sum() + 1e-16
        resp = (1.0 - self.window_influence) * resp + self.window_influence * self.window
        loc = np.unravel_index(int(np.argmax(resp)), resp.shape)
        disp_resp = np.array([loc[1], loc[0]], dtype=np.float64) - (n - 1) / 2.0
        disp_inst = disp_resp * self.total_stride / self.response_up
        disp_img = disp_inst * self.x_sz * self.scale_factors[best] / self.instance_size
        self.center = self.center + disp_img
        scale = (1.0 - self.scale_lr) + self.scale_lr * self.scale_factors[best]
        if float(self.target_sz.max()) * scale > self._max_side:
            scale = 1.0  # never grow beyond the cap of _set_box
        self.target_sz = np.maximum(self.target_sz * scale, self._min_sz)
        self.z_sz *= scale
        self.x_sz *= scale
        h, w = image.shape[:2]
        self.center = np.clip(self.center, 0.0, [w, h])
        t3 = _now()
        self.timings_ms = {"crop": 1e3 * (t1 - t0), "net": 1e3 * (t2 - t1), "post": 1e3 * (t3 - t2)}
        return True, self.box


    def _confidence(self, peak: float) -> float:
        """peak / ref_peak in [0, 1]; the logit's sigmoid when the reference is not positive."""
        if math.isfinite(self.ref_peak) and self.ref_peak > 0:
            return float(min(max(peak / self.ref_peak, 0.0), 1.0))
        return _sigmoid(peak)

    # -- checkpoint ----------------------------------------------------------------------------
    _STATE_FIELDS = ("center", "target_sz", "z_sz", "x_sz", "_min_sz", "base_target_sz", "avg_color",
                     "_image_hw", "peak", "score", "ref_peak")

    def get_state(self) -> dict:
        """Everything the next update depends on, as numpy arrays and builtins (no ORT objects)."""
        if self._kernel is None:
            return {"initialised": False}
        st = {k: getattr(self, k) for k in self._STATE_FIELDS}
        st = {k: (v.copy() if isinstance(v, np.ndarray) else v) for k, v in st.items()}
        st.update(initialised=True, kernel=self._kernel.copy(), avg_color=list(self.avg_color),
                  _image_hw=list(self._image_hw))
        return st

    def set_state(self, state: dict) -> None:
        """Restore a `get_state()` of a tracker with the same models and hyper-parameters; a
        damaged one raises ValueError (one line) and leaves the tracker as it was."""
        with damaged("SiamFC"):
            if not read_flag(state.get("initialised"), "initialised"):
                self._kernel = None
                return
            shape = next(i.shape for i in self.search.session.get_inputs() if i.name == "exemplar_feature")
            kernel = read_kernel(state["kernel"], "exemplar feature", shape)
            center = read_array(state["center"], "center", (2,))
            sizes = {k: read_array(state[k], k, (2,), positive=True) for k in ("target_sz", "base_target_sz")}
            scalars = {k: read_float(state[k], k, lo=0.0) for k in ("z_sz", "x_sz", "_min_sz")}
            peaks = {k: read_float(state[k], k, nan_ok=True, inf_ok=True) for k in ("peak", "ref_peak")}
            score = None if state.get("score") is None else read_float(state["score"], "score", nan_ok=True)
            avg_color = tuple(read_array(state["avg_color"], "avg_color", (3,)).tolist())
            image_hw = tuple(read_int(v, "_image_hw", lo=1) for v in state["_image_hw"])
            if len(image_hw) != 2:
                raise ValueError(f"_image_hw must be two sizes, got {image_hw}")
        # assigned only once everything parsed: a damaged state leaves the tracker as it was
        self._kernel, self.center = kernel, center
        for k, v in {**sizes, **scalars, **peaks}.items():
            setattr(self, k, v)
        self.score, self.avg_color, self._image_hw = score, avg_color, image_hw


def _sigmoid(x: float) -> float:
    return float(1.0 / (1.0 + math.exp(-x))) if x > -700 else 0.0


def _now() -> float:
    import time
    return time.perf_counter()


def create(variant: str = "edge", threads: int = 1, exemplar_model: str | Path | None = None,
           search_model: str | Path | None = None, model: str | Path | None = None,
           **overrides) -> SiamFCTracker:
    """A SiamFC tracker. `variant` picks the shipped models ("edge", the default, or "faithful");
    `model` a prefix `<dir>/<name>` of a pair `<name>_exemplar.onnx` / `<name>_search.onnx`, or
    `exemplar_model` + `search_model` explicit paths (the fp32 files; their int8 twins are found
    beside them). precision / engine: see SiamFCTracker. Keyword overrides: see TUNABLE."""
    exemplar_model, search_model = model_pair(model, exemplar_model, search_model, ("exemplar", "search"),
                                              lambda: model_paths(variant))
    return SiamFCTracker(exemplar_model, search_model, threads=threads, **overrides)
