"""The training log of SiamFC and EdgeTrack runs (`log.jsonl` in the run folder): one JSON
object a line, each with the `step` it was written at.

A run appends to the log between checkpoints, so a run killed after logging a step but before
checkpointing it would log that step again when it resumes; `trim_log` drops those rows first.
"""
from __future__ import annotations

import json
import os
from pathlib import Path

__all__ = ["read_log", "trim_log"]


def read_log(path: str | Path) -> list[dict]:
    """Every row of a training log, in order (blank lines skipped)."""
    return [json.loads(line) for line in Path(path).read_text().splitlines() if line.strip()]


def trim_log(path: str | Path, step: int) -> None:
    """Keep only the rows of the log at `path` written at or before `step` (the checkpoint a run
    resumes from); the file is replaced atomically. No file: nothing to do."""
    p = Path(path)
    if not p.exists():
        return
    rows = [line for line in p.read_text().splitlines() if line.strip() and json.loads(line)["step"] <= step]
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text("".join(r + "\n" for r in rows))
    os.replace(tmp, p)
