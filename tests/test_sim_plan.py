"""The data engine's plan: generators from the registry, the three splits, sensors per sequence,
user meshes (name + hash, never a path), points-only data, and one-line errors."""
from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("embreex")
trimesh = pytest.importorskip("trimesh")

from track3d.dataset import DATASET_JSON, Dataset, DatasetError  # noqa: E402

from track3d_sim import generators as G  # noqa: E402
from track3d_sim import sensors as S  # noqa: E402
from track3d_sim.cli import main  # noqa: E402
from track3d_sim.generate import RUN_FILE, dataset_info, generate, make_settings, plan_of  # noqa: E402
from track3d_sim.sequence import LEGACY_GENERATORS, USER, plan, resolve_unseen, split_categories  # noqa: E402
from track3d_sim.shapes import procedural_shape  # noqa: E402


def _quiet(msg):
    pass


@pytest.fixture
def legacy_registry(monkeypatch):
    """The registry of the first release: the three legacy families only, no named held-out
    generators (restored afterwards), so the plan's rules are tested on a known registry."""
    import track3d_sim.generate as gen_mod
    import track3d_sim.sequence as seq_mod
    monkeypatch.setattr(G, "GENERATORS", {k: v for k, v in G.GENERATORS.items() if k in LEGACY_GENERATORS})
    monkeypatch.setattr(seq_mod, "GENERATORS", G.GENERATORS)
    monkeypatch.setattr(gen_mod, "GENERATORS", G.GENERATORS)
    monkeypatch.setattr(seq_mod, "UNSEEN_GENERATORS", ())
    return G.GENERATORS


@pytest.fixture
def extra_generators(legacy_registry):
    """Two temporary generators registered on the legacy registry."""

    def lumpy(rng, volume, detail):
        return procedural_shape(2, rng, volume, min(detail, 3))

    def blob(rng, volume, detail):
        return procedural_shape(1, rng, volume, min(detail, 3))

    G.register(G.Generator("test_lumpy", lumpy, 2, True, "test generator"))
    G.register(G.Generator("test_blob", blob, 1, True, "test generator"))
    return ("test_lumpy", "test_blob")


def _check_splits(specs):
    by = {sp: [s for s in specs if s.split == sp] for sp in ("train", "test", "test_unseen")}
    gens = {sp: {s.generator for s in v} for sp, v in by.items()}
    fine = {sp: {s.fine_category for s in v} for sp, v in by.items()}
    assert not gens["test_unseen"] & gens["train"], "unseen split shares a generator with train"
    assert not gens["test_unseen"] & gens["test"]
    assert not fine["test"] & fine["train"], "test shares a fine category with train"
    assert gens["test"] <= gens["train"], "a generator of test never appears in train"
    return gens, fine


def test_plan_follows_the_registry(extra_generators):
    unseen, note = resolve_unseen(None, 10)
    assert unseen == extra_generators and "non-legacy" in note
    specs = plan(120, 60, 24, unseen, ("ideal",))
    gens, _ = _check_splits(specs)
    assert gens["test_unseen"] == set(extra_generators)
    assert gens["train"] == set(LEGACY_GENERATORS)
    # nothing held out without an unseen split: every registered generator is trained on
    specs = plan(120, 60, 0, (), ("ideal",))
    gens, _ = _check_splits(specs)
    assert gens["train"] == gens["test"] == set(G.GENERATORS)
    # the override
    unseen, note = resolve_unseen(["spinning_top", "test_blob"], 5)
    gens, _ = _check_splits(plan(120, 60, 24, unseen))
    assert gens["test_unseen"] == {"spinning_top", "test_blob"}
    assert "override" in note or "--unseen-generators" in note


def test_legacy_plan_keeps_the_first_release_categories(legacy_registry):
    cats = split_categories()
    assert [f"{g}/{t}" for g, t in cats["test"]] == [
        "contact_binary/0", "spinning_top/2", "irregular/4", "contact_binary/3", "spinning_top/5"]
    assert len(cats["train"]) == 13 and not cats["test_unseen"]


def test_fallback_holds_out_a_legacy_family(legacy_registry):
    unseen, note = resolve_unseen(None, 3)
    assert unseen == ("irregular",) and "fewer than" in note
    gens, _ = _check_splits(plan(40, 20, 6, unseen))
    assert gens["test_unseen"] == {"irregular"} and "irregular" not in gens["train"]


def test_extra_generator_dataset_reads_back(tmp_path, extra_generators, monkeypatch):
    monkeypatch.setitem(S.DEPTH_SENSORS, "test_noisy", S.DEPTH_SENSORS["ideal"])
    s = make_settings("tiny", seed=4, train=2, test=1, test_unseen=2, frames=2, sensors="ideal,test_noisy")
    out = generate(s, tmp_path / "d", progress=False, log=_quiet)
    data = Dataset(out)
    assert set(data.splits) == {"train", "test", "test_unseen"} and len(data.splits["test_unseen"]) == 2
    assert data.info["categories"]["unseen_generators"] == list(extra_generators)
    metas = {sp: [q.meta for q in data.sequences(sp)] for sp in data.splits}
    assert [m["generator"] for m in metas["test_unseen"]] == ["test_lumpy", "test_blob"]
    for m in metas["test_unseen"]:
        assert m["shape"]["family"] == m["generator"]
        assert m["family_index"] == G.coarse_index(m["generator"])
        assert m["family"] == ("irregular" if m["generator"] == "test_lumpy" else "spinning_top")
        assert m["fine_category"].startswith(m["generator"] + "/")
    assert [q.category for q in data.sequences("test_unseen")] == [2, 1]
    sensors = [m["sensor"] for sp in ("train", "test", "test_unseen") for m in metas[sp]]
    assert set(sensors) == {"ideal", "test_noisy"}
    assert data.info["sensors"]["per_split"]["train"] == {"ideal": 1, "test_noisy": 1}
    assert data.info["sensors"]["names"] == ["ideal", "test_noisy"]
    # the CLI of the stats accepts the new split
    assert main(["stats", str(out), "--split", "test_unseen", "--out", str(tmp_path / "s.png")]) == 0


@pytest.mark.parametrize("argv, needle", [
    (["--test-unseen", "1", "--unseen-generators", "no_such_shape"], "unknown shape generator 'no_such_shape'"),
    (["--unseen-generators", "irregular"], "--test-unseen"),
    (["--test-unseen", "1", "--unseen-generators", ",".join(G.GENERATORS)], "every generator"),
    (["--sensors", "ideal,lidar9000"], "unknown depth sensor 'lidar9000'"),
    (["--test", "-1"], "non-negative"),
])
def test_bad_plan_arguments(tmp_path, capsys, argv, needle):
    out = tmp_path / "bad"
    assert main(["generate", "--preset", "tiny", "--out", str(out), "--no-progress", *argv]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1, err
    assert not out.exists(), "settings errors must come before anything is written"


def test_points_only_with_an_image_sensor_is_refused(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(S.DEPTH_SENSORS, "stereo", S.DEPTH_SENSORS["ideal"])
    out = tmp_path / "po"
    assert main(["generate", "--preset", "tiny", "--out", str(out), "--no-progress", "--points-only",
                 "--sensors", "ideal,stereo"]) == 2
    err = capsys.readouterr().err
    assert "--points-only" in err and "stereo" in err and err.count("\n") == 1
    assert not out.exists()


def _mesh_dir(root: Path) -> Path:
    d = root / "meshes"
    d.mkdir()
    trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(d / "brick.ply")
    trimesh.creation.icosphere(subdivisions=2).export(d / "ball.obj")
    (d / "README.txt").write_text("not a mesh, and not a mesh extension: ignored")
    return d


@pytest.mark.parametrize("kind, needle", [("missing", "does not exist"), ("empty", "no mesh file"),
                                          ("garbage", "rock.obj")])
def test_bad_mesh_folder(tmp_path, capsys, kind, needle):
    d = tmp_path / "meshes"
    if kind != "missing":
        d.mkdir()
        (d / "notes.txt").write_text("hello")
    if kind == "garbage":
        trimesh.creation.icosphere(subdivisions=1).export(d / "good.ply")
        (d / "rock.obj").write_text("this is not a mesh\n\x00\x01 nonsense\n")
    out = tmp_path / "out"
    assert main(["generate", "--preset", "tiny", "--mesh-dir", str(d), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert needle in err and err.count("\n") == 1, err
    assert not out.exists()


def test_user_meshes_name_and_hash_never_a_path(tmp_path):
    d = _mesh_dir(tmp_path)
    single = tmp_path / "single" / "rock.stl"
    single.parent.mkdir()
    trimesh.creation.capsule(height=2.0, radius=0.7).export(single)
    for argv in (["--mesh-dir", str(d)], ["--mesh", f"{single}:5"]):
        out = tmp_path / ("dir" if argv[0] == "--mesh-dir" else "one")
        assert main(["generate", "--preset", "tiny", "--train", "3", "--test", "1", "--frames", "2",
                     "--out", str(out), "--no-progress", *argv]) == 0
        data = Dataset(out)
        files = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in [*d.iterdir(), single]}
        used = []
        for sp in ("train", "test"):
            for q in data.sequences(sp):
                m = q.meta
                assert m["family"] == USER and m["generator"] == USER and m["family_index"] == -1
                assert q.category == -1 and m["fine_category"].startswith("user/")
                assert m["shape"]["sha256"] == files[m["shape"]["source"]]
                used.append(m["shape"]["source"])
        if argv[0] == "--mesh-dir":
            assert used == ["ball.obj", "brick.ply", "ball.obj", "ball.obj"]  # name order, cycled by index
            assert [x["name"] for x in data.info["meshes"]] == ["ball.obj", "brick.ply"]
        else:
            assert set(used) == {"rock.stl"} and data.info["meshes"][0]["size_m"] == 5.0
        for js in [out / DATASET_JSON, out / RUN_FILE, *out.rglob("meta.json")]:
            text = js.read_text()
            assert str(tmp_path) not in text and str(tmp_path.resolve()) not in text, f"absolute path in {js}"
            assert "meshes" + "/" not in text
        # train and test still share no fine category
        cats = {sp: {q.meta["fine_category"] for q in data.sequences(sp)} for sp in ("train", "test")}
        assert not cats["train"] & cats["test"]


def test_user_meshes_have_no_unseen_split(tmp_path, capsys):
    d = _mesh_dir(tmp_path)
    assert main(["generate", "--preset", "tiny", "--mesh-dir", str(d), "--test-unseen", "1",
                 "--out", str(tmp_path / "o"), "--no-progress"]) == 2
    assert "procedural generators" in capsys.readouterr().err


def test_points_only_reads_back_and_boxnet_prepares_it(tmp_path):
    kw = dict(seed=9, train=2, test=1, frames=4)
    full = generate(make_settings("tiny", **kw), tmp_path / "full", progress=False, log=_quiet)
    po = generate(make_settings("tiny", points_only=True, **kw), tmp_path / "po", progress=False, log=_quiet)
    data, ref = Dataset(po), Dataset(full)
    assert data.info["points_only"] is True and ref.info["points_only"] is False
    assert not list(po.rglob("*/left")) and not list(po.rglob("*/right"))
    n_points = 0
    for sp in ("train", "test"):
        for q, r in zip(data.sequences(sp), ref.sequences(sp)):
            # the geometry (labels, depth) is the same as the full render's: only images are skipped
            for name in ("groundtruth_2d.txt", "groundtruth_3d.txt", "absence.label", "cut_by_image.label"):
                assert (q.path / name).read_bytes() == (r.path / name).read_bytes()
            for i in range(len(q)):
                assert (q.path / "depth" / f"{i + 1:06d}.png").read_bytes() == \
                       (r.path / "depth" / f"{i + 1:06d}.png").read_bytes()
                n_points += len(q.points(i))
            with pytest.raises(DatasetError, match="points-only"):
                q.image(0)
            with pytest.raises(DatasetError, match="points-only"):
                q.frame(0)
            assert q.meta["points_only"] is True and q.meta["frame_data"]["mean_object_dn"][0] is None
    assert n_points > 100
    assert main(["preview", str(po / "train" / "0001"), "--out", str(tmp_path / "p.png")]) == 2
    pytest.importorskip("torch")
    from track3d_train.boxnet.cli import main as boxnet_main
    cache = tmp_path / "cache.npz"
    assert boxnet_main(["prepare", "--data", str(po), "--split", "train", "--jitters", "1", "--max-points", "256",
                        "--min-points", "4", "--out", str(cache), "--quiet"]) == 0
    z = np.load(cache)
    assert len(z["offsets"]) > 1 and z["points"].shape[1] == 3


def test_settings_summary_lists_every_split():
    s = make_settings("tiny", test_unseen=2)
    info = dataset_info(s, plan_of(s))
    assert set(info["splits"]) == {"train", "test", "test_unseen"}
    assert len(info["splits"]["test_unseen"]) == 2
    assert info["categories"]["test_unseen_fine"] and not (set(info["categories"]["test_unseen_fine"])
                                                           & set(info["categories"]["train_fine"]))
    json.dumps(info)


def test_points_only_noisy_sensor_matches_the_full_render(tmp_path):
    """A range sensor in a points-only run measures from the left cast alone: its depth maps are
    the bytes of the full render's (the sensor noise has its own per-frame stream)."""
    kw = dict(seed=4, train=1, test=1, frames=3, sensors="tof,flash-lidar")
    full = generate(make_settings("tiny", **kw), tmp_path / "full", progress=False, log=_quiet)
    po = generate(make_settings("tiny", points_only=True, **kw), tmp_path / "po", progress=False, log=_quiet)
    ideal = generate(make_settings("tiny", seed=4, train=1, test=1, frames=3), tmp_path / "ideal",
                     progress=False, log=_quiet)
    differs = 0
    for sp in ("train", "test"):
        for q, r, g in zip(Dataset(po).sequences(sp), Dataset(full).sequences(sp), Dataset(ideal).sequences(sp)):
            assert q.meta["sensor"] in ("tof", "flash-lidar") and q.meta["sensor"] == r.meta["sensor"]
            for i in range(len(q)):
                name = f"depth/{i + 1:06d}.png"
                assert (q.path / name).read_bytes() == (r.path / name).read_bytes()
                differs += (q.path / name).read_bytes() != (g.path / name).read_bytes()
    assert differs > 0  # the sensor really changed the depth


def test_shipped_registry_holds_out_the_named_generators():
    """The real registry: test_unseen is exactly UNSEEN_GENERATORS, none of it in train or test."""
    import track3d_sim.sequence as seq_mod
    unseen, note = resolve_unseen(None, 6)
    assert unseen == seq_mod.UNSEEN_GENERATORS and "UNSEEN_GENERATORS" in note
    gens, _ = _check_splits(plan(90, 45, 12, unseen))
    assert gens["test_unseen"] == set(unseen)
    assert gens["train"] == set(G.default_generators()) - set(unseen)


def test_opt_in_generators_only_in_runs_that_name_them(tmp_path):
    """An opt-in generator (superquadric) is in no default run: plan, fine categories, the
    run's identity and dataset.json are those of the registry without it; --generators draws
    train and test from the named ones only (test_unseen keeps the held-out rule)."""
    assert "superquadric" in G.GENERATORS and "superquadric" not in G.default_generators()
    assert "gaussian_sphere" in G.GENERATORS and "gaussian_sphere" not in G.default_generators()
    assert "aggregate" in G.GENERATORS and "aggregate" not in G.default_generators()
    unseen, _ = resolve_unseen(None, 4)
    gens, _ = _check_splits(plan(60, 30, 4, unseen))
    assert "superquadric" not in gens["train"] | gens["test"]
    s = make_settings("tiny", 0, train=2, test=1, test_unseen=1, frames=1)
    info = dataset_info(s, plan_of(s))
    assert "superquadric" not in info["categories"]["generators"] and "shape_generators" not in info["categories"]
    assert "superquadric" not in json.dumps(info)

    s = make_settings("tiny", 0, train=12, test=4, test_unseen=2, frames=1,
                      shape_generators="superquadric,bilobate")
    specs = plan_of(s)
    gens, _ = _check_splits(specs)
    assert gens["train"] == gens["test"] == {"bilobate", "superquadric"}
    assert gens["test_unseen"] == set(unseen)
    info = dataset_info(s, specs)
    assert info["categories"]["shape_generators"] == ["bilobate", "superquadric"]   # registry order
    assert info["categories"]["generators"][-1] == "superquadric"
    assert info["generator"]["settings"]["shape_generators"] == ["bilobate", "superquadric"]


def test_generators_flag_errors_are_one_line(capsys, tmp_path):
    for args, msg in ((["--generators", "cube"], "unknown shape generator 'cube' in --generators"),
                      (["--generators", "fragment", "--test-unseen", "2"], "hold out every generator")):
        rc = main(["generate", "--preset", "tiny", "--train", "1", "--test", "0", "--frames", "1",
                   "--out", str(tmp_path / "d"), *args])
        err = capsys.readouterr().err
        assert rc != 0 and msg in err and "Traceback" not in err


def test_an_opt_in_generator_held_out_alone_is_in_the_category_list(tmp_path, capsys):
    """--unseen-generators may name an opt-in generator that --generators does not: its bodies
    are the test_unseen split's, so it is among the run's body sources (the fine-category list);
    it used to crash on the first unseen sequence (ValueError: not in list)."""
    out = tmp_path / "d"
    rc = main(["generate", "--preset", "tiny", "--train", "1", "--test", "0", "--test-unseen", "1", "--frames", "1",
               "--points-only", "--generators", "bilobate", "--unseen-generators", "superquadric",
               "--out", str(out), "--quiet"])
    err = capsys.readouterr().err
    assert rc == 0 and "Traceback" not in err, err
    info = json.loads((out / DATASET_JSON).read_text())
    fine = info["categories"]["fine"]
    assert "superquadric" in info["categories"]["generators"]
    seq = Dataset(out).sequences("test_unseen")[0]
    meta = json.loads((out / "test_unseen" / seq.name / "meta.json").read_text())
    assert meta["generator"] == "superquadric"
    assert fine[meta["fine_index"]] == meta["fine_category"] and meta["fine_category"].startswith("superquadric/")
    # a run whose held-out generators are default ones keeps its identity (resumable as before)
    s = make_settings("tiny", 0, train=2, test=1, test_unseen=1, frames=1, shape_generators="superquadric,bilobate")
    assert dataset_info(s, plan_of(s))["categories"]["generators"] == \
        [g for g, v in G.GENERATORS.items() if v.default or g == "superquadric"]


def test_a_small_train_split_that_misses_test_generators_is_named():
    """The train split cycles generator by generator: 18 sequences (the small preset) held 5 of
    the 9 generators the test split has, without a word (docs/simulator.md had said every test
    generator is in train)."""
    from track3d_sim.generate import train_coverage_note

    note = train_coverage_note(plan(18, 9, 0))
    assert note and "fragment" in note and "top_shape" in note and "contact_binary" not in note
    assert train_coverage_note(plan(40, 9, 0)) is None
    assert train_coverage_note(plan(0, 9, 0)) is None          # no train split: nothing to warn
