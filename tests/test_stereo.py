"""Stereo depth (track3d.stereo): accuracy on a textured pair, holes where there is no texture,
the box window vs the full frame, Track3D and `track3d track --depth stereo` on a stereo pair."""
from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from track3d import Camera
from track3d.boxes import iou_3d
from track3d.dataset import FORMAT, FORMAT_VERSION, frame_name, write_depth_png, write_labels, write_rgb
from track3d.estimators import create_estimator
from track3d.stereo import StereoCloud, StereoMatcher, StereoParams
from track3d.tracker import TRACKING, Track3D
from track3d.trackers2d import OracleTracker

CAM = Camera.from_fov(640, 480, 45.0)
_K = np.random.default_rng(7).normal(0, 1, (40, 3)) * 25.0   # ~0.1 m features: 9 px at 9 m
_P = np.random.default_rng(8).uniform(0, 2 * np.pi, 40)


def _texture(p: np.ndarray) -> np.ndarray:
    """A 3D solid texture (values 0..1): the same surface point has the same value in both views."""
    return 0.5 + 0.5 * np.tanh(np.sin(p @ _K.T + _P).sum(-1) / 3.0)


def render_pair(cam: Camera, centre, radius: float, textureless_half: bool = False, background=None):
    """Left and right (H, W, 3) uint8 images of a textured Lambertian sphere (right camera at
    +baseline), and the left true depth (H, W) float64 (0 = background)."""
    c = np.asarray(centre, np.float64)
    imgs, zl = [], None
    for eye in (np.zeros(3), cam.right_offset):
        rays = cam.pixel_rays()
        oc = c - eye
        a = (rays * rays).sum(-1)
        b = -2.0 * rays @ oc
        disc = b * b - 4 * a * (oc @ oc - radius ** 2)
        hit = disc >= 0
        t = np.where(hit, (-b - np.sqrt(np.where(hit, disc, 0))) / (2 * a), 0.0)
        p = rays * t[..., None] + eye
        n = (p - c) / radius
        val = 40 + 200 * _texture(p - c) * np.clip(n @ np.array([-0.3, -0.3, -0.9]), 0.2, 1.0)
        if textureless_half:
            val = np.where(p[..., 0] > c[0], 120.0, val)
        img = np.zeros((cam.height, cam.width), np.float64) if background is None else background.astype(np.float64)
        img = np.where(hit, val, img)
        imgs.append(np.repeat(np.clip(np.rint(img), 0, 255).astype(np.uint8)[..., None], 3, -1))
        if zl is None:
            zl = np.where(hit, t, 0.0)
    return imgs[0], imgs[1], zl


def _box(z):
    vv, uu = np.nonzero(z > 0)
    return np.array([uu.min(), vv.min(), uu.max() + 1 - uu.min(), vv.max() + 1 - vv.min()], np.float64)


@pytest.fixture(scope="module")
def pair():
    return render_pair(CAM, (0.5, 0.2, 9.0), 2.0)


def test_stereo_recovers_depth_within_the_disparity_error(pair):
    left, right, z = pair
    m = StereoMatcher(CAM)
    zs = m.depth(left, right)
    inner = z > 0
    inner &= np.roll(inner, 6, 0) & np.roll(inner, -6, 0) & np.roll(inner, 6, 1) & np.roll(inner, -6, 1)
    ok = inner & (zs > 0)
    # the matcher fills > 90 % of the body; the ring dropped around each of its holes
    # (edge_erode_px) costs a few per cent more
    assert (inner & (StereoMatcher(CAM, edge_erode_px=0).depth(left, right) > 0)).sum() > 0.9 * inner.sum()
    assert ok.sum() > 0.85 * inner.sum()
    dd = CAM.disparity(zs[ok]) - CAM.disparity(z[ok])
    assert np.median(np.abs(dd)) < 0.25 and np.mean(np.abs(dd) < 1.0) > 0.98
    # depth error follows dz = z^2 / (fx B) * dd
    dz = np.abs(zs[ok] - z[ok])
    assert np.median(dz) < 0.25 * np.median(z[ok]) ** 2 / (CAM.fx * CAM.baseline_m)
    # the black background (no texture) gives no depth, except a thin band of foreground
    # fattening along the silhouette (the matching block straddles the edge)
    near = cv2.dilate((z > 0).astype(np.uint8), np.ones((2 * 8 + 1, 2 * 8 + 1), np.uint8)) > 0
    assert (zs[(z == 0) & ~near] > 0).sum() == 0


def test_stereo_leaves_holes_on_textureless_surfaces():
    left, right, z = render_pair(CAM, (0.0, 0.0, 9.0), 2.0, textureless_half=True)
    zs = StereoMatcher(CAM).depth(left, right)
    u = np.arange(CAM.width)[None, :].repeat(CAM.height, 0)
    cu = CAM.cx
    flat = (z > 0) & (u > cu + 15)          # the textureless half (minus the block around the seam)
    textured = (z > 0) & (u < cu - 15) & (u >= StereoMatcher(CAM).num_disparities)  # full search range
    assert (zs[flat] > 0).mean() < 0.05
    assert (zs[textured] > 0).mean() > 0.7


def test_a_body_at_the_left_border_has_depth_up_to_its_own_disparity():
    """OpenCV leaves its first numDisparities columns (208 px here) without disparity; a left
    pixel u needs only u - d >= 0. A textured sphere at the left border gets depth there, in the
    full frame and in the box window alike, and no pixel left of its own disparity does."""
    z_c = 9.0
    left_x = -CAM.cx / CAM.fx * z_c                  # the image's left border at the sphere's depth
    l, r, z = render_pair(CAM, (left_x + 1.5, 0.0, z_c), 2.0)
    m = StereoMatcher(CAM)
    u = np.arange(CAM.width)[None, :].repeat(CAM.height, 0)
    d_true = CAM.disparity(np.where(z > 0, z, 1.0))
    seen = (z > 0) & (u >= d_true + 8) & (u < m.num_disparities)   # in OpenCV's blind band, seen by both
    assert seen.sum() > 5000
    zf = m.depth(l, r)
    assert (zf[seen] > 0).mean() > 0.8
    ok = seen & (zf > 0)
    assert np.median(np.abs(CAM.disparity(zf[ok]) - d_true[ok])) < 0.25
    assert not np.any(zf[u < CAM.disparity(np.where(zf > 0, zf, np.inf))] > 0)   # u - d < 0: a hole
    box = _box(z)
    zw, (u0, _, v0, _) = m.depth_window(l, r, box)
    assert u0 == 0
    win = seen[v0:v0 + zw.shape[0], :zw.shape[1]]
    assert (zw[win] > 0).mean() > 0.8


def test_box_window_equals_full_frame_inside_the_box_and_matches_less(pair):
    """The window gives the full frame's depth inside the box while matching a fraction of the
    frame (the work, not a wall-clock time: a timed assertion failed on a loaded machine)."""
    left, right, z = pair
    m = StereoMatcher(CAM)
    box = _box(z)
    zf = m.depth(left, right)
    zw, w = m.depth_window(left, right, box)
    u0, u1, v0, v1 = w
    x0, y0, x1, y1 = int(box[0]), int(box[1]), int(box[0] + box[2]), int(box[1] + box[3])
    a = zf[y0:y1, x0:x1]
    b = zw[y0 - v0:y1 - v0, x0 - u0:x1 - u0]
    assert np.mean((a > 0) == (b > 0)) > 0.98
    both = (a > 0) & (b > 0)
    dd = np.abs(CAM.disparity(a[both]) - CAM.disparity(b[both]))
    assert np.mean(dd == 0) > 0.9 and np.mean(dd <= 0.25) > 0.99
    assert zw.shape == (v1 - v0, u1 - u0)
    assert zw.size < 0.6 * zf.size      # a 353 x 352 px body: its window (margin 32) is 56% of the frame


def test_window_of_a_bad_box_is_empty(pair):
    left, right, _ = pair
    m = StereoMatcher(CAM)
    for b in ([np.nan, 0, 10, 10], [10, 10, 0, 5], [5000, 10, 10, 10]):
        z, w = m.depth_window(left, right, b)
        assert w is None and z.size == 0
        assert m.points_window(left, right, b).shape == (0, 3)


def test_boxes_at_the_left_border_and_narrow_cameras_do_not_crash(pair):
    # regression: OpenCV fails on crops not wider than the search range + block (found running
    # `track3d track --depth stereo` on a simulated set: a box near the left border)
    left, right, _ = pair
    m = StereoMatcher(CAM)
    full = m.depth(left, right)
    for box in ([0, 100, 8, 40], [150, 200, 30, 30], [630, 0, 10, 10]):
        z, (u0, u1, v0, v1) = m.depth_window(left, right, box)
        assert z.shape == (v1 - v0, u1 - u0)
        assert np.mean((z > 0) == (full[v0:v1, u0:u1] > 0)) > 0.98   # aggregation starts at the crop
    narrow = Camera.from_fov(120, 90, 45.0)                  # search range 64 px
    ln, rn, _ = render_pair(narrow, (0.0, 0.0, 3.0), 1.0)
    assert StereoMatcher(narrow, z_min_m=0.3).depth(ln, rn).shape == (90, 120)   # 272 px > width


def test_stereo_refuses_mismatched_images(pair):
    left, right, _ = pair
    with pytest.raises(ValueError, match="camera is"):
        StereoMatcher(CAM).depth(left[:100], right[:100])
    with pytest.raises(ValueError, match="odd"):
        StereoParams(block_size=4)


def test_stereo_cloud_points_lie_on_the_sphere(pair):
    left, right, z = pair
    pts = StereoCloud(CAM).bind(left, right)(_box(z))
    assert pts.dtype == np.float32 and pts.shape[1] == 3 and len(pts) > 1000
    r = np.linalg.norm(pts - np.array([0.5, 0.2, 9.0]), axis=1)
    assert np.median(np.abs(r - 2.0)) < 0.1


def _sphere_frames(n, cam=CAM):
    out = []
    for k in range(n):
        c = (0.3 + 0.1 * k, 0.2, 9.0 + 0.2 * k)
        left, right, z = render_pair(cam, c, 2.0)
        out.append((left, right, _box(z), np.array([*c, 4.0, 4.0, 4.0]), z))
    return out


def test_track3d_runs_on_a_stereo_pair_callable():
    frames = _sphere_frames(4)
    gt2d = np.array([f[2] for f in frames])
    cloud = StereoCloud(CAM)
    t = Track3D(CAM, OracleTracker(gt2d), create_estimator("baseline"))
    t.init(frames[0][0], gt2d[0], category=0, points=cloud.bind(frames[0][0], frames[0][1]))
    assert np.all(np.isfinite(t.box3d))
    seen = []
    for left, right, b2, b3, _ in frames[1:]:
        src = cloud.bind(left, right)

        def spy(box, src=src):
            seen.append(np.asarray(box).copy())
            return src(box)
        out = t.update(left, spy)
        assert out.status == TRACKING and out.num_points > 1000
        # called with the 2D tracker's box widened by the frustum margin (5% of w, h on each side)
        m = t.frustum_margin
        np.testing.assert_allclose(seen[-1], [b2[0] - b2[2] * m / 2, b2[1] - b2[3] * m / 2,
                                              b2[2] * (1 + m), b2[3] * (1 + m)], rtol=1e-12)
        assert iou_3d(out.box3d, b3) > 0.2                   # the visible cap of the sphere


def _stereo_dataset(root: Path, cam: Camera, n: int = 4) -> Path:
    d = root / "test" / "s1"
    for sub in ("left", "right", "depth"):
        (d / sub).mkdir(parents=True)
    frames = _sphere_frames(n, cam)
    for i, (left, right, _, _, z) in enumerate(frames):
        write_rgb(d / "left" / frame_name(i), left)
        write_rgb(d / "right" / frame_name(i), right)
        write_depth_png(d / "depth" / frame_name(i), z)
    write_labels(d, np.array([f[2] for f in frames], dtype=np.float64), np.array([f[3] for f in frames]),
                 np.zeros(n), np.zeros(n), {"family_index": 0}, decimals_3d=6)
    (root / "dataset.json").write_text(json.dumps({"format": FORMAT, "version": FORMAT_VERSION,
                                                   "camera": cam.to_dict(), "splits": {"test": ["s1"]}}))
    return root


def test_cli_track_with_stereo_depth(tmp_path, capsys):
    from track3d.cli import main

    data = _stereo_dataset(tmp_path / "ds", CAM)
    res = tmp_path / "res"
    assert main(["track", "--data", str(data), "--tracker", "oracle", "--estimator", "baseline", "--depth", "stereo",
                 "--results", str(res), "--video", "none", "--quiet"]) == 0
    status = (res / "test" / "oracle+baseline-stereo" / "s1" / "s1_status.txt").read_text().split()
    assert status[0] == "init" and set(status[1:]) == {"tracking"}
    box3d = np.loadtxt(res / "test" / "oracle+baseline-stereo" / "s1" / "s1_3d_001.txt", delimiter=",")
    gt = np.loadtxt(data / "test" / "s1" / "groundtruth_3d.txt", delimiter=",")
    assert all(iou_3d(b, g) > 0.2 for b, g in zip(box3d[1:], gt[1:]))
    with pytest.raises(SystemExit):                          # argparse: one line, status 2
        main(["track", "--data", str(data), "--depth", "lidar", "--quiet"])
    assert "invalid choice: 'lidar'" in capsys.readouterr().err


def test_cli_stereo_options_set_the_matcher_and_name_and_key_the_results(tmp_path, capsys):
    """--stereo-option KEY=VALUE sets StereoParams for --depth stereo: its results get their own
    name, the run record holds the matcher's settings (so a run with other settings never shares
    a folder with them), and a bad key, value or use is one line."""
    from track3d.cli import main
    from track3d.evaluation.results import read_run_record, run_config_key

    data = _stereo_dataset(tmp_path / "ds", CAM)
    res = tmp_path / "res"
    base = ["track", "--data", str(data), "--tracker", "oracle", "--estimator", "baseline", "--results", str(res),
            "--video", "none", "--quiet"]
    assert main(base + ["--depth", "stereo", "--stereo-option", "follow_depth=0"]) == 0
    assert main(base + ["--depth", "stereo"]) == 0
    rec0 = read_run_record(res, "test", "oracle+baseline-stereo-follow_depth=0")
    rec = read_run_record(res, "test", "oracle+baseline-stereo")
    assert rec0["stereo"]["follow_depth"] == 0 and rec["stereo"]["follow_depth"] == 1.5
    assert run_config_key(rec0) != run_config_key(rec)
    assert main(base + ["--depth", "stereo", "--name", "oracle+baseline-stereo", "--stereo-option",
                        "follow_depth=0"]) == 2          # another matcher's results under that name: refused
    assert "another configuration" in capsys.readouterr().err
    for bad, msg in ((["--stereo-option", "follow_depth=0"], "add --depth stereo"),
                     (["--depth", "stereo", "--stereo-option", "nope=1"], "unknown --stereo-option nope"),
                     (["--depth", "stereo", "--stereo-option", "z_min_m=near"], "z_min_m must be a finite number"),
                     (["--depth", "stereo", "--stereo-option", "follow_depth=0.5"], "follow_depth must be 0")):
        assert main(base + bad) == 2
        err = capsys.readouterr().err
        assert msg in err and len(err.strip().splitlines()) == 1


def test_stereo_clouds_get_the_stereo_a3boxnet(tmp_path):
    """Block-matching stereo has a model of its own (track3d.boxnet.SENSOR_MODELS): chosen by the
    sequence's sensor in the evaluation, by --depth stereo in the CLI, by depth_sensor= in
    Track3D.from_default; an explicit model wins; every other sensor keeps the shared model."""
    from track3d.boxnet import DEFAULT_MODEL, SENSOR_MODELS, A3BoxNetEstimator, model_for_sensor
    from track3d.cli import main
    from track3d.dataset import Dataset
    from track3d.evaluation import TrackerSpec
    from track3d.evaluation.results import read_run_record

    stereo = SENSOR_MODELS["stereo"]
    assert model_for_sensor("stereo").name == stereo and model_for_sensor("STEREO").name == stereo
    for other in (None, "ideal", "tof", "flash-lidar", "sonar"):
        assert model_for_sensor(other).name == DEFAULT_MODEL
    assert A3BoxNetEstimator(depth_sensor="stereo").model.path.name == stereo
    assert A3BoxNetEstimator(model_for_sensor(None), depth_sensor="stereo").model.path.name == DEFAULT_MODEL
    t = Track3D.from_default(CAM, depth_sensor="stereo")
    assert t.estimator.model.path.name == stereo
    assert (t.frustum_margin, t.weight_3d, t.measured_faces) == (0.0, 0.15, False)
    assert Track3D.from_default(CAM, depth_sensor="stereo", weight_3d=0.3).weight_3d == 0.3   # options win
    assert Track3D.from_default(CAM).estimator.model.path.name == DEFAULT_MODEL
    # a user's sensor name: any case, the whole stereo setup (the model's lookup ignored case, the
    # options' did not: "Stereo" got the stereo model with the range sensors' options)
    t = Track3D.from_default(CAM, depth_sensor="Stereo")
    assert t.estimator.model.path.name == stereo
    assert (t.frustum_margin, t.weight_3d, t.measured_faces) == (0.0, 0.15, False)
    for bad in ("lidar", "", 3):   # a typo was taken for an unknown sensor, with no word
        with pytest.raises(ValueError, match="depth_sensor must be one of ideal, tof, flash-lidar, stereo"):
            Track3D.from_default(CAM, depth_sensor=bad)

    data = _stereo_dataset(tmp_path / "ds", CAM)
    seq = Dataset(data).sequences("test")[0]
    assert TrackerSpec("oracle", "a3boxnet").build(seq).estimator.model.path.name == DEFAULT_MODEL
    meta = json.loads((data / "test" / "s1" / "meta.json").read_text())
    (data / "test" / "s1" / "meta.json").write_text(json.dumps({**meta, "depth_sensor": {"name": "stereo"}}))
    seq = Dataset(data).sequences("test")[0]
    assert TrackerSpec("oracle", "a3boxnet").build(seq).estimator.model.path.name == stereo
    mine = TrackerSpec("oracle", "a3boxnet", estimator_options={"model": str(model_for_sensor(None))})
    assert mine.build(seq).estimator.model.path.name == DEFAULT_MODEL

    res = tmp_path / "res"
    assert main(["track", "--data", str(data), "--tracker", "oracle", "--estimator", "a3boxnet", "--depth", "stereo",
                 "--results", str(res), "--video", "none", "--quiet"]) == 0
    used = [m["file"] for m in read_run_record(res, "test", "oracle+a3boxnet-stereo")["track3d"]["models"]]
    assert stereo in used and DEFAULT_MODEL not in used
    # the option only picks a model, which the record's model hashes name: results of the same
    # models share a folder whether the sensor was given or implied
    from track3d.evaluation.results import run_config_key

    def key(**o):
        return run_config_key({"track3d": {"estimator_options": o, "models": [{"sha256": "ab"}]}})
    assert key(depth_sensor="stereo", threads=2) == key() != key(model="x.onnx")


def _eroded_by_hand(valid: np.ndarray, r: int) -> np.ndarray:
    """A valid pixel stays valid iff every pixel within r (8-neighbourhood, Chebyshev distance)
    that lies inside the image is valid: the image's border is not a hole."""
    H, W = valid.shape
    pad = np.pad(valid, r, constant_values=True)
    keep = valid.copy()
    for dy in range(2 * r + 1):
        for dx in range(2 * r + 1):
            keep &= pad[dy:dy + H, dx:dx + W]
    return keep


@pytest.mark.parametrize("scene", ["holes", "fills the frame"])
def test_pixels_next_to_a_hole_have_no_depth(scene):
    """edge_erode_px (default 1): a pixel whose neighbourhood holds a hole (the sky past the
    silhouette, a textureless patch) is a hole too; the others keep their depth unchanged, and a
    body that fills the frame keeps its depth up to the image's border."""
    if scene == "holes":
        left, right, z = render_pair(CAM, (0.0, 0.0, 9.0), 2.0, textureless_half=True)
    else:
        left, right, z = render_pair(CAM, (0.0, 0.0, 12.0), 8.0)
        assert (z > 0).all()
    z0 = StereoMatcher(CAM, edge_erode_px=0).depth(left, right)
    for r in (1, 2):
        zr = StereoMatcher(CAM, edge_erode_px=r).depth(left, right)
        keep = _eroded_by_hand(z0 > 0, r)
        np.testing.assert_array_equal(zr > 0, keep)
        np.testing.assert_array_equal(zr[keep], z0[keep])
        assert ((z0 > 0) & ~keep).sum() > 100
    assert StereoParams().edge_erode_px == 1
    if scene == "fills the frame":
        z1 = StereoMatcher(CAM).depth(left, right)
        for edge in (z1[0], z1[-1], z1[:, -1]):     # the border is not a hole: most of it keeps depth
            assert (edge > 0).sum() > 0.1 * edge.size


@pytest.mark.parametrize("bad", [-1, 9, 1.5, "1"])
def test_edge_erosion_setting_is_checked(bad):
    with pytest.raises(ValueError, match="edge_erode_px"):
        StereoParams(edge_erode_px=bad)


@pytest.mark.parametrize("kind", ["int64 RGB", "float gray above 255", "float RGB", "RGBA", "bool", "empty"])
def test_stereo_images_other_than_uint8_rgb_or_gray_are_refused(kind):
    """An int64 pair crashed OpenCV's colour conversion (cv2.error, not a one-line error) and a
    float grey pair was cast to uint8 with wrap-around (433 -> 177: a silent wrong disparity)."""
    rng = np.random.default_rng(0)
    left = rng.integers(0, 255, (120, 160, 3)).astype(np.uint8)
    right = np.roll(left, -5, 1)
    small = Camera.from_fov(160, 120, 60.0)
    pair = {"int64 RGB": (left.astype(np.int64), right.astype(np.int64)),
            "float gray above 255": (left[..., 0] * 1.7, right[..., 0] * 1.7),
            "float RGB": (left.astype(np.float32), right.astype(np.float32)),
            "RGBA": (np.dstack([left, left[..., :1]]), np.dstack([right, right[..., :1]])),
            "bool": (left[..., 0] > 100, right[..., 0] > 100),
            "empty": (left[:0], right[:0])}[kind]
    with pytest.raises(ValueError, match="uint8"):
        StereoCloud(small).bind(*pair)
    with pytest.raises(ValueError, match="uint8"):
        StereoMatcher(small).depth(*pair)
    assert StereoCloud(small).bind(left, right)([10, 10, 50, 50]).shape[1] == 3   # uint8 RGB is taken
    assert StereoCloud(small).bind(left[..., 0], right[..., 0])([10, 10, 50, 50]).shape[1] == 3   # and grey


# --- following the body's depth (StereoCloud, follow_depth) ---------------------------------------

def test_disparities_to_a_depth_by_hand():
    """fx B = 772.5 px x 0.4 m = 309.0: down to 10 m the search needs d < 30.9 (+1, the
    interpolation's room), so 32 disparities; down to 5 m 62.8 -> 64; nearer than z_min_m or an
    unknown depth: the full range (208)."""
    m = StereoMatcher(CAM)
    assert round(m.fb, 1) == 309.0 and m.num_disparities == 208
    assert m.disparities_to(10.0) == 32 and m.disparities_to(5.0) == 64
    for z in (1.0, 0.0, -3.0, np.nan, np.inf):
        assert m.disparities_to(z) == 208


def _starry(cam: Camera, seed: int = 3) -> np.ndarray:
    """A textured sky at infinity: the same picture in both cameras (disparity 0)."""
    g = np.random.default_rng(seed).uniform(0, 90, (cam.height, cam.width))
    return cv2.GaussianBlur(g, (0, 0), 1.0)


def test_a_followed_search_gives_the_body_s_depth_and_no_false_sky():
    """After the first window the search covers only the depths the body can be at (a sphere at
    7-9 m: 64 disparities, not 208), the body's depth as the full search gives it, and the sky
    behind it, textured, still matches as sky (a search cut at both ends of the body's
    disparities matched 2,000 points of a starry sky among the body's depths). The sphere's front
    at 7.0 m: 309.0 / (7.0 / 1.5) + 1 = 67.2 -> 80 disparities."""
    left, right, z = render_pair(CAM, (0.5, 0.2, 9.0), 2.0, background=_starry(CAM))
    box = _box(z)
    cloud = StereoCloud(CAM)
    first = cloud.bind(left, right)(box)
    assert cloud.last_disparities == 208 and cloud.depth_range is not None
    followed = cloud.bind(left, right)(box)
    assert cloud.last_disparities == 80
    full = StereoCloud(CAM, follow_depth=0)
    ref = full.bind(left, right)(box)
    assert full.last_disparities == 208 and full.depth_range is None
    np.testing.assert_array_equal(first, ref)
    assert abs(len(followed) - len(ref)) < 0.02 * len(ref)
    r = np.linalg.norm(followed - np.array([0.5, 0.2, 9.0]), axis=1)
    assert np.mean(np.abs(r - 2.0) < 0.3) > 0.99                  # nothing of the sky
    assert np.median(np.abs(r - 2.0)) < 0.1


def test_a_body_nearer_than_the_followed_search_is_found_again():
    """A body nearer than the followed search reaches (a depth left from another body, or a jump)
    is not only holes: SGBM matches much of its texture at wrong disparities inside the search
    (a sphere at 7-9 m searched down to 26 m: ~19,000 returns at 22-60 m). Fewer returns per
    pixel than FOLLOW_MIN_SHARE of the last window's: the window is matched again over the full
    range, and the depth followed from it. Without a last window to compare with (a restored
    state without it), the followed search is not trusted either."""
    left, right, z = render_pair(CAM, (0.5, 0.2, 9.0), 2.0)
    box = _box(z)
    ref = StereoCloud(CAM, follow_depth=0).bind(left, right)(box)
    wrong = StereoCloud(CAM).matcher.points_window(left, right, box, 16)
    assert len(wrong) > 1000 and np.median(wrong[:, 2]) > 15.0      # what a blind search would give
    cloud = StereoCloud(CAM)
    cloud.bind(left, right)(box)
    cloud.depth_range = (40.0, 45.0)                           # 16 disparities: down to ~26 m
    pts = cloud.bind(left, right)(box)
    assert cloud.last_disparities == 208
    win = cloud.matcher.window(box)     # both matches counted: the followed one and the retry
    assert cloud.last_cost == cloud.matcher.match_cost(win, 16) + cloud.matcher.match_cost(win, 208)
    np.testing.assert_array_equal(pts, ref)
    assert 6.5 < cloud.depth_range[0] < 7.5
    cloud.set_state({"depth_range": [40.0, 45.0]})            # no density: not trusted
    np.testing.assert_array_equal(cloud.bind(left, right)(box), ref)
    cloud.reset()
    assert cloud.depth_range is None and cloud.density is None


def test_a_cost_budget_holds_for_the_whole_update_the_retry_included():
    """With max_match_cost the cap is the update's budget: a followed search that is not trusted
    is repeated over the full range in what it left (coarser bands), and when even bands of 8 rows
    do not fit, the update has no cloud (rather than the followed search's wrong depths) and the
    next one searches the full range with the whole budget."""
    left, right, z = render_pair(CAM, (0.5, 0.2, 9.0), 2.0)
    box = _box(z)
    m = StereoMatcher(CAM)
    win = m.window(box)
    first = m.match_cost(win, 16)                     # the followed search, every row
    ref = StereoCloud(CAM, follow_depth=0).bind(left, right)(box)
    for k in (2, 4, 8):
        budget = first + m.binned_cost(win, 208, k)
        cloud = StereoCloud(CAM, max_match_cost=budget)
        cloud.set_state({"depth_range": [40.0, 45.0], "density": 0.5})    # 16 disparities: to ~26 m
        pts = cloud.bind(left, right)(box)
        assert cloud.last_disparities == 208 and not cloud.last_dropped
        assert cloud.last_cost == budget                 # the retry in bands of k, to the unit
        assert 0.7 < len(pts) / len(ref) * k < 1.3
        assert 6.5 < cloud.depth_range[0] < 7.5          # the body's depth, not the search's 26 m+
    cloud = StereoCloud(CAM, max_match_cost=first + m.binned_cost(win, 208, 8) - 1)
    cloud.set_state({"depth_range": [40.0, 45.0], "density": 0.5})
    pts = cloud.bind(left, right)(box)
    assert pts.shape == (0, 3) and cloud.last_dropped and cloud.last_cost == first
    assert cloud.depth_range is None                     # the next update: the full range
    pts = cloud.bind(left, right)(box)
    assert not cloud.last_dropped and cloud.last_disparities == 208 and len(pts) > 0
    assert cloud.last_cost <= cloud.matcher.params.max_match_cost
    # a first match dearer than bands of 8 rows can keep is matched in those: a cloud, over budget
    tiny = StereoCloud(CAM, max_match_cost=1000)
    assert len(tiny.bind(left, right)(box)) > 0 and not tiny.last_dropped
    assert tiny.last_cost == m.binned_cost(win, 208, 8) > 1000
    # without a cap both matches are made whatever they cost
    free = StereoCloud(CAM)
    free.set_state({"depth_range": [40.0, 45.0], "density": 0.5})
    np.testing.assert_array_equal(free.bind(left, right)(box), ref)
    assert free.last_cost == first + m.match_cost(win, 208) and not free.last_dropped


def test_stereo_cloud_state_round_trips_and_refuses_damage():
    cloud = StereoCloud(CAM)
    assert cloud.get_state() == {"depth_range": None, "density": None}
    good = {"depth_range": [8.0, 11.5], "density": 0.4}
    cloud.set_state(good)
    assert cloud.get_state() == good
    for bad in ({"depth_range": [11.0, 8.0]}, {"depth_range": [0.0, 5.0]}, {"depth_range": [np.nan, 5.0]},
                {"depth_range": [1.0]}, {"depth_range": "far"}, {"density": 2.0}, {"density": "x"}, [8.0, 11.5]):
        with pytest.raises(ValueError, match="damaged StereoCloud state"):
            cloud.set_state(bad)
    assert cloud.get_state() == good                             # a refused state changes nothing
    with pytest.raises(ValueError, match="follow_depth"):
        StereoParams(follow_depth=0.5)


def test_a_stereo_loop_restored_from_both_states_goes_on_bit_identically():
    """The matcher's followed depth is state beside the Track3D's: a loop restored from both
    goes on exactly as the uninterrupted one (the search range, the cloud and every box)."""
    frames = _sphere_frames(6)
    runs = []
    for restore in (False, True):
        cloud = StereoCloud(CAM)
        t = Track3D.from_default(CAM, depth_sensor="stereo")
        t.init(frames[0][0], frames[0][2], points=cloud.bind(frames[0][0], frames[0][1]))
        for left, right, *_ in frames[1:3]:
            t.update(left, cloud.bind(left, right))
        if restore:
            state = json.loads(json.dumps({"track": t.get_state(), "stereo": cloud.get_state()}))
            assert state["stereo"]["depth_range"] is not None
            cloud = StereoCloud(CAM)
            t = Track3D.from_default(CAM, depth_sensor="stereo")
            t.set_state(state["track"])
            cloud.set_state(state["stereo"])
        out = []
        for left, right, *_ in frames[3:]:
            r = t.update(left, cloud.bind(left, right))
            out.append((r.box2d.tolist(), r.box3d.tolist(), r.num_points, cloud.last_disparities))
        runs.append(out)
    assert runs[0] == runs[1]
    assert all(o[3] < 208 for o in runs[0])       # the followed search ran


def test_rows_binned_for_a_window_by_hand():
    m = StereoMatcher(CAM, max_match_px=4096)
    assert m.rows_for((0, 64, 0, 64)) == 1             # 4096 px: within the cap
    assert m.rows_for((0, 100, 0, 60)) == 2            # 6000 px -> 3000 in bands of 2 rows
    assert m.rows_for((0, 200, 0, 200)) == 4           # 40,000 px: 20,000 at 2, 10,000 at 4
    assert m.rows_for((0, 640, 0, 480)) == 4           # 4 rows at most
    assert StereoMatcher(CAM).rows_for((0, 640, 0, 480)) == 1   # 0: every row
    with pytest.raises(ValueError, match="max_match_px"):
        StereoParams(max_match_px=-1)


def test_match_cost_and_rows_binned_by_cost_by_hand():
    from track3d.stereo import BAND_SOURCE_COST, MATCH_PX_DISPARITIES
    assert MATCH_PX_DISPARITIES == 48 and BAND_SOURCE_COST == 4
    m = StereoMatcher(CAM)
    assert m.match_cost((10, 30, 5, 15), 16) == 200 * 64          # 20 x 10 px x (16 + 48)
    assert m.match_cost((10, 30, 5, 15)) == 200 * (m.num_disparities + 48)   # the full range by default
    win = (300, 400, 0, 100)              # 10,000 px; searched over 16: columns 284..399 of both images
    assert m.binned_cost(win, 16) == m.match_cost(win, 16) == 640_000
    # bands of k from the image's top, plus averaging the crop's k x bands rows of 116 columns
    assert m.binned_cost(win, 16, 2) == 100 * 50 * 64 + 4 * 116 * 50 * 2 == 366_400
    assert m.binned_cost(win, 16, 4) == 100 * 25 * 64 + 4 * 116 * 25 * 4 == 206_400
    assert m.binned_cost(win, 16, 8) == 100 * 13 * 64 + 4 * 116 * 13 * 8 == 131_456   # 13 bands: 0..103
    assert m.binned_cost((300, 400, 3, 101), 16, 4) == 100 * 26 * 64 + 4 * 116 * 26 * 4   # bands 0..25
    assert m.binned_cost((300, 310, 470, 480), 16, 8) == 10 * 2 * 64 + 4 * 26 * 2 * 8   # none past the image
    assert m.binned_cost((0, 10, 0, 8), 16, 8) == 10 * 64 + 4 * 22 * 8   # OpenCV's minimum width: 16 + 5 + 1
    for budget, k in ((640_000, 1), (400_000, 2), (210_000, 4), (140_000, 8), (100_000, 0)):
        assert StereoMatcher(CAM, max_match_cost=budget).rows_for(win, 16) == k, budget
        assert m.rows_for(win, 16, budget=budget) == k
    m = StereoMatcher(CAM, max_match_cost=640_000)
    assert m.rows_for(win, 80) == 4                  # 2 rows: 640,000 + 72,000 of averaging
    assert m.rows_for(win, 208) == m.rows_for(win) == 8   # the full range (208 here) by default
    # with both caps the larger k decides; the pixel cap alone bins in bands of 4 at most
    assert StereoMatcher(CAM, max_match_cost=10 ** 9, max_match_px=4000).rows_for(win, 16) == 4
    assert StereoMatcher(CAM, max_match_cost=400_000, max_match_px=10 ** 6).rows_for(win, 16) == 2
    assert StereoMatcher(CAM, max_match_px=1).rows_for(win, 16) == 4
    with pytest.raises(ValueError, match="max_match_cost"):
        StereoParams(max_match_cost=-1)


def test_a_cost_cap_bins_the_full_range_search_and_not_the_followed_one():
    """max_match_cost bins a window by what its matching costs: the first window of a body (the
    full range, 208 disparities) in bands of rows, the next (followed, fewer disparities) every
    row: the dear frame is cut, the usual one keeps all its returns, bit for bit."""
    frames = _sphere_frames(2)
    a = frames[0][2]
    full = StereoCloud(CAM)
    ref0 = full.bind(frames[0][0], frames[0][1])(a)
    ref1 = full.bind(frames[1][0], frames[1][1])(a)
    n1 = full.last_disparities
    assert n1 < 208
    win = full.matcher.window(a)
    cloud = StereoCloud(CAM, max_match_cost=full.matcher.binned_cost(win, None, 2))
    k = cloud.matcher.rows_for(win)
    assert k == 2 and full.matcher.match_cost(win, n1) <= cloud.matcher.params.max_match_cost
    pts0 = cloud.bind(frames[0][0], frames[0][1])(a)
    assert 0.8 < len(pts0) / len(ref0) * k < 1.2
    # what it matched: bands of 2 rows over the full range
    assert cloud.last_cost == cloud.matcher.binned_cost(win, None, 2) <= cloud.matcher.params.max_match_cost
    pts1 = cloud.bind(frames[1][0], frames[1][1])(a)
    assert cloud.last_disparities == n1 and cloud.matcher.rows_for(win, n1) == 1
    assert cloud.last_cost == full.last_cost == full.matcher.match_cost(win, n1)
    np.testing.assert_array_equal(pts1, ref1)


@pytest.mark.parametrize("cap,rows", [(100000, 2), (50000, 4)])
def test_a_window_of_binned_rows_gives_the_same_surface_with_fewer_points(pair, cap, rows):
    """A window of more than max_match_px pixels is matched with its rows averaged in bands: about
    1/k of the points, on the same sphere, at the same columns, the bands' rows mapped to their
    centres (a band's first row instead would lift the cloud by k/2 px: 1.2 cm per px at 9 m)."""
    left, right, z = pair
    box = _box(z)
    full = StereoMatcher(CAM).points_window(left, right, box)
    m = StereoMatcher(CAM, max_match_px=cap)
    assert m.rows_for(m.window(box)) == rows
    pts = m.points_window(left, right, box)
    assert pts.dtype == np.float32 and 0.7 < len(pts) / len(full) * rows < 1.3
    r = np.linalg.norm(pts - np.array([0.5, 0.2, 9.0]), axis=1)
    assert np.median(np.abs(r - 2.0)) < 0.03
    u = pts[:, 0] / pts[:, 2] * CAM.fx + CAM.cx
    assert abs(np.mean(u) - np.mean(full[:, 0] / full[:, 2] * CAM.fx + CAM.cx)) < 0.5
    v = pts[:, 1] / pts[:, 2] * CAM.fy + CAM.cy
    rows_true = np.nonzero((z > 0).any(axis=1))[0]
    assert abs((v.min() + v.max()) / 2 - (rows_true[0] + rows_true[-1] + 1) / 2) < 0.25 * rows


def test_a_binned_window_at_the_left_border_drops_what_the_right_camera_misses():
    z_c = 9.0
    l, r, z = render_pair(CAM, (-CAM.cx / CAM.fx * z_c + 1.5, 0.0, z_c), 2.0)
    m = StereoMatcher(CAM, max_match_px=4000)
    assert m.rows_for(m.window(_box(z))) == 4
    pts = m.points_window(l, r, _box(z))
    assert len(pts) > 5000
    u = pts[:, 0] / pts[:, 2] * CAM.fx + CAM.cx
    assert np.all(u - CAM.disparity(pts[:, 2]) >= -0.5)    # u - d >= 0 for the pixel's column
    r_ = np.linalg.norm(pts - np.array([-CAM.cx / CAM.fx * z_c + 1.5, 0.0, z_c]), axis=1)
    assert np.median(np.abs(r_ - 2.0)) < 0.05


def test_a_followed_search_holds_across_binned_windows():
    """The follow rule compares returns per pixel of the grid a window was matched on: a body
    growing past max_match_px (every row, then bands of 2 rows) keeps its narrowed search
    instead of falling back to the full range (half the returns per camera pixel)."""
    frames = _sphere_frames(2)
    a = frames[0][2]
    u0, u1, v0, v1 = StereoMatcher(CAM).window(a)
    cloud = StereoCloud(CAM, max_match_px=(u1 - u0) * (v1 - v0))
    assert cloud.matcher.rows_for(cloud.matcher.window(a)) == 1
    big = np.array([a[0] - 40, a[1] - 40, a[2] + 80, a[3] + 80])
    assert cloud.matcher.rows_for(cloud.matcher.window(big)) == 2
    cloud.bind(frames[0][0], frames[0][1])(a)
    cloud.bind(frames[1][0], frames[1][1])(big)
    assert cloud.last_disparities < cloud.matcher.num_disparities


def test_a_frustum_cache_of_stereo_matched_clouds_is_the_loop_s_cloud(tmp_path):
    """`track3d-train boxnet prepare --stereo-match MAX_PX`: each box's cloud matched from the pair
    around it as the loop's StereoCloud does (rows binned past MAX_PX, the followed search from the
    ground truth's near face), not the dataset's depth maps; a dataset without right images is
    refused in one line."""
    from track3d.frustum import extract_frustum
    from track3d_train.boxnet.data import PointCache, prepare_split

    data = _stereo_dataset(tmp_path / "ds", CAM, n=2)
    out = prepare_split(data, "test", tmp_path / "c.npz", jitters=0, max_points=10 ** 6, progress=False,
                        stereo_match=40000)
    c = PointCache(out)
    assert c.info["stereo_match"] == 40000 and len(c) == 2
    from track3d.dataset import Dataset
    seq = Dataset(data).sequences("test")[0]
    m = StereoMatcher(CAM, max_match_px=40000)
    for k in range(2):
        box, g = seq.gt2d[k], seq.gt3d[k]
        assert m.rows_for(m.window(box)) > 1
        n = m.disparities_to((g[2] - g[5] / 2) / m.params.follow_depth)
        want = extract_frustum(m.points_window(seq.image(k), seq.right_image(k), box, n), box.astype(np.float32), CAM.M)
        assert c.n_full[k] == len(want) and len(want) < 0.6 * seq.points(k).shape[0]
        np.testing.assert_array_equal(np.sort(c.points(k)[:, 2]), np.sort(want[:, 2]))
    import shutil
    shutil.rmtree(data / "test" / "s1" / "right")
    with pytest.raises(ValueError, match="no right images"):
        prepare_split(data, "test", tmp_path / "d.npz", jitters=0, progress=False, stereo_match=0)
