"""track3d.stray_returns: a depth sensor's false alarms left out of the frustum, the body kept."""
from __future__ import annotations

import numpy as np

from track3d.camera import Camera
from track3d.stray_returns import drop_stray

CAM = Camera.from_fov(640, 480, 45.0)


def _patch(u0, v0, w, h, z, step=1.0, tilt=0.0):
    """Returns of a surface patch: pixels [u0, u0 + w) x [v0, v0 + h) every `step` px at depth z
    (+ tilt metres per pixel in u), as (n, 3) float32 camera-frame points."""
    u, v = np.meshgrid(np.arange(u0, u0 + w, step) + 0.5, np.arange(v0, v0 + h, step) + 0.5)
    zz = z + tilt * (u - u0)
    x = (u - CAM.cx) / CAM.fx * zz
    y = (v - CAM.cy) / CAM.fy * zz
    return np.stack([x, y, zz], -1).reshape(-1, 3).astype(np.float32)


def _bounds(p):
    return np.stack([p.min(axis=0), p.max(axis=0)]).astype(np.float64)


def test_a_body_alone_comes_back_as_it_was():
    body = _patch(300, 200, 60, 40, 20.0, tilt=0.01)
    b = _bounds(body)
    out, ob = drop_stray(body, b, CAM.M)
    assert out is body and ob is b
    sparse = _patch(300, 200, 60, 40, 20.0, step=5.0)        # a flash LiDAR's grid in a 640 x 480 image
    assert drop_stray(sparse, _bounds(sparse), CAM.M)[0] is sparse


def test_a_lone_return_in_the_sky_and_one_in_front_of_the_body_are_dropped():
    body = _patch(300, 200, 60, 40, 20.0, tilt=0.01)
    sky = _patch(100, 100, 1, 1, 25.0)          # far from any other return in the image
    front = _patch(320, 210, 1, 1, 8.0)         # over the body, 12 m before it
    pts = np.concatenate([body, sky, front])
    out, b = drop_stray(pts, _bounds(pts), CAM.M)
    assert len(out) == len(body)
    np.testing.assert_array_equal(b, _bounds(body))
    assert b[0, 2] == body[:, 2].min()          # the front face is the body's again


def test_a_scattered_handful_in_front_goes_a_patch_of_the_body_behind_stays():
    body = _patch(300, 200, 60, 40, 20.0, tilt=0.01)
    # three false alarms within 0.5 m of one another in depth, over the body, far apart in the image
    handful = np.concatenate([_patch(305, 205, 1, 1, 10.0), _patch(340, 230, 1, 1, 10.2),
                              _patch(355, 215, 1, 1, 10.4)])
    # a part of the body seen past its limb: 2 m behind, a compact patch of 30 returns
    behind = _patch(362, 210, 5, 6, 23.0)
    pts = np.concatenate([body, handful, behind])
    out, b = drop_stray(pts, _bounds(pts), CAM.M)
    assert len(out) == len(body) + len(behind)
    assert b[0, 2] == body[:, 2].min() and b[1, 2] == np.float32(23.0)


def test_nothing_but_lone_returns_is_an_empty_frustum():
    pts = np.concatenate([_patch(100, 100, 1, 1, 10.0), _patch(300, 300, 1, 1, 30.0)])
    out, b = drop_stray(pts, _bounds(pts), CAM.M)
    assert out.shape == (0, 3) and np.all(b[0] == np.inf) and np.all(b[1] == -np.inf)


def test_the_loop_keeps_its_box_through_a_false_alarm_in_front():
    """One false alarm 12 m before a sphere at 20 m had set the measured front face: the box's
    depth extent ran from the alarm to the back of the body."""
    from track3d.synthetic import render_sphere
    from track3d.tracker import Track3D

    cam = Camera.from_fov(320, 240, 45.0)
    image, depth, box2d, _ = render_sphere(cam, [0.0, 0.0, 20.0], 1.5)
    boxes = {}
    for stray in (False, True):
        t = Track3D.from_default(cam, threads=1, drop_stray=stray)
        t.init(image, box2d, 0, points=cam.backproject_depth(depth))
        d = depth.copy()
        d[120, 160] = 8.0                       # the sphere's middle pixel: a return 12 m before it
        boxes[stray] = t.update(image, cam.backproject_depth(d)).box3d
    assert abs(boxes[True][2] - 20.0) < 0.5 and boxes[True][5] < 4.0
    assert boxes[False][5] > 6.0                # without the rule: the box reaches the alarm


def test_a_sensor_grid_coarser_than_the_cells_is_kept_whole():
    """A 128 x 128 flash LiDAR on a 1280 x 960 image lies 10 px apart: every return had counted as
    lone and the whole body was dropped (no_points every frame). Many lone returns, most of the
    frustum's, are a sparse grid, not false alarms."""
    body = _patch(300, 200, 100, 80, 20.0, step=10.0)
    assert len(body) >= 16
    out, b = drop_stray(body, _bounds(body), CAM.M)
    assert out is body
    with_alarm = np.concatenate([body, _patch(320, 210, 1, 1, 8.0)])   # one in front stays a run apart
    out, b = drop_stray(with_alarm, _bounds(with_alarm), CAM.M)
    assert len(out) == len(body) and b[0, 2] == body[:, 2].min()


def test_the_bounds_of_what_is_kept_are_exact_and_in_the_frustums_dtype():
    body = _patch(300, 200, 60, 40, 20.0, tilt=0.01)
    front = _patch(320, 210, 1, 1, 8.0)
    pts = np.concatenate([body, front])
    out, b = drop_stray(pts, _bounds(pts), CAM.M)
    assert b.dtype == np.float64 and b.shape == (2, 3)
    np.testing.assert_array_equal(b, _bounds(out))


def test_no_loop_module_reduces_a_point_array_along_axis_0():
    """numpy's min / max / ptp(axis=0) over a (n, 3) array walks it 3 values at a time: 1-4 ms on
    a near body's frustum against 0.05 ms column by column (track3d.frames.point_bounds). One in
    drop_stray had made the loop's slowest frames (p99.9 6.1 ms against a 2.7 ms median)."""
    import re
    from pathlib import Path

    import track3d
    pattern = re.compile(r"(\.(min|max|ptp)\(\s*axis\s*=\s*0\s*\))|(np\.(amin|amax|min|max|ptp)\([^()]*axis\s*=\s*0)")
    root = Path(track3d.__file__).parent
    found = []
    for f in sorted(root.rglob("*.py")):
        if "evaluation" in f.parts:   # per-sequence tables, not per frame
            continue
        for k, line in enumerate(f.read_text().splitlines(), 1):
            code = line.split("#")[0]
            if pattern.search(code) and '"""' not in line and "``" not in line:
                found.append(f"{f.relative_to(root)}:{k}: {line.strip()}")
    assert not found, "use track3d.frames.point_bounds:\n" + "\n".join(found)
