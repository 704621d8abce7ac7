"""User meshes (--mesh / --mesh-dir) the way published models come: wound inside out, damaged
(a NaN vertex, a truncated file), open, at sizes the scenes cannot hold, without :SIZE; and the
messages a user sees for a folder or a file without an extension. Tiny meshes, 1 sequence, 3 frames."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

pytest.importorskip("embreex")
trimesh = pytest.importorskip("trimesh")

from track3d.dataset import DATASET_JSON, GENERATE_RUN_FILE, Dataset  # noqa: E402

from track3d_sim import SimError  # noqa: E402
from track3d_sim.cli import main  # noqa: E402
from track3d_sim.generate import camera_of, generate, make_settings  # noqa: E402
from track3d_sim.motion import DEPTH_RADIUS_MAX, radius_range  # noqa: E402
from track3d_sim.shapes import load_user_mesh  # noqa: E402


def _ball(path: Path, inward: bool = False) -> Path:
    m = trimesh.creation.icosphere(subdivisions=2)
    if inward:
        m.invert()
    m.export(path)
    return path


def _gen(mesh_arg: str, out: Path, *extra: str) -> int:
    return main(["generate", "--preset", "tiny", "--train", "0", "--test", "1", "--frames", "3", "--quiet",
                 "--mesh", mesh_arg, "--out", str(out), *extra])


def _warnings(capsys) -> list[str]:
    """The warning lines of a run's stderr (the last line is the run's summary)."""
    return [line for line in capsys.readouterr().err.splitlines() if line.startswith("warning:")]


def _one_error(capsys) -> str:
    err = capsys.readouterr().err
    assert err.startswith("track3d-sim: error: ") and err.count("\n") == 1 and "Traceback" not in err, err
    return err


def test_inside_out_mesh_is_flipped_and_gives_the_outward_dataset(tmp_path, capsys):
    """Before: never lit, no ToF returns, a random inertia, and meta said nothing."""
    assert _gen(f"{_ball(tmp_path / 'out.obj')}:6", tmp_path / "a", "--sensors", "tof") == 0
    assert _warnings(capsys) == []  # a well-formed mesh
    assert _gen(f"{_ball(tmp_path / 'in.obj', inward=True)}:6", tmp_path / "b", "--sensors", "tof") == 0
    warn = _warnings(capsys)
    assert len(warn) == 1 and "in.obj" in warn[0] and "inside out" in warn[0], warn
    a, b = tmp_path / "a" / "test" / "0001", tmp_path / "b" / "test" / "0001"
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file() and p.name != "meta.json")
    assert len(files) > 8
    for rel in files:  # labels, depth and images: the same bytes
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    ma, mb = (json.loads((d / "meta.json").read_text()) for d in (a, b))
    assert mb["shape"]["winding_flipped"] is True and "winding_flipped" not in ma["shape"]
    assert mb["motion"]["inertia_source"] == ma["motion"]["inertia_source"] == "mesh"
    seq = Dataset(tmp_path / "b").sequences("test")[0]
    assert all(len(seq.points(i)) > 100 for i in range(3))  # the ToF sees the body


@pytest.mark.parametrize("bad", ["nan", "inf"])
def test_non_finite_vertex_is_refused(tmp_path, capsys, bad):
    """Before: trimesh's processing dropped the vertex, a hole was punched, exit 0."""
    src = _ball(tmp_path / "ball.obj").read_text().splitlines()
    k = [i for i, line in enumerate(src) if line.startswith("v ")][5]
    src[k] = f"v {bad} 0.1 0.2"
    mesh = tmp_path / "damaged.obj"
    mesh.write_text("\n".join(src) + "\n")
    assert _gen(f"{mesh}:5", tmp_path / "o") == 2
    err = _one_error(capsys)
    assert "damaged.obj" in err and "non-finite" in err
    assert not (tmp_path / "o").exists()
    with pytest.raises(SimError, match="non-finite"):
        load_user_mesh(mesh, 5.0)


def test_open_mesh_warns_and_spins_with_a_random_inertia(tmp_path, capsys):
    """Before: no warning, and the open mesh's volume integral was used as its inertia (the
    docs promised a random tensor)."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    mesh = tmp_path / "open.obj"
    trimesh.Trimesh(ball.vertices, ball.faces[12:], process=False).export(mesh)
    assert _gen(f"{mesh}:6", tmp_path / "o") == 0
    warn = _warnings(capsys)
    assert len(warn) == 1 and "open.obj" in warn[0] and "inertia" in warn[0] and "hole" in warn[0], warn
    meta = Dataset(tmp_path / "o").sequences("test")[0].meta
    assert meta["shape"]["watertight"] is False and meta["motion"]["inertia_source"] == "random"
    assert load_user_mesh(mesh, 6.0).inertia() is None


def test_truncated_file_warns(tmp_path, capsys):
    lines = _ball(tmp_path / "ball.obj").read_text().splitlines()
    first_face = next(i for i, line in enumerate(lines) if line.startswith("f "))
    mesh = tmp_path / "cut.obj"
    mesh.write_text("\n".join(lines[:first_face + 60]) + "\n")
    assert _gen(f"{mesh}:6", tmp_path / "o") == 0
    warn = _warnings(capsys)
    assert len(warn) == 1 and "cut.obj" in warn[0] and "not closed" in warn[0], warn


@pytest.mark.parametrize("size", ["0.001", "60", "300"])
def test_body_size_outside_the_scenes_is_refused(tmp_path, capsys, size):
    """Before: 300 m crashed in the depth writer with a traceback and left .partial-0001; 60 m
    ran with its far side beyond 45 m; 1 mm gave a target absent from every frame."""
    assert _gen(f"{_ball(tmp_path / 'ball.obj')}:{size}", tmp_path / "o") == 2
    err = _one_error(capsys)
    assert "ball.obj" in err and "--mesh" in err and ":SIZE" in err and " m" in err
    assert not (tmp_path / "o").exists()


def test_volume_scaled_needle_past_the_view_warns(tmp_path, capsys):
    """A needle scaled to the sampled volumes reaches a bounding radius of 14.6 m: within the
    depth the scenes hold (DEPTH_RADIUS_MAX), past what the view holds whole: a warning."""
    d = tmp_path / "meshes"
    d.mkdir()
    _ball(d / "ball.obj")
    trimesh.creation.box(extents=(400.0, 1.0, 1.0)).export(d / "needle.ply")
    assert main(["generate", "--preset", "tiny", "--test", "1", "--train", "0", "--frames", "3", "--quiet",
                 "--mesh-dir", str(d), "--out", str(tmp_path / "o")]) == 0
    warn = _warnings(capsys)
    assert any("needle.ply" in w and "fills this camera's view" in w for w in warn), warn


@pytest.mark.parametrize("end", ["lo", "hi"])
def test_bodies_at_the_size_bounds_are_in_view_and_within_45_m(tmp_path, end):
    """The quick test behind the range (motion.radius_range), on the small preset's camera: a
    round body (bounding radius = size / 2) at either bound is seen in every frame and its
    far side stays within the frustum's 45 m."""
    lo, hi = radius_range(camera_of(make_settings("small")).tan_half)
    r = lo * 1.001 if end == "lo" else hi * 0.999
    mesh = _ball(tmp_path / "ball.obj")
    kw = dict(train=0, test=1, frames=3, points_only=True)
    s = make_settings("small", meshes=[{"path": str(mesh), "size_m": 2 * r}], **kw)
    seq = Dataset(generate(s, tmp_path / "o", progress=False, log=lambda m: None)).sequences("test")[0]
    assert not seq.absent.any()
    pixels = seq.meta["frame_data"]["object_pixels"]
    assert min(pixels) >= 100, pixels  # about the smallest procedural bodies' far end, not a speck
    for i in range(3):
        assert seq.points(i)[:, 2].max() <= 45.0
    for bad in (lo * 0.99, DEPTH_RADIUS_MAX * 1.01):
        with pytest.raises(SimError, match="SIZE"):
            make_settings("small", meshes=[{"path": str(mesh), "size_m": 2 * bad}], **kw)
    # past the view but within the depth: held, with a warning (a narrow camera's procedural
    # bodies are that large too)
    s = make_settings("small", meshes=[{"path": str(mesh), "size_m": 2 * hi * 1.01}], **kw)
    assert any("fills this camera's view" in w for w in s["meshes"][0]["warnings"])


def test_a_volume_scaled_mesh_is_held_at_a_narrow_camera_as_procedural_bodies_are(tmp_path):
    """A review: at 30 degrees a mesh without :SIZE was refused (radii 2.1-8.4 m against 7.4 m)
    where procedural bodies of the same volumes (up to 9.7 m) are generated."""
    mesh = _ball(tmp_path / "ball.obj")
    s = make_settings("tiny", meshes=[{"path": str(mesh)}], fov_x_deg=30.0, width=640, height=480)
    assert s["meshes"][0]["name"] == "ball.obj"


def test_a_user_mesh_run_written_before_resumes(tmp_path, capsys):
    """Its run file still lists the procedural registry (dropped from a user-mesh run's identity
    since): the same run, resumed, not refused."""
    mesh = _ball(tmp_path / "ball.obj")
    out = tmp_path / "o"
    assert _gen(f"{mesh}:6", out) == 0
    run = out / GENERATE_RUN_FILE
    old = json.loads(run.read_text())
    old["generators"] = ["aggregate", "contact_binary"]
    run.write_text(json.dumps(old))
    (out / DATASET_JSON).unlink()
    assert _gen(f"{mesh}:6", out) == 0


def test_volume_scaled_mesh_records_its_size(tmp_path):
    """Before: size_m 1.0 beside an extent of several metres."""
    d = tmp_path / "meshes"
    d.mkdir()
    trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(d / "brick.ply")
    assert main(["generate", "--preset", "tiny", "--test", "1", "--train", "0", "--frames", "2", "--quiet",
                 "--mesh-dir", str(d), "--out", str(tmp_path / "o")]) == 0
    shape = Dataset(tmp_path / "o").sequences("test")[0].meta["shape"]
    assert shape["size_m"] == pytest.approx(max(shape["extent_m"])) and shape["size_m"] > 2.0


def test_user_mesh_run_lists_no_procedural_generators(tmp_path):
    assert _gen(f"{_ball(tmp_path / 'ball.obj')}:6", tmp_path / "o") == 0
    info = json.loads((tmp_path / "o" / DATASET_JSON).read_text())
    assert "generators" not in info["generator"]["settings"]
    assert info["generator"]["settings"]["meshes"][0]["name"] == "ball.obj"
    assert info["categories"]["generators"] == ["user"]


def test_a_folder_given_to_mesh_points_to_mesh_dir(tmp_path, capsys):
    (tmp_path / "rocks").mkdir()
    assert _gen(str(tmp_path / "rocks"), tmp_path / "o") == 2
    err = _one_error(capsys)
    assert "--mesh-dir" in err and "does not exist" not in err


def test_a_file_without_extension_is_named_as_given(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    Path("rock").write_bytes(_ball(tmp_path / "ball.obj").read_bytes())
    assert _gen("rock:5", Path("o")) == 2
    err = _one_error(capsys)
    assert "user mesh rock " in err and "extension" in err and str(tmp_path) not in err, err


def test_closed_but_inconsistently_wound_mesh_warns_and_gets_a_random_inertia(tmp_path):
    from track3d_sim.shapes import user_mesh_warnings

    ball = trimesh.creation.icosphere(subdivisions=2)
    faces = ball.faces.copy()
    faces[:40] = faces[:40, ::-1]  # a patch of faces wound inward, the rest outward
    mesh = tmp_path / "patchy.obj"
    trimesh.Trimesh(ball.vertices, faces, process=False).export(mesh)
    shape = load_user_mesh(mesh, 6.0)
    assert shape.params["watertight"] is True and shape.params["winding_consistent"] is False
    assert "winding_flipped" not in shape.params and shape.inertia() is None
    warn = user_mesh_warnings(shape, "patchy.obj")
    assert len(warn) == 1 and "not consistently wound" in warn[0]


def test_a_mesh_is_held_at_a_wide_camera_as_procedural_bodies_are(tmp_path):
    """A review: at 160-170 degrees the view's lower bound reaches 1-7 m and a mesh of a
    procedural body's size was refused; it is held, with a warning when small in the view."""
    mesh = _ball(tmp_path / "ball.obj")
    for fov, size in ((170.0, None), (160.0, 2.0)):
        m = {"path": str(mesh), **({"size_m": size} if size else {})}
        s = make_settings("tiny", meshes=[m], fov_x_deg=fov)
        assert s["meshes"][0]["name"] == "ball.obj"
    with pytest.raises(SimError, match="SIZE"):
        make_settings("tiny", meshes=[{"path": str(mesh), "size_m": 0.5}], fov_x_deg=170.0)
