"""Headless CPU ray casting (Embree via embreex) and the photometric model.

Geometry: the body mesh is put into ONE Embree scene per sequence, in the body frame;
per frame the camera rays are transformed into the body frame instead of the mesh.
Rays go through pixel centres (track3d.camera.Camera.pixel_rays, z = 1 in the camera
frame), so the hit parameter t IS the depth z. Only pixels inside the projected
bounding box of the mesh are cast. One sample per pixel: silhouettes are exact
(no anti-aliasing), so the 2D label is exactly the set of pixels that have a depth.

Photometry (documented in docs/simulator.md):
  reflectance: lunar-Lambert (McEwen) mix of Lommel-Seeliger and Lambert,
      f = A * mu0 * [ (1 - L) + 2 L / (mu0 + mu) ],  L(alpha) = exp(-alpha / 60 deg)
  cast shadows: one shadow ray per lit hit toward the sun (any occluder -> shadow)
  exposure:  DN = 255 * G * E * f + ambient  (fixed camera gain G, sun irradiance E
      relative to the irradiance that saturates a white Lambertian facing the sun)
  sensor: photon shot noise (full well FW e-), Gaussian read noise, hot pixels,
      8-bit quantisation.

Camera effects (opt-in per dataset: settings "auto_exposure", "motion_blur"; docs/simulator.md,
"Camera effects"):
  auto exposure: per sequence, the camera brightens a dark scene by k = E_target / E (capped),
      first with a longer exposure (more photons: better SNR, more blur), then with analog gain
      (amplifies shot and read noise alike: brighter, not cleaner);
  motion blur: frames whose projected motion during the exposure exceeds BLUR_STEP_PX are the
      mean of n sub-exposure renders at poses spread over the exposure (n = motion / step,
      capped), linear in DN before the sensor noise.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

EXPOSURE_GAIN = 0.9
FULL_WELL_E = 6000.0
READ_NOISE_DN = 0.5
BLACK_LEVEL_DN = 0.0

# Camera effects (documented in docs/simulator.md, "Camera effects").
BASE_EXPOSURE_MS = 10.0        # the exposure the fixed-camera model (EXPOSURE_GAIN) stands for
MAX_EXPOSURE_MS = 50.0         # half the 100 ms frame interval
MAX_GAIN = 4.0                 # analog gain cap (12 dB)
AE_TARGET_IRRADIANCE = 0.35    # auto exposure brings darker scenes up to the median irradiance
BLUR_STEP_PX = 1.0             # one sub-exposure render per pixel of motion during the exposure
MAX_BLUR_SUBSTEPS = 8


@dataclass(frozen=True)
class Exposure:
    """A sequence's exposure time and analog gain; `scale` multiplies the image brightness."""

    exposure_ms: float = BASE_EXPOSURE_MS
    gain: float = 1.0

    @property
    def scale(self) -> float:
        return self.exposure_ms / BASE_EXPOSURE_MS * self.gain


def auto_exposure(irradiance: float) -> Exposure:
    """Exposure for a sequence lit by `irradiance`: brighten by k = clip(E_target / E, 1, k_max),
    exposure time first (up to MAX_EXPOSURE_MS), then gain (up to MAX_GAIN)."""
    t_max = MAX_EXPOSURE_MS / BASE_EXPOSURE_MS
    k = float(np.clip(AE_TARGET_IRRADIANCE / max(float(irradiance), 1e-9), 1.0, t_max * MAX_GAIN))
    t = min(k, t_max)
    return Exposure(BASE_EXPOSURE_MS * t, k / t)


def _rotvec(Rm: np.ndarray) -> np.ndarray:
    """Rotation matrix -> rotation vector (axis * angle)."""
    c = np.clip((np.trace(Rm) - 1.0) / 2.0, -1.0, 1.0)
    th = math.acos(c)
    w = np.array([Rm[2, 1] - Rm[1, 2], Rm[0, 2] - Rm[2, 0], Rm[1, 0] - Rm[0, 1]])
    if th < 1e-9:
        return w / 2.0
    return w * (th / (2.0 * math.sin(th)))


def _exp_rot(rv: np.ndarray) -> np.ndarray:
    th = float(np.linalg.norm(rv))
    if th < 1e-12:
        return np.eye(3)
    k = rv / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * (K @ K)


def exposure_poses(R: np.ndarray, T: np.ndarray, i: int, exposure_ms: float, fps: float, n: int,
                   ends: bool = False):
    """n poses (R, T) of frame i spread over its exposure (centred on the frame time: the mid
    times of n equal slices; ends=True: from its start to its end), from the angular and linear
    velocities of the sampled motion (central differences)."""
    N = len(R)
    a, b = max(i - 1, 0), min(i + 1, N - 1)
    if b == a:
        return [(R[i], T[i])] * n
    dt = (b - a) / fps
    w = _rotvec(R[b] @ R[a].T) / dt       # camera-frame angular velocity: R(t) = exp(w t) R
    v = (T[b] - T[a]) / dt
    texp = exposure_ms / 1000.0
    taus = (np.linspace(-0.5, 0.5, n) if ends else (np.arange(n) + 0.5) / n - 0.5) * texp
    return [(_exp_rot(w * tau) @ R[i], T[i] + v * tau) for tau in taus]


def blur_substeps(camera, vertices: np.ndarray, poses_ends) -> int:
    """Sub-exposure renders a frame needs: the largest image motion (px) of the body's vertices
    between the exposure's first and last pose, per BLUR_STEP_PX, in 1..MAX_BLUR_SUBSTEPS."""
    (R0, T0), (R1, T1) = poses_ends
    V = vertices[:: max(1, len(vertices) // 500)]
    X0, X1 = V @ R0.T + T0, V @ R1.T + T1
    ok = (X0[:, 2] > 0.1) & (X1[:, 2] > 0.1)
    if not ok.any():
        return 1
    d = np.linalg.norm(camera.project(X1[ok]) - camera.project(X0[ok]), axis=1).max()
    return int(np.clip(math.ceil(d / BLUR_STEP_PX), 1, MAX_BLUR_SUBSTEPS))


class BodyRenderer:
    """Casts the two cameras' rays against one body (Shape + SolidTexture)."""

    def __init__(self, shape, texture, camera):
        from embreex import rtcore_scene as rtcs
        from embreex.mesh_construction import TriangleMesh
        self.shape = shape
        self.texture = texture
        self.camera = camera
        self.V = np.asarray(shape.vertices, np.float64)
        self.F = np.asarray(shape.faces, np.int32)
        self.scene = rtcs.EmbreeScene()
        TriangleMesh(self.scene, self.V[self.F].astype(np.float32))
        self.VN = shape.vertex_normals()
        tri = self.V[self.F]
        fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        self.FN = (fn / np.maximum(np.linalg.norm(fn, axis=1, keepdims=True), 1e-30)).astype(np.float32)
        self.rays = camera.pixel_rays()  # (H, W, 3), z = 1
        self.eps = 1e-4 * max(shape.radius, 1e-3)

    def pixel_window(self, R, T, eye):
        """Integer pixel window [u0, u1) x [v0, v1) that holds the projection of the mesh,
        and the amodal projected bounds (umin, vmin, umax, vmax) in the eye's image."""
        X = self.V @ R.T + (T - eye)
        uv = self.camera.project(X)
        umin, vmin = uv.min(0)
        umax, vmax = uv.max(0)
        W, H = self.camera.width, self.camera.height
        u0 = int(np.clip(math.floor(umin) - 1, 0, W))
        u1 = int(np.clip(math.ceil(umax) + 1, 0, W))
        v0 = int(np.clip(math.floor(vmin) - 1, 0, H))
        v1 = int(np.clip(math.ceil(vmax) + 1, 0, H))
        return (u0, u1, v0, v1), (umin, vmin, umax, vmax)

    def cast(self, R, T, eye=np.zeros(3)):
        """Primary rays of the camera centred at `eye` (left frame; same orientation).

        Returns dict: z (H, W) float64 depth (0 = no hit), mask (H, W) bool, and for the hits
        (row-major order): p (M,3) body-frame points, n (M,3) shading normals, fn face normals,
        view (M,3) unit vectors toward the eye (body frame), window, bounds."""
        H, W = self.camera.height, self.camera.width
        (u0, u1, v0, v1), bounds = self.pixel_window(R, T, eye)
        z = np.zeros((H, W), np.float64)
        mask = np.zeros((H, W), bool)
        out = {"z": z, "mask": mask, "window": (u0, u1, v0, v1), "bounds": bounds}
        if u1 <= u0 or v1 <= v0:
            out.update(p=np.zeros((0, 3)), n=np.zeros((0, 3), np.float32), fn=np.zeros((0, 3), np.float32),
                       view=np.zeros((0, 3)))
            return out
        d = self.rays[v0:v1, u0:u1].reshape(-1, 3)
        Rt = R.T
        ob = Rt @ (np.asarray(eye, np.float64) - T)
        db = np.einsum("ij,jk->ik", d, R)  # = (Rt @ d.T).T
        org = np.broadcast_to(ob.astype(np.float32), db.shape).copy()
        res = self.scene.run(org, db.astype(np.float32), output=1)
        hit = res["geomID"] >= 0
        t = res["tfar"].astype(np.float64)
        sub_z = np.where(hit, t, 0.0)
        z[v0:v1, u0:u1] = sub_z.reshape(v1 - v0, u1 - u0)
        mask[v0:v1, u0:u1] = hit.reshape(v1 - v0, u1 - u0)
        hi = np.flatnonzero(hit)
        prim = res["primID"].take(hi)
        bu, bv = res["u"].take(hi)[:, None], res["v"].take(hi)[:, None]
        f = self.F.take(prim, axis=0)
        n = ((1 - bu - bv) * self.VN.take(f[:, 0], axis=0) + bu * self.VN.take(f[:, 1], axis=0)
             + bv * self.VN.take(f[:, 2], axis=0))
        n /= np.maximum(np.sqrt((n * n).sum(1, keepdims=True)), 1e-12)
        dh = db.take(hi, axis=0)
        p = ob + t.take(hi)[:, None] * dh
        view = -dh / np.sqrt((dh * dh).sum(1, keepdims=True))
        out.update(p=p, n=n, fn=self.FN.take(prim, axis=0), view=view)
        return out

    def surface(self, c) -> tuple[np.ndarray, np.ndarray]:
        """What an active depth sensor sees of the hits of cast result c, as (H, W) float32 maps
        (0 where there is no hit): the cosine between the shading normal and the ray back to the
        eye, and the mean (grey) albedo of the texture."""
        H, W = c["z"].shape
        cos_inc = np.zeros((H, W), np.float32)
        albedo = np.zeros((H, W), np.float32)
        if len(c["p"]):
            cos_inc[c["mask"]] = np.clip((c["n"] * c["view"]).sum(1), 0.0, 1.0)
            albedo[c["mask"]] = self.texture.albedo(c["p"]).mean(1)
        return cos_inc, albedo

    def view(self, background: np.ndarray, R, T, eye, sun_dir_cam, irradiance, ambient) -> np.ndarray:
        """Linear DN image (H, W, 3) float32 of the body at pose (R, T) over `background`."""
        c = self.cast(R, T, eye)
        dn, _ = self.shade(c, R, sun_dir_cam, irradiance, ambient)
        img = background.copy()
        img[c["mask"]] = dn
        return img

    def blurred_view(self, background: np.ndarray, poses, eye, sun_dir_cam, irradiance, ambient) -> np.ndarray:
        """Motion blur: the mean of the views at `poses` (spread over the exposure)."""
        acc = np.zeros(background.shape, np.float64)
        for R, T in poses:
            acc += self.view(background, R, T, eye, sun_dir_cam, irradiance, ambient)
        return (acc / len(poses)).astype(np.float32)

    def shade(self, c, R, sun_dir_cam, irradiance, ambient):
        """Radiance in DN (M, 3) float32 of the hits in cast result c, and the lit mask (M,)."""
        p, n, fn, view = c["p"], c["n"], c["fn"], c["view"]
        M = len(p)
        if M == 0:
            return np.zeros((0, 3), np.float32), np.zeros(0, bool)
        s = R.T @ np.asarray(sun_dir_cam, np.float64)
        mu0 = n @ s
        mu = np.clip((n * view).sum(1), 1e-3, 1.0)
        lit = (mu0 > 0) & ((fn @ s) > 0)
        if lit.any():
            o = (p[lit] + fn[lit] * self.eps).astype(np.float32)
            dsh = np.broadcast_to(s.astype(np.float32), o.shape).copy()
            occ = self.scene.run(o, dsh, query="OCCLUDED")
            idx = np.nonzero(lit)[0]
            lit[idx[occ >= 0]] = False
        cos_a = np.clip(view @ s, -1.0, 1.0)
        alpha = np.arccos(cos_a)
        L = np.exp(-alpha / math.radians(60.0))
        mu0c = np.clip(mu0, 0.0, 1.0)
        f = np.where(lit, mu0c * ((1 - L) + 2 * L / (mu0c + mu)), 0.0)
        A = self.texture.albedo(p)
        dn = A * (255.0 * EXPOSURE_GAIN * irradiance * f + ambient)[:, None]
        return dn.astype(np.float32), lit


def sensor(img_dn: np.ndarray, rng: np.random.Generator, hot: tuple[np.ndarray, np.ndarray, np.ndarray],
           exposure: Exposure | None = None) -> np.ndarray:
    """Linear DN image (H, W, 3) -> noisy uint8 RGB: shot noise + read noise + hot pixels.

    img_dn is the image at BASE_EXPOSURE_MS and unit gain. With `exposure` the sensor collects
    exposure_ms / BASE_EXPOSURE_MS times the photo-electrons (capped at the full well), adds
    read noise (fixed in electrons) and multiplies by the gain; hot pixels (dark current)
    integrate over the exposure too. exposure=None is the fixed-camera model, bit for bit."""
    if exposure is not None:
        return _sensor_exposed(img_dn, rng, hot, exposure)
    x = np.clip(img_dn, 0.0, None) + BLACK_LEVEL_DN
    e_per_dn = FULL_WELL_E / 255.0
    sd = np.sqrt(x / e_per_dn + READ_NOISE_DN ** 2).astype(np.float32)
    x = x + sd * rng.standard_normal(x.shape, dtype=np.float32)
    hy, hx, hv = hot
    if len(hy):
        x[hy, hx] += hv[:, None]
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def hot_pixels(rng: np.random.Generator, H: int, W: int, fraction: float = 2e-4):
    n = int(H * W * fraction)
    return (rng.integers(0, H, n), rng.integers(0, W, n), rng.uniform(20, 180, n).astype(np.float32))


def _sensor_exposed(img_dn, rng, hot, exposure: Exposure) -> np.ndarray:
    e_per_dn = FULL_WELL_E / 255.0
    t = exposure.exposure_ms / BASE_EXPOSURE_MS
    e = np.minimum((np.clip(img_dn, 0.0, None) + BLACK_LEVEL_DN) * (t * e_per_dn), FULL_WELL_E).astype(np.float32)
    read_e = READ_NOISE_DN * e_per_dn
    sd = np.sqrt(e + read_e ** 2).astype(np.float32)
    x = (e + sd * rng.standard_normal(e.shape, dtype=np.float32)) * np.float32(exposure.gain / e_per_dn)
    hy, hx, hv = hot
    if len(hy):
        x[hy, hx] += (hv * np.float32(t * exposure.gain))[:, None]
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)
