"""Per-sequence result files, plain text in the GOT-10k toolkit's manner.

One folder per tracker and sequence: ``<result_dir>/<split>/<tracker>/<sequence>/`` with

    <seq>_001.txt       reported 2D boxes x,y,w,h per frame (fused when fusion is on)
    <seq>_raw_001.txt   the 2D tracker's own boxes
    <seq>_3d_001.txt    3D boxes cx,cy,cz,sx,sy,sz
    <seq>_status.txt    one word per frame: init | tracking | no_points | lost | skipped
    <seq>_time.txt      tracker seconds per frame (I/O excluded; init frames: the init call)
    <seq>_e2e_time.txt  seconds per frame end to end (reading image + depth, back-projection, tracker)
    <seq>_stages.txt    per-stage milliseconds, a commented header names the columns
    (the status file is written last: a sequence without it is unfinished; `track3d eval` needs
    only _001 and _status, the others are optional: read_result)

One file per tracker folder, ``<result_dir>/<split>/<tracker>/run.json``, records the run
that made the results (:func:`write_run_record`): tracker and estimator names and options,
the loop options, every model file with its sha256 and metadata version, the restart
settings, the thread count, the track3d version, and per sequence the frames tracked.

Frames without output (skipped after a restart, before the first init) are rows of nan.
Initialisation frames hold the ground truth (as GOT-10k writes the first frame) and are
never scored; the number of restarts is the number of init frames after the first.
"""
from __future__ import annotations

import json
import re
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..frames import MAX_COORD_M
from ..tracker import STAGES, STATUSES

__all__ = ["SequenceResult", "INIT", "SKIPPED", "RUN_FILE", "OPTIONAL_FILES", "MAX_BOX_VALUE", "MAX_PIXEL_VALUE", "config_differences", "write_result", "read_result", "result_folder",
           "write_run_record", "read_run_record", "run_config_key"]

RUN_FILE = "run.json"

INIT, SKIPPED = "init", "skipped"
STATUS_WORDS = (INIT, *STATUSES, SKIPPED)   # what a status file may hold


@dataclass
class SequenceResult:
    """Arrays for T frames: box2d/box2d_raw (T, 4), box3d (T, 6), status (T,) str,
    seconds / e2e_seconds (T,), stage_ms (T, len(STAGES))."""

    name: str
    box2d: np.ndarray
    box2d_raw: np.ndarray
    box3d: np.ndarray
    status: np.ndarray
    seconds: np.ndarray
    e2e_seconds: np.ndarray
    stage_ms: np.ndarray
    missing: tuple = ()     # the optional files (OPTIONAL_FILES) read_result did not find

    def __len__(self) -> int:
        return len(self.status)

    def head(self, n: int) -> "SequenceResult":
        """The first n frames (all of them when there are fewer)."""
        n = max(int(n), 0)
        return SequenceResult(self.name, self.box2d[:n], self.box2d_raw[:n], self.box3d[:n], self.status[:n],
                              self.seconds[:n], self.e2e_seconds[:n], self.stage_ms[:n], self.missing)

    @property
    def restarts(self) -> int:
        return max(int(np.sum(self.status == INIT)) - 1, 0)

    @property
    def tracked(self) -> np.ndarray:
        """(T,) bool: frames with a tracker update (not init, not skipped): the timed frames."""
        return (self.status != INIT) & (self.status != SKIPPED)


def result_folder(result_dir: str | Path, split: str, tracker: str, sequence: str) -> Path:
    return Path(result_dir) / split / tracker / sequence


def _save(path: Path, a: np.ndarray, fmt: str, header: str = "") -> None:
    np.savetxt(path, a, fmt=fmt, delimiter=",", header=header)


def write_result(folder: str | Path, r: SequenceResult) -> None:
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    n = r.name
    # an earlier run's status file would vouch for the new files half written beside it
    (folder / f"{n}_status.txt").unlink(missing_ok=True)
    _save(folder / f"{n}_001.txt", r.box2d, "%.4f")
    _save(folder / f"{n}_raw_001.txt", r.box2d_raw, "%.4f")
    _save(folder / f"{n}_3d_001.txt", r.box3d, "%.6f")
    _save(folder / f"{n}_time.txt", r.seconds.reshape(-1, 1), "%.8f")
    _save(folder / f"{n}_e2e_time.txt", r.e2e_seconds.reshape(-1, 1), "%.8f")
    _save(folder / f"{n}_stages.txt", r.stage_ms, "%.4f", header=",".join(STAGES) + " (ms)")
    # last: the status file says the sequence is finished (`track3d eval` scores the sequences
    # every run has one of; a run killed while writing leaves the sequence unfinished, not torn)
    (folder / f"{n}_status.txt").write_text("".join(f"{s}\n" for s in r.status))


# The largest magnitude a 3D box value may have (metres): the coordinate bound of the rest of the
# package (track3d.frames.MAX_COORD_M); beyond it a value is a writer's bug, not a box (1e200 had
# been scored as no output and printed as a 200-digit error).
MAX_BOX_VALUE = MAX_COORD_M
# ... and a 2D box value (pixels): a 2D tracker that drifts off the image is reported there, and
# `track3d track` writes it (a review: a box 2e5 px off made the whole run unscoreable at 1e5);
# this bound only keeps squares of centre errors far from float overflow (1e154)
MAX_PIXEL_VALUE = 1e15


def _data_rows(path: Path) -> list[tuple[int, str]]:
    """(1-based line number, text) of the rows numpy reads (not blank, not # comments)."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except (OSError, UnicodeDecodeError):
        return []
    return [(k + 1, line) for k, line in enumerate(text.splitlines())
            if line.strip() and not line.lstrip().startswith("#")]


def _is_number(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def _not_a_file(path: Path) -> str:
    return f"{path} is not a file (a folder or another kind of path where the result file belongs)"


def _parse_error(path: Path, numpy_message: str) -> str:
    """numpy's words for a row it could not read, with the file's own line number (numpy counts
    rows from 0 past comments and blank lines) and what to change: the fields' separator or a
    header line, the two ways another tool's files most often differ from this format."""
    msg = numpy_message.split("; use `usecols`")[0].rstrip(".")
    rows = _data_rows(path)
    # numpy's "could not convert ... at row R, column C" counts R from 0, its "the number of
    # columns changed ... at row R" from 1
    m = re.search(r"at row (\d+)", msg)
    if m:
        k = int(m.group(1)) - ("columns changed" in msg)
        if 0 <= k < len(rows):
            msg = msg[:m.start()] + f"at line {rows[k][0]}" + msg[m.end():]
    hint = ""
    for k, (_, line) in enumerate(rows):
        fields = line.split(",")
        bad = next((f for f in fields if not _is_number(f)), None)
        if bad is None:
            continue
        if len(fields) == 1 and re.search(r"\S[ \t;]+\S", line):
            hint = " (fields are separated by commas, e.g. x,y,w,h)"
        elif k == 0 and not any(_is_number(x) for x in fields) and re.search(r"[A-Za-z_]", bad):
            hint = " (a header line starts with #)"   # a typo in one field of a row is no header
        break
    return f"malformed result file {path}: {msg}{hint}"


def _load(path: Path, cols: int, bound: float | None = None, sizes: tuple[int, ...] = ()) -> np.ndarray:
    """The rows of a result file, (T, cols) float64. nan is "no output"; inf, and with `bound` a
    magnitude beyond it, is refused naming the file and line, as is a negative value in one of
    the `sizes` columns (a box's width, height or extent)."""
    if path.exists() and not path.is_file():
        raise ValueError(_not_a_file(path))
    if not path.is_file():
        raise FileNotFoundError(f"missing result file {path}")
    try:
        with warnings.catch_warnings():   # an empty file is an empty array (below), not numpy's warning
            warnings.filterwarnings("ignore", "loadtxt: input contained no data", UserWarning)
            # utf-8-sig: a byte-order mark (a Windows editor's) is not part of the first number
            a = np.loadtxt(path, delimiter=",", dtype=np.float64, ndmin=2, encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"malformed result file {path}: not UTF-8 text") from None
    except ValueError as e:   # numpy's words name neither the file nor what to do about it
        raise ValueError(_parse_error(path, str(e))) from None
    if a.size == 0:
        return a.reshape(0, cols)
    if a.shape[1] != cols:
        raise ValueError(f"{path} has {a.shape[1]} columns, expected {cols}")
    with np.errstate(invalid="ignore"):
        bad = np.isinf(a) if bound is None else (np.isinf(a) | (np.abs(a) > bound))
        negative = np.zeros_like(bad)
        negative[:, list(sizes)] = a[:, list(sizes)] < 0
    for mask, kind in ((bad, "value"), (negative, "size")):
        if not mask.any():
            continue
        row = int(np.nonzero(mask.any(axis=1))[0][0])
        rows = _data_rows(path)
        line = rows[row][0] if row < len(rows) else row + 1
        value = a[row][mask[row]][0]
        if kind == "size":
            what = "negative: a box's size is >= 0"
        else:
            what = "not finite" if np.isinf(value) else f"beyond {bound:g} in magnitude"
        raise ValueError(f"malformed result file {path} line {line}: {value:g} is {what} "
                         "(nan is the one way to write no output)")
    return a


OPTIONAL_FILES = ("raw_001", "3d_001", "time", "e2e_time", "stages")   # read_result's: missing -> nan


def read_result(folder: str | Path, name: str | None = None) -> SequenceResult:
    """Read the files written by :func:`write_result` (the sequence name defaults to the folder's).

    Needed: ``<seq>_001.txt`` and ``<seq>_status.txt``. Optional (OPTIONAL_FILES; its name in
    SequenceResult.missing when absent): ``_3d_001`` (absent: no 3D box, nan rows), ``_raw_001``
    (absent: nan rows; score(raw=True) refuses such results), ``_time``, ``_e2e_time``, ``_stages``
    (absent: nan, so the speed and latency values are nan)."""
    folder = Path(folder)
    n = name or folder.name
    status_file = folder / f"{n}_status.txt"
    if status_file.exists() and not status_file.is_file():
        raise ValueError(_not_a_file(status_file))
    if not status_file.is_file():
        raise FileNotFoundError(f"no results for sequence {n} in {folder}")
    try:
        lines = status_file.read_text(encoding="utf-8-sig").splitlines()
    except UnicodeDecodeError:
        raise ValueError(f"malformed result file {status_file}: not text") from None
    while lines and not lines[-1].strip():
        lines.pop()
    # one word a line, each line a frame: split() on the whole file had read "tracking lost" on
    # one line as two frames, every later status one frame late
    words = [line.strip() for line in lines]
    for k, w in enumerate(words):
        if not w or len(w.split()) != 1:
            raise ValueError(f"malformed result file {status_file}: line {k + 1} holds "
                             f"{'no status' if not w else f'{len(w.split())} words'} (one status a line)")
    unknown = sorted(set(words) - set(STATUS_WORDS))
    if unknown:   # a misspelt word would be scored as a tracked frame, or a loss missed
        raise ValueError(f"malformed result file {status_file}: unknown status {unknown[0]!r:.40} "
                         f"(one of {', '.join(STATUS_WORDS)} a line)")
    status = np.array(words, dtype=object)
    t = len(status)
    # a folder where an optional file belongs is refused (_load), not taken for "no output"
    missing = tuple(k for k in OPTIONAL_FILES if not (folder / f"{n}_{k}.txt").exists())

    def opt(kind: str, cols: int, bound: float | None = None, sizes: tuple[int, ...] = ()) -> np.ndarray:
        if kind in missing:
            return np.full((t, cols), np.nan)
        return _load(folder / f"{n}_{kind}.txt", cols, bound, sizes)

    r = SequenceResult(
        n, _load(folder / f"{n}_001.txt", 4, MAX_PIXEL_VALUE, (2, 3)), opt("raw_001", 4, MAX_PIXEL_VALUE, (2, 3)),
        opt("3d_001", 6, MAX_BOX_VALUE, (3, 4, 5)), status,
        opt("time", 1)[:, 0], opt("e2e_time", 1)[:, 0], opt("stages", len(STAGES)), missing)
    lengths = {len(r.box2d), len(r.box2d_raw), len(r.box3d), len(r.status), len(r.seconds),
               len(r.e2e_seconds), len(r.stage_ms)}
    if len(lengths) != 1:
        got = ", ".join(f"{k} {len(v)}" for k, v in (("_001", r.box2d), ("_raw_001", r.box2d_raw),
                                                      ("_3d_001", r.box3d), ("_status", r.status),
                                                      ("_time", r.seconds), ("_e2e_time", r.e2e_seconds),
                                                      ("_stages", r.stage_ms)))
        raise ValueError(f"result files of {n} in {folder} differ in length (rows: {got})")
    return r


def _run_path(result_dir: str | Path, split: str, tracker: str) -> Path:
    return Path(result_dir) / split / tracker / RUN_FILE


def read_run_record(result_dir: str | Path, split: str, tracker: str) -> dict | None:
    """The run.json of a tracker's results, or None for results written before records existed."""
    p = _run_path(result_dir, split, tracker)
    if not p.is_file():
        return None
    try:
        rec = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ValueError(f"{p} is not a readable run record ({e})") from None
    if not isinstance(rec, dict):
        raise ValueError(f"{p} is not a run record (not a JSON object)")
    bad = _record_problem(rec)
    if bad:
        raise ValueError(f"{p} is not a run record: {bad} (a field left out is read as unknown)")
    return rec


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _record_problem(rec: dict) -> str | None:
    """Why a field `track3d eval` reads is of the wrong type, or None. Missing fields are
    unknown (records written before a field existed lack it)."""
    checks = (("restart", lambda v: isinstance(v, bool), "true or false"),
              ("restart_skip", lambda v: _is_int(v) and v >= 1, "an integer >= 1"),
              ("max_frames", lambda v: v is None or (_is_int(v) and v >= 1), "null or an integer >= 1"),
              ("dataset", lambda v: v is None or isinstance(v, str), "a name"),
              ("split", lambda v: v is None or isinstance(v, str), "a name"),
              ("frames", lambda v: isinstance(v, dict) and all(_is_int(x) and x >= 0 for x in v.values()),
               "an object of sequence: frame count"),
              ("labels", lambda v: isinstance(v, dict) and all(isinstance(x, str) for x in v.values()),
               "an object of sequence: label digest"),
              ("init_3d", lambda v: isinstance(v, bool), "true or false"),
              ("restart_overlap", lambda v: v is None or isinstance(v, str), "a word"),
              ("two_d", lambda v: isinstance(v, bool), "true or false"),
              ("track3d", lambda v: isinstance(v, dict), "an object"))
    for key, ok, want in checks:
        if key in rec and not ok(rec[key]):
            return f"{key!r} is {json.dumps(rec[key])[:40]}, expected {want}"
    return None


def run_config_key(rec: dict) -> dict:
    """The part of a run record that decides the outputs (what must match to share a folder):
    names, options, models (by hash), restart settings, a first 3D box given; not threads, dates or frame counts."""
    d = rec.get("track3d", {})

    def opts(o: dict) -> dict:
        # threads change speed only; depth_sensor only picks a model, which "models" names by hash;
        # arrays (the oracle's ground truth) are data
        return {k: v for k, v in o.items()
                if k not in ("threads", "depth_sensor") and not (isinstance(v, str) and v.startswith("<array"))}

    return {"tracker": d.get("tracker"), "estimator": d.get("estimator"),
            "tracker_options": opts(d.get("tracker_options", {})),
            "estimator_options": opts(d.get("estimator_options", {})),
            "options": d.get("options"), "models": sorted(m.get("sha256", "") for m in d.get("models", [])),
            "restart": rec.get("restart"), "restart_skip": rec.get("restart_skip"),
            # only when on: the keys of runs without it stay as they were
            **({"init_3d": True, "first_box_fade": rec.get("first_box_fade")} if rec.get("init_3d") else {}),
            **({"restart_overlap": rec["restart_overlap"]} if rec.get("restart_overlap") else {}),
            **({"stereo": rec["stereo"]} if rec.get("stereo") is not None else {})}


def config_differences(old: dict, new: dict, most: int = 4) -> list[str]:
    """What differs between two run_config_key dicts, as "key: old -> new" lines (a dict's own
    keys named key.sub; the models as "models: other files"), at most `most` of them."""
    out = []
    for k in sorted(set(old) | set(new)):
        a, b = old.get(k), new.get(k)
        if a == b:
            continue
        if k == "models":
            out.append("models: other files")
        elif isinstance(a, dict) and isinstance(b, dict):
            out += [f"{k}.{j}: {a.get(j)!r:.40} -> {b.get(j)!r:.40}" for j in sorted(set(a) | set(b))
                    if a.get(j) != b.get(j)]
        else:
            out.append(f"{k}: {a!r:.40} -> {b!r:.40}")
    return out[:most] + ([f"and {len(out) - most} more"] if len(out) > most else [])


def write_run_record(result_dir: str | Path, split: str, tracker: str, rec: dict) -> Path:
    p = _run_path(result_dir, split, tracker)
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps(rec, indent=1, sort_keys=True))
    return p
