"""Frustum proposal and point sampling: C++ extension vs numpy reference, hand cases, edge cases."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from track3d import Camera
from track3d import frustum as fr

CAM = Camera(640, 480, 60.0, 47.0)


def test_extension_is_built_and_used():
    # The fallback is only for an extension lacking a function; the package build must have both.
    assert fr.HAVE_EXTENSION


def _point_at_pixel(cam: Camera, u: float, v: float, z: float) -> list[float]:
    return [(u - cam.cx) / cam.fx * z, (v - cam.cy) / cam.fy * z, z]


def test_hand_case_selection_and_order():
    box = [100.0, 50.0, 20.0, 10.0]  # u in [100, 120), v in [50, 60)
    pts = np.array([
        _point_at_pixel(CAM, 110.5, 55.5, 10.0),   # 0 inside
        _point_at_pixel(CAM, 110.5, 55.5, 0.5),    # 1 too near (z < 1)
        _point_at_pixel(CAM, 110.5, 55.5, 50.0),   # 2 too far (z > 45)
        _point_at_pixel(CAM, 90.0, 55.5, 10.0),    # 3 left of the box
        _point_at_pixel(CAM, 119.5, 59.5, 44.0),   # 4 inside, near the far corner
        _point_at_pixel(CAM, 130.0, 55.5, 10.0),   # 5 right of the box
        _point_at_pixel(CAM, 105.0, 70.0, 10.0),   # 6 below the box
        _point_at_pixel(CAM, 101.0, 51.0, 1.0),    # 7 inside at exactly z = 1
        [np.nan, 0.0, 10.0],                        # 8 NaN
        [0.0, np.inf, 10.0],                        # 9 inf
    ], dtype=np.float32)
    want = pts[[0, 4, 7]]
    for fn in (fr.extract_frustum, fr.extract_frustum_numpy):
        got = fn(pts, box, CAM.M)
        assert got.dtype == np.float32 and got.shape == (3, 3)
        np.testing.assert_array_equal(got, want)


def test_box_edges_are_half_open():
    # Points exactly on pixel coordinates u = 100 (left edge, kept) and u = 120 (right edge, dropped).
    # With z = fx (so u - cx = x exactly) the projection is exact in float64.
    cam = Camera(64, 48, 90.0, 73.739795291688)  # fx = 32 -> z = 32 m is in range
    z = cam.fx
    pts = np.array([[100 - cam.cx, 55 - cam.cy, z], [120 - cam.cx, 55 - cam.cy, z],
                    [110 - cam.cx, 50 - cam.cy, z], [110 - cam.cx, 60 - cam.cy, z]], dtype=np.float32)
    box = [100.0, 50.0, 20.0, 10.0]
    for fn in (fr.extract_frustum, fr.extract_frustum_numpy):
        got = fn(pts, box, cam.M)
        np.testing.assert_array_equal(got, pts[[0, 2]])


@pytest.mark.parametrize("box", [
    [100.0, 100.0, 0.0, 50.0],          # zero width
    [100.0, 100.0, 50.0, 0.0],          # zero height
    [100.0, 100.0, -5.0, 50.0],         # negative width
    [np.nan, 100.0, 50.0, 50.0],        # non-finite
    [100.0, 100.0, np.inf, 50.0],
    [1000.0, 1000.0, 50.0, 50.0],       # wholly outside the image
    [-500.0, -500.0, 100.0, 100.0],
])
def test_degenerate_boxes_give_empty(box):
    pts = (np.random.default_rng(1).normal(size=(1000, 3)) * [2, 2, 3] + [0, 0, 15]).astype(np.float32)
    for fn in (fr.extract_frustum, fr.extract_frustum_numpy):
        out = fn(pts, box, CAM.M)
        assert out.shape == (0, 3) and out.dtype == np.float32


def test_partly_outside_box_keeps_the_inside_part():
    pts = (np.random.default_rng(2).normal(size=(5000, 3)) * [4, 4, 3] + [0, 0, 15]).astype(np.float32)
    box = [-100.0, -100.0, 300.0, 300.0]
    out = fr.extract_frustum(pts, box, CAM.M)
    uv = CAM.project(out)
    assert len(out) > 0
    # The box is not clipped to the image: a cloud reaching outside the view keeps those points too.
    assert np.all(uv >= -100) and np.all(uv < 200)
    assert np.any(uv < 0) and np.any(uv >= 0)
    np.testing.assert_array_equal(out, fr.extract_frustum_numpy(pts, box, CAM.M))


@pytest.mark.parametrize("pts", [np.zeros((0, 3), np.float32), np.zeros((0,), np.float32),
                                 np.full((5, 3), np.nan, np.float32)])
def test_empty_or_all_invalid_cloud(pts):
    for fn in (fr.extract_frustum, fr.extract_frustum_numpy):
        out = fn(pts, [0, 0, 640, 480], CAM.M)
        assert out.shape == (0, 3) and out.dtype == np.float32


def test_bad_shapes_raise_clear_errors():
    with pytest.raises(ValueError, match="shape"):
        fr.extract_frustum(np.zeros((4, 2), np.float32), [0, 0, 1, 1], CAM.M)
    with pytest.raises(ValueError, match="box2d"):
        fr.extract_frustum(np.zeros((4, 3), np.float32), [0, 0, 1], CAM.M)
    with pytest.raises(ValueError, match="M"):
        fr.extract_frustum(np.zeros((4, 3), np.float32), [0, 0, 1, 1], np.eye(3))


def test_float64_and_noncontiguous_input_are_accepted():
    pts = (np.random.default_rng(3).normal(size=(2000, 6)) * 3 + 15)[:, ::2]  # float64, strided
    box = [200.0, 150.0, 240.0, 180.0]
    np.testing.assert_array_equal(fr.extract_frustum(pts, box, CAM.M),
                                  fr.extract_frustum_numpy(pts.astype(np.float32), box, CAM.M))


finite_f = st.floats(-1e4, 1e4, allow_nan=False, width=32)
special_f = st.sampled_from([np.nan, np.inf, -np.inf, 0.0, 1.0, 45.0])


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(0, 3000), x=finite_f, y=finite_f,
       w=st.floats(-10, 800, width=32), h=st.floats(-10, 600, width=32),
       n_special=st.integers(0, 20), special=special_f, zlo=st.floats(0.0, 10.0), zspan=st.floats(0.0, 60.0))
def test_extension_matches_numpy_on_random_clouds(seed, n, x, y, w, h, n_special, special, zlo, zspan):
    rng = np.random.default_rng(seed)
    pts = np.empty((n, 3), np.float32)
    pts[:, :2] = rng.normal(size=(n, 2)) * rng.uniform(0.1, 20)
    pts[:, 2] = rng.uniform(-5, 60, size=n)
    if n:
        rows = rng.integers(0, n, size=n_special)
        cols = rng.integers(0, 3, size=n_special)
        pts[rows, cols] = special
    box = np.array([x % 700 - 30, y % 520 - 20, w, h])
    got = fr.extract_frustum(pts, box, CAM.M, zlo, zlo + zspan)
    want = fr.extract_frustum_numpy(pts, box, CAM.M, zlo, zlo + zspan)
    np.testing.assert_array_equal(got, want)
    assert got.dtype == np.float32 and got.shape[1:] == (3,)
    if len(got):
        assert np.all(np.isfinite(got))
        assert np.all((got[:, 2] >= zlo) & (got[:, 2] <= zlo + zspan))


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), n=st.integers(1, 400))
def test_extension_matches_numpy_with_a_general_camera_matrix(seed, n):
    # A full 3x4 matrix (rotation + translation) exercises every term of the projection.
    rng = np.random.default_rng(seed)
    M = rng.normal(size=(3, 4))
    M[2] = [0.1, -0.2, 1.0, 0.5]
    pts = (rng.normal(size=(n, 3)) * 5 + [0, 0, 20]).astype(np.float32)
    box = np.array([-50.0, -50.0, 100.0, 100.0]) * rng.uniform(0.1, 3)
    np.testing.assert_array_equal(fr.extract_frustum(pts, box, M), fr.extract_frustum_numpy(pts, box, M))


# --- sampling ---------------------------------------------------------------------------------

def _rows(a: np.ndarray) -> list[tuple]:
    return [tuple(r) for r in a.tolist()]


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 300), num=st.integers(1, 300), seed=st.integers(-2**63, 2**64 - 1))
def test_sampling_matches_reference_and_properties(n, num, seed):
    pts = np.arange(n * 3, dtype=np.float32).reshape(n, 3)  # rows are unique and identify indices
    out = fr.sample_points(pts, num, seed)
    assert out.shape == (num, 3) and out.dtype == np.float32
    np.testing.assert_array_equal(out, fr.sample_points_numpy(pts, num, seed))
    np.testing.assert_array_equal(out, fr.sample_points(pts, num, seed))  # deterministic
    idx = (out[:, 0] / 3).astype(np.int64)
    assert np.all((idx >= 0) & (idx < n))
    np.testing.assert_array_equal(out, pts[idx])  # a subset of the input rows
    if n >= num:
        assert len(set(idx.tolist())) == num      # without replacement
    else:
        np.testing.assert_array_equal(idx[:n], np.arange(n))  # every point kept once, in order
        counts = np.bincount(idx, minlength=n)
        assert counts.sum() == num and counts.min() >= 1


def test_sampling_hand_case_and_seed_dependence():
    pts = np.arange(30, dtype=np.float32).reshape(10, 3)
    a = fr.sample_points(pts, 10, seed=0)
    assert sorted(_rows(a)) == _rows(pts)          # a permutation when num == n
    b = fr.sample_points(pts, 10, seed=1)
    assert not np.array_equal(a, b)                # another seed, another order
    # SplitMix64 first output for seed 0 is the published 0xE220A8397B1DCDAF.
    assert fr._SplitMix64(0).next() == 0xE220A8397B1DCDAF


def test_sampling_is_roughly_uniform():
    # 20000 draws of 1 out of 10: each index ~2000 times (binomial sd ~42; 6 sd margin).
    pts = np.arange(30, dtype=np.float32).reshape(10, 3)
    first = np.array([fr.sample_points(pts, 1, s)[0, 0] / 3 for s in range(20000)], dtype=np.int64)
    counts = np.bincount(first, minlength=10)
    assert np.all(np.abs(counts - 2000) < 260), counts


def test_sampling_errors():
    with pytest.raises(ValueError, match="empty"):
        fr.sample_points(np.zeros((0, 3), np.float32), 16, 0)
    with pytest.raises(ValueError, match="num"):
        fr.sample_points(np.zeros((4, 3), np.float32), 0, 0)
    with pytest.raises(ValueError, match="shape"):
        fr.sample_points(np.zeros((4, 2), np.float32), 2, 0)


def test_lone_mask_hand_case_and_the_extension_agrees_bit_for_bit():
    """track3d.frustum.lone_scan's mask: a point is lone when no other lies in the 3 x 3 cells around its
    own. Hand case on a pinhole with fx = fy = 100, principal point (0, 0): points at z = 1 land on
    pixel (100 x, 100 y); cells of 4 px."""
    from track3d.frustum import lone_mask_numpy, lone_scan

    def lone_mask(p, M, cell):
        return lone_scan(p, M, cell, 0.25)[0]

    M = np.array([[100.0, 0, 0, 0], [0, 100.0, 0, 0], [0, 0, 1.0, 0]])
    uv = np.array([[0, 0], [3, 1], [11, 0], [40, 40], [47.9, 40], [48, 40]], float)   # pixels
    pts = np.column_stack([uv / 100.0, np.ones(len(uv))]).astype(np.float32)
    # cells (u // 4, v // 4): (0,0) (0,0) (2,0) (10,10) (11,10) (12,10): the first two share one,
    # the third is two columns off (alone), the last three neighbour one another
    want = np.array([False, False, True, False, False, False])
    np.testing.assert_array_equal(lone_mask_numpy(pts, M, 4.0), want)
    np.testing.assert_array_equal(lone_mask(pts, M, 4.0), want)
    assert not lone_mask_numpy(pts[:1], M, 4.0).any()                    # one point: nothing to tell
    bad = pts.copy()
    bad[0, 2] = np.nan
    assert not lone_mask_numpy(bad, M, 4.0).any() and not lone_mask(bad, M, 4.0).any()
    rng = np.random.default_rng(5)
    for t in range(300):
        n = int(rng.choice([0, 2, 7, 300, 3000]))
        p = rng.normal([0, 0, 20], rng.uniform(0.01, 10), (n, 3)).astype(np.float32)
        if t % 5 == 0 and n:
            p[rng.integers(0, n, max(1, n // 40))] = rng.choice([np.nan, np.inf, 0.0, -3.0, 1e30])
        cell = float(rng.choice([4.0, 0.7, 50.0, 1e-7]))
        np.testing.assert_array_equal(lone_mask(p, CAM.M, cell), lone_mask_numpy(p, CAM.M, cell))



def test_lone_scan_one_run_only_when_no_depth_gap_is_wider_than_two_buckets():
    """lone_scan's one_run lets drop_stray skip sorting the depths: it must never be True where two
    kept points, in depth order, lie more than 2 buckets apart."""
    from track3d.frustum import HAVE_EXTENSION, lone_scan

    rng = np.random.default_rng(9)
    seen = set()
    for t in range(400):
        n = int(rng.choice([2, 5, 50, 2000]))
        p = rng.normal([0, 0, 20], [2, 2, rng.uniform(0.05, 3)], (n, 3)).astype(np.float32)
        if t % 3 == 0:
            p[: max(1, n // 100), 2] -= rng.uniform(0.3, 5)     # a few apart in front
        lone, one_run = lone_scan(p, CAM.M, 4.0, 0.25)
        seen.add(one_run)
        z = np.sort(p[~lone, 2].astype(np.float64))
        if one_run:
            assert len(z) and np.all(np.diff(z) <= 0.5 + 1e-9)
    assert seen == ({True, False} if HAVE_EXTENSION else {False})


def test_select_points_is_a_boolean_index_of_the_rows():
    """track3d.frames.select_points: points[mask], row for row, for any layout and dtype."""
    from track3d.frames import point_bounds, select_points

    p = np.arange(15, dtype=np.float32).reshape(5, 3)
    mask = np.array([True, False, True, True, False])
    np.testing.assert_array_equal(select_points(p, mask), [[0, 1, 2], [6, 7, 8], [9, 10, 11]])
    assert select_points(p, mask).dtype == np.float32
    assert select_points(p, np.zeros(5, bool)).shape == (0, 3)
    rng = np.random.default_rng(0)
    for q in (rng.normal(size=(1000, 3)), rng.normal(size=(1000, 6)).astype(np.float32)[:, ::2],
              np.asfortranarray(rng.normal(size=(1000, 3)))):
        m = rng.random(len(q)) < 0.3
        out = select_points(q, m)
        np.testing.assert_array_equal(out, q[m])
        assert out.dtype == q.dtype
    lo, hi = point_bounds(p)
    np.testing.assert_array_equal(lo, [0, 1, 2])
    np.testing.assert_array_equal(hi, [12, 13, 14])


_BLOCK_EXTENSIONS = """
import importlib.abc, sys, warnings
class Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name in ("track3d._frustum", "track3d._resample"):
            raise ImportError("libstdc++.so.6: version GLIBCXX_3.4.99 not found (simulated)")
        return None
sys.meta_path.insert(0, Block())
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    from track3d import frustum, resample, machine
print("HAVE", frustum.HAVE_EXTENSION, resample.HAVE_EXTENSION)
print("EXT", machine.versions()["extension"])
for w in caught:
    print("WARN", w.category.__name__, str(w.message))
"""


def test_a_missing_extension_is_said_not_silent():
    """A wheel built for another machine (newer glibc / libstdc++) loads without its C++ and ran
    3x slower on the frustum with no word (a wheel-install walkthrough): it now warns once per
    extension, and the machine record every benchmark writes says which code ran."""
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", _BLOCK_EXTENSIONS], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert "HAVE False False" in lines
    assert any(x.startswith("EXT missing") for x in lines)
    warns = [x for x in lines if x.startswith("WARN RuntimeWarning")]
    assert len(warns) == 2
    assert any("track3d._frustum did not load" in w and "GLIBCXX" in w for w in warns)
    assert any("track3d._resample did not load" in w for w in warns)


def test_the_machine_record_names_the_compiled_extension():
    from track3d import machine
    assert machine.versions()["extension"] == "compiled"
