"""Writes tests/data/warp_opencv500.npz: OpenCV's own bilinear warps that track3d.resample must
reproduce byte for byte. Made once with opencv-contrib-python-headless==5.0.0.93 on an x86-64 CPU
with AVX2 (the build and release the shipped models and results were measured with):

    python tests/data/make_warp_fixture.py   # in a venv with only numpy and that OpenCV

Cases: random noise images (1-32 px a side), scales 0.5-6 per axis, offsets that put the crop
inside, across and outside the image, crop widths 1-40 (whole 16-column blocks and the columns
after them), constant (border colours outside 0..255 included) and replicated borders; and one
float32 channel under rotations (the training's motion-blur kernels among them)."""
from pathlib import Path

import cv2
import numpy as np

rng = np.random.default_rng(500)
arrays, cases = {}, []
for i in range(48):
    h, w = int(rng.integers(1, 33)), int(rng.integers(1, 33))
    img = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    sx = float(np.exp(rng.uniform(np.log(0.5), np.log(6.0))))
    sy = sx if i % 3 else float(np.exp(rng.uniform(np.log(0.5), np.log(6.0))))
    ow, oh = int(rng.integers(1, 41)), int(rng.integers(1, 25))
    tx, ty = float(rng.uniform(-sx * w, ow)), float(rng.uniform(-sy * h, oh))
    border = tuple(float(v) for v in rng.uniform(-20.0, 280.0, 3))
    replicate = i % 4 == 3
    m = np.array([[sx, 0.0, tx], [0.0, sy, ty]])
    out = cv2.warpAffine(img, m, (ow, oh), flags=cv2.INTER_LINEAR,
                         borderMode=cv2.BORDER_REPLICATE if replicate else cv2.BORDER_CONSTANT, borderValue=border)
    arrays[f"image{i}"], arrays[f"out{i}"] = img, out
    cases.append([sx, sy, tx, ty, ow, oh, *border, float(replicate)])
arrays["cases"] = np.array(cases, np.float64)
# one float32 channel under rotations (track3d.resample.warp_affine_gray_numpy): the training's
# motion-blur line kernels (3-9 px, all scalar-tail columns) and noise images up to 40 px wide
gray_maps, gray_sizes = [], []
for i in range(24):
    if i % 2:
        n = int(rng.integers(3, 10))
        img = np.zeros((n, n), np.float32)
        img[n // 2] = 1.0
        m = cv2.getRotationMatrix2D(((n - 1) / 2, (n - 1) / 2), float(rng.uniform(0, 180)), 1.0)
        size = (n, n)
    else:
        h, w = int(rng.integers(1, 30)), int(rng.integers(1, 30))
        img = (rng.standard_normal((h, w)) * 60).astype(np.float32)
        m = cv2.getRotationMatrix2D((float(rng.uniform(0, w)), float(rng.uniform(0, h))), float(rng.uniform(0, 360)),
                                    float(np.exp(rng.uniform(-0.7, 0.7))))
        size = (int(rng.integers(1, 41)), int(rng.integers(1, 25)))
    arrays[f"gray_image{i}"], arrays[f"gray_out{i}"] = img, cv2.warpAffine(img, m, size)
    gray_maps.append(m.ravel())
    gray_sizes.append(size)
arrays["gray_maps"], arrays["gray_sizes"] = np.array(gray_maps), np.array(gray_sizes)
arrays["opencv"] = np.array(cv2.__version__)
np.savez_compressed(Path(__file__).with_name("warp_opencv500.npz"), **arrays)
