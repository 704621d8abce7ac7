"""Implicit asteroid generators (not star-shaped): contact binaries with a real neck,
elongated / bent / dog-bone bodies, top-shapes, rubble piles, giant-crater bodies and
angular fragments. Each `make_*(rng, volume_m3, detail) -> Shape` draws continuous
parameters (recorded in `Shape.params`), builds a signed distance field at unit scale
(`implicit.SdfGrid`), adds noise, craters and perched boulders, meshes it by marching cubes
and scales it to the target mean rotated box volume. They are registered in generators.py.
"""
from __future__ import annotations

import math

import numpy as np

from .implicit import SdfGrid, _norm, grid_size, mesh_grid, rotation, sd_ellipsoid, sd_sphere, smax
from .shapes import Shape, scale_to_volume

__all__ = ["make_bilobate", "make_elongated", "make_top_shape", "make_rubble_pile", "make_giant_craters",
           "make_fragment", "make_superquadric", "sd_superellipsoid", "make_gaussian_sphere", "gaussian_log_radius",
           "make_aggregate"]

_MARGIN = 0.3  # unit-scale room around the base primitives for noise, rims and perched boulders


def _u(rng, lo, hi) -> float:
    return float(rng.uniform(lo, hi))


def _grid(lo, hi, detail: int) -> SdfGrid:
    return SdfGrid(np.asarray(lo, float) - _MARGIN, np.asarray(hi, float) + _MARGIN, grid_size(detail))


def _surface_detail(g: SdfGrid, rng, p: dict, noise_amp: float, n_crat: int, crat_max: float,
                    n_bould: int, bould_size: float, perch=(-0.2, 0.35)):
    """The common skin: three octaves of noise, power-law craters, perched boulders."""
    g.displace(rng, noise_amp, 0.7, beta=3.5)
    g.displace(rng, 0.4 * noise_amp, 2.2, beta=3.0)
    g.displace(rng, 0.15 * noise_amp, 7.0, beta=2.5)
    g.craters(rng, n_crat, 0.04, crat_max)
    g.boulders(rng, n_bould, bould_size, perch=perch)
    p.update(noise_amp=float(noise_amp), craters=int(n_crat), crater_max=float(crat_max), boulders=int(n_bould),
             boulder_size=float(bould_size))


def _finish(g: SdfGrid, rng, name: str, volume: float, detail: int, p: dict, post=None) -> Shape:
    v, f = mesh_grid(g)
    if post is not None:
        v = v * np.asarray(post, float)
    stretch = np.exp(rng.normal(0.0, 0.08, 3))
    v = v * stretch
    v -= (v.max(0) + v.min(0)) / 2.0  # body origin at the box centre
    v = scale_to_volume(v, volume)
    p.update(stretch=stretch.tolist(), target_volume_m3=float(volume), detail=int(detail),
             grid_voxels=int(grid_size(detail)))
    return Shape(v, f, name, p)


def make_bilobate(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """Contact binary (Itokawa, 67P): two ellipsoidal lobes joined by a concave neck."""
    big = np.array([1.0, _u(rng, 0.6, 0.85), _u(rng, 0.5, 0.75)])
    ratio = _u(rng, 0.4, 0.95)                     # small / big lobe linear size
    small = ratio * np.array([_u(rng, 0.8, 1.1), _u(rng, 0.6, 0.9), _u(rng, 0.55, 0.85)])
    overlap = _u(rng, 0.05, 0.3)                   # how far the lobes interpenetrate
    neck = _u(rng, 0.08, 0.35) * ratio             # smooth-union width: neck thickness
    bend = math.radians(_u(rng, 0.0, 50.0))        # small lobe off the big lobe's long axis
    phi = _u(rng, 0.0, 2 * math.pi)
    axis = np.array([math.cos(bend), math.sin(bend) * math.cos(phi), math.sin(bend) * math.sin(phi)])
    dist = (big[0] + small[0]) * (1.0 - overlap)
    c1, c2 = -axis * dist * ratio / (1 + ratio), axis * dist / (1 + ratio)
    # small lobe's long axis along the contact line, twisted about it
    R2 = _frame_along(axis, _u(rng, 0, 2 * math.pi), tilt=math.radians(_u(rng, -20, 20)))
    lo = np.minimum(c1 - big, c2 - small.max())
    hi = np.maximum(c1 + big, c2 + small.max())
    g = _grid(lo, hi, detail)
    g.union(lambda q: sd_ellipsoid(q, c1, big), c1 - big, c1 + big)
    g.union(lambda q: sd_ellipsoid(q, c2, small, R2), c2 - small.max(), c2 + small.max(), k=neck)
    p = dict(lobe_big=big.tolist(), lobe_small=small.tolist(), lobe_ratio=ratio, overlap=overlap, neck=neck,
             bend_deg=math.degrees(bend))
    _surface_detail(g, rng, p, _u(rng, 0.02, 0.05), int(rng.integers(10, 35)), 0.25,
                    int(rng.integers(20, 80)), _u(rng, 0.03, 0.05))
    return _finish(g, rng, "bilobate", volume, detail, p)


def _frame_along(axis, twist: float, tilt: float = 0.0) -> np.ndarray:
    """Rotation whose first column is `axis` (tilted by `tilt` rad), twisted by `twist` about it."""
    a = axis / np.linalg.norm(axis)
    t = np.array([0.0, 0.0, 1.0]) if abs(a[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    b = np.cross(a, t)
    b /= np.linalg.norm(b)
    c = np.cross(a, b)
    b, c = math.cos(twist) * b + math.sin(twist) * c, -math.sin(twist) * b + math.cos(twist) * c
    a2 = math.cos(tilt) * a + math.sin(tilt) * b
    b2 = -math.sin(tilt) * a + math.cos(tilt) * b
    return np.stack([a2, b2, c], 1)


def make_elongated(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """Elongated body along a bent centre line (Eros); a waist makes it a dog-bone (Kleopatra)."""
    width = _u(rng, 0.25, 0.45)       # end radius / half length
    waist = _u(rng, 0.0, 0.55)        # 0: banana / cigar, 0.55: strong dog-bone
    bend = _u(rng, 0.0, 0.22)         # centre-line sag / 2 half lengths (more looks like a heart)
    asym = _u(rng, -0.25, 0.25)       # one end bigger than the other
    flat = _u(rng, 0.6, 1.0)          # cross-section flattening (z)
    s = np.linspace(-1.0, 1.0, 25)
    L = 1.0 - width
    pts = np.stack([L * s, 2 * bend * L * (1 - s * s) - bend * L, np.zeros_like(s)], 1)
    rad = width * (1.0 - waist * (1 - s * s) ** 2) * (1.0 + asym * s)
    lo, hi = (pts - rad[:, None]).min(0), (pts + rad[:, None]).max(0)
    g = _grid(lo, hi, detail)
    k = 0.12
    for c, r in zip(pts, rad):
        g.union(lambda q, c=c, r=r: sd_sphere(q, c, r), c - r, c + r, k=k)
    p = dict(width=width, waist=waist, bend=bend, asymmetry=asym, flattening=flat)
    _surface_detail(g, rng, p, _u(rng, 0.02, 0.045), int(rng.integers(20, 50)), 0.25,
                    int(rng.integers(15, 50)), _u(rng, 0.025, 0.04))
    return _finish(g, rng, "elongated", volume, detail, p, post=(1.0, 1.0, flat))


def make_top_shape(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """Top-shape (Ryugu, Bennu): double cone blended with a sphere, equatorial ridge, boulders."""
    c = _u(rng, 0.7, 0.95)            # polar / equatorial half-height of the cone
    mix = _u(rng, 0.3, 0.7)           # cone (1) vs sphere (0)
    ridge = _u(rng, 0.0, 0.07)
    sharp = _u(rng, 0.05, 0.2)        # rounding of the equatorial edge
    g = _grid((-1, -1, -1), (1, 1, 1), detail)
    norm = c / math.hypot(1.0, c)

    def body(q):
        rho = np.hypot(q[..., 0], q[..., 1])
        z = q[..., 2]
        cone = (rho + np.sqrt(z * z + sharp * sharp) / c - 1.0) * norm  # ridge rounded over ~sharp
        sph = _norm(q) - 0.5 * (1 + c)
        return mix * cone + (1 - mix) * sph - ridge * np.exp(-(z / 0.12) ** 2) * np.clip(rho, 0, 1)

    g.union(body, (-1.2, -1.2, -1.2), (1.2, 1.2, 1.2))
    p = dict(cone_height=c, cone_mix=mix, ridge=ridge, ridge_rounding=sharp)
    _surface_detail(g, rng, p, _u(rng, 0.015, 0.035), int(rng.integers(5, 20)), 0.3,
                    int(rng.integers(50, 130)), _u(rng, 0.03, 0.05), perch=(-0.1, 0.4))
    return _finish(g, rng, "top_shape", volume, detail, p)


def make_rubble_pile(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """Near-spherical or oblate rubble pile (Didymos, Itokawa's surface): lumpy spheroid
    strewn with boulders of every size, a few craters."""
    axes = np.array([1.0, _u(rng, 0.85, 1.0), _u(rng, 0.65, 0.95)])
    bulge = _u(rng, 0.0, 0.06)
    g = _grid(-axes, axes, detail)
    g.union(lambda q: sd_ellipsoid(q, np.zeros(3), axes) - bulge * np.exp(-(q[..., 2] / 0.25) ** 2),
            -axes - 0.1, axes + 0.1)
    p = dict(axes=axes.tolist(), bulge=bulge)
    _surface_detail(g, rng, p, _u(rng, 0.03, 0.07), int(rng.integers(3, 12)), 0.25,
                    int(rng.integers(60, 180)), _u(rng, 0.035, 0.055), perch=(-0.1, 0.45))
    return _finish(g, rng, "rubble_pile", volume, detail, p)


def make_giant_craters(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """Body dominated by giant craters and concavities (Mathilde): lumpy ellipsoid with 2-5
    craters of radius comparable to the body, then small craters."""
    axes = np.array([1.0, _u(rng, 0.7, 0.9), _u(rng, 0.6, 0.8)])
    g = _grid(-axes - 0.1, axes + 0.1, detail)
    g.union(lambda q: sd_ellipsoid(q, np.zeros(3), axes), -axes - 0.1, axes + 0.1)
    # two to three knobs blended in: an angular, lumpy outline with saddles between them
    n_knobs = int(rng.integers(2, 4))
    for _ in range(n_knobs):
        d = rng.standard_normal(3)
        d /= np.linalg.norm(d)
        kr = axes * _u(rng, 0.45, 0.65)
        kc = d * axes * 0.7
        R = rotation(rng)
        g.union(lambda q, kc=kc, kr=kr, R=R: sd_ellipsoid(q, kc, kr, R), kc - kr.max(), kc + kr.max(), k=0.12)
    g.displace(rng, _u(rng, 0.04, 0.08), 0.6, beta=4.0)
    n_giant = int(rng.integers(2, 6))
    big = _u(rng, 0.4, 0.7)
    # shallow enough (depth <= 0.3 body radius) never to punch through the thinnest axis
    g.craters(rng, n_giant, 0.3, big, depth=(0.14, 0.22), rim=0.08)
    p = dict(axes=axes.tolist(), knobs=n_knobs, giant_craters=n_giant, giant_crater_max=big)
    _surface_detail(g, rng, p, 0.02, int(rng.integers(20, 45)), 0.2, int(rng.integers(10, 40)), 0.03)
    return _finish(g, rng, "giant_craters", volume, detail, p)


def make_fragment(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """Flat or angular fragment: a random convex polyhedron (bevelled half-spaces) of an
    elongated / flattened envelope, with conchoidal scoops, a few craters and blocks."""
    env = np.array([1.0, _u(rng, 0.5, 0.9), _u(rng, 0.25, 0.65)])
    n_planes = int(rng.integers(8, 17))
    bevel = _u(rng, 0.05, 0.2)
    nrm = rng.standard_normal((n_planes, 3))
    nrm /= np.linalg.norm(nrm, axis=1, keepdims=True)
    nrm = np.concatenate([nrm, np.eye(3), -np.eye(3)])  # the envelope's own faces keep it bounded
    off = np.sqrt(((env * nrm) ** 2).sum(1)) * np.concatenate([rng.uniform(0.7, 1.0, n_planes), np.ones(6)])
    g = _grid(-env, env, detail)

    def poly(q):
        f = q @ nrm[0] - off[0]
        for j in range(1, len(nrm)):
            f = smax(f, q @ nrm[j] - off[j], bevel)
        return f

    g.union(poly, -env - 0.05, env + 0.05)
    n_scoops = int(rng.integers(1, 4))
    g.craters(rng, n_scoops, 0.35, 0.8, depth=(0.06, 0.14), rim=0.0)
    p = dict(envelope=env.tolist(), planes=n_planes, bevel=bevel, scoops=n_scoops)
    _surface_detail(g, rng, p, _u(rng, 0.015, 0.035), int(rng.integers(4, 15)), 0.15,
                    int(rng.integers(5, 25)), _u(rng, 0.03, 0.05))
    return _finish(g, rng, "fragment", volume, detail, p)


def sd_superellipsoid(p, radii, e1: float, e2: float):
    """Superellipsoid about the origin, axis-aligned (semi-axes radii (3,), exponents e1 along z
    and e2 about it; 1 / 1 is the ellipsoid, towards 0 a box, 2 an octahedron): the
    inside-outside function raised to e1 / 2, which is homogeneous of degree 1, so (that - 1) x
    the smallest radius is distance-like near the surface (a bound, not exact)."""
    r = np.asarray(radii, np.float64)
    ax, ay, az = (np.abs(p[..., k]) / np.float32(r[k]) + np.float32(1e-9) for k in range(3))
    xy = (ax ** np.float32(2.0 / e2) + ay ** np.float32(2.0 / e2)) ** np.float32(e2 / e1)
    f = (xy + az ** np.float32(2.0 / e1)) ** np.float32(e1 / 2.0)
    return (f - np.float32(1.0)) * np.float32(r.min())


def make_superquadric(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """A superellipsoid from boxy to pinched, of any flattening and elongation (cobbles,
    boulders, lenticular and flattened bodies), with the common skin. The training world's
    other bodies are ellipsoid-like; these widen the range of hidden depths that go with a
    visible front (a flat face, an edge, a pinch)."""
    axes = np.array([1.0, _u(rng, 0.35, 1.0), _u(rng, 0.25, 0.9)])
    axes[1:] = np.sort(axes[1:])[::-1]
    e1, e2 = (float(np.exp(rng.uniform(np.log(0.25), np.log(1.6)))) for _ in range(2))
    g = _grid(-axes, axes, detail)
    g.union(lambda q: sd_superellipsoid(q, axes, e1, e2), -axes - 0.05, axes + 0.05)
    p = dict(axes=axes.tolist(), e1=e1, e2=e2)
    _surface_detail(g, rng, p, _u(rng, 0.015, 0.05), int(rng.integers(4, 25)), 0.2,
                    int(rng.integers(5, 60)), _u(rng, 0.03, 0.05))
    return _finish(g, rng, "superquadric", volume, detail, p)


def gaussian_log_radius(rng: np.random.Generator, n_waves: int, slope: float):
    """A smooth isotropic random function on the unit sphere with zero mean and unit variance:
    a sum of `n_waves` random plane waves cos(w . u + phase) restricted to the sphere, wave
    numbers log-uniform in 2..9 rad per unit (about the spherical-harmonic degree; a
    wave of 1 would mostly shift the body), amplitudes falling as |w| ** -slope (the larger
    the slope, the more the low orders dominate). Returns h(u) for unit vectors u (..., 3)."""
    k = np.exp(rng.uniform(math.log(2.0), math.log(9.0), n_waves))
    d = rng.standard_normal((n_waves, 3))
    w = d / np.linalg.norm(d, axis=1, keepdims=True) * k[:, None]
    a = k ** -slope
    a = a / math.sqrt(0.5 * float((a * a).sum()))  # each cosine of a random phase has variance 1/2
    phase = rng.uniform(0.0, 2 * math.pi, n_waves)
    w32, a32, ph32 = w.astype(np.float32), a.astype(np.float32), phase.astype(np.float32)

    def h(u):
        return np.cos(u @ w32.T + ph32) @ a32
    return h


def make_gaussian_sphere(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """A Gaussian random sphere (the log of the radius is a random field on the sphere; the
    generic irregular small-body model of the light-scattering literature), stretched to a
    random axis ratio, with the common skin. It belongs to no mission family: its lumps and
    hollows put the hidden back at distances the family generators never make."""
    sigma = _u(rng, 0.15, 0.35)         # relative standard deviation of the log radius
    slope = _u(rng, 0.8, 1.8)
    h = gaussian_log_radius(rng, 32, slope)
    axes = np.array([1.0, _u(rng, 0.45, 1.0), _u(rng, 0.3, 0.9)])
    axes[1:] = np.sort(axes[1:])[::-1]
    # the radius on a dense set of directions bounds the grid
    u = rng.standard_normal((4000, 3)).astype(np.float32)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    rmax = float(np.exp(sigma * h(u) - 0.5 * sigma * sigma).max()) * 1.1

    def body(q):
        r = _norm(q)
        dirs = q / np.maximum(r, np.float32(1e-6))[..., None]
        return (r - np.exp(np.float32(sigma) * h(dirs) - np.float32(0.5 * sigma * sigma))).astype(np.float32)

    g = _grid((-rmax,) * 3, (rmax,) * 3, detail)
    g.union(body, (-rmax,) * 3, (rmax,) * 3)
    p = dict(sigma=sigma, spectrum_slope=slope, axes=axes.tolist())
    _surface_detail(g, rng, p, _u(rng, 0.015, 0.04), int(rng.integers(5, 30)), 0.25,
                    int(rng.integers(5, 60)), _u(rng, 0.03, 0.05))
    return _finish(g, rng, "gaussian_sphere", volume, detail, p, post=axes)


# The ball of radius 0.89 x the smallest semi-axis lies inside a superellipsoid of exponents
# <= 1.2 (at 1.2 the surface comes nearest the centre on the diagonal, at 3 ** -0.6 x sqrt(3)).
_INSCRIBED = 0.89


def make_aggregate(rng: np.random.Generator, volume: float, detail: int = 6) -> Shape:
    """An aggregate of 3-7 lumps (rotated superellipsoids from rounded to blocky, 0.3-0.75 the
    size of the first), each set against a lump already placed, blended from sharp contacts to
    smooth saddles, with the common skin. Gravitational aggregates and multi-lobed bodies
    (Kleopatra, Arrokoth); what matters for training is that the outline a camera sees says
    little about how far the body reaches behind it: a lump may sit behind another."""
    n = int(rng.integers(3, 8))
    blend = float(np.exp(rng.uniform(math.log(0.02), math.log(0.2))))
    centres, radii, rots, exps = [], [], [], []
    for i in range(n):
        r = np.sort(rng.uniform(0.55, 1.0, 3))[::-1] * (0.6 if i == 0 else 0.6 * _u(rng, 0.3, 0.75))
        if i == 0:
            c = np.zeros(3)
        else:
            j = int(rng.integers(0, i))              # the lump it rests against
            d = rng.standard_normal(3)
            d /= np.linalg.norm(d)
            # the balls inscribed in the two lumps overlap, so the aggregate is one piece
            c = centres[j] + d * _INSCRIBED * (radii[j].min() + r.min()) * _u(rng, 0.6, 0.95)
        centres.append(c)
        radii.append(r)
        rots.append(rotation(rng))
        exps.append((float(np.exp(rng.uniform(math.log(0.4), math.log(1.2)))),
                     float(np.exp(rng.uniform(math.log(0.4), math.log(1.2))))))
    reach = [float(r.max()) * 1.5 for r in radii]    # exponents down to 0.4 reach 1.4x the radius on a diagonal
    lo = np.min([c - e for c, e in zip(centres, reach)], axis=0)
    hi = np.max([c + e for c, e in zip(centres, reach)], axis=0)
    g = _grid(lo, hi, detail)
    for c, r, R, (e1, e2), e in zip(centres, radii, rots, exps, reach):
        def lump(q, c=c, r=r, R=R, e1=e1, e2=e2):
            return sd_superellipsoid((q - np.asarray(c, q.dtype)) @ np.asarray(R, q.dtype), r, e1, e2)
        g.union(lump, c - e, c + e, k=blend)
    p = dict(lumps=n, blend=blend, lump_radii=[r.tolist() for r in radii], lump_centres=[c.tolist() for c in centres],
             lump_exponents=[list(e) for e in exps])
    _surface_detail(g, rng, p, _u(rng, 0.015, 0.04), int(rng.integers(5, 30)), 0.2,
                    int(rng.integers(10, 70)), _u(rng, 0.03, 0.05))
    return _finish(g, rng, "aggregate", volume, detail, p)
