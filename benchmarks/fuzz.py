"""Seeded fuzz run of every public entry point; prints counts per outcome.

    python benchmarks/fuzz.py --cases 100000 --minutes 20 --out fuzz.json

Each case draws a random input (seeded: case i of target T always draws the same input) and is
classified as one of

- ``ok``: the call returned and its answer meets the contract below;
- ``clean_error``: a one-line error of the documented kind (ValueError, DatasetError, SimError;
  a CLI exiting 2 with one line on stderr);
- ``wrong``: the call returned an answer that breaks the contract (a silent wrong answer);
- ``crash``: another exception escaped, or the process died (a segfault);
- ``hang``: a case spent --timeout seconds of CPU (spinning) or ten times that of wall-clock
  time (blocked) without finishing; a worker starved by other jobs is not a hang.

Cases run in worker subprocesses (one at a time, niced): a crash or hang of third-party code
(OpenCV) kills only the worker, which is counted and restarted at the next case.

Contracts (the oracles, shared with tests/test_fuzz.py):

- frustum / sampling / crop: the C++ functions equal the numpy references bit for bit, or both
  raise ValueError; frustum points are finite, inside the depth crop, their bounds are their min / max;
- estimators: a finite (6,) box with sizes > 0; the baseline equals the points' min / max box;
  A3BoxNet's centre lies within 10 L of the points' enclosing box and its sizes are at most 10 L
  (L = the points' largest extent, at least 1 m);
- the loop (Track3D.update): never raises on sensor data; status in STATUSES; box2d finite;
  "tracking" implies a finite box3d of positive size and num_points >= min_points;
- the loop with the body's past views over a turning, moving ellipsoid (often cut by the image
  border, its returns sometimes damaged or replaced): as above every frame, and a tracker
  restored from a state taken mid-run gives the same results bit for bit;
- a checkpoint read back damaged: Track3D.set_state refuses it (ValueError, one line) and the
  tracker is as it was (its state the same), or restores it and the loop meets its contract above;
- 2D trackers: update returns (bool, finite (4,) float64 box when ok);
- result folders read back damaged: one-line ValueError / FileNotFoundError, or arrays of one
  length per frame and known status words;
- dataset reader: a dataset that reads has as many label rows as images, finite labels and 0/1
  flags for every frame;
- CLIs: exit 0, or exit 2 with one error line on stderr (argparse prints its usage above it);
  never a traceback;
- the simulator's mesh loader: a Shape with finite vertices, or SimError;
- stereo clouds: a pair that is not uint8 RGB / grey of the camera's size is a ValueError, else
  an (N, 3) float32 cloud, finite, z > 0, for any box; the loop on them as above.
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import os
import select
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from track3d.argparsing import ArgumentParser, run_main

OUTCOMES = ("ok", "clean_error", "wrong", "crash", "hang")
ORACLE_K = 10.0  # A3BoxNet: centre offset and size at most 10 L (measured worst 5.2 L, see docs)


# --- oracles ------------------------------------------------------------------------------------

class Wrong(AssertionError):
    """A returned answer that breaks the contract."""


def expect(cond, what: str) -> None:
    if not cond:
        raise Wrong(what)


def check_box3d(box, points=None, exact=False, k: float = ORACLE_K) -> None:
    """A finite (6,) float64 box; with points: exact=True, their min / max box (the baseline, sizes
    may be 0 for one point), else sizes > 0 and centre / sizes within k L of their enclosing box."""
    b = np.asarray(box)
    expect(b.shape == (6,) and b.dtype == np.float64, f"box3d shape/dtype {b.shape} {b.dtype}")
    expect(np.all(np.isfinite(b)), f"box3d not finite: {b}")
    if points is None or not exact:
        expect(np.all(b[3:] > 0), f"box3d size not positive: {b}")
    if points is None:
        return
    p = np.asarray(points, dtype=np.float64)
    lo, hi = p.min(axis=0), p.max(axis=0)
    if exact:
        expect(np.array_equal(b, np.concatenate([(lo + hi) / 2.0, hi - lo])),
               f"baseline box {b} is not the enclosing box of its points")
        return
    L = max(float((hi - lo).max()), 1.0)
    off = float(np.max(np.maximum(lo - b[:3], b[:3] - hi)))
    expect(off <= k * L and float(b[3:].max()) <= k * L, f"box {b} far from points spanning {L:.3g} m")


def check_track_result(res, statuses, min_points: int) -> None:
    expect(res.status in statuses, f"status {res.status!r}")
    expect(res.box2d.shape == (4,) and np.all(np.isfinite(res.box2d)), f"box2d {res.box2d}")
    expect(res.box3d.shape == (6,), "box3d shape")
    if res.status == "tracking":
        check_box3d(res.box3d)
        expect(res.num_points >= min_points, f"tracking on {res.num_points} points")


def check_tracker_output(out) -> None:
    expect(isinstance(out, tuple) and len(out) == 2, "update must return (ok, box)")
    ok, box = out
    expect(isinstance(ok, bool), f"ok is {type(ok).__name__}")
    b = np.asarray(box)
    expect(b.shape == (4,) and b.dtype == np.float64, f"box {b.shape} {b.dtype}")
    if ok:
        expect(np.all(np.isfinite(b)) and b[2] > 0 and b[3] > 0, f"ok with box {b}")


# --- random inputs ------------------------------------------------------------------------------

SPECIALS = np.array([np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-30, 1e30, -1e30, 3.4e38, -3.4e38, 1e5, -1e5,
                     1.0, 45.0, 45.000004, 0.99999994])


def rand_cloud(rng, max_n=2000, near=True) -> np.ndarray:
    n = int(rng.choice([0, 1, 2, 15, 16, 17, int(rng.integers(0, max_n))]))
    kind = int(rng.integers(0, 5))
    if kind == 0:   # a body in front of the camera
        p = rng.normal([0, 0, rng.uniform(2, 40)], rng.uniform(0.001, 5), (n, 3))
    elif kind == 1:  # anywhere
        p = rng.uniform(-100, 100, (n, 3))
    elif kind == 2:  # huge / tiny scales
        p = rng.normal(0, 10.0 ** rng.uniform(-6, 38), (n, 3))
    elif kind == 3:  # quantised / stuck
        p = np.repeat(rng.normal([0, 0, 10], 1, (1, 3)), n, axis=0)
    else:
        p = rng.normal([0, 0, 10], 2, (n, 3))
    if n and rng.random() < 0.5:
        m = rng.random((n, 3)) < rng.uniform(0, 0.3)
        p[m] = rng.choice(SPECIALS, int(m.sum()))
    with np.errstate(over="ignore", invalid="ignore"):
        return p.astype(rng.choice([np.float32, np.float32, np.float64]))


def rand_box(rng, w=160, h=120) -> list:
    kind = int(rng.integers(0, 7))
    if kind == 6:  # vanishing: positive sides whose product underflows
        return [float(rng.uniform(-2, w)), float(rng.uniform(-2, h)), float(10 ** -rng.uniform(3, 300)),
                float(10 ** -rng.uniform(3, 300))]
    if kind == 0:
        return [float(v) for v in rng.uniform([-20, -20, 0.5, 0.5], [w + 20, h + 20, w, h])]
    if kind == 1:  # tiny
        return [float(rng.uniform(-2, w)), float(rng.uniform(-2, h)), float(rng.choice([0.5, 1, 2, 3, 4, 5])),
                float(rng.choice([1, 2, 3, 40]))]
    if kind == 2:  # touching a border, fractional
        return [w - rng.uniform(0.5, 30), -rng.uniform(0, 30), rng.uniform(1, 80), rng.uniform(1, 80)]
    if kind == 3:  # specials
        return [float(v) for v in rng.choice(SPECIALS, 4)]
    if kind == 4:  # huge
        return [0.0, 0.0, float(10 ** rng.uniform(2, 200)), float(10 ** rng.uniform(2, 200))]
    return [float(rng.integers(0, w)), float(rng.integers(0, h)), float(rng.integers(1, w)), float(rng.integers(1, h))]


def rand_box3d(rng):
    """None, or a first 3D box for Track3D.init: plausible, tiny, huge, special values, wrong length."""
    if rng.random() < 0.6:   # mostly none: the update path keeps its share of the cases
        return None
    kind = int(rng.integers(1, 6))
    if kind == 1:
        return [float(v) for v in rng.uniform([-5, -5, 2, 0.2, 0.2, 0.2], [5, 5, 40, 12, 12, 12])]
    if kind == 2:  # tiny or huge sizes, near or far
        return [0.0, 0.0, float(10 ** rng.uniform(-3, 6)), *[float(10 ** rng.uniform(-300, 6)) for _ in range(3)]]
    if kind == 3:  # specials
        return [float(v) for v in rng.choice(SPECIALS, 6)]
    if kind == 4:  # wrong length
        return [1.0] * int(rng.choice([0, 3, 5, 7]))
    return [float(v) for v in rng.normal(0, 10, 6)]


def rand_category(rng):
    return rng.choice(np.array([-1, 0, 1, 2, 5, 13, -2, 14, 10 ** 20, 1.5, 2.0, True, "1", None, np.nan,
                                np.int64(3)], dtype=object))


def rand_image(rng, w=160, h=120) -> np.ndarray:
    img = np.zeros((h, w, 3), np.uint8)
    x, y = int(rng.integers(0, w - 10)), int(rng.integers(0, h - 10))
    img[y:y + int(rng.integers(5, 60)), x:x + int(rng.integers(5, 60))] = rng.integers(0, 255, 3, dtype=np.uint8)
    return img + rng.integers(0, 20, img.shape, dtype=np.uint8)


# --- targets: each draws one case and runs it; returns "ok" or raises --------------------------

class Env:
    """Objects built once per worker (models load once)."""

    def __init__(self, tmp: Path):
        from track3d.synthetic import CAM

        self.tmp = tmp
        self.cam = CAM
        self._est = {}
        self._data = None

    def estimator(self, name):
        from track3d.estimators import create_estimator

        if name not in self._est:
            # stereo's A3BoxNet carries the back-lit model and its gate (estimate(..., phase_deg=))
            self._est[name] = create_estimator(name, depth_sensor="stereo") if name == "a3boxnet" else \
                create_estimator(name)
        return self._est[name]

    def checkpoint(self, tracker: str, sensor, views: bool):
        """(a builder of the loop, its state after five frames of a turning ellipsoid as JSON would
        give it back, the next three frames (image, returns)), made once per configuration."""
        key = ("checkpoint", tracker, sensor, views)
        if key not in self._est:
            from track3d.synthetic import ellipsoid_returns
            from track3d.tracker import Track3D
            from track3d.sensor_options import sensor_options

            frames = []
            for k in range(8):
                a = 0.06 * k
                R = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
                frames.append(ellipsoid_returns(self.cam, R, np.array([0.2 + 0.02 * k, 0.1, 12.0 - 0.1 * k]),
                                                np.array([1.5, 1.0, 0.8])))
            gt = np.array([b for _, b in frames])
            images = []
            for _, b in frames:   # a grey body on black where its box is: something to follow
                im = np.zeros((self.cam.height, self.cam.width, 3), np.uint8)
                x, y, w, h = (int(round(v)) for v in b)
                im[max(y, 0):y + h, max(x, 0):x + w] = 140
                images.append(im)
            opts = {"tracker_options": {"gt": gt}} if tracker == "oracle" else {}

            def build():
                return Track3D.create(self.cam, tracker=tracker, estimator="a3boxnet",
                                      **opts, **{**sensor_options(sensor), "body_views": views})

            t = build()
            t.init(images[0], gt[0], points=frames[0][0])
            for k in range(1, 5):
                t.update(images[k], frames[k][0])
            state = json.loads(json.dumps(t.get_state()))
            self._est[key] = (build, state, [(images[k], frames[k][0]) for k in range(5, 8)])
        return self._est[key]

    def results(self) -> Path:
        """One sequence's result folder of the oracle + baseline loop on the synthetic dataset."""
        key = ("results",)
        if key not in self._est:
            from track3d.evaluation import Experiment, TrackerSpec

            exp = Experiment(self.dataset(), "test", self.tmp / "results", self.tmp / "reports")
            self._est[key] = exp.run(TrackerSpec("oracle", "baseline"), quiet=True)[0]
        return self._est[key]

    def dataset(self) -> Path:
        if self._data is None:
            from track3d.synthetic import make_synthetic_dataset

            self._data = make_synthetic_dataset(self.tmp / "good", {"a": 4, "b": 3})
        return self._data


def t_frustum(rng, env):
    from track3d.frustum import extract_frustum_bounds, extract_frustum_bounds_numpy

    pts, box = rand_cloud(rng), rand_box(rng)
    z0, z1 = sorted(rng.choice([0.0, 1.0, 1.0, 45.0, 45.0, 100.0, 1e30], 2))
    try:
        a, ab = extract_frustum_bounds(pts, box, env.cam.M, z0, z1)
    except ValueError as e:
        with contextlib.suppress(ValueError):
            extract_frustum_bounds_numpy(pts, box, env.cam.M, z0, z1)
            raise Wrong(f"C++ raised {e}, numpy did not")
        return "clean_error"
    b, bb = extract_frustum_bounds_numpy(pts, box, env.cam.M, z0, z1)
    expect(np.array_equal(a, b) and np.array_equal(ab, bb), "C++ and numpy frustums differ")
    expect(np.all(np.isfinite(a)) and (len(a) == 0 or (a[:, 2].min() >= z0 and a[:, 2].max() <= z1)),
           "frustum points not finite / outside the crop")
    if len(a):
        expect(np.array_equal(ab, np.stack([a.min(0), a.max(0)]).astype(np.float64)), "bounds wrong")
    return "ok"


def t_sampling(rng, env):
    from track3d.frustum import sample_points, sample_points_numpy

    n = int(rng.choice([0, 1, 2, 5, int(rng.integers(0, 600))]))
    pts = rng.normal(0, 1, (n, 3)).astype(np.float32)
    num = rng.choice(np.array([0, 1, 2, 7, 512, int(rng.integers(-3, 700)), 2.5, 2.0, True, "3", None, 10 ** 20],
                              dtype=object))
    seed = rng.choice(np.array([0, 1, -1, 2 ** 64 - 1, int(rng.integers(0, 2 ** 62)), 0.5, None], dtype=object))
    outs = []
    for f in (sample_points, sample_points_numpy):
        try:
            outs.append(f(pts, num, seed))
        except ValueError:
            outs.append(None)
    if outs[0] is None or outs[1] is None:
        expect(outs[0] is None and outs[1] is None, f"only one implementation raised (num={num!r}, seed={seed!r})")
        return "clean_error"
    expect(np.array_equal(outs[0], outs[1]) and outs[0].shape == (int(num), 3), "C++ and numpy samples differ")
    return "ok"


def t_crop(rng, env):
    from track3d.resample import warp_axis_aligned, warp_axis_aligned_numpy

    h, w = (int(v) for v in rng.choice([1, 2, 7, int(rng.integers(1, 80))], 2))
    img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    if rng.random() < 0.1:
        bad = [img[..., 0], img.astype(np.float32), img[..., :2], np.zeros((0, 4, 3), np.uint8)]
        img = bad[int(rng.integers(len(bad)))]
    odd = [0.0, -1.0, np.nan, np.inf, 1e-30, 1e-45, 1e30, 1e300]
    scale = [float(rng.choice(odd)) if rng.random() < 0.1 else float(np.exp(rng.uniform(-3, 3))) for _ in range(2)]
    offset = [float(rng.choice([np.nan, -np.inf, 1e30, 1e9])) if rng.random() < 0.1 else float(rng.uniform(-300, 300))
              for _ in range(2)]
    size = [int(rng.choice([0, -1, 1, 16, 17, int(rng.integers(1, 90))])) for _ in range(2)]
    border_value = [float(rng.choice([np.nan, -5.0, 300.0, 127.5])) if rng.random() < 0.1 else float(rng.uniform(0, 255))
                    for _ in range(3)]
    border = str(rng.choice(["constant", "replicate", "reflect"], p=[0.6, 0.35, 0.05]))
    outs = []
    for f in (warp_axis_aligned, warp_axis_aligned_numpy):
        try:
            outs.append(f(img, scale, offset, size, border_value, border))
        except ValueError:
            outs.append(None)
    if outs[0] is None or outs[1] is None:
        expect(outs[0] is None and outs[1] is None, f"only one implementation raised (scale {scale}, offset {offset})")
        return "clean_error"
    expect(np.array_equal(outs[0], outs[1]), f"C++ and numpy crops differ (scale {scale}, offset {offset}, {border})")
    expect(outs[0].dtype == np.uint8 and outs[0].shape == (size[1], size[0], 3), "crop of the wrong shape or dtype")
    return "ok"


def _t_estimator(name):
    def run(rng, env):
        est = env.estimator(name)
        pts = rand_cloud(rng, 1500)
        if rng.random() < 0.05:
            odd = [np.zeros((5, 4)), np.zeros(9), [[1, 2, 3]] * 20, "points", np.zeros((3, 3), bool), [[1, 2], [3]]]
            pts = odd[int(rng.integers(0, len(odd)))]
        cat = rand_category(rng)
        extra = {}
        if getattr(est, "takes_phase", False) and rng.random() < 0.5:
            odd = [float("nan"), -1.0, 181.0, "x", [120.0], True]
            extra["phase_deg"] = (float(rng.uniform(0.0, 180.0)) if rng.random() < 0.9
                                  else odd[int(rng.integers(0, len(odd)))])
        try:
            box = est.estimate(pts, cat, **extra)
        except ValueError:
            return "clean_error"
        p = np.asarray(pts, dtype=np.float64)
        check_box3d(box, p, exact=(name == "baseline"))
        return "ok"
    return run


class _Scripted:
    def __init__(self, rng):
        self.rng = rng

    def init(self, image, box):
        pass

    def update(self, image):
        r = self.rng.random()
        return (bool(r > 0.1), np.asarray(rand_box(self.rng), dtype=np.float64) if r > 0.05 else np.zeros(3))


def _rand_sun(rng):
    """A sun direction a user may set: none, any direction, or straight along the line of sight."""
    r = rng.random()
    if r < 0.2:
        return None
    if r < 0.3:
        return [0.0, 0.0, float(rng.choice([-1.0, 1.0]))]
    return rng.normal(size=3) * float(rng.choice([1e-6, 1.0, 1e6]))


def _t_loop(name):
    def run(rng, env):
        from track3d.tracker import STATUSES, Track3D
        from track3d.sensor_options import DEPTH_SENSORS, sensor_options

        # every sensor's loop options (stereo: the outline off, its share and containment on)
        sensor = [None, *DEPTH_SENSORS][int(rng.integers(0, len(DEPTH_SENSORS) + 1))]
        t = Track3D(env.cam, _Scripted(rng), env.estimator(name), z_range=(1.0, float(rng.choice([45.0, 1e6]))),
                    **sensor_options(sensor))
        t.set_sun(_rand_sun(rng))
        img = rand_image(rng)
        try:
            t.init(img, rand_box(rng), rand_category(rng), points=rand_cloud(rng) if rng.random() < 0.5 else None,
                   box3d=rand_box3d(rng))
        except ValueError:
            return "clean_error"
        for _ in range(3):
            check_track_result(t.update(img, rand_cloud(rng)), STATUSES, t.min_points)
        return "ok"
    return run


def _damaged(rng, pts: np.ndarray) -> np.ndarray:
    """A body's returns as a sensor may send them: mostly as they are, sometimes empty, with
    non-finite or huge rows, collapsed to one point, noisy, cut short, any random cloud, or not
    at all (None: the depth did not arrive)."""
    r = rng.random()
    if r < 0.02:
        return None
    if r < 0.05:
        return np.zeros((0, 3), np.float32)
    if r < 0.10 and len(pts):
        p = pts.copy()
        p[rng.integers(0, len(p), max(1, len(p) // 10))] = rng.choice(SPECIALS)
        return p
    if r < 0.13 and len(pts):
        return np.repeat(pts[:1], len(pts), axis=0)
    if r < 0.16:
        return (pts + rng.normal(0, 2, pts.shape)).astype(np.float32)
    if r < 0.18:
        return pts[: int(rng.integers(0, 20))]
    if r < 0.21:
        return rand_cloud(rng)
    return pts


def t_loop_views(rng, env):
    """The loop with the body's past views (registration, carving, a cut body's extent) over a
    turning, moving ellipsoid, oracle 2D boxes; a state taken mid-run continues bit-identically."""
    from track3d.body_views import BodyViewsParams
    from track3d.synthetic import ellipsoid_returns
    from track3d.trackers2d import create_tracker
    from track3d.tracker import STATUSES, Track3D
    from track3d.sensor_options import DEPTH_SENSORS, sensor_options

    n = int(rng.integers(8, 60))
    axes = rng.uniform(0.2, 4.0, 3)
    z0 = float(rng.uniform(3.0, 60.0))
    c0 = np.array([rng.uniform(-0.4, 0.4) * z0, rng.uniform(-0.3, 0.3) * z0, z0])
    vel = rng.normal(0.0, 0.3, 3)
    axis = rng.normal(size=3)
    axis /= max(float(np.linalg.norm(axis)), 1e-9)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    rate = np.radians(rng.uniform(0.0, 30.0))

    def attitude(k):   # Rodrigues' rotation by rate * k about axis
        a = rate * k
        return np.eye(3) + np.sin(a) * K + (1.0 - np.cos(a)) * K @ K

    frames = [ellipsoid_returns(env.cam, attitude(k), c0 + vel * k, axes) for k in range(n)]
    gt = np.array([b for _, b in frames])
    absent = (gt[:, 2] <= 0) | (rng.random(n) < 0.03)
    gt[gt[:, 2] <= 0] = [10.0, 10.0, 5.0, 5.0]
    if rng.random() < 0.3:
        gt[:, :2] += rng.normal(0.0, 4.0, (n, 2))
    sensor = [None, *DEPTH_SENSORS][int(rng.integers(0, len(DEPTH_SENSORS) + 1))]
    params = BodyViewsParams(every=int(rng.integers(1, 4)), carve_views=int(rng.integers(0, 13)),
                             carve_angle_deg=float(rng.uniform(0.0, 30.0)), cut_extent=int(rng.integers(0, 4)))

    def build():
        return Track3D(env.cam, create_tracker("oracle", gt=gt, absent=absent), env.estimator("a3boxnet"),
                       **{**sensor_options(sensor), "body_views": params},
                       depth_range_m=30.0 if sensor == "tof" else None)

    t = build()
    image = np.zeros((env.cam.height, env.cam.width, 3), np.uint8)
    try:
        t.init(image, gt[0], points=frames[0][0])
    except ValueError:
        return "clean_error"
    at = int(rng.integers(1, n))
    state, inputs, outs = None, [], []
    for k in range(1, n):
        if k == at:
            state = t.get_state()
        pts = _damaged(rng, frames[k][0])
        res = t.update(image, pts)
        check_track_result(res, STATUSES, t.min_points)
        if state is not None:
            inputs.append(pts)
            outs.append(res)
    t2 = build()
    t2.set_state(state)
    for pts, a in zip(inputs, outs):
        b = t2.update(image, pts)
        expect(a.status == b.status and np.array_equal(a.box2d, b.box2d, equal_nan=True)
               and np.array_equal(a.box3d, b.box3d, equal_nan=True),
               f"restored state diverged: {a.status} {a.box3d} vs {b.status} {b.box3d}")
    return "ok"


SPECIAL_LEAVES = (float("nan"), float("inf"), -float("inf"), 1e300, -1e300, 0.0, -1.0, 1e-300, 2 ** 63, -(2 ** 31),
                  7, None, True, "x", [], {}, [1.0, 2.0], {"__ndarray__": "AAAA", "dtype": "<f8", "shape": [3]})


def damage_plain(rng, x):
    """One damage to plain data (a checkpoint as JSON would hold it): a key or an item dropped or
    doubled, a value replaced (a special number, another type, a broken array record), a string
    (base64, a dtype) with a character changed or cut short, a number scaled."""
    if isinstance(x, dict) and x and rng.random() < 0.75:
        x = dict(x)
        k = list(x)[int(rng.integers(0, len(x)))]
        r = rng.random()
        if r < 0.15:
            del x[k]
        else:
            x[k] = damage_plain(rng, x[k]) if r < 0.6 else _damaged_leaf(rng, x[k])
        return x
    if isinstance(x, list) and x and rng.random() < 0.75:
        x = list(x)
        i = int(rng.integers(0, len(x)))
        r = rng.random()
        if r < 0.2:
            del x[i]
        elif r < 0.3:
            x.append(x[i])
        else:
            x[i] = damage_plain(rng, x[i]) if r < 0.7 else _damaged_leaf(rng, x[i])
        return x
    return _damaged_leaf(rng, x)


def _damaged_leaf(rng, old):
    r = rng.random()
    if isinstance(old, str) and old and r < 0.5:
        s = list(old)
        s[int(rng.integers(0, len(s)))] = chr(int(rng.integers(33, 127)))
        return "".join(s[: int(rng.integers(0, len(s) + 1))] if rng.random() < 0.3 else s)
    if isinstance(old, (int, float)) and not isinstance(old, bool) and r < 0.6:
        return float(old) * float(rng.choice([-1.0, 0.5, 2.0, 1e6])) if rng.random() < 0.3 else \
            SPECIAL_LEAVES[int(rng.integers(0, 11))]
    return SPECIAL_LEAVES[int(rng.integers(0, len(SPECIAL_LEAVES)))]


def t_state(rng, env):
    """A checkpoint read back damaged (`damage_plain`, one to three times): Track3D.set_state
    refuses it with one line and leaves the tracker as it was, or restores it and the loop then
    meets its contract."""
    from track3d.tracker import STATUSES
    from track3d.sensor_options import DEPTH_SENSORS

    tracker = ("oracle", "edgetrack", "kcf")[int(rng.integers(0, 3))]
    sensor = [None, *DEPTH_SENSORS][int(rng.integers(0, len(DEPTH_SENSORS) + 1))]
    views = bool(rng.random() < 0.5)
    build, state, frames = env.checkpoint(tracker, sensor, views)
    t = build()
    t.set_state(state)
    before = json.dumps(t.get_state(), sort_keys=True)
    bad = state
    for _ in range(int(rng.integers(1, 4))):
        bad = damage_plain(rng, bad)
    try:
        t.set_state(bad)
    except ValueError as e:
        expect("\n" not in str(e) and str(e), f"a refused state's error is not one line: {str(e)[:200]!r}")
        expect(json.dumps(t.get_state(), sort_keys=True) == before, f"a refused state changed the tracker: {e}")
        return "clean_error"
    for image, pts in frames:
        check_track_result(t.update(image, pts), STATUSES, t.min_points)
    return "ok"


def _t_tracker(name):
    def run(rng, env):
        from track3d.trackers2d import create_tracker

        tr = create_tracker(name) if rng.random() < 0.7 else create_tracker(name, correct="reinit")
        img = rand_image(rng)
        try:
            tr.init(img, rand_box(rng))
        except ValueError:
            return "clean_error"
        for _ in range(2):
            check_tracker_output(tr.update(rand_image(rng)))
            if hasattr(tr, "correct") and rng.random() < 0.5:
                try:
                    tr.correct(rand_box(rng))
                except ValueError:
                    pass
        return "ok"
    return run


def _t_track3d(tracker: str):
    """The loop with a learned 2D tracker (their crops see any box and image the caller sends)."""
    def run(rng, env):
        from track3d.tracker import STATUSES, Track3D

        if tracker not in env._est:
            env._est[tracker] = Track3D.create(env.cam, tracker=tracker, estimator="baseline")
        t = env._est[tracker]
        img = rand_image(rng)
        try:
            t.init(img, rand_box(rng), rand_category(rng))
        except ValueError:
            return "clean_error"
        for _ in range(2):
            res = t.update(rand_image(rng), rand_cloud(rng))
            check_track_result(res, STATUSES, t.min_points)
            expect(np.all(res.box2d_raw[2:] <= 10 * 160 + 1e-6), f"{tracker} box {res.box2d_raw} beyond 10x the image")
        return "ok"
    return run


def rand_pair(rng, w=160, h=120):
    """A stereo pair: mostly uint8 RGB or grey with the right image a shifted left one, sometimes
    of another dtype, channel count or size."""
    left = rand_image(rng, w, h)
    right = np.roll(left, -int(rng.integers(0, 30)), axis=1) if rng.random() < 0.7 else rand_image(rng, w, h)
    kind = int(rng.integers(0, 10))
    if kind == 0:
        return left[..., 0], right[..., 0]
    if kind == 1:
        dt = rng.choice([np.float32, np.float64, np.int64, np.uint16, np.bool_])
        return left.astype(dt) * (1.7 if dt in (np.float32, np.float64) else 1), right.astype(dt)
    if kind == 2:
        return left[:, : int(rng.integers(0, w))], right
    if kind == 3:
        return np.dstack([left, left[..., :1]]), np.dstack([right, right[..., :1]])
    return left, right


def t_stereo(rng, env):
    """Stereo clouds (track3d.stereo) of any pair and box, alone and as the loop's points."""
    from track3d.stereo import StereoCloud
    from track3d.tracker import STATUSES, Track3D
    from track3d.sensor_options import sensor_options

    params = {"edge_erode_px": int(rng.integers(0, 3)), "block_size": int(rng.choice([1, 3, 5, 7])),
              "z_min_m": float(rng.choice([0.3, 1.5, 20.0])), "follow_depth": float(rng.choice([0.0, 1.0, 1.5, 4.0])),
              "max_match_px": int(rng.choice([0, 1, 64, 16384])),
              "max_match_cost": int(rng.choice([0, 1, 100000, 12000000]))}
    left, right = rand_pair(rng)
    try:
        cloud = StereoCloud(env.cam, **params)
        points = cloud.bind(left, right)
    except ValueError:
        return "clean_error"
    for a in (left, right):
        expect(a.dtype == np.uint8 and a.shape[:2] == (env.cam.height, env.cam.width)
               and (a.ndim == 2 or a.shape[2:] == (3,)), f"a stereo image {a.shape} {a.dtype} was taken")
    box = rand_box(rng)
    for b in (box, rand_box(rng) if rng.random() < 0.5 else box):   # a second window follows the first's depth
        p = points(b)
        expect(isinstance(p, np.ndarray) and p.dtype == np.float32 and p.ndim == 2 and p.shape[1] == 3,
               f"stereo cloud {type(p).__name__} {getattr(p, 'shape', None)} {getattr(p, 'dtype', None)}")
        expect(bool(np.all(np.isfinite(p))) and bool(np.all(p[:, 2] > 0)), "stereo cloud not finite or z <= 0")
        expect(not cloud.last_dropped or len(p) == 0, "a dropped update returned a cloud")
        # the cap is the update's budget whenever the dearest first match fits it in the coarsest bands
        cap, win = params["max_match_cost"], cloud.matcher.window(b)
        expect(cap == 0 or win is None or cloud.matcher.binned_cost(win, None, 8) > cap or cloud.last_cost <= cap,
               f"an update matched {cloud.last_cost} past its budget {cap}")
    # the default loop, or stereo's options (the outline read from the callable's cloud)
    t = Track3D(env.cam, _Scripted(rng), env.estimator("baseline"),
                **(sensor_options("stereo") if rng.random() < 0.5 else {}))
    t.set_sun(_rand_sun(rng))
    try:
        t.init(rand_image(rng), box, 0, points=points)
    except ValueError:
        return "clean_error"
    check_track_result(t.update(rand_image(rng), points), STATUSES, t.min_points)
    return "ok"


def t_results(rng, env):
    """A result folder of `track3d track` damaged (a file dropped, cut short, its bytes flipped, a
    line replaced or doubled): read_result gives one-line ValueError / FileNotFoundError, or
    arrays of one length per frame with known status words."""
    from track3d.evaluation.results import STATUS_WORDS, read_result

    src = env.results()
    folder = env.tmp / "damaged-results" / src.name
    shutil.rmtree(folder.parent, ignore_errors=True)
    shutil.copytree(src, folder)
    files = sorted(p for p in folder.iterdir() if p.suffix == ".txt")
    for _ in range(int(rng.integers(1, 4))):
        f = files[int(rng.integers(0, len(files)))]
        if not f.exists():
            continue
        data, kind = f.read_bytes(), int(rng.integers(0, 5))
        if kind == 0:
            f.unlink()
        elif kind == 1:
            f.write_bytes(data[:int(rng.integers(0, max(len(data), 1)))])
        elif kind == 2 and data:
            b = bytearray(data)
            for i in rng.integers(0, len(b), int(rng.integers(1, 4))):
                b[i] = int(rng.integers(0, 256))
            f.write_bytes(bytes(b))
        elif kind == 3:
            lines = data.decode(errors="replace").splitlines()
            i = int(rng.integers(0, max(len(lines), 1)))
            lines[i:i + 1] = [str(rng.choice(["nan,nan,nan,nan", "1,2", "", "lozt", "tracking lost", "1e400,1,1,1",
                                              "-5,-5,-5,-5,-5,-5", "1,2,3,4,5,6,7,8", "INIT"]))]
            f.write_text("\n".join(lines) + "\n")
        else:
            lines = data.splitlines()
            f.write_bytes(b"\n".join(lines + lines[:int(rng.integers(1, 4))]) + b"\n")
    try:
        r = read_result(folder)
    except (ValueError, FileNotFoundError) as e:
        expect("\n" not in str(e), f"a multi-line error: {str(e)[:200]!r}")
        return "clean_error"
    n = len(r.status)
    expect(r.box2d.shape == (n, 4) and r.box2d_raw.shape == (n, 4) and r.box3d.shape == (n, 6)
           and r.seconds.shape == (n,) and r.e2e_seconds.shape == (n,) and r.stage_ms.shape[0] == n,
           "result arrays of other lengths or widths read")
    expect(set(r.status) <= set(STATUS_WORDS), f"unknown status words read: {set(r.status) - set(STATUS_WORDS)}")
    return "ok"


DATA_FILES = ("dataset.json", "test/a/groundtruth_2d.txt", "test/a/groundtruth_3d.txt", "test/a/absence.label",
              "test/a/cut_by_image.label", "test/a/meta.json", "test/a/left/000002.png", "test/a/depth/000001.png",
              "test/b/groundtruth_2d.txt")


def t_dataset(rng, env):
    from track3d.dataset import Dataset, DatasetError

    root = env.tmp / "damaged"
    shutil.rmtree(root, ignore_errors=True)
    shutil.copytree(env.dataset(), root)
    for _ in range(int(rng.integers(1, 3))):
        f = root / DATA_FILES[int(rng.integers(0, len(DATA_FILES)))]
        kind = int(rng.integers(0, 5))
        if not f.exists():
            continue
        data = f.read_bytes()
        if kind == 0:
            f.unlink()
        elif kind == 1:
            f.write_bytes(data[:int(rng.integers(0, max(len(data), 1)))])
        elif kind == 2:
            f.write_bytes(rng.integers(0, 256, int(rng.integers(0, 200)), dtype=np.uint8).tobytes())
        elif kind == 3 and f.suffix in (".txt", ".label"):
            lines = data.decode(errors="replace").splitlines()
            i = int(rng.integers(0, max(len(lines), 1)))
            lines[i:i + 1] = [rng.choice(["nan,nan,nan,nan", "1,2", "", "inf,0,0,1,1,1", "2", "-1", "0,0,0,0,0,0,0"])]
            f.write_text("\n".join(lines) + "\n")
        elif kind == 4 and f.suffix == ".json":
            f.write_text(rng.choice(["[]", "{}", '{"format": "track3d-dataset", "version": 1}', '"x"', "1",
                                     '{"format": "track3d-dataset", "version": 1, "camera": {}, "splits": {}}']))
    try:
        ds = Dataset(root)
        seqs = [s for split in ds.splits for s in ds.sequences(split)]
        for s in seqs:
            n = len(s)
            images = len(list((s.path / "left").glob("*.png")))
            expect(n == images, f"{s.name}: {n} labels for {images} images")
            expect(np.all(np.isfinite(s.gt2d)) and np.all(np.isfinite(s.gt3d)), "non-finite labels read")
            expect(len(s.absent) == n and len(s.cut) == n, "flags of another length")
            if n:
                s.frame(0)
    except DatasetError:
        return "clean_error"
    return "ok"


def _cli_ok(rc, err: str) -> str:
    if rc == 0:
        return "ok"
    expect(rc == 2, f"exit code {rc}")
    # one error line (argparse prints its usage above it)
    lines = err.strip().splitlines()
    expect("Traceback" not in err and lines and "error" in lines[-1], f"not a one-line error: {err[-300:]}")
    return "clean_error"


def t_cli(rng, env):
    from track3d.cli import main

    data = env.dataset()
    afile = env.tmp / "afile"
    afile.write_text("x")
    pool = [["--tracker", str(rng.choice(["oracle", "kcf", "mosse", "nope", "siamfc-edge"]))],
            ["--estimator", str(rng.choice(["baseline", "nope"]))],
            ["--frames", str(rng.choice(["1", "2", "0", "-5", "x", "99999"]))],
            ["--tracker-option", str(rng.choice(["foo=1", "correct=reinit", "oops", "correct=maybe"]))],
            ["--estimator-option", str(rng.choice(["foo=1", "threads=1", "threads=0"]))],
            ["--results", str(rng.choice([str(afile), str(env.tmp / "res")]))],
            ["--split", str(rng.choice(["test", "train", ""]))], ["--sequence", str(rng.choice(["a", "zzz"]))],
            ["--weight-3d", str(rng.choice(["0.3", "nan", "2", "-1"]))], ["--threads", str(rng.choice(["1", "0", "99999"]))],
            ["--restart-skip", str(rng.choice(["1", "0", "-3"]))], ["--no-fusion"], ["--no-restart"]]
    argv = ["track", "--data", str(rng.choice([str(data), str(env.tmp / "missing"), str(afile)])),
            "--quiet", "--video", "none", "--frames", "2"]
    for i in rng.permutation(len(pool))[:int(rng.integers(0, 5))]:
        argv += pool[int(i)]
    if "--results" not in argv:
        argv += ["--results", str(env.tmp / "res")]
    if rng.random() < 0.15:
        argv = ["eval", "--data", str(data), "--results", str(rng.choice([str(env.tmp / "res"), str(afile)])),
                "--out", str(env.tmp / "rep"), "--no-plots", "--quiet"] + (["--frames", "0"] if rng.random() < .3 else [])
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main(argv)
        except SystemExit as e:  # argparse
            rc = e.code
    return _cli_ok(rc, err.getvalue())


def t_sim_cli(rng, env):
    from track3d_sim.cli import main

    mesh = env.tmp / f"m.{rng.choice(['obj', 'ply', 'stl'])}"
    mesh.write_bytes(rng.integers(0, 256, int(rng.integers(0, 300)), dtype=np.uint8).tobytes())
    size = str(rng.choice(["0", "-1", "nan", "inf", "x", "2.5", "1e400"]))
    argv = ["generate", "--preset", "tiny", "--mesh", f"{mesh}:{size}", "--out", str(env.tmp / "sim"),
            "--test", "0", "--train", "0"]
    err = io.StringIO()
    with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
        try:
            rc = main(argv)
        except SystemExit as e:
            rc = e.code
    return _cli_ok(0 if rc is None else rc, err.getvalue())


def t_mesh_loader(rng, env):
    from track3d_sim.errors import SimError
    from track3d_sim.shapes import load_user_mesh

    r = rng.random()
    ext = "obj" if r < 0.4 else str(rng.choice(["obj", "ply", "stl", "off"]))
    f = env.tmp / f"mesh.{ext}"
    if r < 0.4:  # a readable mesh: random finite vertices, some degenerate
        v = rng.normal(0, 10.0 ** rng.uniform(-4, 4), (int(rng.integers(3, 12)), 3))
        if rng.random() < 0.2:
            v[:, int(rng.integers(0, 3))] = 0.0  # flat
        faces = rng.integers(1, len(v) + 1, (int(rng.integers(1, 24)), 3))
        f.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    elif r < 0.7 and ext == "obj":
        v = rng.choice(SPECIALS, (int(rng.integers(0, 8)), 3))
        faces = rng.integers(0, 10, (int(rng.integers(0, 6)), 3)) + 1
        f.write_text("".join(f"v {a} {b} {c}\n" for a, b, c in v) + "".join(f"f {a} {b} {c}\n" for a, b, c in faces))
    else:
        f.write_bytes(rng.integers(0, 256, int(rng.integers(0, 400)), dtype=np.uint8).tobytes())
    try:
        shape = load_user_mesh(f, float(rng.choice([1.0, 0.5, 100.0])))
    except (SimError, ValueError):
        return "clean_error"
    expect(np.all(np.isfinite(shape.vertices)) and len(shape.faces) > 0, "mesh with non-finite vertices or no faces")
    return "ok"


# name -> (function, weight: share of the cases)
TARGETS = {
    "frustum": (t_frustum, 22), "sampling": (t_sampling, 12), "crop": (t_crop, 4),
    "estimate_baseline": (_t_estimator("baseline"), 14), "estimate_a3boxnet": (_t_estimator("a3boxnet"), 12),
    "loop_baseline": (_loop := _t_loop("baseline"), 12), "loop_a3boxnet": (_t_loop("a3boxnet"), 8),
    "loop_views": (t_loop_views, 2), "state": (t_state, 2),
    "track3d_siamfc": (_t_track3d("siamfc-edge"), 4), "track3d_edgetrack": (_t_track3d("edgetrack"), 4),
    "stereo": (t_stereo, 3),
    **{f"tracker_{n}": (_t_tracker(n), w) for n, w in
       (("kcf", 2), ("csrt", 1), ("mosse", 2), ("medianflow", 2), ("mil", 1), ("boosting", 1))},
    "dataset": (t_dataset, 3), "results": (t_results, 1), "cli": (t_cli, 1), "sim_cli": (t_sim_cli, 0.3), "mesh_loader": (t_mesh_loader, 1.7),
}


def run_case(target: str, seed: int, case: int, env: Env) -> tuple[str, str]:
    rng = np.random.default_rng([seed, case, sum(map(ord, target))])
    try:
        with np.errstate(all="ignore"):
            return TARGETS[target][0](rng, env), ""
    except Wrong as e:
        return "wrong", str(e)[:300]
    except Exception as e:  # noqa: BLE001 - any other escape is a crash by definition
        return "crash", f"{type(e).__name__}: {e}"[:300]


# --- worker / parent ---------------------------------------------------------------------------

def worker(target: str, seed: int, start: int, stop: int) -> None:
    import cv2

    cv2.setNumThreads(1)
    with tempfile.TemporaryDirectory(prefix="track3d-fuzz-") as tmp:
        env = Env(Path(tmp))
        for case in range(start, stop):
            out, detail = run_case(target, seed, case, env)
            sys.stdout.write(json.dumps([case, out, detail]) + "\n")
            sys.stdout.flush()


def plan(cases: int) -> dict[str, int]:
    """Cases per target in proportion to the weights, summing to exactly `cases` (largest
    remainders; at least one each): rounding each share alone fell short of the total asked."""
    total = sum(w for _, w in TARGETS.values())
    exact = {t: cases * w / total for t, (_, w) in TARGETS.items()}
    counts = {t: max(1, int(x)) for t, x in exact.items()}
    by_remainder = sorted(exact, key=lambda t: (int(exact[t]) - exact[t], t))
    for t in by_remainder[: max(0, cases - sum(counts.values()))]:
        counts[t] += 1
    return counts


# A case is a hang when its worker spent `timeout` seconds of CPU on it (spinning), or waited
# HANG_WALL_FACTOR x timeout of wall-clock time (blocked). Wall-clock time alone called a starved
# worker a hang: at nice 15 beside jobs at nice 0 on both cores a 0.9 s case took over 20 s, and
# the worker started in its place (imports and models, a few CPU seconds) timed out next.
HANG_WALL_FACTOR = 10.0


def cpu_seconds(pid: int) -> float | None:
    """User + system CPU seconds process `pid` has used (Linux /proc), or None where unknown."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
        return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    except (OSError, ValueError, IndexError):
        return None


def hang_verdict(cpu_used: float | None, waited: float, timeout: float) -> bool:
    """Is a case that has used `cpu_used` CPU seconds (None: unknown) over `waited` wall-clock
    seconds without finishing a hang? Spinning: `timeout` CPU seconds; blocked or starved:
    HANG_WALL_FACTOR x timeout of wall-clock time; unknown CPU time: `timeout` of wall-clock time."""
    if cpu_used is None:
        return waited >= timeout
    return cpu_used >= timeout or waited >= HANG_WALL_FACTOR * timeout


def run_range(target: str, start: int, stop: int, seed: int, timeout: float, deadline: float, counts: dict,
              examples: list) -> int:
    """Run cases start..stop-1 of `target` in worker processes; returns the next case to run."""
    case = start
    while case < stop and time.time() < deadline:
        proc = subprocess.Popen([sys.executable, __file__, "--worker", target, "--seed", str(seed),
                                 "--start", str(case), "--stop", str(stop)], stdout=subprocess.PIPE,
                                stderr=subprocess.DEVNULL, text=True, preexec_fn=lambda: os.nice(5))
        t_case, cpu_case = time.time(), cpu_seconds(proc.pid)
        while True:
            if time.time() > deadline:
                proc.kill()
                proc.wait()
                return case
            r, _, _ = select.select([proc.stdout], [], [], min(timeout, 1.0))
            if not r:
                cpu = cpu_seconds(proc.pid)
                used = None if cpu is None or cpu_case is None else cpu - cpu_case
                if not hang_verdict(used, time.time() - t_case, timeout):
                    continue
                proc.kill()
                proc.wait()
                counts[target]["hang"] += 1
                examples.append({"target": target, "case": case, "outcome": "hang"})
                case += 1
                break
            line = proc.stdout.readline()
            if not line:  # the worker died: the case it was on crashed the process
                rc = proc.wait()
                if case < stop:
                    counts[target]["crash"] += 1
                    examples.append({"target": target, "case": case, "outcome": "crash", "detail": f"exit {rc}"})
                    case += 1
                break
            c, out, detail = json.loads(line)
            t_case, cpu_case = time.time(), cpu_seconds(proc.pid)
            counts[target][out] += 1
            case = c + 1
            if out in ("wrong", "crash", "hang") and len(examples) < 200:
                examples.append({"target": target, "case": c, "outcome": out, "detail": detail})
            if case >= stop:
                proc.wait()
                break
    return case


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__)
    ap.add_argument("--cases", type=int, default=100_000, help="total cases over all targets (default 100000)")
    ap.add_argument("--seed", type=int, default=0, help="fuzz seed (default 0)")
    ap.add_argument("--minutes", type=float, default=20.0, help="stop after this long, reporting the count reached (20)")
    ap.add_argument("--timeout", type=float, default=20.0,
                    help="CPU seconds one case may take before it is a hang (20; ten times that of wall-clock "
                         "time for a blocked case)")
    ap.add_argument("--targets", nargs="+", choices=sorted(TARGETS), help="only these targets (default all)")
    ap.add_argument("--rounds", type=int, default=10, help="targets are interleaved in this many rounds (10)")
    ap.add_argument("--out", type=Path, help="also write the counts as JSON here (default: print only)")
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--start", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--stop", type=int, default=0, help=argparse.SUPPRESS)
    return ap


def main(argv=None) -> int:
    a = build_parser().parse_args(argv)
    if a.worker:
        worker(a.worker, a.seed, a.start, a.stop)
        return 0
    shares = plan(a.cases)
    if a.targets:
        shares = {t: shares[t] for t in a.targets}
    counts = {t: dict.fromkeys(OUTCOMES, 0) for t in shares}
    examples: list = []
    t0 = time.time()
    deadline = t0 + 60 * a.minutes
    nxt = dict.fromkeys(shares, 0)
    rounds = max(1, int(a.rounds))
    for r in range(1, rounds + 1):  # interleaved, so that a time limit cuts every target alike
        for t, n in shares.items():
            stop = n * r // rounds
            if nxt[t] < stop and time.time() < deadline:
                nxt[t] = run_range(t, nxt[t], stop, a.seed, a.timeout, deadline, counts, examples)
        done = sum(sum(c.values()) for c in counts.values())
        print(f"round {r}/{rounds}: {done} cases, {time.time() - t0:.0f} s", file=sys.stderr, flush=True)
    for t, n in shares.items():
        print(f"{t:20s} {sum(counts[t].values()):7d}/{n:<7d} " + " ".join(f"{o}={counts[t][o]}" for o in OUTCOMES))
    total = {o: sum(c[o] for c in counts.values()) for o in OUTCOMES}
    n_done = sum(total.values())
    print(f"TOTAL {n_done} cases in {time.time() - t0:.0f} s: " + " ".join(f"{o}={total[o]}" for o in OUTCOMES))
    for e in examples[:20]:
        print("example:", json.dumps(e))
    if a.out:
        a.out.write_text(json.dumps({"seed": a.seed, "cases_planned": a.cases, "cases_run": n_done, "total": total,
                                     "per_target": counts, "seconds": time.time() - t0, "examples": examples},
                                    indent=1))
    return 1 if total["wrong"] or total["crash"] or total["hang"] else 0


if __name__ == "__main__":
    sys.exit(run_main(main, "fuzz.py"))
