"""Shared fixtures: one `tiny` dataset per test session, made by the simulator's own CLI."""
from __future__ import annotations

import pytest


@pytest.fixture(scope="session")
def tiny_dataset(tmp_path_factory):
    """Root folder of a `tiny` dataset (seed 0) generated once per test session."""
    from track3d_sim.cli import main

    root = tmp_path_factory.mktemp("tiny") / "ds"
    rc = main(["generate", "--preset", "tiny", "--out", str(root), "--seed", "0", "--workers", "1"])
    assert rc in (0, None), f"track3d-sim generate failed with {rc}"
    return root
