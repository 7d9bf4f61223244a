"""Time integration of the LF-DEM: one step = geometry -> CLM -> R_FU -> two solves -> shear rate from the
stress target (stress control, the default) or the imposed rate (``control="rate"``) -> adaptive dt ->
move.  No I/O here (see ``rheograph.runs.runner``).

Integrators:
- ``euler``: explicit Euler as in LF_DEM; contact springs enter with their value at the start of the step.
- ``implicit``: linearly implicit Euler for the contact springs.  The tangential spring of a sticking
  contact relaxes on a time R_t / (k_t a_bar) ~ 1e-4 at the default stiffness, shorter than the
  displacement-limited dt, so explicit Euler lets sticking contacts rattle at the edge of stability (one
  cause of its disp_max-dependent viscosity).  Here the spring change over the step, dt * K * U, is moved
  into the resistance matrix (one extra PSD block per contact, same factorisation, same cost per step).
  dt is not known before the solve, so K uses the previous step's dt (times ``DT_GROWTH``) and the step
  actually taken is never longer than that: the implicit weight dt_assumed / dt >= 1 keeps it stable.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time as wallclock
from abc import ABC, abstractmethod
from collections import defaultdict
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numba import njit

from rheograph.resources import check_simulation_memory
from rheograph.sim import contacts
from rheograph.sim.assembly import assemble_resistance, build_pattern
from rheograph.sim.geometry import neighbour_pairs, pair_geometry, wrap_offset, wrap_positions
from rheograph.sim.init_config import initial_configuration
from rheograph.sim.lubrication import lubrication_resistance
from rheograph.sim.params import SimParams
from rheograph.sim.solver import make_solver
from rheograph.sim.stress import pair_stress_sums, spring_stress, stress_unit_factor


@dataclass
class SimState:
    """Everything needed to continue a run bit-for-bit (saved in checkpoints).

    positions (N, 2) [a], radii (N,) [a], le_offset [a], time [6 pi eta0 a^2/F_CL], strain, steps;
    the neighbour (Verlet) list pair_i/pair_j (P,), per-pair tangential stretch (P, 2) and contact state (P,),
    and the bookkeeping of the list: non-affine displacement since it was built (N, 2), strain at build.
    """

    positions: np.ndarray
    radii: np.ndarray
    lx: float
    ly: float
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
    previous_interaction_speed: float = -1.0  # lagged_step_control only; < 0 before the first step

    ARRAYS = ("positions", "radii", "pair_i", "pair_j", "stretch", "contact_state", "displacement")
    SCALARS = (
        "lx",
        "ly",
        "le_offset",
        "time",
        "strain",
        "steps",
        "strain_at_build",
        "dt_assumed",
        "previous_interaction_speed",
    )


@dataclass
class StepResult:
    """Observables of one step.  Stresses in sigma0 as (xx, xy, yy); shear rate in gamma0_dot."""

    dt: float
    shear_rate: float
    n_contacts: int
    n_frictional: int
    max_overlap: float = 0.0  # [a], set on recorded steps
    max_stretch: float = 0.0  # [a], set on recorded steps
    stress_lubrication: np.ndarray | None = None
    stress_contact: np.ndarray | None = None
    stress_solvent: np.ndarray | None = None
    contacts: tuple | None = None  # (pairs (M, 2), state (M,), stretch (M, 2)) at this configuration

    @property
    def stress(self) -> np.ndarray:
        return self.stress_lubrication + self.stress_contact + self.stress_solvent


@njit(cache=True)
def _transfer_contacts(old_i, old_j, old_stretch, old_state, new_i, new_j, n):
    """Carry stretch (P, 2 in 2D or 3 in 3D) and contact state from an old to a new neighbour list (both
    sorted by (j, i))."""
    new_stretch = np.zeros((new_i.shape[0], old_stretch.shape[1]))
    new_state = np.zeros(new_i.shape[0], dtype=np.int8)
    old_key = old_j * n + old_i
    for p in range(new_i.shape[0]):
        key = new_j[p] * n + new_i[p]
        k = np.searchsorted(old_key, key)
        if k < old_key.shape[0] and old_key[k] == key:
            new_stretch[p, :] = old_stretch[k, :]
            new_state[p] = old_state[k]
    return new_stretch, new_state


class LinearProblem(NamedTuple):
    """One step's pair geometry, contact classification and linear system (``linear_problem``; in 3D
    ``integrator3d.linear_problem``, with d = 3 and 6 degrees of freedom per particle).

    Per listed pair (P rows): unit normal i -> j ``nvec`` (P, d), distance ``r`` [a], reduced gap ``xi``,
    minimum-image y-separation ``dy`` [a], lubrication coefficients ``coeff``, the masks
    ``lubricated`` / ``in_contact`` / ``active``, dt times the implicit spring stiffnesses ``k_normal``,
    ``k_tangential``, the spring force on i ``f_on_i`` (P, d) [F_CL].  The system: matrix ``data`` on the
    upper-triangle pattern, right-hand sides ``rhs`` (2, 3N in 2D, 6N in 3D) (row 0 springs, row 1
    unit-rate affine flow).  Counts: interacting pairs, contacts, frictional contacts.
    """

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
def classify_pairs(radii, pair_i, pair_j, xi, contact_state, kn, kt, lub_max_gap, dt_implicit):
    """Masks of the listed pairs (P,) by reduced gap ``xi``: ``in_contact`` (xi <= 0), ``lubricated``
    (0 < xi < lub_max_gap), ``active`` (either); dt_implicit times the spring stiffnesses ``k_normal``
    (contacts) and ``k_tangential`` (sticking contacts) [F_CL a^-1 time], zero when ``dt_implicit`` is 0
    (explicit Euler).  Returns (in_contact, lubricated, active, k_normal, k_tangential, number active,
    number in contact); the same in any dimension."""
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
            if contact_state[p] == contacts.STICK:
                k_tangential[p] = kt * abar * dt_implicit
    return in_contact, lubricated, active, k_normal, k_tangential, n_active, n_contacts


@njit(cache=True)
def linear_problem(
    positions,
    radii,
    pair_i,
    pair_j,
    lx,
    ly,
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
):
    """Everything of one step before the solve, in one compiled call (the separate kernels and the NumPy
    glue between them cost ~10 % of a step at N = 400 in call overhead and temporaries).

    Geometry of the listed pairs, the CLM update of ``stretch`` (P, 2) and ``contact_state`` (P,) in
    place, the lubrication coefficients, the resistance matrix data on the pattern (indptr, pair_slot,
    diag_slot, nnz of ``build_pattern``) and the two right-hand sides as rows of ``rhs`` (2, 3N): row 0
    the contact-spring forces (rate-independent), row 1 the affine flow at unit shear rate; returned as a
    ``LinearProblem``.  ``dt_implicit`` > 0 puts dt_implicit * spring stiffness into the contact blocks
    (linearly implicit springs); 0 for explicit Euler.
    """
    nvec, r, xi, dy = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, le_offset)
    n_frictional = contacts.critical_load_update(
        radii, pair_i, pair_j, nvec, xi, stretch, contact_state, kn, kt, mu, critical_load
    )
    in_contact, lubricated, active, k_normal, k_tangential, n_active, n_contacts = classify_pairs(
        radii, pair_i, pair_j, xi, contact_state, kn, kt, lub_max_gap, dt_implicit
    )
    coeff = lubrication_resistance(radii, pair_i, pair_j, xi, active, delta)
    data, rhs_rate = assemble_resistance(
        radii,
        pair_i,
        pair_j,
        nvec,
        dy,
        coeff,
        active,
        in_contact,
        k_normal,
        k_tangential,
        indptr,
        pair_slot,
        diag_slot,
        nnz,
    )
    rhs = np.zeros((2, rhs_rate.shape[0]))
    rhs[1] = rhs_rate
    f_on_i = contacts.contact_spring_forces(
        radii, pair_i, pair_j, nvec, xi, stretch, contact_state, kn, kt, rhs[0]
    )
    return LinearProblem(
        nvec, r, xi, dy, coeff, lubricated, in_contact, active, k_normal, k_tangential, f_on_i, data, rhs,
        n_active, n_contacts, n_frictional,
    )  # fmt: skip


@njit(cache=True)
def move(pos, vel, displacement, shear_rate, dt):
    """Explicit Euler move of positions (N, d) [a] with the non-affine velocities ``vel`` (the
    translations are the first d of each particle's vel.shape[0] / N degrees of freedom) plus the affine
    flow u = shear_rate * y e_x, accumulating the non-affine ``displacement`` (N, d) [a]; returns the
    largest |displacement|.  Any dimension d."""
    dim = pos.shape[1]
    dof = vel.shape[0] // pos.shape[0]
    dmax = 0.0
    for i in range(pos.shape[0]):
        pos[i, 0] += (vel[dof * i] + shear_rate * pos[i, 1]) * dt
        for c in range(1, dim):
            pos[i, c] += vel[dof * i + c] * dt
        displacement[i, 0] += vel[dof * i] * dt
        d = displacement[i, 0] ** 2
        for c in range(1, dim):
            displacement[i, c] += vel[dof * i + c] * dt
            d += displacement[i, c] ** 2
        if d > dmax:
            dmax = d
    return np.sqrt(dmax)


@njit(cache=True)
def max_translation_speed(vel, dim, dof):
    """Largest translation speed |U_i| of the velocities ``vel`` (N dof,), whose first ``dim`` entries
    per particle are the translation."""
    vmax = 0.0
    for i in range(vel.shape[0] // dof):
        v = vel[dof * i] ** 2
        for c in range(1, dim):
            v += vel[dof * i + c] ** 2
        if v > vmax:
            vmax = v
    return np.sqrt(vmax)


@njit(cache=True)
def _advance(
    positions,
    displacement,
    vel,
    radii,
    pair_i,
    pair_j,
    nvec,
    dy,
    contact_state,
    stretch,
    shear_rate,
    dt,
    elastic_unloading,
    lx,
    ly,
    le_offset,
):
    """Move by dt: contact stretches (sliding contacts that unload marked, with ``elastic_unloading``),
    positions (affine + non-affine), Lees-Edwards offset, wrapping.  Returns (largest non-affine
    displacement since the list was built, new offset)."""
    contacts.increment_stretch(
        vel, radii, pair_i, pair_j, nvec, dy, contact_state, stretch, shear_rate, dt, elastic_unloading
    )
    max_displacement = move(positions, vel, displacement, shear_rate, dt)
    le_offset = wrap_offset(le_offset + shear_rate * ly * dt, lx)
    wrap_positions(positions, lx, ly, le_offset)
    return max_displacement, le_offset


DT_GROWTH = 1.2  # largest growth of dt between steps of the implicit integrator


class SimulationBase(ABC):
    """The LF-DEM driver of any dimension: neighbour-list upkeep, the step (solve, shear rate from the
    stress target or the imposed rate, adaptive dt, move) and its timings.  ``Simulation`` (2D) and
    ``integrator3d.Simulation3D`` supply the dimension's kernels through the class attributes and the
    methods ``edges``, ``new_state``, ``one_body_drag``, ``linear_problem`` and ``stress_sums``.

    ``velocity`` holds the last step's non-affine velocities (N DOF,); ``stress_factor`` converts
    stresslet sums to sigma0 (6 pi / box area or volume); ``drag`` is the one-body Stokes drag per degree
    of freedom [6 pi eta0].  ``solver``: the sparse solver's backend name or the solver itself
    (``rheograph.sim.solver``).
    """

    # a dimension's class attributes: DIM (space dimension), DOF (degrees of freedom per particle, the
    # DIM translations first), SOLVENT_UNIT (2 eta0 E at unit rate [sigma0], in the stress's order) and
    # its kernels neighbour_pairs(positions, radii, *edges, le_offset, gap, skin),
    # max_interaction_speed(vel, radii, i, j, nvec, dy, active, state, rate) and advance_kernel(positions,
    # displacement, vel, radii, i, j, nvec, dy, state, stretch, rate, dt, *edges, le_offset)
    DIM: int
    DOF: int
    SOLVENT_UNIT: np.ndarray

    def __init__(self, params: SimParams, state: SimState | None = None, solver="auto"):
        self.params = params
        # refused before the initial configuration or any matrix is allocated
        # the solver allocates nothing before its first analysis: made first, the check counts its needs
        self.solver = make_solver(solver, self.DOF, params.n_particles)
        check_simulation_memory(params.n_particles, dim=self.DIM, iterative=self.solver.name == "amg")
        if state is None:
            state = self.new_state(params)
        self.state = state
        self.stress_factor = stress_unit_factor(*self.edges())
        self.list_cutoff = 2.0 * float(state.radii.max()) * (1.0 + 0.5 * params.lub_max_gap)
        self.drag = self.one_body_drag(state.radii)
        self.velocity = np.zeros(self.DOF * state.radii.shape[0])
        self.max_displacement = 0.0
        self.timings: dict[str, float] = defaultdict(float)  # wall seconds per phase, for benchmarks
        # dt assumed by the implicit spring terms; saved in checkpoints via SimState.dt_assumed
        if state.dt_assumed <= 0.0:
            state.dt_assumed = params.disp_max
        if state.pair_i is None:
            self._rebuild_neighbours()
        else:
            self._analyze()
        if state.displacement is not None:
            self.max_displacement = float(np.sqrt((state.displacement**2).sum(axis=1).max()))

    # ---- what a dimension supplies ------------------------------------------------------------
    @abstractmethod
    def edges(self) -> tuple[float, ...]:
        """The box edges (lx, ly[, lz]) [a], as the kernels take them."""

    @staticmethod
    @abstractmethod
    def new_state(params: SimParams) -> SimState:
        """The state at the start of a state point (its seeded random configuration)."""

    @staticmethod
    @abstractmethod
    def one_body_drag(radii: np.ndarray) -> np.ndarray:
        """Stokes drag per degree of freedom (N DOF,) [6 pi eta0] of particles of ``radii`` (N,)."""

    @abstractmethod
    def linear_problem(self) -> LinearProblem:
        """The current step's linear problem (updates the contact states in place, as a step does)."""

    @abstractmethod
    def stress_sums(self, vel_const, vel_rate, lp: LinearProblem, record: bool) -> tuple:
        """Stresslet sums (lubrication, dashpot) of the rate-independent velocities ``vel_const`` and of
        the unit-rate ones ``vel_rate``, and the spring virial: (lub0, dash0, lub1, dash1, spring), in the
        stress's component order [F_CL a]; ``record``: all components, else at least xy."""

    def advance(self, vel, lp: LinearProblem, shear_rate: float, dt: float) -> None:
        """Move the state by dt with the velocities ``vel`` (stretches, positions, Lees-Edwards offset,
        wrapping: the dimension's ``advance_kernel``); sets ``max_displacement``."""
        s = self.state
        self.max_displacement, s.le_offset = self.advance_kernel(
            s.positions, s.displacement, vel, s.radii, s.pair_i, s.pair_j, lp.nvec, lp.dy, s.contact_state,
            s.stretch, shear_rate, dt, self.params.elastic_unloading, *self.edges(), s.le_offset,
        )  # fmt: skip

    def solve_configuration(self, passes: int = 2) -> StepResult:
        """The result of one step from the configuration this simulation was started from, which must be
        fresh (no step taken): the resistance solve of a snapshot, whose tangential springs start
        unstretched.  dt is set as a running simulation sets it: each of ``passes`` solves starts again
        from the same configuration and assumes DT_GROWTH x the dt the previous one would step with (the
        first, ``disp_max``).  The state is left as after the last pass's step; the neighbour list, the
        sparsity pattern and the symbolic factorisation are made once (a third of a pass's cost)."""
        return solve_configurations([self], passes)[0]

    # ---- neighbour list and sparsity pattern --------------------------------------------------
    def _rebuild_neighbours(self) -> None:
        s, p = self.state, self.params
        new_i, new_j = self.neighbour_pairs(
            s.positions, s.radii, *self.edges(), s.le_offset, p.lub_max_gap, p.neighbour_skin
        )
        n = s.radii.shape[0]
        if s.pair_i is None:
            s.stretch = np.zeros((new_i.shape[0], self.DIM))
            s.contact_state = np.zeros(new_i.shape[0], dtype=np.int8)
        else:
            s.stretch, s.contact_state = _transfer_contacts(
                s.pair_i, s.pair_j, s.stretch, s.contact_state, new_i, new_j, n
            )
        s.pair_i, s.pair_j = new_i, new_j
        s.displacement = np.zeros((n, self.DIM))
        s.strain_at_build = s.strain
        self.max_displacement = 0.0
        self._analyze()

    def _analyze(self) -> None:
        s = self.state
        n = s.radii.shape[0]
        self.indptr, self.indices, self.pair_slot, self.diag_slot = build_pattern(
            s.pair_i, s.pair_j, n, self.DOF
        )
        self.solver.analyze(self.indptr, self.indices, self.DOF * n)

    def _list_is_stale(self) -> bool:
        # two particles approach by at most twice the largest non-affine displacement plus the affine
        # relative motion over the accumulated strain, |d strain| * (longest listed distance)
        drift = 2.0 * self.max_displacement
        drift += abs(self.state.strain - self.state.strain_at_build) * (
            self.list_cutoff + self.params.neighbour_skin
        )
        return drift >= self.params.neighbour_skin

    # ---- one time step -----------------------------------------------------------------------
    def step(self, record: bool = False) -> StepResult:
        """Advance one step (explicit Euler or linearly implicit springs: ``params.integrator``); ``record``
        adds the full stress tensors and the contact list."""
        lp = self.prepare_step()
        return self.complete_step(lp, self.solve_linear(lp), record)

    def prepare_step(self) -> LinearProblem:
        """A step's first part: the neighbour list rebuilt where stale, and the step's linear problem (the
        contact states updated in place).  ``solve_linear`` (or a solver of several simulations' problems
        at once, ``step_together``) solves it and ``complete_step`` finishes the step."""
        clock = wallclock.perf_counter
        t0 = clock()
        if self._list_is_stale():
            self._rebuild_neighbours()
        t1 = clock()
        self.timings["neighbours"] += t1 - t0
        lp = self.linear_problem()
        self.timings["assembly"] += clock() - t1
        return lp

    def solve_linear(self, lp: LinearProblem) -> np.ndarray:
        """Velocities (N DOF, 2) [a / time unit] of R_FU U = ``lp.rhs`` (its columns: springs, unit-rate
        affine flow), by this simulation's sparse Cholesky solver."""
        clock = wallclock.perf_counter
        # (N DOF, 2) with contiguous columns: both right-hand sides solved in one pass over the factor
        rhs = lp.rhs.T
        t2 = clock()
        if lp.n_active:
            self.solver.factorize(lp.data)
            t3 = clock()
            self.timings["factorisation"] += t3 - t2
            vels = self.solver.solve(rhs)
        else:  # nothing interacts: R_FU is the one-body drag, a diagonal
            t3 = clock()
            vels = rhs / self.drag[:, None]
        self.timings["solve"] += clock() - t3
        return vels

    def pattern(self) -> tuple[np.ndarray, np.ndarray, int]:
        """The current matrix's upper-triangle CSC pattern: (indptr, indices, number of rows), on which
        ``LinearProblem.data`` lies."""
        return self.indptr, self.indices, self.DOF * self.state.radii.shape[0]

    def complete_step(self, lp: LinearProblem, vels: np.ndarray, record: bool = False) -> StepResult:
        """A step's last part, from its linear problem ``lp`` (``prepare_step``) and the solution ``vels``
        (N DOF, 2): the shear rate, dt, the stresses where ``record``ed, and the move."""
        s, p = self.state, self.params
        clock = wallclock.perf_counter
        timings = self.timings
        t4 = clock()
        radii = s.radii
        vel_const, vel_rate = np.ascontiguousarray(vels[:, 0]), np.ascontiguousarray(vels[:, 1])

        # stress split S = S_0 + rate * S_1 and the exact rate that meets the target
        lub0, dash0, lub1, dash1, spring = self.stress_sums(vel_const, vel_rate, lp, record)
        f = self.stress_factor
        if p.control == "stress":
            s0_xy = f * (lub0[1] + dash0[1] + spring[1])
            s1_xy = f * (lub1[1] + dash1[1]) + 1.0
            shear_rate = (p.stress - s0_xy) / s1_xy
        else:  # rate control: the rate is imposed, the stress S_0 + rate * S_1 is measured
            shear_rate = p.shear_rate
        vel = vel_const + shear_rate * vel_rate
        self.velocity = vel
        t5 = clock()
        timings["stress"] += t5 - t4

        # adaptive step: no particle, pair separation, contact point or strain increment may move more
        # than disp_max (physics.md §3.4; LF_DEM also limits the normal approach speed of pairs)
        interaction_speed = self.max_interaction_speed(
            vel, radii, s.pair_i, s.pair_j, lp.nvec, lp.dy, lp.active, s.contact_state, shear_rate
        )
        if p.lagged_step_control:
            # LF_DEM (commit 00fa7cc) updates the contact sliding speeds only after the move, so its dt
            # is bounded by the previous step's speeds: ~1.3x fewer steps, and a larger Euler bias
            # (docs/validation/speed.md).  Kept to reproduce LF_DEM's discretisation.
            lagged = s.previous_interaction_speed
            s.previous_interaction_speed = interaction_speed
            if lagged >= 0.0:
                interaction_speed = lagged
        vmax = max(max_translation_speed(vel, self.DIM, self.DOF), interaction_speed, abs(shear_rate))
        dt = p.disp_max / vmax if vmax > 0.0 else p.dt_max
        dt = min(dt, p.dt_max)
        if p.integrator == "implicit":
            dt = min(dt, s.dt_assumed)
            s.dt_assumed = min(DT_GROWTH * dt, p.dt_max)

        result = StepResult(
            dt=dt,
            shear_rate=shear_rate,
            n_contacts=lp.n_contacts,
            n_frictional=lp.n_frictional,
        )
        if record:
            xi = lp.xi
            if xi.shape[0]:  # monitoring only: computed where it is recorded
                result.max_overlap = float(max(0.0, -(xi * 0.5 * (radii[s.pair_i] + radii[s.pair_j])).min()))
                result.max_stretch = float(np.sqrt((s.stretch**2).sum(axis=1)).max())
            touching = s.contact_state != contacts.NONE
            result.contacts = (
                np.stack([s.pair_i[touching], s.pair_j[touching]], axis=1),
                s.contact_state[touching].copy(),
                s.stretch[touching].copy(),
            )
            result.stress_lubrication = f * (lub0 + shear_rate * lub1)
            result.stress_contact = f * (spring + dash0 + shear_rate * dash1)
            result.stress_solvent = shear_rate * self.SOLVENT_UNIT

        self.advance(vel, lp, shear_rate, dt)
        s.time += dt
        s.strain += shear_rate * dt
        s.steps += 1
        timings["update"] += clock() - t5
        return result


def own_solvers(sims: list[SimulationBase], problems: list[LinearProblem]) -> list[np.ndarray]:
    """Each simulation's problem solved by its own sparse solver, one after the other: the default of
    ``step_together``.  Any function of this signature may take its place, e.g. one that solves the
    problems of many snapshots together on a GPU (``rheograph.graphs.batched_solve``)."""
    return [sim.solve_linear(lp) for sim, lp in zip(sims, problems)]


def step_together(
    sims: list[SimulationBase], solve_batch=own_solvers, record: bool = False
) -> list[StepResult]:
    """One step of each of ``sims``, their linear problems solved together by ``solve_batch(sims,
    problems)`` -> velocities (N DOF, 2) each; with ``own_solvers``, exactly ``[sim.step() for sim in
    sims]``."""
    problems = [sim.prepare_step() for sim in sims]
    velocities = solve_batch(sims, problems)
    return [sim.complete_step(lp, vel, record) for sim, lp, vel in zip(sims, problems, velocities)]


def solve_configurations(
    sims: list[SimulationBase], passes: int = 2, solve_batch=own_solvers
) -> list[StepResult]:
    """``SimulationBase.solve_configuration`` of each of ``sims`` (fresh simulations), their passes taken
    together (``step_together``)."""
    if passes < 1:
        raise ValueError(f"solve_configuration takes at least one pass, not {passes}")
    if any(sim.state.steps for sim in sims):
        raise ValueError("solve_configuration needs a fresh simulation (no step taken)")
    starts = [copy.deepcopy(sim.state) for sim in sims]
    for k in range(passes):
        if k:
            # step() has left dt_assumed at DT_GROWTH x its dt (at most dt_max): the next pass assumes it
            for sim, start in zip(sims, starts):
                sim.state = dataclasses.replace(copy.deepcopy(start), dt_assumed=sim.state.dt_assumed)
                sim.max_displacement = 0.0
        results = step_together(sims, solve_batch)
    return results


class Simulation(SimulationBase):
    """A 2D LF-DEM run of one state point, under stress (default) or rate control (``params.control``).

    >>> sim = Simulation(SimParams(n_particles=100, phi=0.7, stress=1.0))
    >>> result = sim.step(record=True)
    """

    DIM = 2
    DOF = 3  # U_x, U_y, w_z
    SOLVENT_UNIT = np.array([0.0, 1.0, 0.0])  # (xx, xy, yy)
    neighbour_pairs = staticmethod(neighbour_pairs)
    max_interaction_speed = staticmethod(contacts.max_interaction_speed)
    advance_kernel = staticmethod(_advance)

    def edges(self) -> tuple[float, float]:
        return self.state.lx, self.state.ly

    @staticmethod
    def new_state(params: SimParams) -> SimState:
        pos, radii, box = initial_configuration(params)
        return SimState(positions=pos, radii=radii, lx=box, ly=box)

    @staticmethod
    def one_body_drag(radii: np.ndarray) -> np.ndarray:
        # translation a, rotation 4 a^3 / 3 [6 pi eta0]
        return np.stack([radii, radii, 4.0 * radii**3 / 3.0], axis=1).ravel()

    def linear_problem(self) -> LinearProblem:
        s, p = self.state, self.params
        return linear_problem(
            s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.le_offset, s.stretch, s.contact_state,
            p.kn, p.kt, p.mu, p.critical_load, p.lub_max_gap, p.delta,
            s.dt_assumed if p.integrator == "implicit" else 0.0,
            self.indptr, self.pair_slot, self.diag_slot, self.indices.shape[0],
        )  # fmt: skip

    def stress_sums(self, vel_const, vel_rate, lp: LinearProblem, record: bool) -> tuple:
        s = self.state
        lub0, dash0, lub1, dash1 = pair_stress_sums(
            vel_const, vel_rate, s.radii, s.pair_i, s.pair_j, lp.nvec, lp.r, lp.dy, lp.coeff, lp.lubricated,
            lp.in_contact, lp.k_normal, lp.k_tangential, record,
        )  # fmt: skip
        spring = spring_stress(s.pair_i, lp.nvec, lp.r, lp.f_on_i, s.contact_state, record)
        return lub0, dash0, lub1, dash1, spring


def viscosity(result: StepResult) -> float:
    """Instantaneous relative viscosity sigma_xy / (eta0 shear_rate) (inf/negative values are kept)."""
    return result.stress[1] / result.shear_rate if result.shear_rate != 0.0 else math.inf


def particle_pressure(result: StepResult) -> float:
    """Pi = -(sigma_xx + sigma_yy + sigma_zz)/3 with sigma_zz = 0 (seed paper / LF_DEM convention)."""
    st = result.stress
    return -(st[0] + st[2]) / 3.0
