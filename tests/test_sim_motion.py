"""Spin states: torque-free tumbling conserves energy and angular momentum and matches the
analytic solution of a symmetric top; principal-axis spin keeps its axis fixed; mesh inertia."""
from __future__ import annotations

import math

import numpy as np
import pytest

from track3d_sim.motion import FPS, make_motion, torque_free
from track3d_sim.shapes import mesh_inertia

TAN_HALF = (math.tan(math.radians(22.5)), math.tan(math.radians(17.25)))


def _conserved(I, R, w):
    E = 0.5 * np.einsum("ni,ij,nj->n", w, I, w)
    L = np.einsum("nij,jk,nk->ni", R, I, w)  # inertial frame
    return E, L


def test_tumbling_conserves_energy_and_angular_momentum():
    I = np.diag([1.0, 1.7, 2.4])
    Q = np.linalg.qr(np.random.default_rng(0).standard_normal((3, 3)))[0]
    I = Q @ I @ Q.T  # not diagonal in the body frame
    w0 = np.radians([12.0, -7.0, 9.0])
    t = np.arange(600) / FPS  # 60 s, several tumbling periods
    R, w = torque_free(I, w0, t)
    E, L = _conserved(I, R, w)
    assert np.abs(E / E[0] - 1).max() < 1e-8
    assert np.abs(L - L[0]).max() / np.linalg.norm(L[0]) < 1e-8
    assert np.allclose(np.einsum("nij,nkj->nik", R, R), np.eye(3), atol=1e-12)
    # it really tumbles: the body-frame angular velocity wanders far from its start
    cos = (w @ w0) / np.linalg.norm(w, axis=1) / np.linalg.norm(w0)
    assert cos.min() < 0.9


def test_symmetric_top_matches_the_analytic_solution():
    # I1 = I2 != I3: w3 constant, (w1, w2) turns at Omega = (I3 - I1) / I1 * w3 in the body frame
    I1, I3 = 1.0, 1.6
    w0 = np.array([0.2, 0.0, 0.5])
    t = np.arange(300) / FPS
    _, w = torque_free(np.diag([I1, I1, I3]), w0, t)
    Om = (I3 - I1) / I1 * w0[2]
    # body-frame Euler: dw1/dt = -Om w2, dw2/dt = Om w1 (sign from I dw/dt = (I w) x w)
    expect = np.stack([0.2 * np.cos(Om * t), 0.2 * np.sin(Om * t), np.full_like(t, 0.5)], 1)
    assert np.abs(w - expect).max() < 1e-9


def test_principal_spin_keeps_its_axis_fixed():
    I = np.diag([3.0, 2.0, 1.0])
    m = make_motion(np.random.default_rng(4), 50, 2.0, TAN_HALF, spin="principal", inertia=I)
    info = m["info"]
    assert info["spin"] == "principal" and info["inertia_source"] == "mesh"
    a = np.asarray(info["spin_axis_body"])
    assert abs(abs(a @ [1, 0, 0]) - 1) < 1e-12 or abs(abs(a @ [0, 0, 1]) - 1) < 1e-12  # a principal axis
    R = m["R"]
    axis_cam = R @ a
    assert np.abs(axis_cam - axis_cam[0]).max() < 1e-9
    # turning at the recorded rate
    ang = np.arccos(np.clip((np.trace(R[0].T @ R[1]) - 1) / 2, -1, 1))
    assert math.degrees(ang) * FPS == pytest.approx(info["spin_deg_s"], rel=1e-6)


def test_tumbling_motion_records_its_state_and_conserves_momentum():
    I = np.diag([1.0, 1.5, 2.2])
    m = make_motion(np.random.default_rng(1), 40, 2.0, TAN_HALF, spin="tumbling", inertia=I)
    info = m["info"]
    assert info["spin"] == "tumbling" and info["tumbling_mode"] in ("SAM", "LAM")
    R = m["R"]
    # angular momentum in the camera frame, from finite-difference body rates, stays put
    dR = np.einsum("nji,njk->nik", R[:-1], R[1:])  # R_i^T R_{i+1}
    ang = np.arccos(np.clip((np.trace(dR, axis1=1, axis2=2) - 1) / 2, -1, 1))
    vee = np.stack([dR[:, 2, 1] - dR[:, 1, 2], dR[:, 0, 2] - dR[:, 2, 0], dR[:, 1, 0] - dR[:, 0, 1]], 1)
    w = vee / (2 * np.sin(ang))[:, None] * ang[:, None] * FPS   # mean body rate over each step
    L = np.einsum("nij,jk,nk->ni", R[:-1], I, w)
    assert np.abs(L - L.mean(0)).max() / np.linalg.norm(L.mean(0)) < 0.05


def test_spin_mode_drawn_and_checked():
    modes = {make_motion(np.random.default_rng(s), 5, 1.0, TAN_HALF)["info"]["spin"] for s in range(30)}
    assert modes == {"principal", "tumbling"}
    with pytest.raises(ValueError, match="spin"):
        make_motion(np.random.default_rng(0), 5, 1.0, TAN_HALF, spin="wobbly")
    with pytest.raises(ValueError, match="positive definite"):
        make_motion(np.random.default_rng(0), 5, 1.0, TAN_HALF, spin="principal", inertia=-np.eye(3))


def test_mesh_inertia_of_a_box_by_hand():
    trimesh = pytest.importorskip("trimesh")
    m = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    v = np.asarray(m.vertices) + [5.0, -1.0, 2.0]  # off the origin: about the centre of mass
    V, com, I = mesh_inertia(v, np.asarray(m.faces))
    assert V == pytest.approx(6.0)
    assert np.allclose(com, [5.0, -1.0, 2.0])
    # I_xx = V (b^2 + c^2) / 12 = 6 (4 + 9) / 12 = 6.5; I_yy = 6 (1 + 9) / 12 = 5; I_zz = 6 (1 + 4) / 12 = 2.5
    assert np.allclose(I, np.diag([6.5, 5.0, 2.5]))
