import json

import numpy as np
import pytest

from track3d import dataset as D
from track3d.camera import Camera


def _write_fake(root, n=3):
    cam = Camera.from_fov(32, 24, 45.0)
    seq = root / "test" / "0001"
    for sub in (D.LEFT_DIR, D.RIGHT_DIR, D.DEPTH_DIR):
        (seq / sub).mkdir(parents=True)
    depth = np.zeros((24, 32), np.float32)
    depth[8:16, 12:20] = 5.0     # the 1 m cube at 5 m fills the 2D label, as the 3D label projects
    for i in range(n):
        img = np.full((24, 32, 3), i * 10, np.uint8)
        D.write_rgb(seq / D.LEFT_DIR / D.frame_name(i), img)
        D.write_rgb(seq / D.RIGHT_DIR / D.frame_name(i), img)
        D.write_depth_png(seq / D.DEPTH_DIR / D.frame_name(i), depth)
    np.savetxt(seq / D.GT2D, np.tile([12, 8, 8, 8], (n, 1)), delimiter=",", fmt="%.3f")
    np.savetxt(seq / D.GT3D, np.tile([0, 0, 5, 1, 1, 1], (n, 1)), delimiter=",", fmt="%.4f")
    np.savetxt(seq / D.ABSENCE, [0, 1, 0][:n], fmt="%d")
    np.savetxt(seq / D.CUT, [0, 0, 0][:n], fmt="%d")
    (seq / D.META).write_text(json.dumps({"family_index": 2, "depth_sensor": "ideal"}))
    (root / D.DATASET_JSON).write_text(json.dumps({
        "format": D.FORMAT, "version": 1, "camera": cam.to_dict(), "splits": {"test": ["0001"]}}))
    return cam


def test_reader_roundtrip(tmp_path):
    cam = _write_fake(tmp_path)
    ds = D.Dataset(tmp_path)
    assert ds.camera == cam
    (seq,) = ds.sequences("test")
    assert len(seq) == 3 and seq.category == 2
    assert seq.absent.tolist() == [False, True, False]
    f = seq[1]
    assert f.image.shape == (24, 32, 3) and f.image[0, 0, 0] == 10
    assert f.points.shape == (64, 3) and np.allclose(f.points[:, 2], 5.0)
    np.testing.assert_allclose(f.box2d, [12, 8, 8, 8])


def test_depth_png_is_millimetres(tmp_path):
    d = np.array([[1.2344, 0.0], [np.nan, 44.9999]])
    D.write_depth_png(tmp_path / "d.png", d)
    back = D.read_depth_png(tmp_path / "d.png")
    np.testing.assert_allclose(back, [[1.234, 0], [0, 45.0]], atol=1e-6)
    with pytest.raises(ValueError):
        D.write_depth_png(tmp_path / "e.png", np.array([[70.0]]))


def test_clear_errors(tmp_path):
    with pytest.raises(D.DatasetError, match="the folder is empty"):
        D.Dataset(tmp_path)
    _write_fake(tmp_path)
    ds = D.Dataset(tmp_path)
    with pytest.raises(D.DatasetError, match="split 'train'"):
        ds.sequences("train")
    with pytest.raises(D.DatasetError, match="sequence 'nope'"):
        ds.sequence("test", "nope")


def test_frame_errors_name_the_file(tmp_path, capfd):
    """A missing depth map printed OpenCV's own warning before the error; a frame of another size
    than the camera said so without naming the file; an empty split was listed as available."""
    _write_fake(tmp_path)
    seq = D.Dataset(tmp_path).sequences("test")[0]
    (seq.path / D.DEPTH_DIR / D.frame_name(1)).unlink()
    with pytest.raises(D.DatasetError, match="missing depth map .*000002.png"):
        seq.depth(1)
    assert "WARN" not in capfd.readouterr().err
    D.write_rgb(seq.path / D.RIGHT_DIR / D.frame_name(2), np.zeros((20, 30, 3), np.uint8))
    with pytest.raises(D.DatasetError, match=r"right/000003.png is 30x20 but the dataset's camera is 32x24"):
        seq.frame(2, right=True)
    (seq.path / D.LEFT_DIR / D.frame_name(0)).unlink()
    with pytest.raises(D.DatasetError, match="missing image"):
        seq.image(0)
    info = json.loads((tmp_path / D.DATASET_JSON).read_text())
    (tmp_path / D.DATASET_JSON).write_text(json.dumps({**info, "splits": {"test": ["0001"], "test_unseen": []}}))
    with pytest.raises(D.DatasetError, match=r"has: test, test_unseen \(empty\)"):
        D.Dataset(tmp_path).sequences("train")


def test_writer_and_reader_round_trip(tmp_path):
    """write_labels / write_dataset_json are the reader's counterpart: what one writes, the other
    reads back exactly (integers stay integers, 3D labels to the stated decimals)."""
    import numpy as np
    from track3d.camera import Camera

    seq = tmp_path / "test" / "0001"
    (seq / D.LEFT_DIR).mkdir(parents=True)
    (seq / D.DEPTH_DIR).mkdir()
    n = 3
    for i in range(n):
        D.write_rgb(seq / D.LEFT_DIR / D.frame_name(i), np.zeros((8, 10, 3), np.uint8))
        D.write_depth_png(seq / D.DEPTH_DIR / D.frame_name(i), np.full((8, 10), 5.0))
    gt2d = np.array([[1, 2, 3, 4], [0, 0, 0, 0], [2, 2, 5, 5]])
    gt3d = np.array([[0.1, 0.2, 5.0, 1.0, 1.0, 1.0]] * n)
    D.write_labels(seq, gt2d, gt3d, [0, 1, 0], [0, 0, 1], {"family_index": 1, "z": [1, 2], "depth_sensor": "ideal"})
    D.write_dataset_json(tmp_path, {"format": D.FORMAT, "version": D.FORMAT_VERSION,
                                    "camera": Camera.from_fov(10, 8, 45.0).to_dict(), "splits": {"test": ["0001"]}})
    assert (seq / D.GT2D).read_text().splitlines()[0] == "1,2,3,4"
    s = D.Dataset(tmp_path).sequence("test", "0001")
    np.testing.assert_array_equal(s.gt2d, gt2d)
    np.testing.assert_allclose(s.gt3d, gt3d, atol=5e-5)
    assert s.absent.tolist() == [False, True, False] and s.cut.tolist() == [False, False, True]
    assert s.category == 1 and s.meta["z"] == [1, 2]
    with pytest.raises(ValueError, match="gt3d"):
        D.write_labels(seq, gt2d, gt3d[:2], [0, 1, 0], [0, 0, 1], {})
    assert not list(tmp_path.glob(".dataset.json.tmp-*"))
