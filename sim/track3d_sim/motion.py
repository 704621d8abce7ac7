"""Random 6-DoF motion of the asteroid relative to the observer (left camera frame).

The centre path is drawn in (u_n, v_n, log z) — normalised image position and log
depth — as a sum of random sinusoids (smooth, with random phases, so velocity
components come out close to normally distributed), plus planned "excursions": short
raised-cosine detours that carry the body across the image border (truncation) and
for a few frames wholly out of view (absence). Depth stays in [1 + R + margin, 45 - R]
so the camera is never inside the body and every surface point lies in the frustum's
1..45 m range. Rotation: spin about a random body axis composed with a slower
precession about a random inertial axis (tumbling), constant rates per sequence.
"""
from __future__ import annotations

import math

import numpy as np

FPS = 10.0          # frames per second of the simulated cameras
Z_NEAR, Z_FAR = 1.0, 45.0


def rotvec_to_matrix(rv: np.ndarray) -> np.ndarray:
    """Rodrigues: (..., 3) rotation vectors -> (..., 3, 3)."""
    rv = np.asarray(rv, np.float64)
    th = np.linalg.norm(rv, axis=-1, keepdims=True)
    k = rv / np.where(th > 0, th, 1.0)
    K = np.zeros(rv.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -k[..., 2], k[..., 1]
    K[..., 1, 0], K[..., 1, 2] = k[..., 2], -k[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -k[..., 1], k[..., 0]
    s, c = np.sin(th)[..., None], np.cos(th)[..., None]
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def _unit(rng):
    v = rng.standard_normal(3)
    return v / np.linalg.norm(v)


def _sines(rng, t, n, amp, fmin, fmax):
    out = np.zeros_like(t)
    for _ in range(n):
        f = rng.uniform(fmin, fmax)
        out += amp * rng.uniform(0.3, 1.0) * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    return out


def make_motion(rng: np.random.Generator, n_frames: int, radius: float, tan_half: tuple[float, float],
                fast: bool | None = None, exits: bool | None = None) -> dict:
    """Poses for n_frames: R (N,3,3) body->camera, T (N,3) body origin in the left camera frame.

    radius: bounding radius of the body (m). tan_half: (tan(ax/2), tan(ay/2)).
    """
    N = int(n_frames)
    t = np.arange(N) / FPS
    dur = max(t[-1], 1.0 / FPS) if N > 1 else 1.0
    fast = bool(rng.random() < 0.2) if fast is None else fast
    speed = rng.lognormal(0.0, 0.35) * (2.5 if fast else 1.0)
    # frequencies in cycles per second; a few periods per 30 s sequence at normal speed
    fmin, fmax = 0.01 * speed, 0.06 * speed
    zmin = Z_NEAR + radius + 0.5
    zmax = max(Z_FAR - radius - 0.5, zmin + 1.0)
    # base depth: log-uniform, the body spans a sensible part of the image on average
    # (mostly the body spans at most ~3/4 of the image height; 20% of sequences are close-ups)
    close = bool(rng.random() < 0.2)
    zlo = min(max(zmin, radius / ((1.3 if close else 0.75) * tan_half[1])), zmax)
    zhi = min(zmax, max(zlo * 1.2, radius / (0.06 * tan_half[0])))
    z0 = math.exp(rng.uniform(math.log(zlo), math.log(zhi)))
    lz = math.log(z0) + _sines(rng, t, 3, 0.2 * speed ** 0.5, fmin, fmax)
    lz += rng.normal(0, 0.25) * (t / dur)  # approach / recede trend (scale change)
    # soft clamp into [log zmin, log zmax]
    a, b = math.log(zmin), math.log(zmax)
    mid, half = (a + b) / 2, (b - a) / 2
    lz = mid + half * np.tanh((lz - mid) / half)
    z = np.exp(lz)
    un = rng.uniform(-0.35, 0.35) + _sines(rng, t, 3, 0.22, fmin, fmax)
    vn = rng.uniform(-0.35, 0.35) + _sines(rng, t, 3, 0.22, fmin, fmax)
    un = 0.8 * np.tanh(un / 0.8)
    vn = 0.8 * np.tanh(vn / 0.8)
    # excursions: truncation at the border and short exits from view
    exits = bool(rng.random() < 0.45) if exits is None else exits
    events = []
    if exits and N >= 12:
        for _ in range(int(rng.integers(1, 3))):
            length = int(rng.integers(max(10, N // 12), max(11, N // 5)))
            length = min(length, N - 2)
            start = int(rng.integers(0, max(1, N - length)))
            axis = int(rng.integers(2))
            sign = rng.choice([-1.0, 1.0])
            k = np.arange(N)
            inside = (k >= start) & (k < start + length)
            bump = np.where(inside, 0.5 - 0.5 * np.cos(2 * np.pi * (k - start) / length), 0.0)
            # peak beyond the border by the body's angular radius (fully out) or less (truncated)
            full_out = rng.random() < 0.6
            ang_r = radius / z / tan_half[axis]
            peak = 1.0 + (1.3 * ang_r + 0.05 if full_out else rng.uniform(-0.3, 0.6) * ang_r)
            if axis == 0:
                un = un + bump * (sign * peak - un)
            else:
                vn = vn + bump * (sign * peak - vn)
            events.append({"start": start, "length": length, "axis": "xy"[axis], "sign": float(sign),
                           "full_out": bool(full_out)})
    T = np.stack([un * z * tan_half[0], vn * z * tan_half[1], z], axis=1)
    # rotation
    R0 = rotvec_to_matrix(_unit(rng) * rng.uniform(0, np.pi))
    w_spin = math.radians(abs(rng.normal(0, 10.0)) + 1.0) * (2.0 if fast else 1.0)  # rad/s
    w_prec = math.radians(abs(rng.normal(0, 4.0)))
    a_spin, a_prec = _unit(rng), _unit(rng)
    Rs = rotvec_to_matrix(a_spin[None] * (w_spin * t)[:, None])
    Rp = rotvec_to_matrix(a_prec[None] * (w_prec * t)[:, None])
    R = Rp @ R0 @ Rs
    v = np.diff(T, axis=0) * FPS
    info = {"fps": FPS, "fast": fast, "speed_scale": float(speed), "z0_m": float(z0), "close_up": close,
            "z_range_m": [float(zmin), float(zmax)], "spin_axis_body": a_spin.tolist(),
            "spin_deg_s": math.degrees(w_spin), "precession_axis": a_prec.tolist(),
            "precession_deg_s": math.degrees(w_prec), "excursions": events,
            "mean_speed_m_s": float(np.linalg.norm(v, axis=1).mean()) if len(v) else 0.0}
    return {"R": R, "T": T, "info": info}
