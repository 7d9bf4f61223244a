"""Time integration of 3D LF-DEM (6 degrees of freedom per sphere): one step = geometry -> CLM -> R_FU ->
two solves -> shear rate (stress control) or imposed rate (rate control) -> adaptive dt -> move.

The same schemes and step rule as the 2D ``rheograph.sim.integrator`` (read its docstring for the
linearly implicit springs and the lagged step control), with the 3D kernels: a planar 3D system (all
centres at one z, box taller than the cut-off in z) takes the 2D simulator's steps to round-off.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit

from rheograph.sim import contacts3d, lubrication3d
from rheograph.sim.assembly3d import UNIT_STRAIN_RATE, assemble_resistance
from rheograph.sim.geometry import wrap_offset
from rheograph.sim.geometry3d import neighbour_pairs, pair_geometry, wrap_positions
from rheograph.sim.init_config3d import initial_configuration
from rheograph.sim.integrator import LinearProblem, SimState, SimulationBase, classify_pairs, move
from rheograph.sim.lubrication import lubrication_resistance
from rheograph.sim.params3d import SimParams3D
from rheograph.sim.stress3d import pair_stress_sums, spring_stress


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
    ``build_pattern(..., block=6)`` pattern and the two right-hand sides (2, 6N), as a ``LinearProblem``.
    ``dt_implicit`` > 0 puts dt_implicit * spring stiffness into the contact blocks (linearly implicit
    springs); 0 for Euler."""
    nvec, r, xi, dy = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, lz, le_offset)
    n_frictional = contacts3d.critical_load_update(
        radii, pair_i, pair_j, nvec, xi, stretch, contact_state, kn, kt, mu, critical_load
    )
    in_contact, lubricated, active, k_normal, k_tangential, n_active, n_contacts = classify_pairs(
        radii, pair_i, pair_j, xi, contact_state, kn, kt, lub_max_gap, dt_implicit
    )
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
    return LinearProblem(
        nvec, r, xi, dy, coeff, lubricated, in_contact, active, k_normal, k_tangential, f_on_i, data, rhs,
        n_active, n_contacts, n_frictional,
    )  # fmt: skip


@njit(cache=True)
def _advance(
    positions, displacement, vel, radii, pair_i, pair_j, nvec, dy, contact_state, stretch, shear_rate, dt,
    elastic_unloading, lx, ly, lz, le_offset,
):  # fmt: skip
    """Move by dt: contact stretches (with the pre-move geometry; sliding contacts that unload marked, with
    ``elastic_unloading``), positions (affine + non-affine), the Lees–Edwards offset, wrapping.  Returns
    (largest non-affine displacement since the list was built, new offset)."""
    contacts3d.increment_stretch(
        vel, radii, pair_i, pair_j, nvec, dy, contact_state, stretch, shear_rate, dt, elastic_unloading
    )
    max_displacement = move(positions, vel, displacement, shear_rate, dt)
    le_offset = wrap_offset(le_offset + shear_rate * ly * dt, lx)
    wrap_positions(positions, lx, ly, lz, le_offset)
    return max_displacement, le_offset


class Simulation3D(SimulationBase):
    """A 3D LF-DEM run of one state point, under stress or rate control (``params.control``): the driver
    of ``SimulationBase`` with the 3D kernels.

    >>> sim = Simulation3D(SimParams3D(n_particles=200, phi=0.5, stress=10.0))
    >>> result = sim.step(record=True)   # result.stress: (xx, xy, xz, yy, yz, zz) [sigma0]

    ``velocity`` holds the last step's non-affine velocities (6N: U (3), w (3) per particle).
    ``stress_factor`` converts stresslet sums to sigma0 (6 pi / box volume).
    """

    DIM = 3
    DOF = 6  # U (3), w (3)
    SOLVENT_UNIT = np.array([0.0, 1.0, 0.0, 0.0, 0.0, 0.0])  # (xx, xy, xz, yy, yz, zz)
    neighbour_pairs = staticmethod(neighbour_pairs)
    max_interaction_speed = staticmethod(contacts3d.max_interaction_speed)
    one_body_drag = staticmethod(lubrication3d.one_body_drag)
    advance_kernel = staticmethod(_advance)

    def edges(self) -> tuple[float, float, float]:
        return self.state.lx, self.state.ly, self.state.lz

    @staticmethod
    def new_state(params: SimParams3D) -> SimState3D:
        pos, radii, box = initial_configuration(params)
        return SimState3D(positions=pos, radii=radii, lx=box, ly=box, lz=box)

    def linear_problem(self) -> LinearProblem:
        s, p = self.state, self.params
        return linear_problem(
            s.positions, s.radii, s.pair_i, s.pair_j, s.lx, s.ly, s.lz, s.le_offset, s.stretch,
            s.contact_state, p.kn, p.kt, p.mu, p.critical_load, p.lub_max_gap, p.delta,
            s.dt_assumed if p.integrator == "implicit" else 0.0,
            self.indptr, self.pair_slot, self.diag_slot, self.indices.shape[0], UNIT_STRAIN_RATE,
        )  # fmt: skip

    def stress_sums(self, vel_const, vel_rate, lp: LinearProblem, record: bool) -> tuple:
        s = self.state
        lub0, dash0, lub1, dash1 = pair_stress_sums(
            vel_const, vel_rate, s.radii, s.pair_i, s.pair_j, lp.nvec, lp.r, lp.dy, lp.coeff, lp.lubricated,
            lp.in_contact, lp.k_normal, lp.k_tangential, UNIT_STRAIN_RATE,
        )  # fmt: skip
        spring = spring_stress(s.pair_i, lp.nvec, lp.r, lp.f_on_i, s.contact_state)
        return lub0, dash0, lub1, dash1, spring
