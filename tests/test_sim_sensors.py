"""Depth sensors of the simulator: the documented noise models hold, labels stay the geometry's."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from track3d.camera import Camera

from track3d_sim import sensors as S
from track3d_sim.errors import SimError
from track3d_sim.sensors import FLASH_LIDAR, TOF, RenderedFrame, measure_depth

CAM = Camera.from_fov(320, 240, 45.0)


def _frame(z, albedo=0.5, cos_inc=1.0, cam=CAM):
    z = np.broadcast_to(np.asarray(z, np.float64), (cam.height, cam.width)).copy()
    hit = z > 0
    img = np.zeros((cam.height, cam.width, 3), np.uint8)
    return RenderedFrame(z, np.where(hit, cos_inc, 0).astype(np.float32),
                         np.where(hit, albedo, 0).astype(np.float32), img, img)


def _ranges(z, cam=CAM):
    r = cam.pixel_rays()
    return z * np.sqrt((r * r).sum(-1))


@pytest.mark.parametrize("z", [2.0, 8.0, 20.0])
def test_tof_range_noise_matches_the_model(z):
    f = _frame(z)
    m = measure_depth("tof", f, CAM, np.random.default_rng(1))
    ok = m > 0
    r_true = _ranges(f.z)[ok]
    err = _ranges(m)[ok] - r_true
    s = S.tof_sigma(TOF, S.tof_signal(TOF, r_true, 0.5, 1.0))
    assert ok.sum() > 5000
    assert abs(err.mean()) < 4 * s.mean() / np.sqrt(ok.sum())        # unbiased
    assert np.std(err / s) == pytest.approx(1.0, abs=0.05)             # sd = model's sigma(range)


def test_tof_noise_grows_with_range_and_darkness():
    s = lambda r, a, c=1.0: float(S.tof_sigma(TOF, S.tof_signal(TOF, r, a, c)))  # noqa: E731
    assert s(2, 0.5) < s(10, 0.5) < s(25, 0.5)
    assert s(10, 0.5) < s(10, 0.1)
    # at the reference return the two terms add in quadrature
    assert s(TOF.ref_range_m, TOF.ref_albedo) == pytest.approx(np.hypot(TOF.sigma_floor_m, TOF.sigma_ref_m))


@pytest.mark.parametrize("albedo, cos_inc, z", [(0.5, 1.0, 10.0), (0.05, 1.0, 10.0), (0.5, 0.15, 10.0),
                                                (0.12, 0.5, 15.0), (0.5, 0.05, 5.0)])
def test_tof_dropout_rate_matches_the_model(albedo, cos_inc, z):
    f = _frame(z, albedo, cos_inc)
    m = measure_depth("tof", f, CAM, np.random.default_rng(2))
    p = S.tof_return_probability(TOF, _ranges(f.z), albedo, cos_inc)
    assert (m > 0).mean() == pytest.approx(p.mean(), abs=0.01)
    if cos_inc < TOF.min_cos_incidence:
        assert not (m > 0).any()


def test_tof_dark_and_grazing_surfaces_drop_more():
    p = lambda a, c: float(S.tof_return_probability(TOF, 15.0, a, c))  # noqa: E731
    assert p(0.5, 1.0) > 0.95 and p(0.05, 1.0) < p(0.5, 1.0) and p(0.5, 0.2) < p(0.5, 1.0)


def test_tof_max_range_is_respected():
    z = np.linspace(20.0, 40.0, CAM.width)[None, :].repeat(CAM.height, 0)
    f = _frame(z, albedo=1.0)
    m = measure_depth("tof", f, CAM, np.random.default_rng(3))
    r = _ranges(f.z)
    assert (m[r > TOF.max_range_m] == 0).all()
    assert (m[r < TOF.max_range_m - 1.0] > 0).mean() > 0.9
    assert (_ranges(m)[m > 0] < TOF.max_range_m + 0.2).all()


def test_tof_is_deterministic_for_a_seed_and_keeps_background_empty():
    z = np.zeros((CAM.height, CAM.width))
    z[50:150, 100:200] = 7.0
    f = _frame(z)
    a = measure_depth("tof", f, CAM, np.random.default_rng(5))
    b = measure_depth("tof", f, CAM, np.random.default_rng(5))
    np.testing.assert_array_equal(a, b)
    assert (a[z == 0] == 0).all() and (a[z > 0] > 0).mean() > 0.95


def _lowres_exact(model):
    """The low-resolution sensor without noise or dropouts: registration only."""
    return S._tof_lowres(dataclasses.replace(model, sigma_floor_m=0.0, sigma_ref_m=0.0, min_signal=0.0,
                                             min_cos_incidence=0.0))


def test_flash_lidar_returns_land_on_its_pixel_centres():
    cam = Camera.from_fov(640, 480, 45.0)
    f = _frame(10.0, cam=cam)
    m = _lowres_exact(FLASH_LIDAR)(f, cam, np.random.default_rng(0))
    w, h, fl, cx, cy = S.lidar_intrinsics(FLASH_LIDAR, cam)
    assert (w, h) == (128, 128)
    # expected: each lidar pixel centre ray (i + .5, j + .5) that falls in the left image
    jj, ii = np.mgrid[0:h, 0:w]
    u = np.floor(cam.fx * (ii + 0.5 - cx) / fl + cam.cx).astype(int)
    v = np.floor(cam.fy * (jj + 0.5 - cy) / fl + cam.cy).astype(int)
    inside = (u >= 0) & (u < cam.width) & (v >= 0) & (v < cam.height)
    expect = np.zeros_like(m, bool)
    expect[v[inside], u[inside]] = True
    np.testing.assert_array_equal(m > 0, expect)
    assert (m > 0).sum() == 128 * 96                     # 45 deg x 34.5 deg of its 45 x 45 deg
    np.testing.assert_allclose(m[m > 0], 10.0)


def test_flash_lidar_zbuffer_keeps_the_nearest_surface():
    cam = Camera.from_fov(640, 480, 45.0)
    z = np.full((cam.height, cam.width), 20.0)
    z[:, 323:] = 5.0          # a near surface starting mid-pixel of the lidar: its column sees it
    m = _lowres_exact(FLASH_LIDAR)(_frame(z, cam=cam), cam, np.random.default_rng(0))
    vals = m[m > 0]
    assert set(np.unique(vals)) == {5.0, 20.0}
    # the lidar pixel covering left columns 320..324 holds both surfaces and reports the near one
    col = np.unique(np.nonzero(m == 5.0)[1]).min()
    assert col <= 323


def test_flash_lidar_noise_and_holes():
    cam = Camera.from_fov(640, 480, 45.0)
    f = _frame(30.0, cam=cam)
    m = measure_depth("flash-lidar", f, cam, np.random.default_rng(4))
    ok = m > 0
    assert 0.95 * 128 * 96 < ok.sum() <= 128 * 96       # sparse: 12288 returns for 307200 pixels
    err = m[ok] - 30.0
    r = 30.0 * np.sqrt(1 + ((np.nonzero(ok)[1] + 0.5 - cam.cx) / cam.fx) ** 2
                       + ((np.nonzero(ok)[0] + 0.5 - cam.cy) / cam.fy) ** 2)
    sd_z = S.tof_sigma(FLASH_LIDAR, S.tof_signal(FLASH_LIDAR, r, 0.5, 1.0)) * 30.0 / r
    assert np.std(err / sd_z) == pytest.approx(1.0, abs=0.05)


def test_unknown_sensor_is_one_line_sim_error():
    with pytest.raises(SimError, match="unknown depth sensor 'sonar'") as e:
        measure_depth("sonar", _frame(5.0), CAM, np.random.default_rng(0))
    assert "\n" not in str(e.value)
    with pytest.raises(SimError, match="unknown depth sensor"):
        S.sensor_info("sonar")


def test_tof_parameters_are_checked():
    with pytest.raises(SimError, match="max_range_m"):
        dataclasses.replace(TOF, max_range_m=0.0)


# --- through the renderer -------------------------------------------------------------------

@pytest.fixture(scope="module")
def rendered():
    pytest.importorskip("embreex")
    pytest.importorskip("trimesh")
    from track3d_sim import render
    from track3d_sim.generate import camera_of, make_settings
    from track3d_sim.sequence import plan, render_sequence

    settings = make_settings("tiny", seed=3, frames=3)
    cam = camera_of(settings)
    spec = plan(1, 0)[0]
    casts = []
    orig = render.BodyRenderer.cast

    def spy(self, R, T, eye=np.zeros(3)):
        c = orig(self, R, T, eye)
        if not np.any(eye):
            casts.append(c["z"].copy())
        return c

    out = {}
    render.BodyRenderer.cast = spy
    try:
        for s in ("ideal", "tof", "flash-lidar", "stereo"):
            casts.clear()
            out[s] = render_sequence(dataclasses.replace(spec, sensor=s), settings, cam, None, keep_depth=True)
            out[s]["casts"] = list(casts)
    finally:
        render.BodyRenderer.cast = orig
    return out, spec, settings, cam


def test_ideal_depth_is_the_rendered_geometry_bit_for_bit(rendered):
    out, *_ = rendered
    r = out["ideal"]
    assert len(r["depth"]) == len(r["casts"]) == 3
    for d, z in zip(r["depth"], r["casts"]):
        assert d.dtype == np.float64 and d.tobytes() == z.tobytes()


@pytest.mark.parametrize("sensor", ["tof", "flash-lidar", "stereo"])
def test_sensor_changes_depth_only(rendered, sensor):
    out, *_ = rendered
    ideal, r = out["ideal"], out[sensor]
    for k in ("gt2d", "gt3d", "absent", "cut"):
        np.testing.assert_array_equal(r[k], ideal[k])
    assert r["meta"]["depth_sensor"]["name"] == sensor and ideal["meta"]["depth_sensor"] == {"name": "ideal"}
    for k in ("frame_data", "sun", "motion"):
        assert r["meta"][k] == ideal["meta"][k]           # same images, same scene
    d, g = np.array(r["depth"]), np.array(ideal["depth"])
    assert not np.array_equal(d, g) and (d > 0).any()
    both = (d > 0) & (g > 0)
    tol = {"tof": 0.5, "flash-lidar": 0.5, "stereo": 3.0}[sensor]
    assert np.median(np.abs(d[both] - g[both])) < tol


def test_unknown_sensor_fails_before_rendering(rendered):
    from track3d_sim.sequence import render_sequence

    _, spec, settings, cam = rendered
    with pytest.raises(SimError, match="unknown depth sensor 'radar'"):
        render_sequence(dataclasses.replace(spec, sensor="radar"), settings, cam, None)


# --- camera effects -------------------------------------------------------------------------

def test_auto_exposure_longer_exposure_first_then_gain():
    from track3d_sim import render as Rn

    assert Rn.auto_exposure(1.0) == Rn.Exposure(10.0, 1.0)                  # bright: untouched
    e = Rn.auto_exposure(0.35 / 3)
    assert e.exposure_ms == pytest.approx(30.0) and e.gain == pytest.approx(1.0)
    e = Rn.auto_exposure(0.35 / 10)
    assert e.exposure_ms == pytest.approx(50.0) and e.gain == pytest.approx(2.0)
    e = Rn.auto_exposure(1e-4)                                                # capped: 5x time, 4x gain
    assert e.exposure_ms == pytest.approx(50.0) and e.gain == pytest.approx(4.0) and e.scale == pytest.approx(20.0)


@pytest.mark.parametrize("dn, exposure_ms, gain", [(5.0, 50.0, 4.0), (5.0, 50.0, 1.0), (20.0, 10.0, 2.0)])
def test_low_light_sensor_noise_matches_the_model(dn, exposure_ms, gain):
    from track3d_sim import render as Rn

    img = np.full((200, 200, 3), dn, np.float32)
    none = (np.zeros(0, int), np.zeros(0, int), np.zeros(0, np.float32))
    out = Rn.sensor(img, np.random.default_rng(0), none, Rn.Exposure(exposure_ms, gain)).astype(np.float64)
    e_per_dn = Rn.FULL_WELL_E / 255.0
    t = exposure_ms / Rn.BASE_EXPOSURE_MS
    electrons = dn * t * e_per_dn
    sd = gain / e_per_dn * np.sqrt(electrons + (Rn.READ_NOISE_DN * e_per_dn) ** 2)
    assert out.mean() == pytest.approx(dn * t * gain, rel=0.01)
    assert out.std() == pytest.approx(np.sqrt(sd ** 2 + 1 / 12), rel=0.03)     # + 8-bit rounding
    # same output brightness from the fixed camera (more light): gain makes it noisier
    ref = Rn.sensor(np.full_like(img, dn * t * gain), np.random.default_rng(0), none).astype(np.float64)
    assert (out.std() > 1.3 * ref.std()) == (gain > 1.5)


def test_exposure_none_is_the_fixed_camera():
    from track3d_sim import render as Rn

    img = np.random.default_rng(1).uniform(0, 100, (40, 50, 3)).astype(np.float32)
    hot = Rn.hot_pixels(np.random.default_rng(2), 40, 50, 0.01)
    a = Rn.sensor(img, np.random.default_rng(3), hot)
    x = img + Rn.BLACK_LEVEL_DN
    sd = np.sqrt(x / (Rn.FULL_WELL_E / 255.0) + Rn.READ_NOISE_DN ** 2).astype(np.float32)
    x = x + sd * np.random.default_rng(3).standard_normal(x.shape, dtype=np.float32)
    x[hot[0], hot[1]] += hot[2][:, None]
    np.testing.assert_array_equal(a, np.clip(np.rint(x), 0, 255).astype(np.uint8))


def test_exposure_poses_follow_the_motion():
    from track3d_sim import render as Rn
    from track3d_sim.motion import rotvec_to_matrix

    w = np.array([0.0, 0.5, 0.0])                        # rad/s about y
    fps = 10.0
    R = np.stack([rotvec_to_matrix(w * k / fps) for k in range(3)])
    T = np.array([[0.0, 0, 10], [0.1, 0, 10], [0.2, 0, 10]])
    poses = Rn.exposure_poses(R, T, 1, 40.0, fps, 2, ends=True)
    for (Rk, Tk), tau in zip(poses, (-0.02, 0.02)):
        np.testing.assert_allclose(Rk, rotvec_to_matrix(w * (0.1 + tau)), atol=1e-9)
        np.testing.assert_allclose(Tk, [0.1 + 1.0 * tau, 0, 10], atol=1e-9)
    mid = Rn.exposure_poses(R, T, 1, 40.0, fps, 3)
    np.testing.assert_allclose(mid[1][0], R[1], atol=1e-12)


def test_motion_blur_spreads_a_fast_body_and_keeps_a_still_one():
    pytest.importorskip("embreex")
    pytest.importorskip("trimesh")
    from track3d_sim import render as Rn
    from track3d_sim.shapes import procedural_shape
    from track3d_sim.textures import SolidTexture

    cam = Camera.from_fov(160, 120, 45.0)
    shape = procedural_shape(2, np.random.default_rng(0), 60.0, 3)
    r = Rn.BodyRenderer(shape, SolidTexture(0, np.random.default_rng(1), shape.vertices), cam)
    bg = np.zeros((120, 160, 3), np.float32)
    R0, T0 = np.eye(3), np.array([0.0, 0.0, 12.0])
    args = (np.zeros(3), np.array([0.0, 0.0, -1.0]), 1.0, 0.8)
    sharp = r.view(bg, R0, T0, *args)
    still = r.blurred_view(bg, [(R0, T0)] * 4, *args)
    np.testing.assert_allclose(still, sharp, rtol=1e-6)
    R = np.stack([R0, R0, R0])
    T = np.stack([T0 - [1.0, 0, 0], T0, T0 + [1.0, 0, 0]])       # 10 m/s across: ~3.6 px in 20 ms
    ends = Rn.exposure_poses(R, T, 1, 20.0, 10.0, 2, ends=True)
    n = Rn.blur_substeps(cam, shape.vertices, ends)
    shift = cam.fx * 0.2 / (shape.vertices[:, 2] + 12.0).min()   # the nearest vertex moves most
    assert 2 <= n == int(np.ceil(shift / Rn.BLUR_STEP_PX)) < Rn.MAX_BLUR_SUBSTEPS
    blurred = r.blurred_view(bg, Rn.exposure_poses(R, T, 1, 20.0, 10.0, n), *args)
    lit_sharp, lit_blur = (sharp.sum(-1) > 0).sum(), (blurred.sum(-1) > 0).sum()
    assert lit_blur > lit_sharp                                     # smeared along x
    assert blurred.sum() == pytest.approx(sharp.sum(), rel=0.05)    # same light, spread out


def test_camera_effects_change_images_not_labels_and_are_recorded():
    pytest.importorskip("embreex")
    from track3d_sim.generate import camera_of, make_settings
    from track3d_sim.sequence import plan, render_sequence

    base = make_settings("tiny", seed=3, frames=2)
    fx = make_settings("tiny", seed=3, frames=2, auto_exposure=True, motion_blur=True)
    spec = plan(2, 0)[1]                                   # irradiance 0.13: auto exposure 26 ms
    a, b = render_sequence(spec, base, camera_of(base), None), render_sequence(spec, fx, camera_of(fx), None)
    np.testing.assert_array_equal(a["gt2d"], b["gt2d"])
    np.testing.assert_array_equal(a["gt3d"], b["gt3d"])
    ce = b["meta"]["camera_effects"]
    assert ce["auto_exposure"] and ce["motion_blur"] and ce["exposure_ms"] > 20 and ce["gain"] == 1.0
    assert len(b["meta"]["frame_data"]["blur_substeps"]) == 2
    assert a["meta"]["camera_effects"] == {"auto_exposure": False, "exposure_ms": 10.0, "gain": 1.0,
                                           "motion_blur": False}
    dn_a, dn_b = a["meta"]["frame_data"]["mean_object_dn"], b["meta"]["frame_data"]["mean_object_dn"]
    assert all(y > 1.5 * x for x, y in zip(dn_a, dn_b))


def test_false_alarms_hand_cases():
    """add_false_alarms: rate 0 changes nothing; rate 1 puts every pixel's return in the gate,
    before the surface where there is one (the first return), as z along the pixel's ray."""
    cam = Camera.from_fov(8, 6, 60.0)
    z = np.zeros((6, 8))
    z[2:4, 3:5] = 10.0
    rng = np.random.default_rng(0)
    assert np.array_equal(S.add_false_alarms(z, cam, 0.0, (1.0, 45.0), rng), z)
    out = S.add_false_alarms(z, cam, 1.0, (1.0, 45.0), np.random.default_rng(1))
    r = out * np.sqrt((cam.pixel_rays() ** 2).sum(-1))         # range along each ray
    assert (r >= 1.0 - 1e-9).all() and (r <= 45.0 + 1e-9).all()
    body = z > 0
    assert (out[body] <= 10.0 + 1e-9).all()                    # in front of the surface (same ray)
    assert (out[~body] > 0).all()                              # the sky returns too
    same = S.add_false_alarms(z, cam, 1.0, (1.0, 45.0), np.random.default_rng(1))
    assert same.tobytes() == out.tobytes()                     # deterministic
    # a gate nearer than the surface's start: no alarm possible there
    assert np.array_equal(S.add_false_alarms(z, cam, 1.0, (50.0, 60.0), np.random.default_rng(2))[body], z[body])
    assert S.false_alarm_gate("tof") == (TOF.min_range_m, TOF.max_range_m)
    assert S.false_alarm_gate("ideal") == (1.0, 45.0)


def test_false_alarms_change_only_the_depth_and_are_recorded(rendered):
    """A run with --false-alarms draws its own stream: labels, images and the sensor's own noise
    stay as without; about rate x pixels change; meta.json records the rate and the gate."""
    from track3d_sim.generate import make_settings
    from track3d_sim.sequence import render_sequence

    out, spec, settings, cam = rendered
    noisy = make_settings("tiny", seed=3, frames=3, false_alarms=0.01)
    for sensor in ("ideal", "tof"):
        r = render_sequence(dataclasses.replace(spec, sensor=sensor), noisy, cam, None, keep_depth=True)
        base = out[sensor]
        for k in ("gt2d", "gt3d", "absent", "cut"):
            np.testing.assert_array_equal(r[k], base[k])
        assert r["meta"]["frame_data"] == base["meta"]["frame_data"]
        d, g = np.array(r["depth"]), np.array(base["depth"])
        changed = d != g
        assert 0.003 < changed.mean() < 0.03 and (d[changed] > 0).all()
        assert r["meta"]["depth_sensor"]["false_alarm_rate"] == 0.01
    assert "false_alarm_rate" not in out["ideal"]["meta"]["depth_sensor"]


def test_false_alarm_settings_are_checked():
    from track3d_sim.generate import make_settings

    for bad in (-1e-5, 0.5, "x"):
        with pytest.raises(SimError, match="false alarm rate"):
            make_settings("tiny", false_alarms=bad)
    with pytest.raises(SimError, match="range sensor"):
        make_settings("tiny", sensors="stereo", false_alarms=1e-4)


def test_flash_lidar_false_alarms_are_drawn_on_its_own_grid_before_the_surface():
    """They had been drawn on the left image after reprojection: most body pixels there hold no
    LiDAR sample, so alarms fell behind the surface (20 of 28 over a body), and the rate counted
    image pixels (307,200), not the sensor's (16,384)."""
    cam = Camera.from_fov(640, 480, 45.0)
    yy, xx = np.mgrid[0:480, 0:640]
    body = (xx - 320) ** 2 + (yy - 240) ** 2 < 100 ** 2
    frame = RenderedFrame(np.where(body, 20.0, 0.0), np.where(body, 1.0, 0.0), np.where(body, 0.5, 0.0), None, None)
    clean = measure_depth("flash-lidar", frame, cam, np.random.default_rng(0))
    noisy = measure_depth("flash-lidar", frame, cam, np.random.default_rng(0),
                          false_alarms=(0.01, np.random.default_rng(1)))
    changed = noisy != clean
    assert 0 < changed.sum() < 0.02 * 128 * 128 * 2        # about rate x the sensor's pixels, not the image's
    assert (noisy[body & changed] <= 20.0 + 1e-9).all()     # over the body: before its surface
    assert (noisy[changed] > 0).all()
