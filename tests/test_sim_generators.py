"""Shape generators: registry, determinism, closed outward single-component meshes, volume
scaling, recorded parameters, (non-)star-shapedness measured by ray casting, labels."""
from __future__ import annotations

import math

import numpy as np
import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")
pytest.importorskip("skimage")

from track3d.camera import Camera  # noqa: E402

from track3d_sim.errors import SimError  # noqa: E402
from track3d_sim.generators import GENERATORS, Generator, make_body, register  # noqa: E402
from track3d_sim.shapes import mean_box_volume, mesh_inertia  # noqa: E402

NAMES = list(GENERATORS)
NEW = ["bilobate", "elongated", "top_shape", "rubble_pile", "giant_craters", "fragment"]
VOLUME = 300.0


@pytest.fixture(scope="module")
def bodies():
    return {n: make_body(n, np.random.default_rng(7), VOLUME, 4) for n in NAMES}


def test_registry():
    assert len(set(NAMES)) == len(NAMES) and set(NEW) <= set(NAMES)
    for g in GENERATORS.values():
        assert g.coarse in (0, 1, 2) and g.description
    with pytest.raises(ValueError, match="twice"):
        register(Generator("bilobate", GENERATORS["bilobate"].make, 0, False, "duplicate"))
    with pytest.raises(SimError, match="unknown shape generator"):
        make_body("no_such_body", np.random.default_rng(0), VOLUME, 4)


@pytest.mark.parametrize("name", NEW + ["gaussian_sphere", "aggregate"])
def test_deterministic_for_a_seed(name, bodies):
    again = make_body(name, np.random.default_rng(7), VOLUME, 4)
    assert again.vertices.tobytes() == bodies[name].vertices.tobytes()
    assert again.faces.tobytes() == bodies[name].faces.tobytes()
    other = make_body(name, np.random.default_rng(8), VOLUME, 4)
    assert other.vertices.shape != again.vertices.shape or not np.array_equal(other.vertices, again.vertices)


def _edges_closed_and_consistent(f: np.ndarray) -> bool:
    """Every undirected edge in exactly two faces, traversed once in each direction."""
    directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).astype(np.int64)
    n = int(f.max()) + 1
    key = directed[:, 0] * n + directed[:, 1]
    rev = directed[:, 1] * n + directed[:, 0]
    return len(np.unique(key)) == len(key) and bool(np.isin(rev, key).all())


def _components(f: np.ndarray) -> int:
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    n = int(f.max()) + 1
    g = coo_matrix((np.ones(3 * len(f)), (f.reshape(-1), np.roll(f, 1, axis=1).reshape(-1))), shape=(n, n))
    return connected_components(g, directed=False)[0]


@pytest.mark.parametrize("name", NAMES)
def test_mesh_is_closed_outward_single_and_scaled(name, bodies):
    s = bodies[name]
    v, f = s.vertices, s.faces
    assert v.dtype == np.float64 and v.shape[1] == 3 and f.dtype == np.int32 and f.shape[1] == 3
    assert _edges_closed_and_consistent(f), "an edge is not shared by exactly two consistently wound faces"
    vol, _, _ = mesh_inertia(v, f)
    assert vol > 0, "faces are not oriented outward"
    assert _components(f) == 1
    assert len(np.unique(f)) == len(v), "unused vertices"
    assert np.allclose((v.max(0) + v.min(0)) / 2, 0.0, atol=1e-9 * s.radius), "origin is not the box centre"
    # scaled by the mean rotated box volume (another set of rotations than the scaling used)
    assert mean_box_volume(v, seed=11, n=200) == pytest.approx(VOLUME, rel=0.08)
    assert s.family == name and s.params["target_volume_m3"] == VOLUME


def test_the_same_mesh_check_catches_holes_and_flips(bodies):
    f = bodies["bilobate"].faces
    assert not _edges_closed_and_consistent(f[1:])
    flipped = f.copy()
    flipped[0] = flipped[0, ::-1]
    assert not _edges_closed_and_consistent(flipped)


@pytest.mark.parametrize("name", NEW)
def test_continuous_parameters_recorded(name):
    a = make_body(name, np.random.default_rng(1), VOLUME, 3).params
    b = make_body(name, np.random.default_rng(2), VOLUME, 3).params
    floats = [k for k, x in a.items() if isinstance(x, float) and k != "target_volume_m3"]
    assert len(floats) >= 2, f"{name} records too few continuous parameters: {a}"
    assert any(a[k] != b[k] for k in floats)


def _crossings(shape, n_dirs: int = 20000, seed: int = 0) -> np.ndarray:
    """Surface crossings of rays from the volume centroid in n_dirs random directions."""
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh
    scene = rtcs.EmbreeScene()
    TriangleMesh(scene, shape.vertices[shape.faces].astype(np.float32))
    com = mesh_inertia(shape.vertices, shape.faces)[1]
    d = np.random.default_rng(seed).standard_normal((n_dirs, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    org = np.broadcast_to(com, d.shape).astype(np.float64).copy()
    count = np.zeros(n_dirs, int)
    alive = np.arange(n_dirs)
    eps = 1e-5 * shape.radius
    for _ in range(50):
        res = scene.run(org[alive].astype(np.float32), d[alive].astype(np.float32), output=1)
        hit = res["geomID"] >= 0
        count[alive[hit]] += 1
        t = res["tfar"][hit].astype(np.float64)
        org[alive[hit]] += d[alive[hit]] * (t + eps)[:, None]
        alive = alive[hit]
        if len(alive) == 0:
            break
    return count


@pytest.mark.parametrize("name", NAMES)
def test_star_shaped_flag_is_measured(name):
    g = GENERATORS[name]
    if g.star_shaped:
        shape = make_body(name, np.random.default_rng(3), VOLUME, 4)
        assert np.all(_crossings(shape) == 1)
    else:  # some ray from the centroid crosses the surface more than once (a real concavity)
        counts = [_crossings(make_body(name, np.random.default_rng(s), VOLUME, 5)).max() for s in (3, 4, 5, 6)]
        assert max(counts) >= 2, f"{name} is flagged non-star-shaped but every ray crossed once"


@pytest.mark.parametrize("name", NEW)
def test_depth_points_inside_3d_label_box(name, bodies):
    from track3d_sim.motion import make_motion
    from track3d_sim.render import BodyRenderer
    from track3d_sim.textures import SolidTexture
    shape = bodies[name]
    cam = Camera.from_fov(160, 120, 45.0)
    tan_half = (math.tan(math.radians(cam.fov_x_deg) / 2), math.tan(math.radians(cam.fov_y_deg) / 2))
    rng = np.random.default_rng(5)
    motion = make_motion(rng, 6, shape.radius, tan_half, exits=False, spin="tumbling", inertia=shape.inertia())
    rend = BodyRenderer(shape, SolidTexture(0, rng, shape.vertices), cam)
    n = 0
    for i in (0, 5):
        R, T = motion["R"][i], motion["T"][i]
        X = shape.vertices @ R.T + T
        lo, hi = X.min(0), X.max(0)
        p = cam.backproject_depth(rend.cast(R, T)["z"])
        n += len(p)
        tol = 1e-4 * shape.radius + 1e-5 * hi[2]
        assert np.all(p >= lo - tol) and np.all(p <= hi + tol), f"{name}: depth point outside the 3D box"
    assert n > 50


def test_contact_sheet_cli(tmp_path):
    from PIL import Image

    from track3d_sim.cli import main
    out = tmp_path / "sheet.png"
    assert main(["shapes", "--out", str(out), "--generator", "fragment", "--generator", "irregular",
                 "--count", "2", "--detail", "3", "--cell", "64", "--no-progress"]) == 0
    im = Image.open(out)
    assert im.size[0] == 2 * 64 and im.size[1] > 2 * 64
    assert np.asarray(im).max() > 50  # bodies are lit
    assert main(["shapes", "--out", str(tmp_path / "x.png"), "--generator", "nope", "--no-progress"]) == 2


def test_superellipsoid_distance_hand_cases():
    """sd_superellipsoid: 0 on the semi-axes' ends, -min radius at the centre, for e1 = e2 = 1
    (the ellipsoid) (|p / r| - 1) x min radius along an axis; small exponents fill the box's
    corner, large ones cut it."""
    from track3d_sim.bodies import sd_superellipsoid
    r = np.array([2.0, 1.0, 0.5])
    p = np.array([[2.0, 0, 0], [0, 1.0, 0], [0, 0, 0.5], [0, 0, 0], [4.0, 0, 0]], np.float32)
    d = sd_superellipsoid(p, r, 1.0, 1.0)
    np.testing.assert_allclose(d, [0, 0, 0, -0.5, 0.5], atol=1e-5)
    corner = np.array([[1.6, 0.8, 0.4]], np.float32)             # 0.8 of the way to the box corner
    assert sd_superellipsoid(corner, r, 0.25, 0.25)[0] < 0 < sd_superellipsoid(corner, r, 1.0, 1.0)[0]


def test_gaussian_log_radius_hand_cases():
    """One wave: h = sqrt(2) cos(w . u + phase) (a cosine of a random phase has variance 1/2), and
    with |w| >= 2 the phase sweeps past a multiple of pi, so max |h| is sqrt(2); many waves: zero
    mean and unit variance over the sphere and the seeds; the same function for the same seed."""
    from track3d_sim.bodies import gaussian_log_radius
    rng = np.random.default_rng(0)
    u = rng.standard_normal((20000, 3)).astype(np.float32)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    h1 = gaussian_log_radius(np.random.default_rng(5), 1, 1.0)(u)
    assert abs(np.abs(h1).max() - math.sqrt(2)) < 0.02 and np.abs(h1).max() <= math.sqrt(2) + 1e-5
    vals = np.concatenate([gaussian_log_radius(np.random.default_rng(s), 32, 1.3)(u) for s in range(40)])
    assert abs(vals.mean()) < 0.1 and abs(vals.var() - 1.0) < 0.15
    again = gaussian_log_radius(np.random.default_rng(3), 32, 1.3)(u)
    np.testing.assert_array_equal(again, gaussian_log_radius(np.random.default_rng(3), 32, 1.3)(u))


def test_aggregate_lumps_rest_on_each_other():
    """Each lump after the first rests on one placed before it: the balls inscribed in the two
    (0.89 x the smallest semi-axis, exponents <= 1.2) overlap, so the body is one piece by
    construction; 3-7 lumps, none larger than the first."""
    from track3d_sim.bodies import _INSCRIBED
    assert 3 ** -0.6 * math.sqrt(3) > _INSCRIBED        # the superellipsoid's nearest surface point at e = 1.2
    for seed in range(12):
        p = make_body("aggregate", np.random.default_rng(seed), VOLUME, 3).params
        c, r = np.array(p["lump_centres"]), [np.array(x) for x in p["lump_radii"]]
        assert 3 <= p["lumps"] == len(c) == len(r) <= 7
        assert max(max(e) for e in p["lump_exponents"]) <= 1.2
        for i in range(1, len(c)):
            assert r[i].max() <= r[0].max()
            assert any(np.linalg.norm(c[i] - c[j]) < _INSCRIBED * (r[i].min() + r[j].min()) for j in range(i))
