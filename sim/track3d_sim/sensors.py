"""Depth sensors: how a sequence's depth map is measured from the rendered geometry.

The labels (2D and 3D boxes) are always the geometry's; only the stored depth map (and so the
point cloud a tracker sees) depends on the sensor. `dataset.json` and each sequence's
`meta.json` say which sensor made the depth.

    z = measure_depth("tof", frame, camera, rng)     # (H, W) float64 metres, 0 = no return

Sensors (docs/simulator.md, "Depth sensors", gives the published figures behind the defaults):

- ``ideal``: the rendered z, unchanged.
- ``tof``: an amplitude-modulated time-of-flight camera on the left camera's pixel grid
  (`TOF`): range noise from the return signal, dropouts on weak (dark, grazing, far) returns,
  an unambiguous maximum range.
- ``flash-lidar``: a pulsed 128 x 128 flash LiDAR (`FLASH_LIDAR`) with its own intrinsics,
  boresighted with the left camera; its returns are reprojected into the left image grid
  with a z-buffer (pixels without a return are 0), so the stored depth is sparse.
- ``stereo``: semi-global matching of the rendered left/right images (`track3d.stereo`, the
  runtime's implementation): the holes and errors come from the images themselves.

The ToF signal model, per pixel (range r = |ray| * z, albedo a, cos of incidence c):

    s     = (a / ref_albedo) * c * (ref_range_m / r)**2          relative return signal
    sigma = sqrt(sigma_floor_m**2 + sigma_ref_m**2 / s)           range noise (shot-noise limited)
    P(return) = 1 / (1 + (min_signal / s)**dropout_slope)          soft detection threshold
    no return when c < min_cos_incidence, r > max_range_m or r < min_range_m

The range error is applied along the pixel's ray (z scales with r).

False alarms (`measure_depth(..., false_alarms=)`, `track3d-sim generate --false-alarms RATE`,
any sensor but stereo): each of the sensor's pixels (the flash LiDAR's own 128 x 128, before
reprojection), with probability RATE, returns a range where there is no surface (a dark count, a
solar photon, a dust grain), drawn uniformly in the sensor's range gate and before the rendered
surface where the pixel sees one (the sensor reports the first return). The gate is the ToF
models' [min_range_m, max_range_m], the paper's 1-45 m for ideal depth.
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numpy as np

from .errors import SimError

__all__ = ["RenderedFrame", "ToFModel", "TOF", "FLASH_LIDAR", "DEPTH_SENSORS", "SENSORS_NEEDING_IMAGES", "measure_depth",
           "tof_signal", "tof_sigma", "tof_return_probability", "sensor_info", "add_false_alarms",
           "false_alarm_gate", "FALSE_ALARM_SENSORS"]


@dataclass
class RenderedFrame:
    """What the renderer knows of one frame, in the left camera's pixel grid.

    z: (H, W) float64 true depth (z, not range) in metres, 0 = background;
    cos_incidence: (H, W) float32 cosine between the surface normal and the ray to the camera
      (0 where there is no hit); albedo: (H, W) float32 mean albedo of the hit surface (0..1);
    left, right: (H, W, 3) uint8 RGB images as written to disk (right: camera at +baseline)."""

    z: np.ndarray
    cos_incidence: np.ndarray
    albedo: np.ndarray
    left: np.ndarray
    right: np.ndarray


@dataclass(frozen=True)
class ToFModel:
    """A time-of-flight depth sensor (AMCW ToF camera or pulsed flash LiDAR); see module doc.

    resolution: (width, height) of the sensor's own pixel grid, None = the left camera's grid
      (the sensor is then registered pixel for pixel, as RGB-D cameras deliver it);
    fov_x_deg: its horizontal field of view (square pixels), None = the left camera's;
    the sensor is boresighted with the left camera (same centre and axes)."""

    name: str
    sigma_floor_m: float = 0.005     # range-independent noise (timing jitter, calibration residue)
    sigma_ref_m: float = 0.017       # signal-dependent noise at the reference return (s = 1)
    ref_range_m: float = 10.0        # reference return: this range, ...
    ref_albedo: float = 0.5          # ... this (relative) albedo, normal incidence
    min_signal: float = 0.05         # relative signal at which half of the returns drop out
    dropout_slope: float = 4.0       # steepness of the detection threshold
    min_cos_incidence: float = 0.1   # grazing cut-off: no return beyond ~84 deg incidence
    min_range_m: float = 0.5
    max_range_m: float = 30.0        # AMCW: unambiguous range c / (2 f_mod), 30 m at 5 MHz
    resolution: tuple[int, int] | None = None
    fov_x_deg: float | None = None

    def __post_init__(self) -> None:
        for k in ("sigma_floor_m", "sigma_ref_m", "min_signal", "dropout_slope", "min_cos_incidence",
                  "min_range_m"):
            if not float(getattr(self, k)) >= 0.0:
                raise SimError(f"ToF parameter {k} must be >= 0, got {getattr(self, k)}")
        for k in ("ref_range_m", "ref_albedo", "max_range_m"):
            if not float(getattr(self, k)) > 0.0:
                raise SimError(f"ToF parameter {k} must be > 0, got {getattr(self, k)}")
        if self.resolution is not None and (len(self.resolution) != 2 or min(self.resolution) < 1):
            raise SimError(f"ToF resolution must be (width, height), got {self.resolution}")


# AMCW ToF camera class (Azure Kinect DK depth camera: random error sd <= 17 mm, 15-95 %
# reflectivity targets; operating range limited by the illuminator), with the illuminator
# scaled so that the reference return is at 10 m and the modulation at 5 MHz (30 m unambiguous).
TOF = ToFModel("tof")

# Pulsed 3D flash LiDAR class (ASC 3D Flash LIDAR 128 x 128 InGaAs APD focal plane array,
# DragonEye / GoldenEye; Ball VNS 256 x 256 on STS-134 STORRM): centimetre range precision,
# ranges of hundreds of metres to kilometres (not a limit at 1-45 m), coarse pixels.
FLASH_LIDAR = ToFModel("flash-lidar", sigma_floor_m=0.02, sigma_ref_m=0.01, ref_range_m=45.0, ref_albedo=0.5,
                       min_signal=0.02, dropout_slope=4.0, min_cos_incidence=0.05, min_range_m=0.5,
                       max_range_m=60.0, resolution=(128, 128), fov_x_deg=45.0)


def _ray_norm(camera) -> np.ndarray:
    """(H, W) |ray| of each left pixel's ray scaled to z = 1: range = z * |ray|."""
    r = camera.pixel_rays()
    return np.sqrt((r * r).sum(-1))


def tof_signal(model: ToFModel, range_m, albedo, cos_incidence) -> np.ndarray:
    """Relative return signal s (1 at the model's reference return)."""
    r = np.maximum(np.asarray(range_m, np.float64), 1e-9)
    return (np.asarray(albedo, np.float64) / model.ref_albedo) * np.asarray(cos_incidence, np.float64) \
        * (model.ref_range_m / r) ** 2


def tof_sigma(model: ToFModel, signal) -> np.ndarray:
    """Range noise sd (metres) of returns with relative signal `signal`."""
    s = np.maximum(np.asarray(signal, np.float64), 1e-12)
    return np.sqrt(model.sigma_floor_m ** 2 + model.sigma_ref_m ** 2 / s)


def tof_return_probability(model: ToFModel, range_m, albedo, cos_incidence) -> np.ndarray:
    """Probability that a surface at range_m with this albedo and incidence gives a return."""
    r = np.asarray(range_m, np.float64)
    c = np.asarray(cos_incidence, np.float64)
    s = tof_signal(model, r, albedo, c)
    with np.errstate(divide="ignore", over="ignore"):
        p = 1.0 / (1.0 + (model.min_signal / np.maximum(s, 1e-300)) ** model.dropout_slope)
    ok = (c >= model.min_cos_incidence) & (r <= model.max_range_m) & (r >= model.min_range_m) & (s > 0)
    return np.where(ok, p, 0.0)


def _tof_returns(model: ToFModel, z, ray_norm, albedo, cos_inc, rng) -> np.ndarray:
    """Measured z (0 = no return) of pixels with true z (> 0), on any grid."""
    hit = z > 0
    r = z * ray_norm
    p = tof_return_probability(model, r, albedo, cos_inc)
    s = tof_signal(model, r, albedo, cos_inc)
    # Draw every pixel's noise (not only the hits) so that the stream does not depend on the scene.
    u = rng.random(z.shape)
    e = rng.standard_normal(z.shape) * tof_sigma(model, s)
    keep = hit & (u < p)
    rm = r + e
    out = np.where(keep & (rm > 0), z * rm / np.where(hit, r, 1.0), 0.0)
    return out


def _tof_full(model: ToFModel):
    def measure(frame: RenderedFrame, camera, rng: np.random.Generator) -> np.ndarray:
        z = np.asarray(frame.z, np.float64)
        return _tof_returns(model, z, _ray_norm(camera), frame.albedo, frame.cos_incidence, rng)
    return measure


def _zbuffer(idx: np.ndarray, depth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Nearest sample per cell: (cells, positions into idx) of the winners, deterministic."""
    order = np.lexsort((depth, idx))
    cells, first = np.unique(idx[order], return_index=True)
    return cells, order[first]


def lidar_intrinsics(model: ToFModel, camera) -> tuple[int, int, float, float, float]:
    """(width, height, f, cx, cy) of the sensor's own pinhole grid (square pixels)."""
    w, h = model.resolution if model.resolution is not None else (camera.width, camera.height)
    fov = model.fov_x_deg if model.fov_x_deg is not None else camera.fov_x_deg
    f = w / (2.0 * math.tan(math.radians(fov) / 2.0))
    return int(w), int(h), f, w / 2.0, h / 2.0


def _tof_lowres(model: ToFModel):
    """A sensor with its own grid: each of its pixels returns the nearest surface in its
    footprint (first return) along its centre ray; returns are reprojected into the left grid
    with a z-buffer. False alarms (rate, rng) are drawn on the sensor's own grid."""
    def measure(frame: RenderedFrame, camera, rng: np.random.Generator, false_alarms=None) -> np.ndarray:
        z = np.asarray(frame.z, np.float64)
        H, W = z.shape
        w, h, f, cx, cy = lidar_intrinsics(model, camera)
        # left-grid surface points -> the sensor's pixels (boresighted: only the intrinsics differ)
        vv, uu = np.nonzero(z > 0)
        zs = z[vv, uu]
        x = (uu + 0.5 - camera.cx) / camera.fx
        y = (vv + 0.5 - camera.cy) / camera.fy
        i = np.floor(f * x + cx).astype(np.int64)
        j = np.floor(f * y + cy).astype(np.int64)
        inside = (i >= 0) & (i < w) & (j >= 0) & (j < h)
        cells, win = _zbuffer((j * w + i)[inside], zs[inside])
        src = np.flatnonzero(inside)[win]
        lz = np.zeros(h * w)
        lz[cells] = zs[src]
        la = np.zeros(h * w, np.float32)
        la[cells] = np.asarray(frame.albedo)[vv[src], uu[src]]
        lc = np.zeros(h * w, np.float32)
        lc[cells] = np.asarray(frame.cos_incidence)[vv[src], uu[src]]
        jj, ii = np.divmod(np.arange(h * w), w)
        rx, ry = (ii + 0.5 - cx) / f, (jj + 0.5 - cy) / f
        norm = np.sqrt(rx * rx + ry * ry + 1.0)
        meas = _tof_returns(model, lz, norm, la, lc, rng)
        if false_alarms is not None:
            rate, arng = false_alarms
            meas = _alarms(meas, lz, norm, rate, (float(model.min_range_m), float(model.max_range_m)), arng)
        # the sensor's returns, as points along its pixel centre rays, into the left grid
        k = np.flatnonzero(meas > 0)
        zk = meas[k]
        u = np.floor(camera.fx * rx[k] + camera.cx).astype(np.int64)
        v = np.floor(camera.fy * ry[k] + camera.cy).astype(np.int64)
        ok = (u >= 0) & (u < W) & (v >= 0) & (v < H)
        cells, win = _zbuffer((v * W + u)[ok], zk[ok])
        out = np.zeros(H * W)
        out[cells] = zk[ok][win]
        return out.reshape(H, W)
    return measure


def _stereo(frame: RenderedFrame, camera, rng: np.random.Generator) -> np.ndarray:
    from track3d.stereo import StereoMatcher

    return StereoMatcher(camera).depth(frame.left, frame.right)


def _ideal(frame: RenderedFrame, camera, rng: np.random.Generator) -> np.ndarray:
    return np.asarray(frame.z, dtype=np.float64)


TOF_MODELS = {m.name: m for m in (TOF, FLASH_LIDAR)}
DEPTH_SENSORS = {"ideal": _ideal, "tof": _tof_full(TOF), "flash-lidar": _tof_lowres(FLASH_LIDAR),
                 "stereo": _stereo}
# sensors that measure depth from the rendered images (so a points-only run cannot have them)
SENSORS_NEEDING_IMAGES = frozenset({"stereo"})


# sensors whose depth may carry false alarms (stereo's errors are the matcher's own)
FALSE_ALARM_SENSORS = frozenset({"ideal", "tof", "flash-lidar"})
LOWRES_SENSORS = frozenset({"flash-lidar"})   # with a pixel grid of their own (false alarms drawn there)
IDEAL_GATE_M = (1.0, 45.0)   # the paper's working range (IV-A)


def false_alarm_gate(sensor: str) -> tuple[float, float]:
    """The range gate (near, far) in metres a false alarm of `sensor` falls in."""
    m = TOF_MODELS.get(sensor)
    return IDEAL_GATE_M if m is None else (float(m.min_range_m), float(m.max_range_m))


def _alarms(depth: np.ndarray, surface: np.ndarray, norm: np.ndarray, rate: float, gate: tuple[float, float],
            rng: np.random.Generator) -> np.ndarray:
    """`depth` (any grid, metres, 0 = no return) with false alarms: each pixel, with probability
    `rate`, returns a range uniform in the gate and before the pixel's rendered `surface` z where
    there is one, as z along its ray (`norm`: |ray| at z = 1). Two draws per pixel whatever the
    scene, so the stream does not depend on it."""
    z = np.asarray(depth, np.float64)
    u = rng.random(z.shape)
    t = rng.random(z.shape)
    near, far = gate
    sz = np.asarray(surface, np.float64)
    stop = np.where(sz > 0, np.minimum(sz * norm, far), far)
    alarm = (u < rate) & (stop > near)
    out = z.copy()
    out[alarm] = (near + (stop[alarm] - near) * t[alarm]) / norm[alarm]
    return out


def add_false_alarms(depth: np.ndarray, camera, rate: float, gate: tuple[float, float],
                     rng: np.random.Generator, surface: np.ndarray | None = None) -> np.ndarray:
    """`depth` (H, W) metres on the left camera's grid, 0 = no return, with each pixel's return
    replaced, with probability `rate`, by a false alarm: a range uniform in the gate, before the
    pixel's rendered surface (`surface`, (H, W) z; None: `depth` itself) when it has one (the
    first return), as z along the pixel's ray. A new array. A sensor with its own grid (the flash
    LiDAR) draws them there instead: `measure_depth(..., false_alarms=)`."""
    return _alarms(depth, depth if surface is None else surface, _ray_norm(camera), rate, gate, rng)


def sensor_info(sensor: str) -> dict:
    """The sensor's name and parameters, as recorded in meta.json."""
    if sensor not in DEPTH_SENSORS:
        raise SimError(f"unknown depth sensor {sensor!r} (choose from {', '.join(DEPTH_SENSORS)})")
    if sensor in TOF_MODELS:
        d = asdict(TOF_MODELS[sensor])
        d["resolution"] = list(d["resolution"]) if d["resolution"] else None
        return d
    if sensor == "stereo":
        from track3d.stereo import StereoParams

        # the maps are full-frame matches over the whole range: following a body's depth is the
        # loop's (StereoCloud), not the sensor's
        return {"name": "stereo", **{k: v for k, v in asdict(StereoParams()).items() if k != "follow_depth"}}
    return {"name": sensor}


def measure_depth(sensor: str, frame: RenderedFrame, camera, rng: np.random.Generator,
                  false_alarms: tuple[float, np.random.Generator] | None = None) -> np.ndarray:
    """The depth map (H, W) float64 metres (0 = no return) that `sensor` measures of `frame`;
    false_alarms (rate, generator): a range sensor's false returns (FALSE_ALARM_SENSORS), drawn on
    the sensor's own grid before the rendered surface, with their own generator."""
    f = DEPTH_SENSORS.get(sensor)
    if f is None:
        raise SimError(f"unknown depth sensor {sensor!r} (choose from {', '.join(DEPTH_SENSORS)})")
    if false_alarms is None or sensor not in FALSE_ALARM_SENSORS:
        return f(frame, camera, rng)
    if sensor in LOWRES_SENSORS:
        return f(frame, camera, rng, false_alarms)
    rate, arng = false_alarms
    return add_false_alarms(f(frame, camera, rng), camera, rate, false_alarm_gate(sensor), arng,
                            surface=np.asarray(frame.z, np.float64))
