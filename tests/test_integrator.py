"""Whole-system checks: assembled matrix, stress control, dilute limit, integrators."""

import numpy as np
import pytest

from rheograph.sim import SimParams, Simulation
from rheograph.sim.assembly import assemble_resistance, dense_from_upper_csc
from rheograph.sim.geometry import pair_geometry
from rheograph.sim.integrator import SimState, particle_pressure, viscosity
from rheograph.sim.lubrication import lubrication_resistance, pair_block


def small_sim(**kw):
    base = dict(n_particles=80, phi=0.76, stress=10.0, strain=1.0)
    base.update(kw)
    return Simulation(SimParams(**base))


def advance(sim, n):
    for _ in range(n):
        sim.step()


def test_assembled_resistance_is_spd_and_matches_dense_pair_sum():
    sim = small_sim()
    advance(sim, 300)  # develop contacts
    s, p = sim.state, sim.params
    nvec, r, xi, dy = pair_geometry(s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.le_offset)
    in_contact = xi <= 0
    active = in_contact | ((xi > 0) & (xi < p.lub_max_gap))
    assert in_contact.any() and (active & ~in_contact).any()
    coeff = lubrication_resistance(s.radii, s.pair_i, s.pair_j, xi, active, p.delta)
    zeros = np.zeros(xi.shape[0])
    data, _ = assemble_resistance(
        s.radii,
        s.pair_i,
        s.pair_j,
        nvec,
        dy,
        coeff,
        active,
        in_contact,
        zeros,
        zeros,
        sim.indptr,
        sim.pair_slot,
        sim.diag_slot,
        sim.indices.shape[0],
    )
    n = s.radii.shape[0]
    dense = dense_from_upper_csc(data, sim.indices, sim.indptr, 3 * n)
    ref = np.zeros((3 * n, 3 * n))
    for k in range(n):
        ref[3 * k, 3 * k] = ref[3 * k + 1, 3 * k + 1] = s.radii[k]
        ref[3 * k + 2, 3 * k + 2] = 4 * s.radii[k] ** 3 / 3
    for q in np.flatnonzero(active):
        idx = np.r_[3 * s.pair_i[q] : 3 * s.pair_i[q] + 3, 3 * s.pair_j[q] : 3 * s.pair_j[q] + 3]
        ref[np.ix_(idx, idx)] += pair_block(coeff[q], nvec[q, 0], nvec[q, 1], np.empty((6, 6)))
    np.testing.assert_allclose(dense, ref, atol=1e-9 * np.abs(ref).max())
    assert np.linalg.eigvalsh(dense).min() > 0


@pytest.mark.parametrize("integrator", ["euler", "implicit"])
def test_measured_shear_stress_equals_target_to_round_off(integrator):
    sim = small_sim(integrator=integrator)
    for k in range(400):
        res = sim.step(record=(k % 40 == 0))
        if res.stress_lubrication is not None:
            assert res.stress[1] == pytest.approx(10.0, rel=1e-10)
            # the parts add up and the solvent carries eta0 * shear_rate
            assert res.stress_solvent[1] == pytest.approx(res.shear_rate, rel=1e-14)
    assert sim.state.strain > 0


def test_dilute_limit_viscosity_tends_to_one():
    etas = {}
    for phi in (0.02, 0.3, 0.6):
        sim = Simulation(SimParams(n_particles=100 if phi > 0.1 else 30, phi=phi, stress=1.0))
        vals = []
        for _ in range(200):
            res = sim.step(record=True)
            vals.append(viscosity(res))
        etas[phi] = np.mean(vals)
    assert etas[0.02] == pytest.approx(1.0, abs=0.02)
    assert 1.0 < etas[0.3] < etas[0.6]


def test_no_interactions_means_exactly_solvent_viscosity():
    """Particles on a sparse lattice (all gaps > cut-off): eta_r = 1 and Pi = 0 to round-off."""
    params = SimParams(n_particles=36, phi=0.05, stress=1.0)
    n_small, n_large = params.species_counts()
    box = params.box_length()
    g = (np.arange(6) + 0.5) / 6 * box - box / 2
    pos = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    radii = np.r_[np.ones(n_small), np.full(n_large, params.size_ratio)]
    sim = Simulation(params, state=SimState(positions=pos, radii=radii, lx=box, ly=box))
    res = sim.step(record=True)
    assert viscosity(res) == pytest.approx(1.0, rel=1e-12)
    assert particle_pressure(res) == pytest.approx(0.0, abs=1e-12)


def test_implicit_step_is_never_longer_than_assumed():
    sim = small_sim(integrator="implicit", disp_max=4e-3)
    for _ in range(200):
        assumed = sim.state.dt_assumed
        res = sim.step()
        assert res.dt <= assumed * (1 + 1e-12)


def test_frictionless_low_stress_has_no_frictional_contacts():
    sim = small_sim(stress=0.1)
    for _ in range(300):
        res = sim.step()
    assert res.n_frictional == 0


def test_lagged_step_control_bounds_dt_by_the_previous_steps_pair_speeds():
    """LF_DEM's rule: dt of step n is bounded by the pair speeds of step n-1, so a pair that sped up
    moves further than disp_max; the default rule uses the current speeds and never overshoots."""
    p_lag = dict(lagged_step_control=True, disp_max=2e-3)
    sim = small_sim(**p_lag)
    advance(sim, 300)
    overshoots = 0
    for _ in range(100):
        previous = sim.state.previous_interaction_speed
        dt = sim.step().dt
        current = sim.state.previous_interaction_speed
        assert previous > 0.0 and dt <= 2e-3 / previous * (1.0 + 1e-12)
        overshoots += current * dt > 2e-3 * (1.0 + 1e-9)
    assert overshoots > 0
    default = small_sim(disp_max=2e-3)
    advance(default, 50)
    assert default.state.previous_interaction_speed == -1.0  # untouched by the default rule


def test_linear_problem_equals_the_separate_kernels():
    """The fused pre-solve kernel is a composition, not new physics: every output must equal, bit for bit,
    what the individual kernels give (geometry, CLM update, masks, lubrication, implicit stiffness, matrix,
    right-hand sides) on a dense frictional state with contacts of every kind."""
    from rheograph.sim import contacts
    from rheograph.sim.integrator import linear_problem

    params = SimParams(n_particles=100, phi=0.78, stress=20.0, integrator="implicit", disp_max=2e-3)
    sim = Simulation(params)
    for _ in range(300):
        sim.step()
    s, p = sim.state, params
    stretch, state = s.stretch.copy(), s.contact_state.copy()
    dt = 1.3e-3
    lp = linear_problem(
        s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.le_offset, stretch, state, p.kn, p.kt,
        p.mu, p.critical_load, p.lub_max_gap, p.delta, dt, sim.indptr, sim.pair_slot, sim.diag_slot,
        sim.indices.shape[0],
    )  # fmt: skip
    ref_stretch, ref_state = s.stretch.copy(), s.contact_state.copy()
    nvec, r, xi, dy = pair_geometry(s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.le_offset)
    n_frictional = contacts.critical_load_update(
        s.radii, s.pair_i, s.pair_j, nvec, xi, ref_stretch, ref_state, p.kn, p.kt, p.mu, p.critical_load
    )
    in_contact = xi <= 0.0
    lubricated = (xi > 0.0) & (xi < p.lub_max_gap)
    active = in_contact | lubricated
    abar = 0.5 * (s.radii[s.pair_i] + s.radii[s.pair_j])
    k_normal = np.where(in_contact, p.kn * abar * dt, 0.0)
    k_tangential = np.where(ref_state == contacts.STICK, p.kt * abar * dt, 0.0)
    coeff = lubrication_resistance(s.radii, s.pair_i, s.pair_j, xi, active, p.delta)
    data, rhs_rate = assemble_resistance(
        s.radii, s.pair_i, s.pair_j, nvec, dy, coeff, active, in_contact, k_normal, k_tangential,
        sim.indptr, sim.pair_slot, sim.diag_slot, sim.indices.shape[0],
    )  # fmt: skip
    springs = np.zeros(3 * p.n_particles)
    f_on_i = contacts.contact_spring_forces(
        s.radii, s.pair_i, s.pair_j, nvec, xi, ref_stretch, ref_state, p.kn, p.kt, springs
    )
    # the state must exercise every branch: contacts, sticking contacts, lubricated gaps
    assert in_contact.sum() > 10 and (ref_state == contacts.STICK).any() and lubricated.any()
    np.testing.assert_array_equal(stretch, ref_stretch)
    np.testing.assert_array_equal(state, ref_state)
    for got, want in [
        (lp.nvec, nvec), (lp.r, r), (lp.xi, xi), (lp.dy, dy), (lp.coeff, coeff),
        (lp.lubricated, lubricated), (lp.in_contact, in_contact), (lp.active, active),
        (lp.k_normal, k_normal), (lp.k_tangential, k_tangential), (lp.f_on_i, f_on_i), (lp.data, data),
        (lp.rhs[0], springs), (lp.rhs[1], rhs_rate),
    ]:  # fmt: skip
        np.testing.assert_array_equal(got, want)
    assert (lp.n_active, lp.n_contacts, lp.n_frictional) == (active.sum(), in_contact.sum(), n_frictional)
