"""Whole-system checks of the 3D simulator: the planar system is the 2D simulator, stress and rate
control, power balance, assembled matrix, symmetry of the flow."""

import copy
import dataclasses
from pathlib import Path

import numpy as np
import pytest

from rheograph.errors import ParameterError
from rheograph.io.hdf5 import read_checkpoint
from rheograph.sim import SimParams, Simulation, contacts3d
from rheograph.sim.assembly import dense_from_upper_csc
from rheograph.sim.integrator import viscosity
from rheograph.sim.integrator3d import SimState3D, Simulation3D
from rheograph.sim.lubrication3d import pair_block, strain_force
from rheograph.sim.params3d import SimParams3D
from rheograph.sim.stress3d import add_lubrication_stresslet

# 25-40 s from a cold numba cache (the 3D step compiles whole): with the long tests in CI; the 3D kernels'
# own tests (lubrication3d, contacts3d, geometry3d) run by default
pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
E_UNIT = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])


def planar_twin(sim2d: Simulation, params3d: SimParams3D, lz: float) -> Simulation3D:
    """A 3D simulation of the 2D one's current state: centres at z = 0, the same neighbour list, stretches
    and contact states, in a box of height lz; stresses per unit height, as the 2D ones are."""
    s = sim2d.state
    z = np.zeros((s.radii.size, 1))
    state = SimState3D(
        positions=np.hstack([s.positions, z]), radii=s.radii.copy(), lx=s.lx, ly=s.ly, lz=lz,
        le_offset=s.le_offset, time=s.time, strain=s.strain, steps=s.steps, pair_i=s.pair_i.copy(),
        pair_j=s.pair_j.copy(), stretch=np.hstack([s.stretch, np.zeros((s.stretch.shape[0], 1))]),
        contact_state=s.contact_state.copy(), displacement=np.hstack([s.displacement, z]),
        strain_at_build=s.strain_at_build, dt_assumed=s.dt_assumed,
        previous_interaction_speed=s.previous_interaction_speed,
    )  # fmt: skip
    sim = Simulation3D(params3d, state)
    sim.stress_factor = sim2d.stress_factor
    return sim


@pytest.mark.parametrize(
    "integrator, elastic_unloading", [("implicit", False), ("euler", False), ("implicit", True)]
)
def test_planar_3d_system_takes_the_2d_simulators_steps(integrator, elastic_unloading):
    """All centres at z = 0 (box 12 a tall, beyond the cut-off): 100 steps from a sheared frictional 2D
    state give the 2D dt, shear rate, stresses (xx, xy, yy), contact counts and positions to round-off,
    with no out-of-plane velocity, rotation about x or y, or stress (xz, yz, zz); with elastic unloading
    too."""
    common = dict(
        n_particles=80, stress=10.0, strain=1.0, integrator=integrator, disp_max=2e-3,
        elastic_unloading=elastic_unloading,
    )  # fmt: skip
    sim2 = Simulation(SimParams(phi=0.76, **common))
    for _ in range(300):
        sim2.step()
    sim3 = planar_twin(sim2, SimParams3D(phi=0.5, **common), lz=12.0)
    frictional = 0
    for _ in range(100):
        r2 = sim2.step(record=True)
        r3 = sim3.step(record=True)
        assert r3.dt == pytest.approx(r2.dt, rel=1e-9)
        assert r3.shear_rate == pytest.approx(r2.shear_rate, rel=1e-9)
        assert (r3.n_contacts, r3.n_frictional) == (r2.n_contacts, r2.n_frictional)
        scale = np.abs(r2.stress).max()
        np.testing.assert_allclose(r3.stress[[0, 1, 3]], r2.stress, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(r3.stress_contact[[0, 1, 3]], r2.stress_contact, atol=1e-9 * scale)
        np.testing.assert_allclose(r3.stress[[2, 4, 5]], 0.0, atol=1e-14 * scale)
        vel = sim3.velocity.reshape(-1, 6)
        assert np.all(np.abs(vel[:, 2:5]) < 1e-14 * np.abs(vel).max())
        np.testing.assert_allclose(sim3.state.positions[:, :2], sim2.state.positions, rtol=0, atol=1e-9)
        frictional += r2.n_frictional
    assert np.all(sim3.state.positions[:, 2] == 0.0)
    assert frictional > 100  # frictional contacts took part throughout


def clone(sim: Simulation3D, **params) -> Simulation3D:
    """An independent copy of a simulation's state (with changed parameters, if given)."""
    new_params = SimParams3D(**{**sim.params.to_dict(), **params})
    return Simulation3D(new_params, copy.deepcopy(sim.state))


def sheared_3d(steps=150, **kw):
    base = dict(n_particles=150, phi=0.55, stress=10.0, integrator="implicit", disp_max=2e-3, seed=2)
    base.update(kw)
    sim = Simulation3D(SimParams3D(**base))
    for _ in range(steps):
        sim.step()
    return sim


@pytest.fixture(scope="module")
def sheared():
    return sheared_3d()


def test_assembled_resistance_is_spd_and_the_sum_of_pair_blocks(sheared):
    sim = clone(sheared)
    s = sim.state
    lp = sim.linear_problem()
    assert lp.in_contact.any() and lp.lubricated.sum() > 50
    n = s.radii.size
    dense = dense_from_upper_csc(lp.data, sim.indices, sim.indptr, 6 * n)
    ref = np.diag(sim.drag)
    from rheograph.sim.lubrication3d import contact_block

    for q in np.flatnonzero(lp.active):
        i, j = s.pair_i[q], s.pair_j[q]
        idx = np.r_[6 * i : 6 * i + 6, 6 * j : 6 * j + 6]
        blk = contact_block(
            lp.coeff[q],
            lp.nvec[q],
            s.radii[i],
            s.radii[j],
            lp.k_normal[q],
            lp.k_tangential[q],
            np.empty((12, 12)),
        )
        ref[np.ix_(idx, idx)] += blk
    np.testing.assert_allclose(dense, ref, atol=1e-12 * np.abs(ref).max())
    assert np.linalg.eigvalsh(dense).min() > 0


def test_rate_control_imposes_the_rate_and_matches_stress_control(sheared):
    """The rate-controlled step at the rate stress control chose gives the same velocities and the
    target shear stress (linearity of the split S_0 + rate S_1); over 50 rate-controlled steps the
    rate, strain = rate * time and the Lees–Edwards offset follow the imposed rate."""
    stress_sim = clone(sheared)
    r_stress = stress_sim.step(record=True)
    rate = r_stress.shear_rate
    rate_sim = clone(sheared, control="rate", shear_rate=rate)
    r_rate = rate_sim.step(record=True)
    assert r_rate.shear_rate == rate
    np.testing.assert_allclose(rate_sim.velocity, stress_sim.velocity, rtol=0, atol=1e-12)
    assert r_rate.stress[1] == pytest.approx(10.0, rel=1e-10)
    np.testing.assert_allclose(rate_sim.state.positions, stress_sim.state.positions, atol=1e-12)
    t0, g0, off0 = rate_sim.state.time, rate_sim.state.strain, rate_sim.state.le_offset
    for _ in range(50):
        assert rate_sim.step().shear_rate == rate
    s = rate_sim.state
    assert s.strain - g0 == pytest.approx(rate * (s.time - t0), rel=1e-12)
    shift = (s.le_offset - off0 - rate * (s.time - t0) * s.ly) / s.lx
    assert shift == pytest.approx(round(shift), abs=1e-9)


def test_power_balance_of_stress_control_for_equal_spheres():
    """sigma gamma_dot equals the dissipation computed from the resistance kernels: solvent, one-body
    drag on (U, w), lubrication as the quadratic form U R U - 2 rate U.R_FE:E + rate^2 E:R_SE:E, dashpots
    on the total relative motion, plus the power the springs absorb, F_i . (relative contact-point
    velocity).  Explicit Euler, so the implicit spring terms do not enter.  Equal spheres: the rotation
    stresslet with Y^M (LF_DEM) is reciprocal to the torque from strain (Y^H) only for lambda = 1.  What
    is left is the springs' lever arms a_i + a_j against the centre distance in the virial, ~overlap/2a
    of the tangential work: 1e-4 covers it."""
    sim = sheared_3d(steps=250, size_ratio=1.0, phi=0.58, stress=20.0, integrator="euler", n_particles=120)
    s, p = sim.state, sim.params
    lp = sim.linear_problem()
    sim.solver.factorize(lp.data)
    vels = sim.solver.solve(np.ascontiguousarray(lp.rhs.T))
    probe = clone(sim)
    rate = probe.step(record=True).shear_rate
    u = (vels[:, 0] + rate * vels[:, 1]).reshape(-1, 6)
    np.testing.assert_allclose(u.ravel(), probe.velocity, atol=1e-12)
    f = sim.stress_factor
    a = s.radii
    parts = dict(solvent=rate**2, lubrication=0.0, dashpot=0.0, springs=0.0)
    parts["drag"] = f * np.sum(a * (u[:, :3] ** 2).sum(1) + 4 / 3 * a**3 * (u[:, 3:] ** 2).sum(1))
    blk, g = np.empty((12, 12)), np.empty(12)
    spin = np.array([0.0, 0.0, -0.5 * rate])
    for k in range(s.pair_i.size):
        i, j = s.pair_i[k], s.pair_j[k]
        n = lp.nvec[k]
        pair = np.r_[u[i], u[j]]
        if lp.in_contact[k]:
            pair_block(lp.coeff[k], n, blk)
            total = pair + np.r_[0, 0, 0, spin, rate * lp.dy[k], 0, 0, spin]
            parts["dashpot"] += f * total @ blk @ total
        elif lp.lubricated[k]:
            pair_block(lp.coeff[k], n, blk)
            strain_force(lp.coeff[k], n, E_UNIT, g)
            at_rest = np.zeros(6)
            z = np.zeros(3)
            add_lubrication_stresslet(at_rest, lp.coeff[k], n, z, z, z, z, E_UNIT)
            parts["lubrication"] += f * (pair @ blk @ pair - 2 * rate * pair @ g + rate**2 * at_rest[1])
        if s.contact_state[k] != contacts3d.NONE:
            v_i = u[i, :3] + a[i] * np.cross(u[i, 3:] + spin, n)
            v_j = u[j, :3] + np.array([rate * lp.dy[k], 0, 0]) + a[j] * np.cross(u[j, 3:] + spin, -n)
            parts["springs"] += f * lp.f_on_i[k] @ (v_j - v_i)
    assert (s.contact_state != contacts3d.NONE).sum() > 20 and lp.lubricated.sum() > 100
    assert parts["drag"] > 0 and parts["lubrication"] > 0 and parts["dashpot"] > 0
    power_in = p.stress * rate
    assert abs(parts["springs"]) > 0.05 * power_in  # the springs take part
    assert sum(parts.values()) == pytest.approx(power_in, rel=1e-4)


def test_half_turn_about_the_vorticity_axis_and_mirror_in_z_leave_the_step_invariant(sheared):
    """Simple shear is invariant under a half turn about z, (x, y, z) -> (-x, -y, z), and under the mirror
    z -> -z.  Transforming the sheared frictional state (positions, stretches, displacements) gives the
    transformed velocities (angular velocity as a pseudo-vector), the transformed stress and the same dt
    and rate."""
    ref = clone(sheared)
    r_ref = ref.step(record=True)
    for q in (np.diag([-1.0, -1.0, 1.0]), np.diag([1.0, 1.0, -1.0])):
        sim = clone(sheared)
        s = sim.state
        s.positions = s.positions @ q.T
        s.stretch = s.stretch @ q.T
        s.displacement = s.displacement @ q.T
        r = sim.step(record=True)
        assert r.dt == pytest.approx(r_ref.dt, rel=1e-10)
        assert r.shear_rate == pytest.approx(r_ref.shear_rate, rel=1e-10)
        v_ref = ref.velocity.reshape(-1, 6)
        v = sim.velocity.reshape(-1, 6)
        scale = np.abs(v_ref).max()
        np.testing.assert_allclose(v[:, :3], v_ref[:, :3] @ q.T, atol=1e-10 * scale)
        np.testing.assert_allclose(v[:, 3:], np.linalg.det(q) * v_ref[:, 3:] @ q.T, atol=1e-10 * scale)
        full = lambda t: np.array([[t[0], t[1], t[2]], [t[1], t[3], t[4]], [t[2], t[4], t[5]]])  # noqa: E731
        np.testing.assert_allclose(
            full(r.stress), q @ full(r_ref.stress) @ q.T, atol=1e-10 * abs(r_ref.stress[1])
        )
    assert abs(r_ref.stress[2]) > 1e-6 and abs(r_ref.stress[4]) > 1e-6  # the mirror is not trivial


def test_dilute_3d_suspension_has_the_solvent_viscosity_and_no_pressure():
    """Spheres on a sparse cubic lattice (all gaps beyond the cut-off): eta_r = 1 and Pi = 0 exactly
    (no Einstein term in LF-DEM)."""
    from rheograph.sim.stress3d import particle_pressure

    params = SimParams3D(n_particles=64, phi=0.05, stress=1.0, size_ratio=1.0)
    box = params.box_length()
    g = (np.arange(4) + 0.5) / 4 * box - box / 2
    pos = np.stack(np.meshgrid(g, g, g), -1).reshape(-1, 3)
    sim = Simulation3D(params, SimState3D(positions=pos, radii=np.ones(64), lx=box, ly=box, lz=box))
    res = sim.step(record=True)
    assert viscosity(res) == pytest.approx(1.0, rel=1e-12)
    assert particle_pressure(res.stress) == pytest.approx(0.0, abs=1e-12)


def test_the_step_moves_by_velocity_times_dt_with_dt_from_the_largest_speed(sheared):
    """Explicit Euler: each sphere moves by (U + rate y e_x) dt (through the wrap), and dt = disp_max /
    max(|U|, pair approach and contact sliding speeds, rate), recomputed here from the velocities.  The
    total momentum sum a_i U_i vanishes (pair forces cancel, uniform Stokes drag coefficient)."""
    sim = clone(sheared, integrator="euler")
    before = sim.state.positions.copy()
    lp = clone(sim).linear_problem()
    res = sim.step()
    u = sim.velocity.reshape(-1, 6)
    s = sim.state
    rate = res.shear_rate
    moved = s.positions - before
    expected = (u[:, :3] + np.outer(rate * before[:, 1], [1.0, 0.0, 0.0])) * res.dt
    # undo the periodic wrap: multiples of the box (and the Lees–Edwards shift across y)
    crossed_y = np.round((moved[:, 1] - expected[:, 1]) / s.ly)
    moved[:, 0] += crossed_y * s.le_offset
    moved -= np.round((moved - expected) / [s.lx, s.ly, s.lz]) * [s.lx, s.ly, s.lz]
    np.testing.assert_allclose(moved, expected, atol=1e-12)
    assert np.abs(u[:, 2]).max() > 1e-3 * np.abs(u[:, :3]).max()  # out-of-plane motion is exercised
    speeds = [np.linalg.norm(u[:, :3], axis=1).max(), abs(rate)]
    for k in np.flatnonzero(lp.active):
        i, j = s.pair_i[k], s.pair_j[k]
        rel = u[j, :3] - u[i, :3] + np.array([rate * lp.dy[k], 0.0, 0.0])
        speeds.append(abs(rel @ lp.nvec[k]))
        if sim.state.contact_state[k] != contacts3d.NONE:
            sliding = contacts3d.sliding_velocity(
                sim.velocity, s.radii, s.pair_i, s.pair_j, lp.nvec, lp.dy, rate, k
            )
            speeds.append(np.linalg.norm(sliding))
    assert res.dt == pytest.approx(sim.params.disp_max / max(speeds), rel=1e-12)
    np.testing.assert_allclose(s.radii @ u[:, :3], 0.0, atol=1e-10 * np.abs(u[:, :3]).max())


STEADY_SIGMA200 = (
    ROOT / "data/flow_curves_3d/multirun/N500_phi0.56_s200_seed1_d0.002_implicit_3d/trajectory.h5"
)


def sliding_chatter(elastic_unloading: bool, steps: int = 24) -> tuple[float, float]:
    """From the last checkpoint of a steady N = 500, phi = 0.56, sigma/sigma0 = 200 run: the fraction of
    sliding contacts whose sliding velocity turned by more than 120 degrees since the step before, and
    the median dt of the last two thirds of ``steps`` steps."""
    params, state = read_checkpoint(STEADY_SIGMA200)
    sim = Simulation3D(dataclasses.replace(params, elastic_unloading=elastic_unloading), state)
    previous, turned, slid, dts = {}, 0, 0, []
    for k in range(steps):
        lp = sim.prepare_step()
        s = sim.state
        pairs, states = np.stack([s.pair_i, s.pair_j], axis=1), s.contact_state.copy()
        result = sim.complete_step(lp, sim.solve_linear(lp))
        current = {}
        for p in np.flatnonzero(states == contacts3d.SLIDE):
            rate, vel = result.shear_rate, sim.velocity
            v = np.array(contacts3d.sliding_velocity(vel, s.radii, *pairs.T, lp.nvec, lp.dy, rate, p))
            key = tuple(pairs[p])
            current[key] = v
            if key in previous:
                slid += 1
                turned += v @ previous[key] < -0.5 * np.linalg.norm(v) * np.linalg.norm(previous[key])
        previous = current
        if k >= steps // 3:
            dts.append(result.dt)
    return turned / slid, float(np.median(dts))


def test_elastic_unloading_stops_the_chatter_of_sliding_contacts_and_lengthens_the_step():
    """In steady dense flow about half the sliding contacts reverse their sliding every step (the explicit
    Coulomb force spins weakly held spheres back and forth), and their speed sets dt; with elastic
    unloading those contacts stick, fewer than a fifth reverse, and the step is 1.5x longer or more."""
    chatter_lfdem, dt_lfdem = sliding_chatter(elastic_unloading=False)
    chatter, dt = sliding_chatter(elastic_unloading=True)
    assert chatter_lfdem > 0.35 and chatter < 0.2
    assert dt > 1.5 * dt_lfdem


def test_elastic_unloading_needs_the_implicit_integrator():
    refused = r"^sim\.elastic_unloading=True is invalid: .*integrator=implicit"
    with pytest.raises(ParameterError, match=refused):
        SimParams3D(integrator="euler", elastic_unloading=True)
