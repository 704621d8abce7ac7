"""The Ray backend writes the same bytes as one and two local processes (one local Ray instance)."""
from __future__ import annotations

import hashlib
import shutil
from pathlib import Path

import pytest

pytest.importorskip("embreex")
pytest.importorskip("trimesh")
ray = pytest.importorskip("ray", reason="ray is not installed (pip install 'track3d[cluster]')")

from track3d_sim.generate import generate, make_settings  # noqa: E402


def _hashes(root: Path) -> dict:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


def test_ray_local_same_bytes_as_workers(tmp_path):
    s = make_settings("tiny", seed=21, frames=4, test_unseen=1)
    quiet = dict(progress=False, log=lambda m: None)
    one = _hashes(generate(s, tmp_path / "w1", workers=1, **quiet))
    two = _hashes(generate(s, tmp_path / "w2", workers=2, **quiet))
    assert len(one) == 7 * (4 * 3 + 5) + 2
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)  # one instance for both runs
    try:
        out = tmp_path / "ray"
        got = _hashes(generate(s, out, ray="local", **quiet))
        assert got == one == two
        # resume under Ray: two sequences missing, a stale partial, no dataset.json
        (out / "dataset.json").unlink()
        for name in ("0002", "0004"):
            shutil.rmtree(out / "train" / name)
        (out / "train" / ".partial-0004").mkdir()
        (out / "train" / ".partial-0004" / "junk").write_text("x")
        assert _hashes(generate(s, out, ray="local", **quiet)) == one
    finally:
        ray.shutdown()


def test_unreachable_ray_address_is_one_line_and_writes_nothing(tmp_path, capsys):
    from track3d_sim.cli import main
    out = tmp_path / "r"
    assert main(["generate", "--preset", "tiny", "--frames", "2", "--ray", "127.0.0.1:1", "--out", str(out),
                 "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "no Ray cluster answers at 127.0.0.1:1" in err and err.count("\n") == 1
    assert not out.exists()
