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
"""
from __future__ import annotations

import math

import numpy as np

EXPOSURE_GAIN = 0.9
FULL_WELL_E = 6000.0
READ_NOISE_DN = 0.5
BLACK_LEVEL_DN = 0.0


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


def sensor(img_dn: np.ndarray, rng: np.random.Generator, hot: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Linear DN image (H, W, 3) -> noisy uint8 RGB: shot noise + read noise + hot pixels."""
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
