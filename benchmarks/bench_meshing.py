"""Which marching-cubes library meshes the implicit asteroid generators: speed, faces, watertightness.

The same signed distance grids (the generators' own, captured just before meshing) are meshed by
scikit-image (`measure.marching_cubes`, Lewiner), PyMCubes (`mcubes.marching_cubes`) and
manifold3d (`Manifold.level_set`, marching tetrahedra, sampling the grid through a Python
callback). Writes ./bench-results/meshing_<tag>.json and prints a table.

    .venv/bin/pip install pymcubes manifold3d   # the two candidates not in the sim extra
    nice .venv/bin/python benchmarks/bench_meshing.py --tag cpu
"""
from __future__ import annotations

import sys
import time

import numpy as np
from benchlib.output import DEFAULT_OUT
from benchlib.record import finish_record, start_record

from track3d_sim import bodies
from track3d_sim.generators import make_body
from track3d_sim.noise import trilinear

from track3d.argparsing import ArgumentParser, run_main
from track3d.jsonable import write_json


def _closed(f: np.ndarray) -> bool:
    """Every edge in exactly two faces, once in each direction (closed, consistently wound)."""
    if len(f) == 0:
        return False
    d = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]]).astype(np.int64)
    n = int(f.max()) + 1
    key, rev = d[:, 0] * n + d[:, 1], d[:, 1] * n + d[:, 0]
    return len(np.unique(key)) == len(key) and bool(np.isin(rev, key).all())


def _grids(names, detail, seed):
    """The generators' SDF grids at `detail` (values with the closed outer layer), captured."""
    grids = []
    orig = bodies.mesh_grid

    def capture(g):
        out = orig(g)          # sets the outer layer, as the generators mesh it
        grids.append(g.values.copy())
        return out

    bodies.mesh_grid = capture
    try:
        for name in names:
            make_body(name, np.random.default_rng(seed), 300.0, detail)
    finally:
        bodies.mesh_grid = orig
    return grids


def _skimage(v):
    from skimage.measure import marching_cubes
    verts, faces, _, _ = marching_cubes(v, 0.0, allow_degenerate=False)
    return verts, faces


def _mcubes(v):
    import mcubes
    return mcubes.marching_cubes(-v.astype(np.float64), 0.0)


def _manifold(v):
    import manifold3d
    n = np.array(v.shape)

    def f(x, y, z):  # positive inside for manifold3d
        return -float(trilinear(v, np.array([[x, y, z]]), wrap=False)[0])

    m = manifold3d.Manifold.level_set(f, [1, 1, 1, *(n - 2).tolist()], 1.0)
    mesh = m.to_mesh()
    return np.asarray(mesh.vert_properties)[:, :3], np.asarray(mesh.tri_verts)


def build_parser() -> ArgumentParser:
    ap = ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tag", default="cpu", help="./bench-results/meshing_<tag>.json (default cpu)")
    ap.add_argument("--seed", type=int, default=0, help="seed of the bodies (default 0)")
    ap.add_argument("--manifold-detail", type=int, default=4,
                    help="detail for manifold3d, whose per-point Python callback is slow (default 4)")
    return ap


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    rec = start_record("meshing")
    names = ["bilobate", "elongated", "top_shape", "rubble_pile", "giant_craters", "fragment"]
    libs = {"scikit-image": _skimage, "PyMCubes": _mcubes, "manifold3d": _manifold}
    rows = []
    for detail in (4, 6):
        grids = _grids(names, detail, args.seed)
        for lib, fn in libs.items():
            if lib == "manifold3d" and detail != args.manifold_detail:
                continue
            ms, faces, closed = [], [], []
            for v in grids:
                t = time.perf_counter()
                _, f = fn(v)
                ms.append(1000 * (time.perf_counter() - t))
                faces.append(len(f))
                closed.append(_closed(np.asarray(f)))
            rows.append({"library": lib, "detail": detail, "grid_voxels": int(max(grids[0].shape)),
                         "ms_median": float(np.median(ms)), "ms_max": float(np.max(ms)),
                         "faces_median": int(np.median(faces)), "closed": f"{sum(closed)}/{len(closed)}"})
            print(f"{lib:13s} detail {detail}  {rows[-1]['ms_median']:8.1f} ms (max {rows[-1]['ms_max']:8.1f})"
                  f"  faces {rows[-1]['faces_median']:6d}  closed+consistent {rows[-1]['closed']}")
    out = write_json(DEFAULT_OUT / f"meshing_{args.tag}.json",
                     finish_record({**rec, "bodies": names, "rows": rows}))
    print(f"wrote {out}")


if __name__ == "__main__":
    sys.exit(run_main(main, "bench_meshing.py"))
