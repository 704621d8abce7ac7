"""Asteroid meshes: three procedural shape families and user meshes (OBJ / PLY / ...).

Procedural bodies are star-shaped: a radial function r(d) of the unit direction d is
evaluated at the vertices of a subdivided icosphere (so the mesh is closed and
watertight by construction), then stretched anisotropically (and bent for the
irregular family) and scaled to a target box volume.

Families (coarse categories, the one-hot input of A3BoxNet):
  0 contact_binary  two ellipsoidal lobes joined by a neck (Itokawa-like)
  1 spinning_top    equatorial ridge, double-cone profile (Ryugu / Bennu-like)
  2 irregular       elongated, bent, saddle-dented, heavily cratered (Eros-like)
Each sequence varies its body: lobe sizes, noise seed, craters, boulders, stretch.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from track3d.dataset import COARSE_CATEGORIES as FAMILIES  # stated once

from .errors import SimError
from .noise import fft_noise, trilinear


# Axis-aligned box volume range of the paper (section III-B), m^3.
VOLUME_RANGE = (16.0, 1600.0)


@dataclass
class Shape:
    vertices: np.ndarray          # (V, 3) float64, body frame, metres
    faces: np.ndarray             # (F, 3) int32
    family: str
    params: dict = field(default_factory=dict)
    # a closed, consistently wound surface (every procedural body; a user mesh when trimesh finds
    # it watertight and consistently wound): only then is its volume integral an inertia tensor
    closed: bool = True

    @property
    def radius(self) -> float:
        """Bounding radius about the body origin (metres)."""
        return float(np.linalg.norm(self.vertices, axis=1).max())

    @property
    def extent(self) -> np.ndarray:
        return self.vertices.max(0) - self.vertices.min(0)

    def vertex_normals(self) -> np.ndarray:
        return vertex_normals(self.vertices, self.faces)

    def inertia(self) -> np.ndarray | None:
        """(3, 3) inertia tensor about the centre of mass, body axes, unit density (kg m^2 per
        kg/m^3); None when the mesh is not a closed outward solid (an open or inconsistently wound
        user mesh)."""
        if not self.closed:  # through holes the signed tetrahedra sum to a number, not the body's
            return None
        try:
            I = mesh_inertia(self.vertices, self.faces)[2]
        except SimError:
            return None
        return I if np.all(np.linalg.eigvalsh(I) > 0) else None


def mesh_inertia(v: np.ndarray, f: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    """Volume (m^3), centre of mass (3,) and inertia tensor (3, 3) about the centre of mass of a
    closed outward-oriented mesh at uniform unit density: a sum over signed tetrahedra
    (origin, a, b, c) with the exact second moments of a tetrahedron."""
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    vol = np.einsum("ij,ij->i", a, np.cross(b, c)) / 6.0
    V = float(vol.sum())
    if not V > 0:
        raise SimError(f"mesh encloses no positive volume ({V}); it must be closed and outward-oriented")
    com = (vol[:, None] * (a + b + c)).sum(0) / 4.0 / V
    # second moments  S_jk = sum vol/20 (sum_i x_ij x_ik + (sum_i x_ij)(sum_i x_ik)), vertices o, a, b, c
    s = a + b + c
    S = (np.einsum("n,nj,nk->jk", vol, a, a) + np.einsum("n,nj,nk->jk", vol, b, b)
         + np.einsum("n,nj,nk->jk", vol, c, c) + np.einsum("n,nj,nk->jk", vol, s, s)) / 20.0
    S -= V * np.outer(com, com)  # about the centre of mass
    return V, com, np.trace(S) * np.eye(3) - S


def vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (V, 3) float32 of an outward-oriented mesh."""
    tri = v[f]
    fn = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    vn = np.zeros_like(v)
    for k in range(3):
        np.add.at(vn, f[:, k], fn)
    n = np.linalg.norm(vn, axis=1, keepdims=True)
    return (vn / np.where(n > 0, n, 1.0)).astype(np.float32)


def _icosphere(subdivisions: int) -> tuple[np.ndarray, np.ndarray]:
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=int(subdivisions), radius=1.0)
    v = np.asarray(m.vertices, dtype=np.float64)
    v /= np.linalg.norm(v, axis=1, keepdims=True)
    return v, np.asarray(m.faces, dtype=np.int32)


def _sphere_noise(rng: np.random.Generator, d: np.ndarray, n: int, beta: float, freq: float) -> np.ndarray:
    """Smooth noise on the unit sphere: a periodic 3D grid sampled at scaled directions."""
    g = fft_noise(rng, (n, n, n), beta=beta)
    return trilinear(g, (d * freq + 2.0 * freq) % n * 1.0, wrap=True).astype(np.float64)


def _ellipsoid_far(d: np.ndarray, c: np.ndarray, r: np.ndarray) -> np.ndarray:
    """Distance along unit rays d from the origin (inside the ellipsoid) to its surface."""
    dp = d / r
    cp = c / r
    a = (dp * dp).sum(1)
    b = dp @ cp
    cc = cp @ cp - 1.0
    return (b + np.sqrt(np.maximum(b * b - a * cc, 0.0))) / a


def _rand_unit(rng: np.random.Generator, n: int) -> np.ndarray:
    u = rng.standard_normal((n, 3))
    return u / np.linalg.norm(u, axis=1, keepdims=True)


def _craters(rng, d, radius, n, rmin, rmax, depth):
    """Bowl craters with raised rims; radius in radians, power-law sizes."""
    if n <= 0:
        return radius
    c = _rand_unit(rng, n)
    # power law N(>r) ~ r^-2 between rmin and rmax
    u = rng.random(n)
    rho = rmin * (1 - u * (1 - (rmin / rmax) ** 2)) ** -0.5
    dep = depth * rho * rng.uniform(0.6, 1.2, n)
    out = radius.copy()
    for j in range(n):
        cosang = np.clip(d @ c[j], -1.0, 1.0)
        near = cosang > np.cos(min(np.pi, 1.6 * rho[j]))
        if not near.any():
            continue
        x = np.arccos(cosang[near]) / rho[j]
        prof = np.where(x < 1.0, -(1.0 - x * x), 0.0) + 0.3 * np.exp(-((x - 1.0) / 0.22) ** 2)
        out[near] += dep[j] * prof * radius[near]
    return out


def _boulders(rng, d, radius, n, size):
    if n <= 0:
        return radius
    c = _rand_unit(rng, n)
    w = size * rng.uniform(0.5, 1.5, n)
    h = w * rng.uniform(0.3, 0.8, n)
    out = radius.copy()
    for j in range(n):
        cosang = d @ c[j]
        near = cosang > np.cos(3.0 * w[j])
        if not near.any():
            continue
        a = np.arccos(np.clip(cosang[near], -1, 1))
        out[near] += h[j] * np.exp(-0.5 * (a / w[j]) ** 2) * radius[near]
    return out


def _radial(family: int, rng: np.random.Generator, d: np.ndarray) -> tuple[np.ndarray, dict]:
    p: dict = {}
    if family == 0:  # contact binary
        big = np.array([rng.uniform(0.9, 1.1), rng.uniform(0.55, 0.7), rng.uniform(0.5, 0.65)])
        ratio = rng.uniform(0.55, 0.8)
        small = big * ratio * rng.uniform(0.9, 1.1, 3)
        c1 = np.array([-0.75 * big[0], 0.0, 0.0])
        c2 = np.array([0.7 * small[0], rng.uniform(-0.08, 0.08), rng.uniform(-0.08, 0.08)])
        r1 = _ellipsoid_far(d, c1, big)
        r2 = _ellipsoid_far(d, c2, small)
        k = 8.0
        r = (r1 ** k + r2 ** k) ** (1.0 / k)
        r *= 1.0 + 0.06 * _sphere_noise(rng, d, 32, 3.5, 3.0) + 0.02 * _sphere_noise(rng, d, 64, 2.0, 10.0)
        p.update(lobe_big=big.tolist(), lobe_small=small.tolist())
        n_crat, n_bould = int(rng.integers(6, 20)), int(rng.integers(30, 90))
    elif family == 1:  # spinning top
        a, c = 1.0, rng.uniform(0.75, 0.95)
        sinlat = d[:, 2]
        coslat = np.sqrt(np.maximum(1 - sinlat ** 2, 0))
        r_cone = 1.0 / (coslat / a + np.abs(sinlat) / c)
        r_sph = np.full_like(r_cone, 0.85)
        mix = rng.uniform(0.25, 0.5)
        ridge = rng.uniform(0.03, 0.07) * np.exp(-(np.arcsin(np.clip(sinlat, -1, 1)) / 0.15) ** 2)
        r = mix * r_cone + (1 - mix) * r_sph + ridge
        r *= 1.0 + 0.04 * _sphere_noise(rng, d, 32, 3.5, 3.0) + 0.015 * _sphere_noise(rng, d, 64, 2.0, 10.0)
        p.update(cone_height=c, cone_mix=mix)
        n_crat, n_bould = int(rng.integers(5, 15)), int(rng.integers(60, 160))
    elif family == 2:  # irregular, Eros-like
        base = np.array([1.0, rng.uniform(0.42, 0.6), rng.uniform(0.38, 0.5)])
        r = _ellipsoid_far(d, np.zeros(3), base)
        r *= 1.0 + 0.14 * _sphere_noise(rng, d, 32, 4.0, 2.0) + 0.03 * _sphere_noise(rng, d, 64, 2.0, 10.0)
        # the saddle (a Himeros-like depression) on one long side
        sd = np.array([0.0, rng.choice([-1.0, 1.0]), rng.uniform(-0.3, 0.3)])
        sd /= np.linalg.norm(sd)
        ang = np.arccos(np.clip(d @ sd, -1, 1))
        r *= 1.0 - rng.uniform(0.08, 0.16) * np.exp(-(ang / 0.55) ** 2)
        p.update(axes=base.tolist())
        n_crat, n_bould = int(rng.integers(25, 60)), int(rng.integers(20, 60))
    else:
        raise SimError(f"unknown shape family {family} (families: 0..{len(FAMILIES) - 1})")
    r = _craters(rng, d, r, n_crat, 0.05, 0.5, 0.35)
    r = _boulders(rng, d, r, n_bould, 0.025)
    p.update(craters=n_crat, boulders=n_bould)
    return r, p


def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.standard_normal((n, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return quat_to_matrix(q)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def _hull_points(vertices: np.ndarray) -> np.ndarray:
    """The convex hull's vertices: they alone decide every rotated box (10-50x fewer points)."""
    if len(vertices) < 64:
        return vertices
    try:
        from scipy.spatial import ConvexHull
        return vertices[ConvexHull(vertices).vertices]
    except Exception:  # qhull refuses flat or degenerate point sets: use them all
        return vertices


def mean_box_volume(vertices: np.ndarray, seed: int = 0, n: int = 48) -> float:
    """Geometric mean over random rotations of the axis-aligned box volume (m^3)."""
    R = _random_rotations(np.random.default_rng(seed), n)
    v = np.einsum("rij,vj->rvi", R, _hull_points(vertices))
    ext = v.max(1) - v.min(1)
    return float(np.exp(np.mean(np.log(np.prod(ext, axis=1)))))


def scale_to_volume(vertices: np.ndarray, volume: float) -> np.ndarray:
    return vertices * (volume / mean_box_volume(vertices)) ** (1.0 / 3.0)


def procedural_shape(family: int, rng: np.random.Generator, volume: float, subdivisions: int = 6) -> Shape:
    """A procedural asteroid of the given family whose rotated box volume is ~`volume` m^3."""
    d, faces = _icosphere(subdivisions)
    r, params = _radial(int(family), rng, d)
    v = d * r[:, None]
    stretch = np.exp(rng.normal(0.0, 0.12, 3))
    v = v * stretch
    if family == 2:  # banana bend about the short axis
        k = rng.uniform(0.1, 0.25) * rng.choice([-1.0, 1.0])
        v[:, 2] += k * (v[:, 0] ** 2 - (v[:, 0] ** 2).mean())
        params["bend"] = float(k)
    v -= (v.max(0) + v.min(0)) / 2.0  # body origin at the box centre
    v = scale_to_volume(v, volume)
    params.update(stretch=stretch.tolist(), target_volume_m3=float(volume), subdivisions=int(subdivisions))
    return Shape(v, faces, FAMILIES[int(family)], params)


def _mesh_formats() -> set[str]:
    import trimesh
    return {f.lower() for f in trimesh.available_formats()}


def load_user_mesh(path: str | Path, size_m: float) -> Shape:
    """Load a user mesh (any format trimesh reads: OBJ, PLY, STL, GLB ...), centre it at its box
    centre and scale it so its largest extent is `size_m` metres. Raises SimError naming the
    problem (and the file as `path` names it) for a missing file, a folder, an extension trimesh
    does not read, a file that is not a mesh, a non-finite vertex, or a degenerate mesh.

    A closed mesh wound inside out (negative signed volume, common in published models) has its
    faces flipped (params winding_flipped); `user_mesh_warnings` says so and flags open meshes."""
    import trimesh
    path = Path(path)
    if path.is_dir():
        raise SimError(f"user mesh {path} is a folder, not a mesh file (--mesh-dir {path} uses every mesh file "
                       f"in a folder)")
    if not path.is_file():
        raise SimError(f"user mesh {path} does not exist")
    if not (np.isfinite(size_m) and size_m > 0):
        raise SimError(f"user mesh size must be a positive number of metres, got {size_m}")
    formats = _mesh_formats()
    suffix = path.suffix.lower().lstrip(".")
    if suffix not in formats:
        # trimesh picks its reader by the extension; its own message names the absolute path
        what = f"extension .{suffix} is not a mesh format trimesh reads" if suffix else "has no file extension"
        raise SimError(f"user mesh {path} {what} (the reader is chosen by it: "
                       f"{', '.join(sorted(formats & {'obj', 'ply', 'stl', 'glb', 'gltf', 'off'}))}, ...)")
    try:
        # unprocessed first: trimesh's processing drops a NaN / inf vertex with its faces, which
        # would punch a hole in the body without a word
        raw = trimesh.load(str(path), force="mesh", process=False)
        m = trimesh.load(str(path), force="mesh", process=True)
    except Exception as e:  # trimesh raises many types for unreadable input
        msg = str(e).replace(str(path.resolve()), str(path))
        raise SimError(f"user mesh {path} could not be read as a mesh: {type(e).__name__}: {msg}") from None
    if not isinstance(m, trimesh.Trimesh) or len(getattr(m, "faces", [])) == 0:
        raise SimError(f"user mesh {path} is not a triangle mesh (no faces found)")
    bad = int(np.count_nonzero(~np.all(np.isfinite(np.asarray(getattr(raw, "vertices", np.zeros((0, 3))),
                                                              dtype=np.float64)), axis=1)))
    v = np.asarray(m.vertices, dtype=np.float64)
    f = np.asarray(m.faces, dtype=np.int32)
    if bad or not np.all(np.isfinite(v)):
        what = "1 vertex with a non-finite coordinate" if bad == 1 else \
            f"{bad or 'some'} vertices with non-finite coordinates"
        raise SimError(f"user mesh {path} has {what} (NaN or inf): the file is damaged; repair or re-export it")
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    ext = v.max(0) - v.min(0)
    if len(f) < 4 or np.count_nonzero(area > 1e-12 * max(ext.max(), 1e-30) ** 2) < 4 \
            or np.any(ext <= 1e-9 * max(ext.max(), 1e-30)):
        raise SimError(f"user mesh {path} is degenerate (flat or without area: extents {ext.tolist()}, "
                       f"{len(f)} faces)")
    watertight = bool(m.is_watertight)
    closed = watertight and bool(m.is_winding_consistent)
    params = {"source": str(path), "size_m": float(size_m), "watertight": watertight}
    if watertight and not closed:
        params["winding_consistent"] = False
    if closed and float(m.volume) < 0:
        # wound inward: seen from outside every face is a back face (never lit, no depth sensor
        # return, a negative volume for the inertia); reversing each face's vertex order turns it out
        f = np.ascontiguousarray(f[:, ::-1])
        params["winding_flipped"] = True
    if not watertight:  # edges used by one face only: the rims of the holes
        params["open_edges"] = int(np.count_nonzero(np.unique(m.edges_sorted, axis=0, return_counts=True)[1] == 1))
    v = v - (v.max(0) + v.min(0)) / 2.0
    v = v * (size_m / ext.max())
    return Shape(v, f, "user", params, closed=closed)


def user_mesh_warnings(shape: Shape, name: str) -> list[str]:
    """One-line warnings (without the "warning: " prefix) about a loaded user mesh `name`."""
    p = shape.params
    out = []
    if p.get("winding_flipped"):
        out.append(f"user mesh {name} is wound inside out (its faces face inward: negative volume); its faces "
                   f"were flipped (meta.json shape.winding_flipped)")
    if not p.get("watertight", True):
        out.append(f"user mesh {name} is not closed ({p.get('open_edges', 0)} open edges: holes, or a damaged or "
                   f"truncated file): it spins with a random inertia tensor, not its own, and rays through a hole "
                   f"see the inside (depth and images show the far wall there)")
    elif p.get("winding_consistent") is False:
        out.append(f"user mesh {name} is closed but not consistently wound: faces wound inward are never lit and "
                   f"give depth sensors no return, and it spins with a random inertia tensor")
    return out
