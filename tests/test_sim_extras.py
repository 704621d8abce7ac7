"""The simulator's PLY export and its trilinear lookup (hand-checked against a plain loop)."""
from __future__ import annotations

import numpy as np
import pytest

from track3d_sim.cli import main
from track3d_sim.noise import trilinear


def _trilinear_loop(grid, c, wrap):
    """Reference: the textbook 8-corner weighted sum, one point at a time."""
    n = np.array(grid.shape[:3])
    out = []
    for p in c:
        if not wrap:
            p = np.clip(p, 0.0, n - 1.000001)
        lo = np.floor(p).astype(int)
        f = p - lo
        acc = 0.0
        for d in np.ndindex(2, 2, 2):
            idx = lo + np.array(d)
            idx = idx % n if wrap else np.minimum(idx, n - 1)
            w = np.prod([f[k] if d[k] else 1 - f[k] for k in range(3)])
            acc = acc + w * grid[tuple(idx)]
        out.append(acc)
    return np.array(out)


@pytest.mark.parametrize("wrap", [True, False])
@pytest.mark.parametrize("channels", [None, 3])
def test_trilinear_matches_the_8_corner_sum(wrap, channels):
    rng = np.random.default_rng(1)
    shape = (5, 6, 7) + ((channels,) if channels else ())
    grid = rng.standard_normal(shape).astype(np.float32)
    c = rng.uniform(-3, 12, size=(50, 3))
    got = trilinear(grid, c, wrap=wrap)
    ref = _trilinear_loop(grid, c, wrap)
    assert got.shape == ref.shape
    np.testing.assert_allclose(got, ref, rtol=1e-5, atol=1e-5)


def test_trilinear_hand_case():
    grid = np.zeros((2, 2, 2), np.float32)
    grid[1, 1, 1] = 8.0
    # the centre of the cell weights every corner 1/8: 8 * 1/8 = 1
    assert trilinear(grid, np.array([[0.5, 0.5, 0.5]]), wrap=False)[0] == pytest.approx(1.0)
    # periodic: coordinate 2 wraps to 0, where the value is 0
    assert trilinear(grid, np.array([[2.0, 2.0, 2.0]]), wrap=True)[0] == pytest.approx(0.0)


def test_ply_export_writes_the_frame_cloud(tiny_dataset, tmp_path, capsys):
    from track3d.dataset import Dataset

    seq = Dataset(tiny_dataset).sequences("train")[0]
    out = tmp_path / "f.ply"
    assert main(["ply", str(seq.path), "--frame", "2", "--out", str(out)]) == 0
    assert capsys.readouterr().out.strip().endswith(f"-> {out}")     # it had printed nothing
    raw = out.read_bytes()
    head, body = raw.split(b"end_header\n", 1)
    n = int([l for l in head.decode().splitlines() if l.startswith("element vertex")][0].split()[-1])
    rec = np.frombuffer(body, dtype=[("x", "<f4"), ("y", "<f4"), ("z", "<f4"),
                                     ("r", "u1"), ("g", "u1"), ("b", "u1")])
    pts = seq.points(1)
    assert n == len(rec) == len(pts) > 0
    np.testing.assert_array_equal(np.c_[rec["x"], rec["y"], rec["z"]], pts)


def test_ply_export_bad_frame(tiny_dataset, tmp_path, capsys):
    from track3d.dataset import Dataset

    seq = Dataset(tiny_dataset).sequences("train")[0]
    assert main(["ply", str(seq.path), "--frame", "999", "--out", str(tmp_path / "x.ply")]) == 2
    assert "out of range" in capsys.readouterr().err
    assert not (tmp_path / "x.ply").exists()
