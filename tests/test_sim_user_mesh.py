"""User meshes (--mesh / --mesh-dir) the way published models come: wound inside out, damaged
(a NaN vertex, a truncated file), open, at sizes the scenes cannot hold, without :SIZE; split at
texture / normal seams, with zero-area faces, wound inconsistently, with OBJ relative indices,
written rotated (SIZE is along the body's axes); and the messages a user sees for a folder, a
file without an extension, an empty file, a file under another format's extension, a fin, a size
with a unit, and what --mesh-dir leaves out. Tiny meshes, 1 sequence, 3 frames."""
from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np

import pytest

pytest.importorskip("embreex")
trimesh = pytest.importorskip("trimesh")

from track3d.dataset import DATASET_JSON, GENERATE_RUN_FILE, Dataset  # noqa: E402

from track3d_sim import SimError  # noqa: E402
from track3d_sim.cli import main  # noqa: E402
from track3d_sim.generate import _identity, camera_of, generate, make_settings, plan_of  # noqa: E402
from track3d_sim.motion import DEPTH_RADIUS_MAX, radius_range  # noqa: E402
from track3d_sim.shapes import USER_MESH_LOADER, load_user_mesh, user_mesh_warnings  # noqa: E402


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


def _signed_volume(shape) -> float:
    v, f = shape.vertices, shape.faces
    return float(np.einsum("ij,ij->", v[f[:, 0]], np.cross(v[f[:, 1]], v[f[:, 2]]))) / 6.0


@pytest.mark.parametrize("most_inward", [False, True])
def test_closed_but_inconsistently_wound_mesh_is_made_consistent_and_outward(tmp_path, most_inward):
    """Before: kept as it was (faces wound inward never lit, no depth return) with a random inertia."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    faces = ball.faces[:, ::-1].copy() if most_inward else ball.faces.copy()
    faces[:40] = faces[:40, ::-1]  # a patch of faces wound the other way from the rest
    mesh = tmp_path / "patchy.obj"
    trimesh.Trimesh(ball.vertices, faces, process=False).export(mesh)
    shape = load_user_mesh(mesh, 6.0)
    assert shape.closed and shape.params["winding_repaired"] is True and "winding_consistent" not in shape.params
    assert "winding_flipped" not in shape.params  # the repair's own side, not the file's
    assert shape.inertia() is not None and _signed_volume(shape) > 0
    # every face outward: the same faces, vertex for vertex, as the well-wound ball's
    ref = load_user_mesh(_ball(tmp_path / "ball.obj"), 6.0)
    assert {tuple(np.roll(t, -int(np.argmin(t)))) for t in shape.faces} == \
        {tuple(np.roll(t, -int(np.argmin(t)))) for t in ref.faces}
    warn = user_mesh_warnings(shape, "patchy.obj")
    assert len(warn) == 1 and "patchy.obj" in warn[0] and "winding_repaired" in warn[0], warn


def _write_obj(path: Path, v, f, corner: str = "") -> Path:
    """An OBJ as exporters write one: corner "//n" gives every face its own normal (flat
    shading), "/t" every face corner its own texture coordinate (a seam along every edge)."""
    lines = [f"v {x:.8f} {y:.8f} {z:.8f}" for x, y, z in v]
    if corner == "//n":
        tri = np.asarray(v)[np.asarray(f)]
        n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        lines += [f"vn {x:.6f} {y:.6f} {z:.6f}" for x, y, z in n / np.linalg.norm(n, axis=1, keepdims=True)]
        lines += [f"f {a + 1}//{k + 1} {b + 1}//{k + 1} {c + 1}//{k + 1}" for k, (a, b, c) in enumerate(f)]
    elif corner == "/t":
        lines += [f"vt {(k % 97) / 97:.4f} {(k // 97) / 97:.4f}" for k in range(3 * len(f))]
        lines += [f"f {a + 1}/{3 * k + 1} {b + 1}/{3 * k + 2} {c + 1}/{3 * k + 3}" for k, (a, b, c) in enumerate(f)]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in f]
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.mark.parametrize("corner", ["//n", "/t"])
def test_seams_are_merged_and_an_inside_out_file_with_them_is_flipped(tmp_path, capsys, corner):
    """Before: trimesh split the vertices at every normal / texture seam, so the closed body read
    as open ("a damaged file"), got a random inertia, and inside out it was not flipped: black in
    every frame, no ToF return, labels as if all were well."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    out = _write_obj(tmp_path / "out.obj", ball.vertices, ball.faces, corner)
    shape = load_user_mesh(out, 6.0)
    assert shape.closed and shape.params["watertight"] is True and shape.params["vertices_merged"] > 0
    assert len(shape.vertices) == len(ball.vertices) and shape.inertia() is not None
    assert user_mesh_warnings(shape, "out.obj") == []
    inward = _write_obj(tmp_path / "in.obj", ball.vertices, ball.faces[:, ::-1], corner)
    assert _gen(f"{_ball(tmp_path / 'plain.obj')}:6", tmp_path / "a", "--sensors", "tof") == 0
    assert _gen(f"{inward}:6", tmp_path / "b", "--sensors", "tof") == 0
    warn = _warnings(capsys)
    assert len(warn) == 1 and "in.obj" in warn[0] and "inside out" in warn[0], warn
    a, b = tmp_path / "a" / "test" / "0001", tmp_path / "b" / "test" / "0001"
    for rel in ("groundtruth_3d.txt", "depth/000002.png", "left/000002.png"):
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel  # lit and seen as the plain file
    meta = json.loads((b / "meta.json").read_text())
    assert meta["shape"]["winding_flipped"] is True and meta["motion"]["inertia_source"] == "mesh"


@pytest.mark.parametrize("extra", ["repeated", "collinear"])
def test_a_zero_area_face_does_not_open_a_closed_mesh(tmp_path, extra):
    """Before: one extra face (a, a, b), or (a, b, midpoint of ab), made the body "not closed"
    with a random inertia and a warning blaming a damaged file."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    v, f = ball.vertices, ball.faces
    a, b = f[0, 0], f[0, 1]
    if extra == "repeated":
        f = np.vstack([f, [a, a, b]])
    else:
        v = np.vstack([v, (v[a] + v[b]) / 2.0])
        f = np.vstack([f, [a, b, len(v) - 1]])
    shape = load_user_mesh(_write_obj(tmp_path / "ball.obj", v, f), 6.0)
    assert shape.closed and shape.params["degenerate_faces_dropped"] == 1
    assert len(shape.faces) == len(ball.faces) and len(shape.vertices) == len(ball.vertices)
    assert user_mesh_warnings(shape, "ball.obj") == [] and shape.inertia() is not None


def test_an_open_mesh_wound_inward_is_flipped(tmp_path):
    """Before: a mesh with a hole, wound inside out, was kept so: never lit, no depth return."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    outward = load_user_mesh(_write_obj(tmp_path / "open.obj", ball.vertices, ball.faces[12:]), 6.0)
    shape = load_user_mesh(_write_obj(tmp_path / "open_in.obj", ball.vertices, ball.faces[12:, ::-1]), 6.0)
    assert "winding_flipped" not in outward.params and shape.params["winding_flipped"] is True
    assert shape.params["inward_area_share"] > 0.9 and not shape.closed
    assert {tuple(np.roll(t, -int(np.argmin(t)))) for t in shape.faces} == \
        {tuple(np.roll(t, -int(np.argmin(t)))) for t in outward.faces}  # every face as the outward file's
    warn = user_mesh_warnings(shape, "open_in.obj")
    assert len(warn) == 2 and "inside out" in warn[0] and "flipped" in warn[0] and "not closed" in warn[1], warn


def test_obj_negative_indices_count_the_lines_read_so_far(tmp_path):
    """Before: trimesh counted -1 from the end of the file, and a file writing each triangle as
    three v lines and `f -3 -2 -1` loaded as 320 copies of its last triangle."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    lines = []
    for k, t in enumerate(ball.faces):
        lines += [f"v {x:.8f} {y:.8f} {z:.8f}" for x, y, z in ball.vertices[t]]
        lines.append("f -3 -2 -1" if k % 2 else "f -3//-1 -2//-1 -1//-1")
        if k % 2 == 0:
            lines.insert(-1, "vn 0 0 1")
    mesh = tmp_path / "soup.obj"
    mesh.write_text("\n".join(lines) + "\n")
    shape = load_user_mesh(mesh, 6.0)
    ref = load_user_mesh(_ball(tmp_path / "ball.obj"), 6.0)
    assert shape.closed and len(shape.faces) == len(ref.faces) and len(shape.vertices) == len(ref.vertices)
    assert np.allclose(np.sort(shape.vertices, axis=0), np.sort(ref.vertices, axis=0), atol=1e-6)
    assert _signed_volume(shape) == pytest.approx(_signed_volume(ref), rel=1e-6)
    mesh.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -4 -2 -1\n")
    with pytest.raises(SimError, match=r"soup.obj line 4: face index -4 points before the first v line"):
        load_user_mesh(mesh, 6.0)


def test_size_is_the_length_along_the_body_axes(tmp_path):
    """Before: the largest side of the box in the file's axes: a 20:1 rod written diagonally
    came out 13.9 m long with :8. The refused range of SIZE is still the one the loader holds."""
    rod = trimesh.creation.box(extents=(20.0, 1.0, 1.0))
    rot = trimesh.geometry.align_vectors([1.0, 0.0, 0.0], np.ones(3) / np.sqrt(3.0))
    rod.apply_transform(rot)
    assert max(rod.extents) < 13.0  # written along a diagonal of the file's axes
    rod.export(tmp_path / "rod.ply")
    shape = load_user_mesh(tmp_path / "rod.ply", 8.0)
    axis = rot[:3, 0]  # the rod's long axis in the file
    along = shape.vertices @ axis
    assert along.max() - along.min() == pytest.approx(8.0, rel=1e-3)
    # an axis-aligned body keeps its box: SIZE is its largest extent, exactly
    assert load_user_mesh(_ball(tmp_path / "ball.obj"), 6.0).extent.max() == pytest.approx(6.0, rel=1e-9)
    with pytest.raises(SimError) as e:
        make_settings("tiny", meshes=[{"path": str(tmp_path / "rod.ply"), "size_m": 500.0}])
    lo, hi = (float(x) for x in re.search(r"SIZE in ([\d.]+)-([\d.]+) m", str(e.value)).groups())
    for size in (lo * 1.01, hi * 0.99):
        make_settings("tiny", meshes=[{"path": str(tmp_path / "rod.ply"), "size_m": size}])
    for size in (lo * 0.97, hi * 1.03):
        with pytest.raises(SimError, match="SIZE"):
            make_settings("tiny", meshes=[{"path": str(tmp_path / "rod.ply"), "size_m": size}])


def test_a_user_mesh_run_of_the_old_loader_is_not_resumed(tmp_path, capsys):
    """The same command renders another body with this loader (SIZE along the body's axes,
    repairs): a run it started is refused, not completed with a mix of both."""
    mesh = _ball(tmp_path / "ball.obj")
    out = tmp_path / "o"
    assert _gen(f"{mesh}:6", out) == 0
    run = out / GENERATE_RUN_FILE
    old = json.loads(run.read_text())
    assert old["meshes"][0]["loader"] == USER_MESH_LOADER
    for m in old["meshes"]:
        del m["loader"]  # as the loader before the version was recorded wrote it
    run.write_text(json.dumps(old))
    (out / DATASET_JSON).unlink()
    capsys.readouterr()
    assert _gen(f"{mesh}:6", out) == 2
    err = _one_error(capsys)
    assert "different settings (meshes)" in err
    # a procedural run's identity is as it was: no mesh, no loader
    ident = _identity(make_settings("tiny"))
    assert ident["meshes"] == [] and "loader" not in json.dumps(ident)


def _fin(path: Path) -> Path:
    """A closed ball with a fin: two faces on one of its edges (three faces or more on an edge)."""
    ball = trimesh.creation.icosphere(subdivisions=2)
    a, b = ball.faces[0, :2]
    v = np.vstack([ball.vertices, (ball.vertices[a] + ball.vertices[b]) * 0.75])
    f = np.vstack([ball.faces, [[a, b, len(v) - 1], [b, a, len(v) - 1]]])
    return _write_obj(path, v, f)


def test_messages_name_what_is_wrong(tmp_path, capsys, monkeypatch):
    """Before: an empty file and a file under another format's extension were "not a triangle
    mesh (no faces found)"; a fin was "0 open edges: holes"; :0.5km was "does not exist"."""
    (tmp_path / "empty.obj").write_bytes(b"")
    with pytest.raises(SimError, match=r"empty.obj is empty \(0 bytes\)"):
        load_user_mesh(tmp_path / "empty.obj", 5.0)
    ball = trimesh.creation.icosphere(subdivisions=1)
    (tmp_path / "stl_as.obj").write_bytes(trimesh.exchange.stl.export_stl(ball))
    (tmp_path / "obj_as.stl").write_text(_ball(tmp_path / "ball.obj").read_text())
    for name, looks in (("stl_as.obj", "STL"), ("obj_as.stl", "OBJ")):
        with pytest.raises(SimError) as e:
            load_user_mesh(tmp_path / name, 5.0)
        msg = str(e.value)
        assert name in msg and f"looks like {looks}" in msg and "chosen by the extension" in msg, msg
        assert "\n" not in msg
    shape = load_user_mesh(_fin(tmp_path / "fin.obj"), 5.0)
    warn = user_mesh_warnings(shape, "fin.obj")
    assert len(warn) == 1 and "non-manifold edges (1 edge shared by more than two faces" in warn[0], warn
    assert "open edges" not in warn[0] and "hole" not in warn[0]
    monkeypatch.chdir(tmp_path)
    with pytest.raises(SystemExit):
        _gen("ball.obj:0.5km", Path("o"))
    err = capsys.readouterr().err
    assert "plain number of metres" in err and "ball.obj:500" in err and "does not exist" not in err, err
    assert err.count("\n") == 1 and "Traceback" not in err


def test_mesh_dir_skips_hidden_files_and_names_what_it_leaves_out(tmp_path):
    """Before: macOS's `._ball.obj` beside ball.obj failed the run as not a mesh; files of other
    extensions were left out without a word, and so were meshes past the sequences' count."""
    d = tmp_path / "meshes"
    d.mkdir()
    for name in ("a.obj", "b.obj", "c.obj"):
        _ball(d / name)
    (d / "._a.obj").write_bytes(b"\x00\x05\x16\x07" + b"\x00" * 60)  # AppleDouble metadata
    (d / "notes.txt").write_text("where the meshes come from")
    s = make_settings("tiny", train=2, test=1, mesh_dir=str(d))
    assert [m["name"] for m in s["meshes"]] == ["a.obj", "b.obj", "c.obj"]
    assert len(s["mesh_warnings"]) == 2, s["mesh_warnings"]
    skipped, unused = s["mesh_warnings"]
    assert "notes.txt" in skipped and "._a.obj" not in skipped
    assert "c.obj" in unused and "a.obj" not in unused and "b.obj" not in unused and "2 sequences" in unused
    used = {spec.mesh for spec in plan_of(s)}
    assert used == {0, 1}  # what the warning says: mesh 2 is the body of no sequence
    s = make_settings("tiny", train=3, test=1, mesh_dir=str(d))
    assert not any("not used" in w for w in s["mesh_warnings"])


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


def test_consistent_winding_is_linear_and_right_on_a_large_mesh():
    """trimesh.repair.fix_winding took ~90 us a face (minutes on a 2-million-face shape model,
    loaded once per sequence); the walk that replaced it had overflowed scipy's int32
    predecessors past 46,000 faces and left such a mesh inconsistent. Two parts, each with half
    its faces flipped at random: every edge runs both ways afterwards."""
    import trimesh

    from track3d_sim.shapes import consistent_winding

    m = trimesh.creation.icosphere(subdivisions=6)   # 81,920 faces
    n = len(m.vertices)
    f = np.concatenate([m.faces, m.faces + n])
    rng = np.random.default_rng(0)
    flip = rng.random(len(f)) < 0.5
    f[flip] = f[flip][:, ::-1]
    g = consistent_winding(f)
    directed = np.stack([g[:, [0, 1, 2]].reshape(-1), g[:, [1, 2, 0]].reshape(-1)], axis=1)
    assert len(np.unique(directed, axis=0)) == len(directed)   # no edge run the same way twice
    assert np.array_equal(np.sort(g, axis=1), np.sort(f, axis=1))   # the same faces, reordered only


def test_a_mesh_loaded_again_comes_from_the_cache_as_a_copy_until_the_file_changes(tmp_path):
    """A run loads each mesh once to check it and once per sequence (seconds a load for a
    2-million-face model): the last files loaded are kept, each caller gets its own copy, and an
    edited file is read again."""
    import os

    import trimesh

    from track3d_sim import shapes

    f = tmp_path / "b.obj"
    trimesh.creation.icosphere(subdivisions=2).export(f)
    a = shapes.load_user_mesh(f, 4.0)
    a.vertices *= 2.0
    a.params["mine"] = 1
    b = shapes.load_user_mesh(f, 4.0)
    assert np.ptp(b.vertices, axis=0).max() == pytest.approx(4.0) and "mine" not in b.params
    trimesh.creation.icosphere(subdivisions=1).export(f)
    os.utime(f, ns=(f.stat().st_atime_ns, f.stat().st_mtime_ns + 10**9))
    assert len(shapes.load_user_mesh(f, 4.0).faces) == 80


def test_every_part_of_a_mesh_is_turned_out_on_its_own_and_many_parts_take_one_walk(tmp_path):
    """Parts wound each by its first face, then one flip by the whole mesh's volume, had left a
    small part inside out beside a large one (reported "repaired", its inertia from a negative
    volume); and a walk started once per part was quadratic in the parts (21 s for 32,000
    boulders). A body of 3,000 tetrahedra, half of them inside out, some with one face flipped
    inside: each comes out facing out."""
    import trimesh

    from track3d_sim.shapes import consistent_winding, face_parts, load_user_mesh, outward_parts

    tet = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    out = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])   # outward
    rng = np.random.default_rng(1)
    v, f = [], []
    for k in range(3000):
        faces = out + 4 * k
        if k % 2:
            faces = faces[:, ::-1]            # the part inside out
        if k % 3 == 0:
            faces[0] = faces[0, ::-1]         # and one face wound against its part
        v.append(tet * 0.1 + rng.uniform(-5, 5, 3))
        f.append(faces)
    v, f = np.concatenate(v), np.concatenate(f)
    g, turned = outward_parts(v, consistent_winding(f))
    labels = face_parts(g)
    a, b, c = v[g[:, 0]], v[g[:, 1]], v[g[:, 2]]
    vol = np.bincount(labels, weights=np.einsum("ij,ij->i", a, np.cross(b, c)))
    assert len(vol) == 3000 and np.all(vol > 0)
    # through the loader: two shells, the small one inside out, none repaired
    big = trimesh.creation.icosphere(subdivisions=2, radius=2.0)
    small = trimesh.creation.icosphere(subdivisions=1, radius=0.5)
    sf = small.faces[:, ::-1] + len(big.vertices)
    mesh = trimesh.Trimesh(np.concatenate([big.vertices, small.vertices + [3.0, 0, 0]]),
                           np.concatenate([big.faces, sf]), process=False)
    mesh.export(tmp_path / "binary.obj")
    shape = load_user_mesh(tmp_path / "binary.obj", 5.0)
    assert shape.params.get("parts_flipped") == 1 and shape.closed
    parts = face_parts(shape.faces)
    a, b, c = (shape.vertices[shape.faces[:, k]] for k in range(3))
    assert np.all(np.bincount(parts, weights=np.einsum("ij,ij->i", a, np.cross(b, c))) > 0)

