"""`track3d-sim restereo`: a stereo dataset's depth recomputed from its images is what `generate`
writes with this release's matcher, byte for byte; other sensors' sequences are left alone; a
second run does nothing; a points-only dataset is a one-line error."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")

from track3d.dataset import Dataset, read_depth_png, write_depth_png  # noqa: E402

from track3d_sim.cli import main  # noqa: E402
from track3d_sim.generate import generate, make_settings  # noqa: E402


def _quiet(msg):
    pass


def _depth_hashes(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("depth/*.png"))}


def test_restereo_rewrites_stale_stereo_depth_as_generate_writes_it(tmp_path, capsys):
    root = generate(make_settings("tiny", seed=21, train=2, test=1, frames=3, sensors="ideal,stereo"),
                    tmp_path / "d", progress=False, log=_quiet)
    fresh = _depth_hashes(root)
    ds = Dataset(root)
    seqs = [s for sp in ds.splits for s in ds.sequences(sp)]
    stereo = [s for s in seqs if s.depth_sensor == "stereo"]
    others = [s for s in seqs if s.depth_sensor != "stereo"]
    assert stereo and others
    # make the stereo sequences look as an older matcher left them: other depth, other settings
    for s in stereo:
        for f in sorted((s.path / "depth").glob("*.png")):
            z = read_depth_png(f)
            write_depth_png(f, np.where(z > 0, z + 0.5, 0.0))
        meta = json.loads((s.path / "meta.json").read_text())
        meta["depth_sensor"]["edge_erode_px"] = 0
        (s.path / "meta.json").write_text(json.dumps(meta, indent=1, sort_keys=True))
    assert _depth_hashes(root) != fresh
    other_meta = {s.name: (s.path / "meta.json").read_bytes() for s in others}

    assert main(["restereo", str(root), "--quiet"]) == 0
    assert f"{len(stereo)} sequences recomputed" in capsys.readouterr().out
    assert _depth_hashes(root) == fresh
    for s in Dataset(root).sequences("train") + Dataset(root).sequences("test"):
        if s.depth_sensor == "stereo":
            assert s.meta["depth_sensor"]["edge_erode_px"] == 1
        else:
            assert (s.path / "meta.json").read_bytes() == other_meta[s.name]

    assert main(["restereo", str(root), "--quiet"]) == 0          # nothing left to do
    assert "0 sequences recomputed" in capsys.readouterr().out


def test_restereo_refuses_points_only_data_and_non_datasets(tmp_path, capsys):
    root = generate(make_settings("tiny", seed=22, train=1, test=0, frames=2, points_only=True),
                    tmp_path / "p", progress=False, log=_quiet)
    assert main(["restereo", str(root), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "points-only" in err and len(err.strip().splitlines()) == 1
    assert main(["restereo", str(tmp_path / "nothing"), "--quiet"]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_restereo_rewrites_an_upper_case_depth_folder_in_place(tmp_path, capsys):
    """A depth folder of 000001.PNG files (the reader takes them): restereo had written a second
    file per frame, 000001.png, and the next open refused the folder as holding both."""
    root = generate(make_settings("tiny", seed=21, train=1, test=1, frames=3, sensors="stereo"),
                    tmp_path / "d", progress=False, log=_quiet)
    fresh = {k.lower(): v for k, v in _depth_hashes(root).items()}
    for s in Dataset(root).sequences("test"):
        for f in sorted((s.path / "depth").glob("*.png")):
            z = read_depth_png(f)
            write_depth_png(f.with_suffix(".PNG"), np.where(z > 0, z + 0.5, 0.0))
            f.unlink()
        meta = json.loads((s.path / "meta.json").read_text())
        meta["depth_sensor"]["edge_erode_px"] = 0
        (s.path / "meta.json").write_text(json.dumps(meta, indent=1, sort_keys=True))
    assert main(["restereo", str(root), "--quiet"]) == 0
    capsys.readouterr()
    (s,) = Dataset(root).sequences("test")                       # opens: one file per frame
    assert sorted(p.name for p in (s.path / "depth").iterdir()) == ["000001.PNG", "000002.PNG", "000003.PNG"]
    got = {str(p.relative_to(root)).lower(): hashlib.sha256(p.read_bytes()).hexdigest()
           for p in sorted(root.rglob("depth/*.PNG"))}
    assert got == {k: v for k, v in fresh.items() if k.startswith("test")}
