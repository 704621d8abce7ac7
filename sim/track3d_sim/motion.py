"""Random 6-DoF motion of the asteroid relative to the observer (left camera frame).

The centre path is drawn in (u_n, v_n, log z) — normalised image position and log
depth — as a sum of random sinusoids (smooth, with random phases, so velocity
components come out close to normally distributed), plus planned "excursions": short
raised-cosine detours that carry the body across the image border (truncation) and
for a few frames wholly out of view (absence). Depth stays in [1 + R + margin, 45 - R]
so the camera is never inside the body and every surface point lies in the frustum's
1..45 m range.

Rotation (spin state, `spin=`):
  principal  uniform rotation about one principal axis of the body's inertia tensor (the
             axis of largest inertia, 80%, or of smallest), the axis fixed in space;
  tumbling   torque-free non-principal-axis rotation (Toutatis, Apophis): Euler's equations
             I dw/dt = (I w) x w in the body frame with the attitude quaternion, integrated
             by RK4 with `SUBSTEPS` steps per frame; energy and angular momentum are conserved
             (tests/test_sim_motion.py). The body rotates about its box centre.
The inertia tensor comes from the mesh at uniform density (`shapes.mesh_inertia`); without one,
a random triaxial tensor is drawn.
"""
from __future__ import annotations

import math

import numpy as np

from track3d.frustum import Z_MAX as Z_FAR, Z_MIN as Z_NEAR  # stated once

FPS = 10.0          # frames per second of the simulated cameras

# Depth rules of the centre path (make_motion), named because `radius_range` derives the body
# sizes the scenes can hold from the same numbers.
DEPTH_MARGIN = 0.5  # m between the bounding sphere and the frustum's near / far limits
# Past this bounding radius the depth range collapses to [zmin, zmin + 1] and the far side passes
# Z_FAR, then the 16-bit depth maps' 65.5 m (a user mesh of 300 m had crashed the depth writer):
# the largest body a scene holds at all (radius_range's hi is the largest one whole in the view)
DEPTH_RADIUS_MAX = (Z_FAR - Z_NEAR - 2.0 * DEPTH_MARGIN - 1.0) / 2.0
FIT_HEIGHT = 0.75   # nearest base depth: the body spans at most this fraction of the image height
CLOSE_FIT = 1.3     # ... or this much for a close-up
MIN_SPAN = 0.06     # farthest base depth: the body's radius spans at least this fraction of the half-width
MIN_DEPTH_RATIO = 1.2  # the base-depth range is at least this wide (farthest / nearest)


def radius_range(tan_half: tuple[float, float]) -> tuple[float, float]:
    """(lo, hi): the bounding radii (m, about the body origin) of the bodies the scenes can hold
    for a camera with these (tan(ax/2), tan(ay/2)).

    hi: the bounding sphere fits the image height at the farthest depth the path may reach
    (Z_FAR - R - DEPTH_MARGIN), which also keeps the far side within Z_FAR - DEPTH_MARGIN. A larger
    body never fits in the image (a round one fills it), and beyond R = (Z_FAR - Z_NEAR - 2
    DEPTH_MARGIN - 1) / 2 = 21 m the depth range collapses to [zmin, zmin + 1] and the far side
    passes Z_FAR (then the 16-bit depth maps' 65.5 m). Presets (45 deg, 4:3): 10.5 m; the
    procedural bodies reach about 9.7 m.
    lo: the farthest base depth still shows the body at the smallest planned size (its radius
    MIN_SPAN of the half-width, as the smallest procedural bodies far away). A smaller body is held
    near Z_NEAR + R + DEPTH_MARGIN and only shrinks in the image, to nothing at millimetre sizes.
    Presets: 0.046 m."""
    tx, ty = float(tan_half[0]), float(tan_half[1])
    near = Z_NEAR + DEPTH_MARGIN
    lo = MIN_DEPTH_RATIO * near * MIN_SPAN * tx / (1.0 - MIN_DEPTH_RATIO * MIN_SPAN * tx)
    hi = (Z_FAR - DEPTH_MARGIN) * ty / (1.0 + ty)
    return lo, hi


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


SPIN_MODES = ("principal", "tumbling")
TUMBLING_FRACTION = 0.3   # of sequences when the spin mode is drawn
SUBSTEPS = 16             # RK4 steps per frame interval for tumbling


def _quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return np.array([aw * bw - ax * bx - ay * by - az * bz, aw * bx + ax * bw + ay * bz - az * by,
                     aw * by - ax * bz + ay * bw + az * bx, aw * bz + ax * by - ay * bx + az * bw])


def _quat_matrix(q: np.ndarray) -> np.ndarray:
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def torque_free(inertia: np.ndarray, omega0: np.ndarray, times: np.ndarray,
                substeps: int = SUBSTEPS) -> tuple[np.ndarray, np.ndarray]:
    """Torque-free rigid rotation from identity attitude with body-frame angular velocity omega0
    (rad/s) at times[0]. Returns R (N, 3, 3) body -> inertial and omega (N, 3) body frame.

    State: attitude quaternion q (dq/dt = q * (0, w) / 2) and w (I dw/dt = (I w) x w),
    integrated by classical RK4 with `substeps` steps per interval; q is renormalised per step."""
    I = np.asarray(inertia, np.float64)
    Iinv = np.linalg.inv(I)

    def deriv(y):
        q, w = y[:4], y[4:]
        dq = 0.5 * _quat_mul(q, np.array([0.0, *w]))
        dw = Iinv @ np.cross(I @ w, w)
        return np.concatenate([dq, dw])

    y = np.concatenate([[1.0, 0.0, 0.0, 0.0], np.asarray(omega0, np.float64)])
    Rs = np.zeros((len(times), 3, 3))
    ws = np.zeros((len(times), 3))
    for i in range(len(times)):
        if i > 0:
            dt = (times[i] - times[i - 1]) / substeps
            for _ in range(substeps):
                k1 = deriv(y)
                k2 = deriv(y + 0.5 * dt * k1)
                k3 = deriv(y + 0.5 * dt * k2)
                k4 = deriv(y + dt * k3)
                y = y + dt / 6.0 * (k1 + 2 * k2 + 2 * k3 + k4)
                y[:4] /= np.linalg.norm(y[:4])
        Rs[i] = _quat_matrix(y[:4])
        ws[i] = y[4:]
    return Rs, ws


def _spin(rng: np.random.Generator, t: np.ndarray, fast: bool, spin: str | None,
          inertia: np.ndarray | None) -> tuple[np.ndarray, dict]:
    """Body -> inertial rotations (N, 3, 3) relative to the initial attitude, and the info."""
    if spin is None:
        spin = "tumbling" if rng.random() < TUMBLING_FRACTION else "principal"
    if spin not in SPIN_MODES:
        raise ValueError(f"spin must be one of {SPIN_MODES}, got {spin!r}")
    info: dict = {"spin": spin}
    if inertia is None:
        I = np.diag(np.sort(rng.uniform(0.5, 1.5, 3)))
        info["inertia_source"] = "random"
    else:
        I = np.asarray(inertia, np.float64)
        if I.shape != (3, 3) or not np.all(np.isfinite(I)):
            raise ValueError(f"inertia must be a finite (3, 3) tensor, got shape {I.shape}")
        I = 0.5 * (I + I.T)
        info["inertia_source"] = "mesh"
    evals, evecs = np.linalg.eigh(I)            # ascending principal moments, columns = axes
    if evals[0] <= 0:
        raise ValueError(f"inertia must be positive definite, got principal moments {evals.tolist()}")
    info["principal_moments"] = (evals / evals.max()).tolist()
    w = math.radians(abs(rng.normal(0, 10.0)) + 1.0) * (2.0 if fast else 1.0)  # rad/s
    if spin == "principal":
        axis = evecs[:, 2] if rng.random() < 0.8 else evecs[:, 0]
        axis = axis * rng.choice([-1.0, 1.0])
        info.update(spin_axis_body=axis.tolist(), spin_deg_s=math.degrees(w))
        return rotvec_to_matrix(axis[None] * (w * t)[:, None]), info
    # tumbling: angular velocity well away from every principal axis
    while True:
        u = _unit(rng)
        if np.abs(evecs.T @ u).max() < 0.9:
            break
    Rs, _ = torque_free(I, u * w, t)
    L = I @ (u * w)
    E = 0.5 * (u * w) @ L
    info.update(spin_axis_body=u.tolist(), spin_deg_s=math.degrees(w),
                angular_momentum_body0=L.tolist(), energy=float(E),
                # 2 E I_mid / L^2 > 1: short-axis mode (SAM), < 1: long-axis mode (LAM)
                tumbling_mode="SAM" if 2 * E * evals[1] / (L @ L) > 1 else "LAM")
    return Rs, info


def make_motion(rng: np.random.Generator, n_frames: int, radius: float, tan_half: tuple[float, float],
                fast: bool | None = None, exits: bool | None = None, spin: str | None = None,
                inertia: np.ndarray | None = None) -> dict:
    """Poses for n_frames: R (N,3,3) body->camera, T (N,3) body origin in the left camera frame.

    radius: bounding radius of the body (m). tan_half: (tan(ax/2), tan(ay/2)).
    spin: "principal" | "tumbling" (drawn from rng when None, `TUMBLING_FRACTION` tumbling).
    inertia: (3, 3) body-frame inertia tensor (any scale), e.g. `shapes.mesh_inertia`.
    """
    N = int(n_frames)
    t = np.arange(N) / FPS
    dur = max(t[-1], 1.0 / FPS) if N > 1 else 1.0
    fast = bool(rng.random() < 0.2) if fast is None else fast
    speed = rng.lognormal(0.0, 0.35) * (2.5 if fast else 1.0)
    # frequencies in cycles per second; a few periods per 30 s sequence at normal speed
    fmin, fmax = 0.01 * speed, 0.06 * speed
    zmin = Z_NEAR + radius + DEPTH_MARGIN
    zmax = max(Z_FAR - radius - DEPTH_MARGIN, zmin + 1.0)
    # base depth: log-uniform, the body spans a sensible part of the image on average
    # (mostly the body spans at most ~3/4 of the image height; 20% of sequences are close-ups)
    close = bool(rng.random() < 0.2)
    zlo = min(max(zmin, radius / ((CLOSE_FIT if close else FIT_HEIGHT) * tan_half[1])), zmax)
    zhi = min(zmax, max(zlo * MIN_DEPTH_RATIO, radius / (MIN_SPAN * tan_half[0])))
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
    Rs, spin_info = _spin(rng, t, fast, spin, inertia)
    R = R0 @ Rs  # the observer does not rotate: the body's own rotation seen from a fixed attitude
    v = np.diff(T, axis=0) * FPS
    info = {"fps": FPS, "fast": fast, "speed_scale": float(speed), "z0_m": float(z0), "close_up": close,
            "z_range_m": [float(zmin), float(zmax)], **spin_info, "excursions": events,
            "mean_speed_m_s": float(np.linalg.norm(v, axis=1).mean()) if len(v) else 0.0}
    return {"R": R, "T": T, "info": info}
