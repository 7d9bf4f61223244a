"""Critical Load Model: frictionless / stick / slide / reset transitions and spring forces."""

import numpy as np
import pytest
from conftest import sheared_frictional_problem

from rheograph.sim import contacts
from rheograph.sim.contacts import FRICTIONLESS, NONE, SLIDE, STICK, UNLOADING

KN, KT, MU = 1000.0, 500.0, 0.5
RADII = np.array([1.0, 1.4])
PI, PJ = np.array([0]), np.array([1])
ABAR = 1.2
NVEC = np.array([[1.0, 0.0]])


def nearest_image_vector(state, i, j):
    """Vector from particle i to the nearest of the 3 x 3 Lees-Edwards images of j, found by search
    (independent of the simulator's minimum-image convention)."""
    images = [
        state.positions[j] + kx * np.array([state.lx, 0.0]) + ky * np.array([state.le_offset, state.ly])
        for kx in (-1, 0, 1)
        for ky in (-1, 0, 1)
    ]
    return min((x - state.positions[i] for x in images), key=np.linalg.norm)


def clm(overlap, stretch_t, stretch_n=0.0, state=NONE):
    xi = np.array([-overlap / ABAR])
    stretch = np.array([[stretch_n, stretch_t]])
    state = np.array([state], dtype=np.int8)
    nf = contacts.critical_load_update(RADII, PI, PJ, NVEC, xi, stretch, state, KN, KT, MU, 1.0)
    return nf, state[0], stretch[0]


def test_below_critical_load_is_frictionless_and_resets_memory():
    overlap = 0.5 / (KN * ABAR)  # F_n = 0.5 F_CL
    nf, state, stretch = clm(overlap, 1e-3)
    assert (nf, state) == (0, FRICTIONLESS)
    np.testing.assert_array_equal(stretch, 0.0)


def test_above_critical_load_sticks_within_the_coulomb_bound():
    overlap = 3.0 / (KN * ABAR)  # F_n = 3 F_CL: capacity mu (3 - 1) = 1
    small = 0.5 / (KT * ABAR)  # |F_t| = 0.5 < 1
    nf, state, stretch = clm(overlap, small, stretch_n=0.2)
    assert (nf, state) == (1, STICK)
    np.testing.assert_allclose(stretch, [0.0, small])  # projected onto the tangent, magnitude kept


def test_beyond_the_bound_slides_and_is_rescaled_onto_it():
    overlap = 3.0 / (KN * ABAR)
    big = 4.0 / (KT * ABAR)
    nf, state, stretch = clm(overlap, -big)
    assert (nf, state) == (1, SLIDE)
    assert KT * ABAR * np.abs(stretch[1]) == pytest.approx(MU * (3.0 - 1.0))
    assert stretch[1] < 0  # direction kept


@pytest.mark.parametrize("before", [NONE, STICK, SLIDE])
def test_an_unloading_contact_beyond_the_bound_sticks_on_it_and_no_other_does(before):
    """Elastic unloading: a sliding contact whose stretch the last step turned back (UNLOADING) sticks on
    the Coulomb bound, where any other state beyond the bound slides; within the bound both stick, below
    the critical load both lose their memory."""
    overlap = 3.0 / (KN * ABAR)  # capacity mu (3 - 1) = 1
    big = 4.0 / (KT * ABAR)
    nf, unloading, stretch = clm(overlap, -big, state=UNLOADING)
    assert (nf, unloading) == (1, STICK)
    assert KT * ABAR * stretch[1] == pytest.approx(-MU * (3.0 - 1.0))  # on the bound, direction kept
    assert clm(overlap, -big, state=before)[1] == SLIDE
    assert clm(overlap, 0.5 / (KT * ABAR), state=UNLOADING)[1] == STICK
    assert clm(0.5 / (KN * ABAR), big, state=UNLOADING)[1] == FRICTIONLESS


@pytest.mark.parametrize("elastic_unloading", [False, True])
def test_only_a_sliding_contact_whose_sliding_opposes_its_stretch_is_marked_unloading(elastic_unloading):
    """increment_stretch marks UNLOADING exactly the SLIDE contacts whose sliding velocity points against
    their stretch, and only with elastic_unloading; the stretch increment itself is the same."""
    nvec = np.array([[1.0, 0.0]])  # tangent (0, 1)
    dy = np.array([0.0])
    dt = 1e-3
    for state, sliding, marked in [
        (SLIDE, -0.3, True),  # against the stretch (+y): unloading
        (SLIDE, +0.3, False),  # along it: still loading
        (STICK, -0.3, False),  # a stuck contact is held by its spring already
        (FRICTIONLESS, -0.3, False),
    ]:
        vel = np.array([0.0, 0.0, 0.0, 0.0, sliding, 0.0])  # j slides along +/- y
        states = np.array([state], dtype=np.int8)
        stretch = np.array([[0.0, 2e-4]])
        contacts.increment_stretch(vel, RADII, PI, PJ, nvec, dy, states, stretch, 0.0, dt, elastic_unloading)
        np.testing.assert_allclose(stretch[0], [0.0, 2e-4 + sliding * dt], rtol=1e-14)
        assert states[0] == (UNLOADING if marked and elastic_unloading else state)


def test_separation_clears_the_contact():
    xi = np.array([0.01])
    stretch = np.array([[0.0, 1e-3]])
    state = np.array([STICK], dtype=np.int8)
    contacts.critical_load_update(RADII, PI, PJ, NVEC, xi, stretch, state, KN, KT, MU, 1.0)
    assert state[0] == NONE and np.all(stretch == 0)


def test_frictionless_when_mu_is_zero():
    overlap = 3.0 / (KN * ABAR)
    xi = np.array([-overlap / ABAR])
    stretch = np.array([[0.0, 1e-4]])
    state = np.zeros(1, dtype=np.int8)
    nf = contacts.critical_load_update(RADII, PI, PJ, NVEC, xi, stretch, state, KN, KT, 0.0, 1.0)
    assert nf == 0 and state[0] == FRICTIONLESS


def test_spring_forces_obey_newton_and_torque_convention():
    overlap = 0.01
    xi = np.array([-overlap / ABAR])
    stretch = np.array([[0.0, 2e-3]])
    state = np.array([STICK], dtype=np.int8)
    out = np.zeros(6)
    f_on_i = contacts.contact_spring_forces(RADII, PI, PJ, NVEC, xi, stretch, state, KN, KT, out)
    fn = KN * ABAR * overlap
    ft = KT * ABAR * 2e-3
    np.testing.assert_allclose(f_on_i[0], [-fn, ft])
    np.testing.assert_allclose(out[[0, 1]], -out[[3, 4]])  # action = reaction
    # torques a_i n x F_t and a_j n x F_t, same sign
    np.testing.assert_allclose(out[[2, 5]], [RADII[0] * ft, RADII[1] * ft])


def test_stretch_increment_uses_total_relative_surface_velocity():
    """Pure affine shear of a pair aligned with y slides the contact by -(shear_rate * dy) ... checked
    against the formula (U_j - U_i + shear * dy e_x).t - (a_i w_i + a_j w_j)."""
    nvec = np.array([[0.0, 1.0]])  # j above i: t = (-1, 0)
    dy = np.array([2.4])
    vel = np.zeros(6)  # no non-affine motion
    shear = 0.5
    sx, sy = contacts.sliding_velocity(vel, RADII, PI, PJ, nvec, dy, shear, 0)
    # affine: relative translation shear*dy along x, both rotate at -shear/2
    vt = (shear * 2.4) * -1.0 - (RADII[0] * -0.25 + RADII[1] * -0.25)
    np.testing.assert_allclose([sx, sy], [vt * -1.0, 0.0])


def test_max_interaction_speed_matches_brute_force():
    """dt limiter: max over active pairs of |n.(U_j - U_i)| (affine included) and contact sliding speed."""
    rng = np.random.default_rng(5)
    radii = np.array([1.0, 1.4, 1.0, 1.4])
    pi, pj = np.array([0, 0, 1]), np.array([1, 2, 3])
    theta = rng.random(3) * 2 * np.pi
    nvec = np.stack([np.cos(theta), np.sin(theta)], axis=1)
    dy = np.array([2.0, -1.5, 0.7])
    vel = rng.normal(size=12)
    active = np.array([True, True, False])
    state = np.array([STICK, NONE, STICK], dtype=np.int8)  # pair 2 inactive: ignored entirely
    shear = 0.8
    expected = 0.0
    for p in range(2):
        i, j = pi[p], pj[p]
        du = vel[3 * j : 3 * j + 2] - vel[3 * i : 3 * i + 2] + np.array([shear * dy[p], 0.0])
        expected = max(expected, abs(du @ nvec[p]))
        if state[p] != NONE:
            t = np.array([-nvec[p, 1], nvec[p, 0]])
            w = radii[i] * (vel[3 * i + 2] - shear / 2) + radii[j] * (vel[3 * j + 2] - shear / 2)
            expected = max(expected, abs(du @ t - w))
    got = contacts.max_interaction_speed(vel, radii, pi, pj, nvec, dy, active, state, shear)
    assert got == pytest.approx(expected, rel=1e-12)


def test_contact_spring_stress_is_the_virial_over_touching_pairs_found_by_brute_force():
    """The contact-spring stress of a sheared frictional packing (the kernels the step uses: pair
    geometry, spring forces, virial) against an independent sum: each touching pair's nearest periodic
    image searched over the 3 x 3 Lees–Edwards images, F_i = -k_n a_bar overlap n + k_t a_bar stretch,
    sigma = (6 pi / A) sum sym(r (x) F_i).  Repulsive contacts give a positive pressure."""
    from rheograph.sim.geometry import pair_geometry
    from rheograph.sim.integrator import Simulation
    from rheograph.sim.params import SimParams
    from rheograph.sim.stress import spring_stress, stress_unit_factor

    params = SimParams(n_particles=64, phi=0.78, stress=20.0, integrator="implicit", disp_max=2e-3)
    sim = Simulation(params)
    for _ in range(300):
        sim.step()
    s = sim.state
    assert (s.contact_state == STICK).any() or (s.contact_state == SLIDE).any()
    nvec, r, xi, _ = pair_geometry(s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.le_offset)
    out = np.zeros(3 * s.radii.size)
    f_on_i = contacts.contact_spring_forces(
        s.radii, s.pair_i, s.pair_j, nvec, xi, s.stretch, s.contact_state, params.kn, params.kt, out
    )
    factor = stress_unit_factor(s.lx, s.ly)
    kernel = factor * spring_stress(s.pair_i, nvec, r, f_on_i, s.contact_state, True)

    brute = np.zeros(3)
    touching = np.flatnonzero(s.contact_state != NONE)
    assert touching.size > 10
    for p in touching:
        i, j = s.pair_i[p], s.pair_j[p]
        rvec = nearest_image_vector(s, i, j)
        dist = np.linalg.norm(rvec)
        n = rvec / dist
        abar = 0.5 * (s.radii[i] + s.radii[j])
        overlap = s.radii[i] + s.radii[j] - dist
        force = -params.kn * abar * overlap * n + params.kt * abar * s.stretch[p]
        brute += factor * np.array(
            [rvec[0] * force[0], 0.5 * (rvec[0] * force[1] + rvec[1] * force[0]), rvec[1] * force[1]]
        )
    np.testing.assert_allclose(kernel, brute, rtol=1e-10, atol=1e-12 * np.abs(brute).max())
    assert -(kernel[0] + kernel[2]) / 3.0 > 0.0  # Pi = -tr(sigma)/3 of repulsive springs


def test_contact_dashpot_stress_is_the_virial_of_the_dashpot_forces_found_by_brute_force():
    """The full (xx, xy, yy) dashpot stress of the step's kernel, for the solved velocities of both parts
    (springs at zero rate, unit-rate affine flow), against an independent sum over touching pairs: the
    nearest Lees-Edwards image, the dashpot force on i F_i = -[R_contact (U + U_affine)]_i with the
    affine flow y e_x and spin -1/2 at unit rate, and sym(r (x) F_i) -- the same virial convention as the
    springs.  The xx and yy components carry the dashpot's share of the particle pressure."""
    from rheograph.sim.lubrication import contact_block
    from rheograph.sim.stress import pair_stress_sums

    sim, lp, matrix = sheared_frictional_problem(64)
    s = sim.state
    velocities = np.linalg.solve(matrix, lp.rhs.T)  # (3N, 2): springs, unit rate
    _, dash_const, _, dash_rate = pair_stress_sums(
        velocities[:, 0], velocities[:, 1], s.radii, s.pair_i, s.pair_j, lp.nvec, lp.r, lp.dy, lp.coeff,
        lp.lubricated, lp.in_contact, lp.k_normal, lp.k_tangential, True,
    )  # fmt: skip

    touching = np.flatnonzero(lp.in_contact)
    assert touching.size > 10
    for part, kernel in ((0, dash_const), (1, dash_rate)):
        brute = np.zeros(3)
        for q in touching:
            i, j = s.pair_i[q], s.pair_j[q]
            rvec = nearest_image_vector(s, i, j)
            n = rvec / np.linalg.norm(rvec)
            u = np.r_[velocities[3 * i : 3 * i + 3, part], velocities[3 * j : 3 * j + 3, part]]
            if part == 1:  # relative affine flow: j moves by y_j - y_i along x, both spin at -1/2
                u += [0.0, 0.0, -0.5, rvec[1], 0.0, -0.5]
            block = contact_block(
                lp.coeff[q], *n, s.radii[i], s.radii[j], lp.k_normal[q], lp.k_tangential[q], np.empty((6, 6))
            )
            force = -(block @ u)[0:2]
            brute += [rvec[0] * force[0], 0.5 * (rvec[0] * force[1] + rvec[1] * force[0]), rvec[1] * force[1]]
        np.testing.assert_allclose(kernel, brute, rtol=1e-9, atol=1e-10 * np.abs(brute).max())
    assert abs(dash_rate[0]) > 1e-3 * abs(dash_rate[1])  # the normal components are not trivially zero


@pytest.mark.parametrize("theta", [0.0, 0.9, 2.5])
def test_stretch_grows_with_the_sliding_of_the_contact_point(theta):
    """increment_stretch integrates the tangential surface velocity of j relative to i at the contact:
    a uniform translation adds nothing; j moving along the tangent t adds v dt t; a rigid rotation of the
    pair at centre distance r (U = omega z x x, spins omega) slides by omega (r - a_i - a_j) -- zero at
    touching distance; the affine shear at rate g (relative velocity g dy e_x, spins -g/2) slides by
    g (dy t_x + (a_i + a_j)/2); and a pair that is not in contact keeps its stretch untouched."""
    n = np.array([np.cos(theta), np.sin(theta)])
    t = np.array([-n[1], n[0]])
    nvec = n[None, :]
    dt, omega = 0.01, 0.3

    def increment(vel, state=STICK, shear_rate=0.0, r=2.4):
        stretch = np.full((1, 2), 0.25)
        dy = np.array([r * n[1]])
        contacts.increment_stretch(
            vel, RADII, PI, PJ, nvec, dy, np.array([state], dtype=np.int8), stretch, shear_rate, dt, False
        )
        return stretch[0] - 0.25

    np.testing.assert_allclose(increment(np.array([0.4, -0.7, 0.0, 0.4, -0.7, 0.0])), 0.0, atol=1e-15)
    np.testing.assert_allclose(increment(np.r_[0.0, 0.0, 0.0, 0.5 * t, 0.0]), 0.5 * dt * t, rtol=1e-12)
    for r in (2.4, 2.39):  # touching, and overlapping by 0.01
        xi_, xj_ = np.zeros(2), r * n
        rigid = np.r_[omega * np.array([-xi_[1], xi_[0]]), omega, omega * np.array([-xj_[1], xj_[0]]), omega]
        np.testing.assert_allclose(increment(rigid, r=r), omega * (r - 2.4) * dt * t, atol=1e-15)
    # affine shear at rate g alone: relative velocity g dy e_x, spins -g/2 -> sliding along t
    g, r = 2.0, 2.4
    expected = (g * r * n[1] * t[0] + 0.5 * g * 2.4) * dt * t
    np.testing.assert_allclose(increment(np.zeros(6), shear_rate=g, r=r), expected, atol=1e-14)
    np.testing.assert_array_equal(increment(np.r_[0.0, 0.0, 0.0, t, 0.0], state=NONE), 0.0)
