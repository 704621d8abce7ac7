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

import re
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


# What load_user_mesh makes of a file, as a number. A run records it beside each user mesh's hash
# (generate._public_meshes): a loader that renders the same file differently must not resume a run
# an older one started. 2: texture / normal seams merged, degenerate faces dropped, winding made
# consistent, open meshes wound inward flipped, OBJ negative indices counted in file order, and
# SIZE measured along the body's own axes (it had been the file's axes).
USER_MESH_LOADER = 2


def _mesh_formats() -> set[str]:
    import trimesh
    return {f.lower() for f in trimesh.available_formats()}


# Extensions of text formats: binary content under one is another format, not a damaged file
_TEXT_FORMATS = {"obj", "off", "gltf", "xyz", "stl_ascii"}


def _sniff_format(path: Path) -> str | None:
    """The format the start of a file looks like ("obj", "ply", "stl", ..., "binary" for bytes
    of none of these), or None: trimesh chooses its reader by the extension alone, and a
    file under another format's extension reads as "no faces found"."""
    try:
        size = path.stat().st_size
        with open(path, "rb") as fh:
            head = fh.read(4096)
    except OSError:
        return None
    text = head.lstrip()
    if head.startswith(b"ply"):
        return "ply"
    if head.startswith(b"glTF"):
        return "glb"
    if len(head) >= 84 and 84 + 50 * int.from_bytes(head[80:84], "little") == size:
        return "stl"  # binary STL: an 80-byte header, a triangle count, 50 bytes a triangle
    if text.startswith(b"solid") and b"facet" in head:
        return "stl"
    if text.startswith(b"OFF"):
        return "off"
    if text.startswith(b"{") and b'"asset"' in head:
        return "gltf"
    if b"\0" in head:
        return "binary"
    if re.search(rb"(?m)^[ \t]*v[ \t]+[-+.\d]", head):
        return "obj"
    return None


def _format_hint(path: Path, suffix: str) -> str:
    """'; <why>' when the file's content is not what its extension says, else ''."""
    found = _sniff_format(path)
    if found is None or found == suffix or (found == "stl" and suffix == "stl_ascii"):
        return ""
    if found == "binary":
        if suffix not in _TEXT_FORMATS:  # a truncated binary file of the right format: not a mix-up
            return ""
        what = "binary data"
    else:
        what = f"what looks like {found.upper()}"
    return (f"; it holds {what}, but the reader is chosen by the extension (.{suffix}): is the file "
            f"another format? (rename it)")


# A face line with a negative (relative) index
_OBJ_RELATIVE = re.compile(rb"(?m)^[ \t]*f[ \t][^\n]*-\d")


def _obj_absolute(data: bytes, path: Path) -> bytes | None:
    """OBJ text with its negative face indices made absolute, or None when it has none.

    OBJ counts index -1 as the last v (vt, vn) line read BEFORE the face line; trimesh counts it
    from the end of the file. The two agree only when every vertex precedes every face: a file
    writing each triangle as three v lines and `f -3 -2 -1` had loaded as copies of its last
    triangle."""
    if not _OBJ_RELATIVE.search(data):
        return None
    seen = {"v": 0, "vt": 0, "vn": 0}
    lines = data.decode("latin-1").split("\n")  # latin-1: every byte comes back as it was
    for k, line in enumerate(lines):
        words = line.split()
        if not words:
            continue
        if words[0] in seen:
            seen[words[0]] += 1
        elif words[0] == "f" and "-" in line:
            for w, word in enumerate(words[1:], 1):
                parts = word.split("/")
                for j, kind in enumerate(("v", "vt", "vn")[:len(parts)]):
                    if not parts[j].startswith("-"):
                        continue
                    try:
                        rel = int(parts[j])
                    except ValueError:  # not an index: trimesh's reader says what it makes of it
                        continue
                    if seen[kind] + rel < 0:
                        raise SimError(f"user mesh {path} line {k + 1}: face index {rel} points before the "
                                       f"first {kind} line (only {seen[kind]} read so far): the file is damaged")
                    parts[j] = str(seen[kind] + rel + 1)
                words[w] = "/".join(parts)
            lines[k] = " ".join(words)
    return "\n".join(lines).encode("latin-1")


def _edge_uses(f: np.ndarray) -> np.ndarray:
    """How many faces use each distinct edge of faces `f` (order of the edges unspecified)."""
    e = np.sort(f[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1).astype(np.int64)
    key = e[:, 0] * (int(f.max()) + 1) + e[:, 1] if len(e) else e[:, 0]
    return np.unique(key, return_counts=True)[1]


def _bad_edges(f: np.ndarray) -> int:
    """Edges not used by exactly two faces (open or non-manifold)."""
    return int(np.count_nonzero(_edge_uses(f) != 2)) if len(f) else 0


def _face_links(f: np.ndarray):
    """The faces of `f` (F, 3) int64 that share an edge used by exactly two faces: (fi, fj, same),
    `same` 1 where both run along it in the same direction (one of the two is wound the other
    way). Edges of more than two faces (non-manifold) link nothing."""
    n = len(f)
    a = f[:, [0, 1, 2]].reshape(-1)
    b = f[:, [1, 2, 0]].reshape(-1)
    face = np.repeat(np.arange(n, dtype=np.int64), 3)
    key = np.minimum(a, b) * (int(f.max()) + 1) + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    k = key[order]
    starts = np.flatnonzero(np.r_[True, k[1:] != k[:-1]])
    counts = np.diff(np.r_[starts, len(k)])
    pairs = starts[counts == 2]
    i, j = order[pairs], order[pairs + 1]
    return face[i], face[j], (a[i] == a[j]).astype(np.int8)


def face_parts(f: np.ndarray) -> np.ndarray:
    """(F,) int labels of the connected parts of faces `f` (faces linked by an edge of two faces)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    f = np.asarray(f, dtype=np.int64)
    if len(f) == 0:
        return np.zeros(0, dtype=np.int64)
    fi, fj, _ = _face_links(f)
    g = coo_matrix((np.ones(len(fi)), (fi, fj)), shape=(len(f), len(f)))
    return connected_components(g, directed=False)[1].astype(np.int64)


def outward_parts(v: np.ndarray, f: np.ndarray) -> tuple[np.ndarray, int]:
    """Faces `f` with every closed part of negative signed volume reversed, and how many parts
    were: each part of a body (a contact binary written as two shells) faces out on its own; one
    flip by the whole mesh's volume had left a small part inside out beside a large one."""
    f = np.asarray(f, dtype=np.int64)
    labels = face_parts(f)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    vol = np.bincount(labels, weights=np.einsum("ij,ij->i", a, np.cross(b, c)))
    inward = vol < 0
    out = f.copy()
    flip = inward[labels]
    out[flip] = out[flip][:, ::-1]
    return out, int(np.count_nonzero(inward))


def consistent_winding(f: np.ndarray) -> np.ndarray:
    """Faces `f` (F, 3) with each connected part wound one way: a face sharing an edge with a
    face is flipped when both run along that edge in the same direction. Which way a part ends up
    is its first face's (`outward_parts` then turns each closed part out).

    Linear in the faces: one breadth-first walk (scipy) from a node joined to the first face of
    every part; trimesh.repair.fix_winding took ~90 us a face, minutes on a 2-million-face shape
    model, and a walk started once per part had been quadratic in the parts (a rubble pile of
    boulders). Edges of more than two faces (non-manifold) do not link their faces."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import breadth_first_order

    f = np.asarray(f, dtype=np.int64)
    n = len(f)
    if n == 0:
        return f.copy()
    fi, fj, same = _face_links(f)
    firsts = np.unique(face_parts(f), return_index=True)[1].astype(np.int64)
    root = n   # the extra node: its links say nothing (relation 0)
    src = np.r_[fi, fj, np.full(len(firsts), root)]
    dst = np.r_[fj, fi, firsts]
    rel = np.r_[same, same, np.zeros(len(firsts), dtype=np.int8)]
    g = coo_matrix((np.ones(len(src)), (src, dst)), shape=(n + 1, n + 1)).tocsr()
    rel_key = src * (n + 1) + dst
    by = np.argsort(rel_key)
    rel_key, rel = rel_key[by], rel[by]
    seq, pred = breadth_first_order(g, root, directed=False, return_predecessors=True)
    kids = seq[1:].astype(np.int64)
    parents = pred[kids].astype(np.int64)   # scipy's int32: parent * n overflowed past 46,000 faces
    step = rel[np.searchsorted(rel_key, parents * (n + 1) + kids)]
    parity = np.zeros(n + 1, dtype=np.int8)
    for node, parent, r in zip(kids.tolist(), parents.tolist(), step.tolist()):   # parents come first
        parity[node] = parity[parent] ^ r
    out = f.copy()
    turn = parity[:n] == 1
    out[turn] = out[turn][:, ::-1]
    return out


# A box in the file's axes whose longest side is within this factor of the least box's is the
# body's own box
BODY_FRAME_TOLERANCE = 1.02


def body_extents(vertices: np.ndarray) -> np.ndarray:
    """The extents (3,) of a body along its own axes, largest last: the sides of its minimum-volume
    oriented bounding box (trimesh.bounds.oriented_bounds), or of its box in the file's axes when
    that one's longest side is within BODY_FRAME_TOLERANCE of the least box's. What a scientist
    calls the body's length does not depend on how the file happens to be rotated: the largest side
    of the box in the file's axes had made a 20:1 rod written diagonally 1.7x too long.

    trimesh's search costs (hull points) x (directions): on a large hull the box's axes are found
    from a strided subset of the points and the extents measured along them from all of them."""
    import trimesh
    v = np.asarray(vertices, dtype=np.float64)
    sub = v[::-(-len(v) // 20000)] if len(v) > 20000 else v
    hull = _hull_points(sub)
    try:
        to_origin, _ = trimesh.bounds.oriented_bounds(hull[::-(-len(hull) // 2000)] if len(hull) > 2000 else hull)
        R = np.asarray(to_origin, dtype=np.float64)[:3, :3]
    except Exception:  # a point set qhull and the flat fallback both refuse: the file's axes
        R = np.eye(3)
    p = v @ R.T
    ext = np.sort(p.max(0) - p.min(0))
    aabb = np.sort(v.max(0) - v.min(0))
    # On a faceted model the least box leans onto the facets and its sides come out short (1.1% on
    # a 320-face sphere, 0.2% on a 1280-face ellipsoid written along its axes), and trimesh searches
    # a coarse grid of directions: a box in the file's axes about as long is a model written in its
    # own frame, measured in it
    return aabb if abs(aabb[2] - ext[2]) <= (BODY_FRAME_TOLERANCE - 1.0) * ext[2] else ext


# The last few meshes loaded, by path, size and the file's stat: a run loads each mesh once to
# check it and once per sequence, and a 2-million-face shape model takes seconds a load
_LOADED: dict = {}
_LOADED_MAX = 2


def load_user_mesh(path: str | Path, size_m: float) -> Shape:
    """`_load_user_mesh`'s Shape (a copy: callers rescale and annotate theirs), from a small cache
    of the last files loaded in this process (keyed by the file's size and modification time,
    so an edited file is read again)."""
    p = Path(path)
    try:
        st = p.stat()
        # the inode and change time too: a file replaced by one of the same size with its time
        # kept (cp -p, rsync -t, tar) must not bring back the old body
        key = (str(p.resolve()), float(size_m), st.st_size, st.st_mtime_ns, st.st_ino, st.st_ctime_ns) \
            if p.is_file() else None
    except OSError:
        key = None
    shape = _LOADED.get(key) if key is not None else None
    if shape is None:
        shape = _load_user_mesh(path, size_m)   # errors name the file as `path` gives it
        if key is not None:
            if len(_LOADED) >= _LOADED_MAX:
                _LOADED.pop(next(iter(_LOADED)))
            _LOADED[key] = shape
    return Shape(shape.vertices.copy(), shape.faces.copy(), shape.family, dict(shape.params), closed=shape.closed)


def _load_user_mesh(path: str | Path, size_m: float) -> Shape:
    """Load a user mesh (any format trimesh reads: OBJ, PLY, STL, GLB ...), centre it at its box
    centre and scale it so its length along its longest own axis (`body_extents`) is `size_m`
    metres. Raises SimError naming the problem (and the file as `path` names it) for a missing or
    empty file, a folder, an extension trimesh does not read, a file that is not a mesh (with a
    hint when its content is another format), a non-finite vertex, or a degenerate mesh.

    Repairs what exporters commonly write, recorded in the params (meta.json) and, when the
    surface changes, in `user_mesh_warnings`: vertices split at texture or normal seams are
    merged (vertices_merged), faces repeating a vertex and zero-area faces are dropped
    (degenerate_faces_dropped), a closed mesh wound inconsistently is made consistent
    (winding_repaired), and a closed mesh wound inside out (negative signed volume) or an open
    one facing mostly inward has its faces flipped (winding_flipped)."""
    import io

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
    if path.stat().st_size == 0:
        raise SimError(f"user mesh {path} is empty (0 bytes)")
    text = _obj_absolute(path.read_bytes(), path) if suffix == "obj" else None

    def load(process: bool):
        if text is not None:  # the rewritten text, read as the file would be
            return trimesh.load(io.BytesIO(text), file_type="obj", force="mesh", process=process)
        return trimesh.load(str(path), force="mesh", process=process)

    try:
        # unprocessed first: trimesh's processing drops a NaN / inf vertex with its faces, which
        # would punch a hole in the body without a word
        raw = load(False)
        m = load(True)
    except Exception as e:  # trimesh raises many types for unreadable input
        msg = str(e).replace(str(path.resolve()), str(path))
        raise SimError(f"user mesh {path} could not be read as a mesh: {type(e).__name__}: {msg}"
                       f"{_format_hint(path, suffix)}") from None
    if not isinstance(m, trimesh.Trimesh) or len(getattr(m, "faces", [])) == 0:
        raise SimError(f"user mesh {path} is not a triangle mesh (no faces found){_format_hint(path, suffix)}")
    bad = int(np.count_nonzero(~np.all(np.isfinite(np.asarray(getattr(raw, "vertices", np.zeros((0, 3))),
                                                              dtype=np.float64)), axis=1)))
    if bad or not np.all(np.isfinite(np.asarray(m.vertices, dtype=np.float64))):
        what = "1 vertex with a non-finite coordinate" if bad == 1 else \
            f"{bad or 'some'} vertices with non-finite coordinates"
        raise SimError(f"user mesh {path} has {what} (NaN or inf): the file is damaged; repair or re-export it")

    # Readers split a vertex wherever its texture coordinate or normal changes (a UV seam, flat
    # per-face normals): the surface is then open along every seam, its winding cannot be checked
    # across them, and an inside-out file was left unflipped (black in every frame). The body's
    # shape is the positions alone.
    n_read = len(m.vertices)
    m.merge_vertices(merge_tex=True, merge_norm=True)
    params: dict = {}
    if len(m.vertices) < n_read:
        params["vertices_merged"] = int(n_read - len(m.vertices))
    v = np.asarray(m.vertices, dtype=np.float64)
    f = np.asarray(m.faces, dtype=np.int64)
    ext = v.max(0) - v.min(0)
    area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    # A face repeating a vertex (a, a, b) has no area but uses its edge twice more: the surface
    # reads as not closed. A zero-area face on distinct vertices goes too unless the surface needs
    # it (a T-junction's sliver closes the surface; dropping it would open it). Zero as a text
    # file writes it: a height below 1e-5 of the body's size (6 decimals on a body of size 1 put
    # a collinear point up to 1e-6 off its line)
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 2] != f[:, 0])
    longest = np.max(np.linalg.norm(v[f] - v[np.roll(f, 1, axis=1)], axis=2), axis=1)
    zero = area <= 1e-5 * max(ext.max(), 1e-30) * longest
    if np.any(keep & zero) and np.any(keep & ~zero) and _bad_edges(f[keep & ~zero]) <= _bad_edges(f[keep]):
        keep &= ~zero
    if not keep.all() and keep.any():
        params["degenerate_faces_dropped"] = int(np.count_nonzero(~keep))
        m.update_faces(keep)
        m.remove_unreferenced_vertices()
        v = np.asarray(m.vertices, dtype=np.float64)
        f = np.asarray(m.faces, dtype=np.int64)
        ext = v.max(0) - v.min(0)
        area = np.linalg.norm(np.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]]), axis=1)
    if len(f) < 4 or np.count_nonzero(area > 1e-12 * max(ext.max(), 1e-30) ** 2) < 4 \
            or np.any(ext <= 1e-9 * max(ext.max(), 1e-30)):
        raise SimError(f"user mesh {path} is degenerate (flat or without area: extents {ext.tolist()}, "
                       f"{len(f)} faces)")
    body = body_extents(v)
    if body[0] <= 1e-9 * body[2]:  # flat, but not in the file's axes
        raise SimError(f"user mesh {path} is degenerate (flat: extents along its own axes {body.tolist()}, "
                       f"{len(f)} faces)")

    watertight = bool(m.is_watertight)
    params = {"source": str(path), "size_m": float(size_m), "watertight": watertight, **params}
    if watertight and not m.is_winding_consistent:
        # a closed surface is orientable: neighbours are flipped to agree with one face (then the
        # volume's sign below says whether that face pointed out)
        m.faces = consistent_winding(np.asarray(m.faces, dtype=np.int64))
        f = np.asarray(m.faces, dtype=np.int64)
        if m.is_winding_consistent:
            params["winding_repaired"] = True
    closed = watertight and bool(m.is_winding_consistent)
    if watertight and not closed:
        params["winding_consistent"] = False
    if closed:
        # a part wound inward: seen from outside every face is a back face (never lit, no depth
        # sensor return, a negative volume for the inertia); reversing its faces turns it out
        f, turned = outward_parts(v, f)
        if turned and not params.get("winding_repaired"):  # a repair's first face decided its side: not the file's
            params["winding_flipped"] = True
            if turned < len(np.unique(face_parts(f))):
                params["parts_flipped"] = turned
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    normal = np.cross(b - a, c - a)
    if not watertight:
        uses = _edge_uses(f)
        params["open_edges"] = int(np.count_nonzero(uses == 1))  # the rims of the holes
        if np.any(uses > 2):  # an edge of three or more faces: a fin, parts touching along an edge
            params["nonmanifold_edges"] = int(np.count_nonzero(uses > 2))
        # an open surface has no volume to tell in from out: the faces' share of area facing the
        # box centre does (a hole does not turn a body inside out)
        centre = (v.max(0) + v.min(0)) / 2.0
        towards = np.einsum("ij,ij->i", normal, (a + b + c) / 3.0 - centre) < 0
        share = float(area[towards].sum() / max(area.sum(), 1e-300))
        if share > 0.5:
            f = f[:, ::-1]
            params["winding_flipped"] = True
            params["inward_area_share"] = round(share, 3)
    v = v - (v.max(0) + v.min(0)) / 2.0
    v = v * (size_m / body[2])
    return Shape(v, np.ascontiguousarray(f, dtype=np.int32), "user", params, closed=closed)


def user_mesh_warnings(shape: Shape, name: str) -> list[str]:
    """One-line warnings (without the "warning: " prefix) about a loaded user mesh `name`."""
    p = shape.params
    out = []
    if p.get("winding_repaired"):
        out.append(f"user mesh {name} was not consistently wound (some of its faces faced inward); its faces "
                   f"were turned to face outward (meta.json shape.winding_repaired)")
    if p.get("winding_flipped") and p.get("watertight", True) and p.get("parts_flipped"):
        out.append(f"user mesh {name} has {p['parts_flipped']} part(s) wound inside out (faces facing inward: "
                   f"negative volume); their faces were flipped (meta.json shape.winding_flipped)")
    elif p.get("winding_flipped") and p.get("watertight", True):
        out.append(f"user mesh {name} is wound inside out (its faces face inward: negative volume); its faces "
                   f"were flipped (meta.json shape.winding_flipped)")
    elif p.get("winding_flipped"):
        out.append(f"user mesh {name} is open and wound mostly inside out ({p.get('inward_area_share', 1):.0%} of "
                   f"its area faces its centre); its faces were flipped (meta.json shape.winding_flipped)")
    if not p.get("watertight", True):
        holes, nm = p.get("open_edges", 0), p.get("nonmanifold_edges", 0)
        # a surface without holes can still fail the closed test: an edge of three faces or more
        what = []
        if holes or not nm:
            what.append(f"is not closed ({holes} open edges: holes, or a damaged or truncated file)")
        if nm:
            what.append(f"has non-manifold edges ({nm} edge{'s' if nm != 1 else ''} shared by more than two "
                        f"faces: a fin, or parts touching along an edge)")
        see = ", and rays through a hole see the inside (depth and images show the far wall there)" if holes else ""
        out.append(f"user mesh {name} {' and '.join(what)}: it spins with a random inertia tensor, not its "
                   f"own{see}")
    elif p.get("winding_consistent") is False:
        out.append(f"user mesh {name} is closed but not consistently wound: faces wound inward are never lit and "
                   f"give depth sensors no return, and it spins with a random inertia tensor")
    return out
