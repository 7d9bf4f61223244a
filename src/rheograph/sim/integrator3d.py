"""Time integration of 3D LF-DEM (6 degrees of freedom per sphere): one step = geometry -> CLM -> R_FU ->
two solves -> shear rate (stress control) or imposed rate (rate control) -> adaptive dt -> move.

The same schemes and step rule as the 2D ``rheograph.sim.integrator`` (read its docstring for the
linearly implicit springs and the lagged step control), with the 3D kernels: a planar 3D system (all
centres at one z, box taller than the cut-off in z) takes the 2D simulator's steps to round-off.
"""

from __future__ import annotations

import copy
import dataclasses
import time as wallclock
from collections import defaultdict
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from rheograph.resources import check_simulation_memory
from rheograph.sim import contacts3d
from rheograph.sim.assembly import build_pattern
from rheograph.sim.assembly3d import UNIT_STRAIN_RATE, assemble_resistance
from rheograph.sim.geometry import wrap_offset
from rheograph.sim.geometry3d import neighbour_pairs, pair_geometry, wrap_positions
from rheograph.sim.init_config3d import initial_configuration
from rheograph.sim.integrator import DT_GROWTH, SimState, StepResult, _transfer_contacts
from rheograph.sim.lubrication import lubrication_resistance
from rheograph.sim.lubrication3d import one_body_drag
from rheograph.sim.params3d import SimParams3D
from rheograph.sim.solver import make_solver
from rheograph.sim.stress3d import pair_stress_sums, spring_stress, stress_unit_factor

SOLVENT_UNIT = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])  # 2 eta0 E at unit rate [sigma0], (xx, xy, ...)


@dataclass
class SimState3D:
    """Everything needed to continue a 3D run bit-for-bit.

    positions (N, 3) [a], radii (N,) [a], box edges lx, ly, lz [a], le_offset [a], time
    [6 pi eta0 a^2/F_CL], strain, steps; the neighbour list pair_i/pair_j (P,), per-pair tangential
    stretch (P, 3) and contact state (P,), non-affine displacement since the list was built (N, 3),
    strain at build, the dt assumed by the implicit springs and the lagged step control's speed.
    """

    positions: np.ndarray
    radii: np.ndarray
    lx: float
    ly: float
    lz: float
    le_offset: float = 0.0
    time: float = 0.0
    strain: float = 0.0
    steps: int = 0
    pair_i: np.ndarray | None = None
    pair_j: np.ndarray | None = None
    stretch: np.ndarray | None = None
    contact_state: np.ndarray | None = None
    displacement: np.ndarray | None = None
    strain_at_build: float = 0.0
    dt_assumed: float = 0.0
    previous_interaction_speed: float = -1.0

    # what a checkpoint holds (rheograph.io.hdf5): the 2D state's names, with the cube's third edge
    ARRAYS = SimState.ARRAYS
    SCALARS = (*SimState.SCALARS[:2], "lz", *SimState.SCALARS[2:])


class LinearProblem3D(NamedTuple):
    """One step's pair geometry, contact classification and linear system, as the 2D ``LinearProblem``
    with 3-vectors: ``nvec`` (P, 3), ``f_on_i`` (P, 3) [F_CL], ``rhs`` (2, 6N) (row 0 springs, row 1 the
    affine flow at unit shear rate)."""

    nvec: np.ndarray
    r: np.ndarray
    xi: np.ndarray
    dy: np.ndarray
    coeff: np.ndarray
    lubricated: np.ndarray
    in_contact: np.ndarray
    active: np.ndarray
    k_normal: np.ndarray
    k_tangential: np.ndarray
    f_on_i: np.ndarray
    data: np.ndarray
    rhs: np.ndarray
    n_active: int
    n_contacts: int
    n_frictional: int


@njit(cache=True)
def linear_problem(
    positions,
    radii,
    pair_i,
    pair_j,
    lx,
    ly,
    lz,
    le_offset,
    stretch,
    contact_state,
    kn,
    kt,
    mu,
    critical_load,
    lub_max_gap,
    delta,
    dt_implicit,
    indptr,
    pair_slot,
    diag_slot,
    nnz,
    e_unit,
):
    """Everything of one step before the solve, in one compiled call: pair geometry, the CLM update of
    ``stretch`` (P, 3) and ``contact_state`` in place, lubrication coefficients, the matrix data on the
    ``build_pattern(..., block=6)`` pattern and the two right-hand sides.  ``dt_implicit`` > 0 puts
    dt_implicit * spring stiffness into the contact blocks (linearly implicit springs); 0 for Euler."""
    nvec, r, xi, dy = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, lz, le_offset)
    n_frictional = contacts3d.critical_load_update(
        radii, pair_i, pair_j, nvec, xi, stretch, contact_state, kn, kt, mu, critical_load
    )
    npair = pair_i.shape[0]
    in_contact = np.empty(npair, dtype=np.bool_)
    lubricated = np.empty(npair, dtype=np.bool_)
    active = np.empty(npair, dtype=np.bool_)
    k_normal = np.zeros(npair)
    k_tangential = np.zeros(npair)
    n_active = 0
    n_contacts = 0
    for p in range(npair):
        in_contact[p] = xi[p] <= 0.0
        lubricated[p] = (xi[p] > 0.0) and (xi[p] < lub_max_gap)
        active[p] = in_contact[p] or lubricated[p]
        n_active += active[p]
        n_contacts += in_contact[p]
        if dt_implicit > 0.0:
            abar = 0.5 * (radii[pair_i[p]] + radii[pair_j[p]])
            if in_contact[p]:
                k_normal[p] = kn * abar * dt_implicit
            if contact_state[p] == contacts3d.STICK:
                k_tangential[p] = kt * abar * dt_implicit
    coeff = lubrication_resistance(radii, pair_i, pair_j, xi, active, delta)
    data, rhs_rate = assemble_resistance(
        radii, pair_i, pair_j, nvec, dy, coeff, active, in_contact, k_normal, k_tangential,
        indptr, pair_slot, diag_slot, nnz, e_unit,
    )  # fmt: skip
    rhs = np.zeros((2, rhs_rate.shape[0]))
    rhs[1] = rhs_rate
    f_on_i = contacts3d.contact_spring_forces(
        radii, pair_i, pair_j, nvec, xi, stretch, contact_state, kn, kt, rhs[0]
    )
    return LinearProblem3D(
        nvec, r, xi, dy, coeff, lubricated, in_contact, active, k_normal, k_tangential, f_on_i, data, rhs,
        n_active, n_contacts, n_frictional,
    )  # fmt: skip


@njit(cache=True)
def _move(pos, vel, displacement, shear_rate, dt):
    """Explicit Euler move with the affine flow u = shear_rate * y e_x; returns max |non-affine disp.|."""
    dmax = 0.0
    for i in range(pos.shape[0]):
        ux = vel[6 * i]
        uy = vel[6 * i + 1]
        uz = vel[6 * i + 2]
        pos[i, 0] += (ux + shear_rate * pos[i, 1]) * dt
        pos[i, 1] += uy * dt
        pos[i, 2] += uz * dt
        displacement[i, 0] += ux * dt
        displacement[i, 1] += uy * dt
        displacement[i, 2] += uz * dt
        d = displacement[i, 0] ** 2 + displacement[i, 1] ** 2 + displacement[i, 2] ** 2
        if d > dmax:
            dmax = d
    return np.sqrt(dmax)


@njit(cache=True)
def _max_translation_speed(vel):
    vmax = 0.0
    for i in range(vel.shape[0] // 6):
        v = vel[6 * i] ** 2 + vel[6 * i + 1] ** 2 + vel[6 * i + 2] ** 2
        if v > vmax:
            vmax = v
    return np.sqrt(vmax)


@njit(cache=True)
def _advance(
    positions, displacement, vel, radii, pair_i, pair_j, nvec, dy, contact_state, stretch, shear_rate, dt,
    lx, ly, lz, le_offset,
):  # fmt: skip
    """Move by dt: contact stretches (with the pre-move geometry), positions (affine + non-affine), the
    Lees–Edwards offset, wrapping.  Returns (largest non-affine displacement since the list was built,
    new offset)."""
    contacts3d.increment_stretch(vel, radii, pair_i, pair_j, nvec, dy, contact_state, stretch, shear_rate, dt)
    max_displacement = _move(positions, vel, displacement, shear_rate, dt)
    le_offset = wrap_offset(le_offset + shear_rate * ly * dt, lx)
    wrap_positions(positions, lx, ly, lz, le_offset)
    return max_displacement, le_offset


class Simulation3D:
    """A 3D LF-DEM run of one state point, under stress or rate control (``params.control``).

    >>> sim = Simulation3D(SimParams3D(n_particles=200, phi=0.5, stress=10.0))
    >>> result = sim.step(record=True)   # result.stress: (xx, xy, xz, yy, yz, zz) [sigma0]

    ``velocity`` holds the last step's non-affine velocities (6N: U (3), w (3) per particle).
    ``stress_factor`` converts stresslet sums to sigma0 (6 pi / box volume).
    """

    def __init__(self, params: SimParams3D, state: SimState3D | None = None, solver: str = "auto"):
        self.params = params
        # refused before the initial configuration or any matrix is allocated
        check_simulation_memory(params.n_particles, dim=3)
        if state is None:
            pos, radii, box = initial_configuration(params)
            state = SimState3D(positions=pos, radii=radii, lx=box, ly=box, lz=box)
        self.state = state
        self.solver = make_solver(solver)
        self.stress_factor = stress_unit_factor(state.lx, state.ly, state.lz)
        self.list_cutoff = 2.0 * float(state.radii.max()) * (1.0 + 0.5 * params.lub_max_gap)
        self.drag = one_body_drag(state.radii)
        self.velocity = np.zeros(6 * state.radii.shape[0])
        self.max_displacement = 0.0
        self.timings: dict[str, float] = defaultdict(float)  # wall seconds per phase, for benchmarks
        if state.dt_assumed <= 0.0:
            state.dt_assumed = params.disp_max
        if state.pair_i is None:
            self._rebuild_neighbours()
        else:
            self._analyze()
        if state.displacement is not None:
            self.max_displacement = float(np.sqrt((state.displacement**2).sum(axis=1).max()))

    # ---- neighbour list and sparsity pattern --------------------------------------------------
    def _rebuild_neighbours(self) -> None:
        s, p = self.state, self.params
        new_i, new_j = neighbour_pairs(
            s.positions, s.radii, s.lx, s.ly, s.lz, s.le_offset, p.lub_max_gap, p.neighbour_skin
        )
        n = s.radii.shape[0]
        if s.pair_i is None:
            s.stretch = np.zeros((new_i.shape[0], 3))
            s.contact_state = np.zeros(new_i.shape[0], dtype=np.int8)
        else:
            s.stretch, s.contact_state = _transfer_contacts(
                s.pair_i, s.pair_j, s.stretch, s.contact_state, new_i, new_j, n
            )
        s.pair_i, s.pair_j = new_i, new_j
        s.displacement = np.zeros((n, 3))
        s.strain_at_build = s.strain
        self.max_displacement = 0.0
        self._analyze()

    def _analyze(self) -> None:
        s = self.state
        n = s.radii.shape[0]
        self.indptr, self.indices, self.pair_slot, self.diag_slot = build_pattern(s.pair_i, s.pair_j, n, 6)
        self.solver.analyze(self.indptr, self.indices, 6 * n)

    def _list_is_stale(self) -> bool:
        # as in 2D: two particles approach by at most twice the largest non-affine displacement plus the
        # affine relative motion over the accumulated strain
        drift = 2.0 * self.max_displacement
        drift += abs(self.state.strain - self.state.strain_at_build) * (
            self.list_cutoff + self.params.neighbour_skin
        )
        return drift >= self.params.neighbour_skin

    def linear_problem(self) -> LinearProblem3D:
        """The current step's linear problem (updates the contact states in place, as a step does)."""
        s, p = self.state, self.params
        return linear_problem(
            s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.lz, s.le_offset, s.stretch,
            s.contact_state, p.kn, p.kt, p.mu, p.critical_load, p.lub_max_gap, p.delta,
            s.dt_assumed if p.integrator == "implicit" else 0.0,
            self.indptr, self.pair_slot, self.diag_slot, self.indices.shape[0], UNIT_STRAIN_RATE,
        )  # fmt: skip

    def solve_configuration(self, passes: int = 2) -> StepResult:
        """The result of one stress-controlled step from the configuration this simulation was started
        from, which must be fresh (no step taken): the resistance solve of a snapshot, whose tangential
        springs start unstretched.  dt is set as a running simulation sets it: each of ``passes`` solves
        starts again from the same configuration and assumes DT_GROWTH x the dt the previous one would
        step with (the first, ``disp_max``), as the 2D one-solve does.  The state is left as after the
        last pass's step; the neighbour list and the symbolic factorisation are made once."""
        if self.state.steps:
            raise ValueError("solve_configuration needs a fresh simulation (no step taken)")
        start = copy.deepcopy(self.state)
        for k in range(passes):
            if k:
                self.state = dataclasses.replace(copy.deepcopy(start), dt_assumed=self.state.dt_assumed)
                self.max_displacement = 0.0
            result = self.step()
        return result

    # ---- one time step -----------------------------------------------------------------------
    def step(self, record: bool = False) -> StepResult:
        """Advance one step; ``record`` adds the stress tensors (6,) and the contact list."""
        s, p = self.state, self.params
        clock = wallclock.perf_counter
        timings = self.timings
        t0 = clock()
        if self._list_is_stale():
            self._rebuild_neighbours()
        t1 = clock()
        timings["neighbours"] += t1 - t0
        radii = s.radii
        lp = self.linear_problem()
        nvec, dy = lp.nvec, lp.dy
        t2 = clock()
        timings["assembly"] += t2 - t1
        rhs = lp.rhs.T  # (6N, 2): both right-hand sides in one pass over the factor
        if lp.n_active:
            self.solver.factorize(lp.data)
            t3 = clock()
            timings["factorisation"] += t3 - t2
            vels = self.solver.solve(rhs)
        else:  # nothing interacts: R_FU is the one-body drag, a diagonal
            t3 = clock()
            vels = rhs / self.drag[:, None]
        vel_const, vel_rate = np.ascontiguousarray(vels[:, 0]), np.ascontiguousarray(vels[:, 1])
        t4 = clock()
        timings["solve"] += t4 - t3

        # stress split S = S_0 + rate * S_1: stress control picks the rate that meets the target
        lub0, dash0, lub1, dash1 = pair_stress_sums(
            vel_const, vel_rate, radii, s.pair_i, s.pair_j, nvec, lp.r, dy, lp.coeff, lp.lubricated,
            lp.in_contact, lp.k_normal, lp.k_tangential, UNIT_STRAIN_RATE,
        )  # fmt: skip
        spring = spring_stress(s.pair_i, nvec, lp.r, lp.f_on_i, s.contact_state)
        f = self.stress_factor
        if p.control == "stress":
            s0_xy = f * (lub0[1] + dash0[1] + spring[1])
            s1_xy = f * (lub1[1] + dash1[1]) + 1.0
            shear_rate = (p.stress - s0_xy) / s1_xy
        else:
            shear_rate = p.shear_rate
        vel = vel_const + shear_rate * vel_rate
        self.velocity = vel
        t5 = clock()
        timings["stress"] += t5 - t4

        # adaptive step, as in 2D: no particle, pair separation, contact point or strain increment
        # moves more than disp_max
        interaction_speed = contacts3d.max_interaction_speed(
            vel, radii, s.pair_i, s.pair_j, nvec, dy, lp.active, s.contact_state, shear_rate
        )
        if p.lagged_step_control:
            lagged = s.previous_interaction_speed
            s.previous_interaction_speed = interaction_speed
            if lagged >= 0.0:
                interaction_speed = lagged
        vmax = max(_max_translation_speed(vel), interaction_speed, abs(shear_rate))
        dt = p.disp_max / vmax if vmax > 0.0 else p.dt_max
        dt = min(dt, p.dt_max)
        if p.integrator == "implicit":
            dt = min(dt, s.dt_assumed)
            s.dt_assumed = min(DT_GROWTH * dt, p.dt_max)

        result = StepResult(
            dt=dt, shear_rate=shear_rate, n_contacts=lp.n_contacts, n_frictional=lp.n_frictional
        )
        if record:
            xi = lp.xi
            if xi.shape[0]:
                result.max_overlap = float(max(0.0, -(xi * 0.5 * (radii[s.pair_i] + radii[s.pair_j])).min()))
                result.max_stretch = float(np.sqrt((s.stretch**2).sum(axis=1)).max())
            touching = s.contact_state != contacts3d.NONE
            result.contacts = (
                np.stack([s.pair_i[touching], s.pair_j[touching]], axis=1),
                s.contact_state[touching].copy(),
                s.stretch[touching].copy(),
            )
            result.stress_lubrication = f * (lub0 + shear_rate * lub1)
            result.stress_contact = f * (spring + dash0 + shear_rate * dash1)
            result.stress_solvent = shear_rate * SOLVENT_UNIT

        self.max_displacement, s.le_offset = _advance(
            s.positions, s.displacement, vel, radii, s.pair_i, s.pair_j, nvec, dy, s.contact_state,
            s.stretch, shear_rate, dt, s.lx, s.ly, s.lz, s.le_offset,
        )  # fmt: skip
        s.time += dt
        s.strain += shear_rate * dt
        s.steps += 1
        timings["update"] += clock() - t5
        return result
