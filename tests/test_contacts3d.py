"""3D contacts: CLM states, the 3-vector tangential spring kept tangent as the pair rotates, forces and
torques (Newton, angular momentum), sliding kinematics, and reduction to the 2D kernels."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rheograph.sim import contacts, contacts3d
from rheograph.sim.contacts3d import FRICTIONLESS, NONE, SLIDE, STICK, UNLOADING
from rheograph.sim.geometry3d import pair_geometry

KN, KT, MU = 1000.0, 500.0, 0.5
RADII = np.array([1.0, 1.4])
PI, PJ = np.array([0]), np.array([1])
ABAR = 1.2
N0 = np.array([0.48, -0.6, 0.64])  # a unit vector off every axis


def clm(overlap, stretch, n=N0):
    xi = np.array([-overlap / ABAR])
    stretch = np.array([stretch], dtype=float)
    state = np.zeros(1, dtype=np.int8)
    nf = contacts3d.critical_load_update(RADII, PI, PJ, n[None, :], xi, stretch, state, KN, KT, MU, 1.0)
    return nf, state[0], stretch[0]


def test_critical_load_model_states_and_the_coulomb_bound():
    t = np.cross(N0, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    # F_n = kn a_bar overlap = 0.6 < F_CL: frictionless, memory lost
    assert clm(0.5e-3, 1e-3 * t)[1:] == (FRICTIONLESS,) + (pytest.approx(np.zeros(3)),)
    # F_n = 6 F_CL: capacity mu (F_n - 1) = 2.5, F_t = kt a_bar |s| = 0.6 * 1e3 * |s|
    nf, state, s = clm(5e-3, 2e-3 * t)
    assert (nf, state) == (1, STICK)
    np.testing.assert_allclose(s, 2e-3 * t, rtol=1e-12, atol=1e-18)
    nf, state, s = clm(5e-3, 1e-2 * t + 3e-3 * N0)  # beyond the bound, with a normal part
    assert (nf, state) == (1, SLIDE)
    assert KT * ABAR * np.linalg.norm(s) == pytest.approx(MU * (KN * ABAR * 5e-3 - 1.0), rel=1e-12)
    np.testing.assert_allclose(s / np.linalg.norm(s), t, atol=1e-12)  # normal part projected out
    assert clm(-1e-3, 1e-3 * t)[1] == NONE and np.all(clm(-1e-3, 1e-3 * t)[2] == 0.0)


def test_spring_forces_obey_newton_and_the_angular_momentum_balance():
    """F_j = -F_i, T_i parallel to T_j, and x_i x F_i + x_j x F_j + T_i + T_j = overlap n x F_t (the lever
    arms a_i, a_j sum to a_i + a_j while the centres are a_i + a_j - overlap apart)."""
    overlap = 4e-3
    x_i = np.array([0.3, 0.2, -0.1])
    x_j = x_i + (2.4 - overlap) * N0
    stretch = np.array([[2e-3, 1e-3, 0.5e-3]])
    stretch[0] -= (stretch[0] @ N0) * N0
    out = np.zeros(12)
    f_on_i = contacts3d.contact_spring_forces(
        RADII,
        PI,
        PJ,
        N0[None, :],
        np.array([-overlap / ABAR]),
        stretch,
        np.array([STICK], np.int8),
        KN,
        KT,
        out,
    )
    f_i, t_i, f_j, t_j = out[:3], out[3:6], out[6:9], out[9:]
    f_t = KT * ABAR * stretch[0]
    np.testing.assert_allclose(f_i, -KN * ABAR * overlap * N0 + f_t, rtol=1e-12)
    np.testing.assert_allclose(f_on_i[0], f_i, rtol=0)
    np.testing.assert_allclose(f_j, -f_i, rtol=0)
    np.testing.assert_allclose(np.cross(t_i, t_j), 0.0, atol=1e-14)
    np.testing.assert_allclose(t_i, 1.0 * np.cross(N0, f_t), rtol=1e-12)
    np.testing.assert_allclose(t_j, 1.4 * np.cross(N0, f_t), rtol=1e-12)
    torque_total = np.cross(x_i, f_i) + np.cross(x_j, f_j) + t_i + t_j
    np.testing.assert_allclose(torque_total, overlap * np.cross(N0, f_t), atol=1e-13)


@pytest.mark.parametrize("overlap", [0.0, 0.01])
def test_sliding_velocity_of_rigid_motion_and_of_a_tangential_slide(overlap):
    """A rigidly moving pair (translation + rotation Omega about any point) slides at -overlap Omega x n
    (zero when just touching); j translating along a tangent t slides at that velocity, and the stretch
    grows by it times dt."""
    r = 2.4 - overlap
    x_i = np.array([0.5, -0.2, 0.1])
    x_j = x_i + r * N0
    u0, omega = np.array([0.3, -0.1, 0.2]), np.array([0.7, -0.4, 0.9])
    vel = np.r_[u0 + np.cross(omega, x_i), omega, u0 + np.cross(omega, x_j), omega]
    dy = np.array([r * N0[1]])
    v = np.array(contacts3d.sliding_velocity(vel, RADII, PI, PJ, N0[None, :], dy, 0.0, 0))
    np.testing.assert_allclose(v, -overlap * np.cross(omega, N0), atol=1e-14)
    t = np.cross(N0, [0.0, 1.0, 0.0])
    t /= np.linalg.norm(t)
    slide = np.r_[np.zeros(6), 0.8 * t + 0.5 * N0, np.zeros(3)]  # the normal part does not slide
    v = np.array(contacts3d.sliding_velocity(slide, RADII, PI, PJ, N0[None, :], dy, 0.0, 0))
    np.testing.assert_allclose(v, 0.8 * t, atol=1e-14)
    stretch = np.zeros((1, 3))  # the step integrates that velocity into the stretch
    contacts3d.increment_stretch(
        slide, RADII, PI, PJ, N0[None, :], dy, np.array([STICK], np.int8), stretch, 0.0, 0.01, False
    )
    np.testing.assert_allclose(stretch[0], 0.008 * t, atol=1e-16)


def test_one_projection_after_a_rigid_rotation_scales_the_rolling_component_by_cos_theta():
    e = np.cross(N0, [0.0, 0.0, 1.0])
    e /= np.linalg.norm(e)  # rotation axis, normal to n
    along = np.cross(e, N0)  # the tangent the rotation moves n towards
    theta = 0.3
    n_new = Rotation.from_rotvec(theta * e).apply(N0)
    _, _, s = clm(5e-3, 1e-3 * along + 2e-3 * e, n=n_new)
    assert s @ n_new == pytest.approx(0.0, abs=1e-18)
    assert s @ e == pytest.approx(2e-3, rel=1e-12)  # the component along the axis is untouched
    assert np.linalg.norm(s - (s @ e) * e) == pytest.approx(1e-3 * np.cos(theta), rel=1e-12)


def test_stretch_stays_tangent_and_turns_with_a_rolling_pair():
    """A touching pair rotating rigidly about an axis normal to n, in 400 small steps through the step's
    kernels (increment with the old geometry, move, new geometry, CLM projection): the stretch stays
    normal to n (round-off) and turns with the pair, losing only a second-order amount of its length,
    |s| = |s0| prod cos(d theta) ~ |s0| (1 - theta d theta / 2).  The centres stay at a_i + a_j so that a
    rigid rotation does not slide (it slides by -overlap Omega x n); the CLM is handed an overlap of
    2e-3 (F_n = 2.4 F_CL) to keep the contact frictional."""
    e = np.cross(N0, [0.0, 1.0, 0.0])
    e /= np.linalg.norm(e)
    omega, dt, steps = 0.5, 2e-3, 400
    theta, dtheta = omega * dt * steps, omega * dt
    pos = np.array([[0.1, -0.3, 0.2], [0.0, 0.0, 0.0]])
    pos[1] = pos[0] + 2.4 * N0
    t0 = np.cross(e, N0)
    stretch = np.array([1e-4 * t0 + 0.5e-4 * e])
    s0 = stretch[0].copy()
    state = np.array([STICK], dtype=np.int8)
    xi = np.array([-2e-3 / ABAR])
    big = 1e3  # a box far larger than the pair: no periodic images
    rot = Rotation.from_rotvec(dtheta * e)
    for _ in range(steps):
        n, _, _, dy = pair_geometry(pos, RADII, PI, PJ, big, big, big, 0.0)
        contacts3d.critical_load_update(RADII, PI, PJ, n, xi, stretch, state, KN, KT, MU, 1.0)
        assert state[0] == STICK and abs(stretch[0] @ n[0]) < 1e-18
        centre = pos.mean(axis=0)
        w = omega * e
        vel = np.r_[np.cross(w, pos[0] - centre), w, np.cross(w, pos[1] - centre), w]
        contacts3d.increment_stretch(vel, RADII, PI, PJ, n, dy, state, stretch, 0.0, dt, False)
        pos = centre + rot.apply(pos - centre)
    n, _, _, _ = pair_geometry(pos, RADII, PI, PJ, big, big, big, 0.0)
    contacts3d.critical_load_update(RADII, PI, PJ, n, xi, stretch, state, KN, KT, MU, 1.0)
    assert abs(stretch[0] @ n[0]) < 1e-18
    rolled = stretch[0] - (stretch[0] @ e) * e
    assert stretch[0] @ e == pytest.approx(0.5e-4, rel=1e-12)  # the axial part is untouched
    assert np.linalg.norm(rolled) == pytest.approx(1e-4 * np.cos(dtheta) ** steps, rel=1e-9)
    assert 1 - np.linalg.norm(rolled) / 1e-4 == pytest.approx(theta * dtheta / 2, rel=1e-3)
    np.testing.assert_allclose(stretch[0], Rotation.from_rotvec(theta * e).apply(s0), atol=1e-3 * 1e-4)


@pytest.mark.parametrize("elastic_unloading", [False, True])
def test_planar_contacts_reduce_to_the_2d_kernels(elastic_unloading):
    """Contacts in the plane z = 0 with in-plane stretches and motion: the CLM, the spring forces and
    torque about z, the stretch increment and (with elastic unloading) the sliding contacts it marks
    unloading are the 2D kernels', with nothing out of the plane."""
    rng = np.random.default_rng(2)
    m = 6
    radii = np.array([1.0, 1.4, 1.0, 1.4, 1.0, 1.4, 1.0])
    pi = np.array([0, 0, 1, 2, 3, 4])
    pj = np.array([1, 2, 3, 4, 5, 6])
    ang = rng.uniform(0, 2 * np.pi, m)
    n2 = np.stack([np.cos(ang), np.sin(ang)], axis=1)
    n3 = np.c_[n2, np.zeros(m)]
    xi = np.array([-2e-3, -8e-3, -1e-4, -5e-3, 0.01, -3e-3])
    s2 = rng.normal(scale=3e-3, size=(m, 2))
    s2[1] = [0.05, -0.04]  # far beyond the Coulomb bound: slides
    s3 = np.c_[s2, np.zeros(m)]
    st2, st3 = np.full(m, STICK, np.int8), np.full(m, STICK, np.int8)
    nf2 = contacts.critical_load_update(radii, pi, pj, n2, xi, s2, st2, KN, KT, MU, 1.0)
    nf3 = contacts3d.critical_load_update(radii, pi, pj, n3, xi, s3, st3, KN, KT, MU, 1.0)
    assert nf2 == nf3 and np.array_equal(st2, st3) and {FRICTIONLESS, STICK, SLIDE, NONE} <= set(st3)
    np.testing.assert_allclose(s3[:, :2], s2, rtol=1e-13, atol=1e-18)
    out2, out3 = np.zeros(21), np.zeros(42)
    contacts.contact_spring_forces(radii, pi, pj, n2, xi, s2, st2, KN, KT, out2)
    contacts3d.contact_spring_forces(radii, pi, pj, n3, xi, s3, st3, KN, KT, out3)
    out3 = out3.reshape(-1, 6)
    np.testing.assert_allclose(out3[:, [0, 1, 5]], out2.reshape(-1, 3), rtol=1e-12, atol=1e-12)
    assert np.all(out3[:, 2:5] == 0.0)
    vel2 = rng.normal(size=21)
    vel3 = np.zeros((7, 6))
    vel3[:, [0, 1, 5]] = vel2.reshape(-1, 3)
    dy = rng.normal(size=m)
    # the sliding contact's stretch against its sliding velocity: it unloads
    if np.dot(contacts.sliding_velocity(vel2, radii, pi, pj, n2, dy, 0.7, 1), s2[1]) > 0.0:
        s2[1], s3[1] = -s2[1], -s3[1]
    contacts.increment_stretch(vel2, radii, pi, pj, n2, dy, st2, s2, 0.7, 0.01, elastic_unloading)
    contacts3d.increment_stretch(vel3.ravel(), radii, pi, pj, n3, dy, st3, s3, 0.7, 0.01, elastic_unloading)
    np.testing.assert_allclose(s3[:, :2], s2, rtol=1e-12, atol=1e-16)
    assert np.all(s3[:, 2] == 0.0)
    assert np.array_equal(st2, st3) and (UNLOADING in st3) == elastic_unloading
