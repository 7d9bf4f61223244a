"""Graph features of a 3D sheared-suspension snapshot (pure numpy; no torch here): the 3D analogues of
``rheograph.graphs.features``, under the same names so that one ``GraphSettings`` reads both.

Axes as in the 3D simulator (``rheograph.sim.geometry3d``): flow x, gradient y, vorticity z; the box is
(lx, ly, lz) with the Lees–Edwards offset ``le_offset`` on the images across the y faces, and z plainly
periodic.  Functions here take the box as one tuple ``box3 = (lx, ly, lz, le_offset)`` [a].

Simple shear is not rotation invariant: the flow and gradient directions are physical, so a feature may
depend on them; what the flow leaves invariant are the reflection z -> -z (across the flow–gradient
plane), the point inversion r -> -r and translations, and every feature below is unchanged by them (a
vector feature turns into that of the reversed edge under the inversion).  The features keep their 2D
meaning:

* ``gap``, ``distance``, ``contact``, ``overlap``, ``lubrication``, ``log_lubrication``, ``load``,
  ``frictional``, ``tangential_stretch`` (|stretch|, a 3-vector), ``sliding``: scalars of the pair,
  invariant under every rotation of the pair frame; as in 2D.
* ``dx``, ``dy``: the pair vector's flow and gradient components r n_x, r n_y; ``cos`` = n_x (the
  cosine of the angle to the flow direction) and ``sin`` = n_y (the gradient component, 2D's sine of the
  angle to the flow direction within the shear plane).  The vorticity component n_z is left out on
  purpose: its sign flips under the symmetry z -> -z; what it adds enters through ``nyy_nzz``.
* ``nxny`` (the shear-stress projection of a pair stresslet), ``nxx_nyy`` (the first normal-stress
  difference's), and the 3D-only ``nyy_nzz`` = n_y^2 - n_z^2 (the second normal-stress difference's);
  ``contact_shear``, ``contact_normal``, ``lubrication_shear``, ``spring_shear``: the pair's stress
  contributions, as in 2D (``spring_shear`` = kt_ratio a_bar r sym(n (x) stretch)_xy / delta_sigma).

Summed per volume instead of per area, the contact and spring sums are the stress in units of sigma:
the contact-spring pressure -tr(sigma)/3 is (2 pi sigma / V) sum overlap a_bar r, the 2D expression with
the volume for the area (``snapshot_descriptors``).
"""

from __future__ import annotations

import numpy as np

from rheograph.graphs.features import (
    Relaxation,
    contact_history,
    one_solve_viscosity,
    pair_records,
    refuse_centres_inside,
    relax_simulations,
)
from rheograph.sim.geometry3d import neighbour_pairs, pair_geometry
from rheograph.sim.integrator3d import SimState3D, Simulation3D
from rheograph.sim.params3d import SimParams3D
from rheograph.sim.stress3d import particle_pressure

# edge features that only a 3D snapshot has (a 2D model cannot ask for them)
EDGE_FEATURES_3D_ONLY = ("nyy_nzz",)


def check_separations3d(where: str, positions, radii, box3, noise: float = 0.0) -> None:
    """``rheograph.graphs.features.check_separations`` in 3D: refuses a configuration (positions (N, 3)
    [a], wrapped) in which a particle's centre lies within another particle, by more than positions of
    precision ``noise`` [a] explain."""
    lx, ly, lz, le_offset = box3
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    pair_i, pair_j = neighbour_pairs(positions, radii, lx, ly, lz, le_offset, 0.0, 0.0)
    _, distance, _, _ = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, lz, le_offset)
    refuse_centres_inside(where, radii, pair_i, pair_j, distance, noise)


def snapshot_pairs3d(positions, radii, box3, cutoff, params) -> dict:
    """Per-pair geometry of the P pairs i < j with surface gap < ``cutoff`` [a]: the keys of the 2D
    ``snapshot_pairs`` (``i``, ``j``, ``xi``, ``r``, ``nx``, ``ny``, ``abar``, ``overlap``, ``lub_gap``)
    and ``nz``."""
    lx, ly, lz, le_offset = box3
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    radii = np.asarray(radii, dtype=np.float64)
    pair_i, pair_j = neighbour_pairs(positions, radii, lx, ly, lz, le_offset, 0.0, cutoff)
    nvec, r, xi, _ = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, lz, le_offset)
    return pair_records(radii, pair_i, pair_j, nvec, r, xi, cutoff, params)


def snapshot_edges3d(positions, radii, box3, cutoff, params, contacts=None):
    """Directed edges (2, 2P) and every edge feature (module docstring) of a 3D snapshot, as the 2D
    ``snapshot_edges``: (edge_index, features dict of (2P,) arrays, the pair dict of
    ``snapshot_pairs3d``); edge k and k + P are the two directions of one pair."""
    p = snapshot_pairs3d(positions, radii, box3, cutoff, params)
    xi, r, nx, ny, nz = p["xi"], p["r"], p["nx"], p["ny"], p["nz"]
    overlap, lub_gap, abar = p["overlap"], p["lub_gap"], p["abar"]
    delta = float(params["delta"])
    load = np.arcsinh(float(params["stress"]) * abar * overlap)
    pair_features = {
        "gap": (xi, 1.0),
        "distance": (r, 1.0),
        "dx": (nx * r, -1.0),
        "dy": (ny * r, -1.0),
        "sin": (ny, -1.0),
        "cos": (nx, -1.0),
        "contact": ((xi < 0).astype(np.float64), 1.0),
        "overlap": (overlap, 1.0),
        "lubrication": (delta / lub_gap, 1.0),
        "log_lubrication": (-np.log(lub_gap), 1.0),
        "nxny": (nx * ny, 1.0),
        "nxx_nyy": (nx * nx - ny * ny, 1.0),
        "nyy_nzz": (ny * ny - nz * nz, 1.0),
        "contact_shear": (overlap * abar * r * nx * ny, 1.0),
        "contact_normal": (overlap * abar * r, 1.0),
        "lubrication_shear": (abar * r * (nx * ny) ** 2 * delta / lub_gap, 1.0),
        "load": (load, 1.0),
        "frictional": ((load > np.arcsinh(1.0)).astype(np.float64), 1.0),
    }
    if contacts is not None:
        history = contact_history(p, contacts, radii.size, float(params["kn_coefficient"]), dim=3)
        s = history["stretch"]
        pair_features["tangential_stretch"] = (np.sqrt((s**2).sum(axis=1)), 1.0)
        pair_features["sliding"] = (history["sliding"].astype(np.float64), 1.0)
        shear = float(params["kt_ratio"]) * abar * r * 0.5 * (nx * s[:, 1] + ny * s[:, 0])
        pair_features["spring_shear"] = (shear, 1.0)
    edge_index = np.stack([np.r_[p["i"], p["j"]], np.r_[p["j"], p["i"]]])
    feats = {name: np.r_[value, sign * value] for name, (value, sign) in pair_features.items()}
    return edge_index, feats, p


def snapshot_simulation3d(
    positions, radii, box3, params: dict, solver="auto"
) -> tuple[SimParams3D, Simulation3D]:
    """A stress-controlled implicit ``Simulation3D`` started from one snapshot (no contact history),
    ``solver`` its sparse solver (``rheograph.sim.solver``)."""
    lx, ly, lz, le_offset = box3
    mapping = {k: v for k, v in params.items() if k != "dim"}
    sim_params = SimParams3D.from_mapping({**mapping, "integrator": "implicit", "control": "stress"})
    state = SimState3D(
        positions=np.array(positions, dtype=np.float64),
        radii=np.asarray(radii, dtype=np.float64),
        lx=lx,
        ly=ly,
        lz=lz,
        le_offset=le_offset,
    )
    return sim_params, Simulation3D(sim_params, state, solver)


def solve_viscosity3d(positions, radii, box3, params: dict, passes: int = 2) -> float:
    """Relative viscosity eta_r of one stress-controlled resistance solve on a 3D snapshot: the 2D
    ``solve_viscosity`` with the 3D simulator's step (``Simulation3D.solve_configuration``:
    the tangential springs unstretched, dt assumed as a running simulation would after ``passes``)."""
    sim_params, sim = snapshot_simulation3d(positions, radii, box3, params)
    return one_solve_viscosity(sim_params, sim.solve_configuration(passes))


def relax_positions3d(
    positions, radii, box3, params: dict, strain: float = 0.01, max_steps: int | None = None
) -> Relaxation:
    """The 2D ``relax_positions`` with the 3D simulator: the snapshot sheared by ``strain`` at its
    imposed stress; the returned ``positions`` are (N, 3) and ``pressure`` is -tr(sigma)/3."""
    _, sim = snapshot_simulation3d(positions, radii, box3, params)
    return relax_simulations([sim], strain, max_steps, step_pressure3d)[0]


def step_pressure3d(result) -> float:
    """Pi = -tr(sigma)/3 [sigma0] of a recorded 3D ``StepResult``."""
    return particle_pressure(result.stress)
