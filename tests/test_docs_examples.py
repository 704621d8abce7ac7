"""The docs' code runs as written: docs/runtime.md's embedding example (state, confidence and
a calibrated camera), extracted from the page and run in a fresh interpreter."""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def python_block(page: Path, heading: str) -> str:
    """The first ```python block after `heading` in a Markdown page."""
    text = page.read_text()
    at = text.index(f"\n{heading}\n")
    m = re.compile(r"```python\n(.*?)```", re.S).search(text, at)
    assert m, f"no python block after {heading!r} in {page}"
    return m.group(1)


def test_runtime_embedding_example_runs_as_written(tmp_path):
    code = python_block(ROOT / "docs" / "runtime.md", "## Embedding")
    for shown in ("Camera.from_intrinsics", "get_state", "set_state", "out.score", "held_frames", "out.lost"):
        assert shown in code, f"the embedding example no longer shows {shown}"
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    statuses = [line.split()[0] for line in r.stdout.splitlines()[:4]]
    assert statuses == ["tracking"] * 4, r.stdout          # the synthetic sphere is tracked
    assert (tmp_path / "track3d.state").is_file()


def test_runtime_stereo_example_runs_as_written(tmp_path):
    """The Stereo section's example, with a camera whose baseline is given (it had shown
    StereoCloud(camera) with no word on the baseline, which from_intrinsics defaulted to 0.4 m)."""
    code = python_block(ROOT / "docs" / "runtime.md", "## Stereo (`track3d.stereo`)")
    assert "baseline_m=" in code
    r = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.splitlines()
    assert [line.split()[0] for line in lines] == ["tracking"] * 3, r.stdout
    # the sphere's centre drifts from 22 m towards 14 m: the depth of its box is the pair's
    z = float(lines[-1].split("[")[1].split()[2])
    assert 12.0 < z < 22.0, r.stdout
