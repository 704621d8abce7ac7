"""The per-machine cache of precision="auto" / engine="auto" (variants.json): a damaged file or
entry is measured again with one warning, a cached pick follows the same rule as a fresh one, a
cached reason carries the same exclusions, and a forced ISA is visible to a benchmark record."""
from __future__ import annotations

import json
import math
import re

import pytest

import track3d.variant_choice as vc
from track3d.cpu_features import forced_isa_flags, isa_flags
from track3d.onnxmodel import MODELS_DIR, ModelError, variant_path

MODEL = MODELS_DIR / "a3boxnet.onnx"   # fp32 and a passing int8 twin: two candidates on onnxruntime
VNNI_BF16 = frozenset({"avx2", "avx512", "vnni", "avx512_bf16", "int8_dot", "bf16_dot"})
FP32, INT8 = "onnxruntime/fp32", "onnxruntime/int8"

pytestmark = pytest.mark.skipif(not variant_path(MODEL, "int8").is_file(), reason="no int8 twin: one candidate")


@pytest.fixture(autouse=True)
def _cache_in_tmp(tmp_path, monkeypatch):
    monkeypatch.setenv("TRACK3D_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("TRACK3D_ISA_FLAGS", raising=False)


@pytest.fixture
def timings(monkeypatch):
    """measure() replaced by set times ("engine/precision" -> ms; unset: the reference fastest):
    the pick is then known, and no test spends the real half-second budget."""
    times: dict[str, float] = {}

    def fake(sessions, feeds):
        return {c: times.get(vc._label(c), 1.0 + 0.5 * i) for i, c in enumerate(sessions)}

    monkeypatch.setattr(vc, "measure", fake)
    return times


def _cache_file(tmp_path):
    return tmp_path / "cache" / "variants.json"


def _choose(engine="onnxruntime"):
    return vc.choose(MODEL, 1, "auto", engine, flags=VNNI_BF16)[0]


def _one_entry(tmp_path) -> tuple[str, dict]:
    data = json.loads(_cache_file(tmp_path).read_text())
    assert len(data) == 1
    return next(iter(data.items()))


def _damage(tmp_path, change) -> None:
    key, entry = _one_entry(tmp_path)
    _cache_file(tmp_path).write_text(json.dumps({key: change(entry)}))


def _assert_measured_again_once(tmp_path, capsys):
    """Measured afresh with one stderr line naming the file; the fresh entry written back, so the
    next load trusts it silently."""
    again = _choose()
    err = capsys.readouterr().err.strip().splitlines()
    assert "measured now" in again["reason"]
    assert len(err) == 1 and str(_cache_file(tmp_path)) in err[0] and "warning" in err[0], err
    third = _choose()
    assert "cached" in third["reason"] and capsys.readouterr().err == ""
    assert (third["engine"], third["precision"]) == (again["engine"], again["precision"])
    return again


def _with(entry, **changes):
    return {**entry, **changes}


def _ms_with(entry, **ms):
    return {**entry, "ms": {**entry["ms"], **{k.replace("__", "/"): v for k, v in ms.items()}}}


DAMAGED_ENTRIES = {
    "no ms": lambda e: {k: v for k, v in e.items() if k != "ms"},
    "a string": lambda e: "garbage",
    "null": lambda e: None,
    "a list": lambda e: [e],
    "ms a list": lambda e: _with(e, ms=[1.0, 2.0]),
    "negative time": lambda e: _ms_with(e, onnxruntime__fp32=-1.0),
    "zero time": lambda e: _ms_with(e, onnxruntime__fp32=0.0),
    "NaN time": lambda e: _ms_with(e, onnxruntime__fp32=math.nan),
    "infinite time": lambda e: _ms_with(e, onnxruntime__int8=math.inf),
    "time a string": lambda e: _ms_with(e, onnxruntime__fp32="0.5"),
    "time a bool": lambda e: _ms_with(e, onnxruntime__fp32=True),
    "unknown variant timed": lambda e: _ms_with(e, tensorrt__fp32=0.1),
    "a candidate untimed": lambda e: _with(e, ms={FP32: e["ms"][FP32]}),
    "no times": lambda e: _with(e, ms={}),
    "unknown engine picked": lambda e: _with(e, pick=["tensorrt", "fp32"]),
    "unknown precision picked": lambda e: _with(e, pick=["onnxruntime", "fp16"]),
    "pick of one name": lambda e: _with(e, pick=["onnxruntime"]),
    "pick a string": lambda e: _with(e, pick="onnxruntime/fp32"),
    "an extra key": lambda e: _with(e, note="hand-edited"),
    "another model's name": lambda e: _with(e, model="../../etc/passwd"),
    "other flags": lambda e: _with(e, flags=["avx2"]),
    "another cpu": lambda e: _with(e, cpu=123),
    "a bad date": lambda e: _with(e, measured="yesterday"),
    "failed a list": lambda e: _with(e, failed=[]),
    "a failure of a timed variant": lambda e: _with(e, failed={FP32: "boom"}),
}


@pytest.mark.parametrize("damage", DAMAGED_ENTRIES.values(), ids=DAMAGED_ENTRIES.keys())
def test_a_damaged_entry_is_measured_again_with_one_warning(damage, timings, tmp_path, capsys):
    first = _choose()
    assert "measured now" in first["reason"]
    _damage(tmp_path, damage)
    capsys.readouterr()
    again = _assert_measured_again_once(tmp_path, capsys)
    assert (again["engine"], again["precision"]) == ("onnxruntime", "fp32")


UNREADABLE_FILES = {
    "empty": b"",
    "not JSON": b"this is not json\n",
    "cut short": b'{"abc": {"pick": ["onnxruntime", ',
    "a list": b"[]",
    "a string": b'"variants"',
    "null": b"null",
    "not text": b"\xff\xfe\x00\x81",
    "nested too deep": b"[" * 100_000,
}


@pytest.mark.parametrize("content", UNREADABLE_FILES.values(), ids=UNREADABLE_FILES.keys())
def test_an_unreadable_cache_file_is_measured_again_with_one_warning(content, timings, tmp_path, capsys):
    _cache_file(tmp_path).parent.mkdir(parents=True)
    _cache_file(tmp_path).write_bytes(content)
    _assert_measured_again_once(tmp_path, capsys)
    json.loads(_cache_file(tmp_path).read_text())   # rewritten whole


CONTRADICTIONS = {
    # the walkthrough's case: fp32 clearly faster, the pick hand-edited to the slower variant
    "slower picked": ({FP32: 0.70, INT8: 0.94}, lambda e: _with(e, pick=["onnxruntime", "int8"])),
    # faster, but by less than MIN_GAIN: the rule keeps the reference
    "pick within MIN_GAIN": ({FP32: 1.00, INT8: 0.97}, lambda e: _with(e, pick=["onnxruntime", "int8"])),
    # the pick left alone, the times edited under it
    "times edited": ({FP32: 0.70, INT8: 0.94}, lambda e: _ms_with(e, onnxruntime__int8=0.30)),
}


@pytest.mark.parametrize("times,damage", CONTRADICTIONS.values(), ids=CONTRADICTIONS.keys())
def test_a_cached_pick_that_contradicts_its_timings_is_not_trusted(times, damage, timings, tmp_path, capsys):
    timings.update(times)
    first = _choose()
    assert (first["engine"], first["precision"]) == ("onnxruntime", "fp32")
    _damage(tmp_path, damage)
    capsys.readouterr()
    again = _assert_measured_again_once(tmp_path, capsys)
    assert (again["engine"], again["precision"]) == ("onnxruntime", "fp32")


def test_one_rule_picks_for_a_fresh_and_a_cached_measurement():
    cands = [("onnxruntime", "fp32"), ("onnxruntime", "int8"), ("openvino", "bf16")]
    assert vc.pick_fastest({FP32: 1.0, INT8: 0.5, "openvino/bf16": 0.7}, cands) == ("onnxruntime", "int8")
    assert vc.pick_fastest({FP32: 1.0, INT8: 0.97}, cands) == ("onnxruntime", "fp32")     # < MIN_GAIN
    assert vc.pick_fastest({INT8: 0.9, "openvino/bf16": 0.9}, cands) == ("onnxruntime", "int8")  # tie: order
    assert vc.pick_fastest({FP32: 1.0, "openvino/bf16": 0.5}, cands) == ("openvino", "bf16")


def test_a_valid_cached_pick_is_used_without_a_warning(timings, tmp_path, capsys):
    timings.update({FP32: 1.0, INT8: 0.5})
    first = _choose()
    second = _choose()
    assert (first["precision"], second["precision"]) == ("int8", "int8")
    assert "cached" in second["reason"] and capsys.readouterr().err == ""
    assert second["measured_ms"] == first["measured_ms"]


def test_the_cached_reason_carries_the_same_exclusions(timings, tmp_path, monkeypatch, capsys):
    """After the first load the reason had dropped every exclusion ("no int8 file", "failed the
    accuracy rule", a variant that failed to load) and said "measured earlier" within one run."""
    real_open = vc.open_session

    def open_session(path, threads, engine, precision):
        if (engine, precision) == ("onnxruntime", "int8"):
            raise ModelError("stand-in: this engine cannot compile the graph")
        return real_open(path, threads, engine, precision)

    monkeypatch.setattr(vc, "open_session", open_session)
    first = _choose(engine="auto")
    second = _choose(engine="auto")
    assert "measured now" in first["reason"] and "measured now" not in second["reason"]
    assert "onnxruntime/int8 failed to load (stand-in" in first["reason"]
    assert any(n in first["reason"] for n in ("OpenVINO not installed", "openvino/bf16 failed the accuracy rule"))
    # the same times, exclusions and flags; only where the times came from differs
    assert second["reason"].split(": ", 1)[1] == first["reason"].split(": ", 1)[1]
    assert re.search(r"cached .*measured \d{4}-\d\d-\d\dT\d\d:\d\d:\d\dZ", second["reason"]), second["reason"]
    assert second["measured_ms"] == first["measured_ms"]
    assert capsys.readouterr().err == ""


def test_forced_isa_flags_are_reported(monkeypatch):
    """TRACK3D_ISA_FLAGS changes what auto believes: a benchmark record must be able to say so."""
    assert forced_isa_flags() is None
    monkeypatch.setenv("TRACK3D_ISA_FLAGS", "avx2, vnni")
    assert forced_isa_flags() == {"avx2", "vnni", "int8_dot"} == isa_flags()
    monkeypatch.setenv("TRACK3D_ISA_FLAGS", "")
    assert forced_isa_flags() == frozenset() == isa_flags()   # forced to none: fp32 only


def test_threads_writing_the_cache_never_leave_it_torn(tmp_path, monkeypatch):
    """A review: threads of one process wrote through one temp file named by the pid, and a torn
    file was renamed into place (reads found variants.json unreadable 185-276 times a run)."""
    import threading

    from track3d import variant_choice as vc

    monkeypatch.setenv("TRACK3D_CACHE_DIR", str(tmp_path))
    problems, stop = [], threading.Event()

    def write(k):
        for i in range(40):
            vc._cache_write(f"key{k}-{i}", {"x": "y" * 2000})

    def read():
        while not stop.is_set():
            problem = vc._cache_load()[1]
            if problem:
                problems.append(problem)

    readers = [threading.Thread(target=read) for _ in range(2)]
    writers = [threading.Thread(target=write, args=(k,)) for k in range(6)]
    for t in readers + writers:
        t.start()
    for t in writers:
        t.join()
    stop.set()
    for t in readers:
        t.join()
    assert not problems, problems[:3]
    assert not list(tmp_path.glob("*.tmp"))
