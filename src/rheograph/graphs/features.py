"""Graph features of a sheared-suspension snapshot (pure numpy; no torch here).

Nodes are particles, with the one-hot of their radius (small, large) as features.  Edges join pairs whose
surface gap h = r - a_i - a_j is below ``cutoff`` (in units of the small radius a), found with the
Lees–Edwards images; both directions are present.

Edge features, by name (``EDGE_FEATURES``):

* the seed paper's geometry: ``gap`` (reduced gap xi = h / a_bar, a_bar = (a_i + a_j)/2), ``distance`` r,
  its components ``dx``, ``dy``, and ``sin``, ``cos`` of its angle to the flow direction;
* physics-aware, from positions alone — they make contacts and lubrication visible, which a raw gap of
  ~1e-3 a next to distances of 2–3 a hides from a linear encoder:
  ``contact`` (1 when the surfaces overlap, h < 0), ``overlap`` (overlap in units of delta_sigma =
  6 pi / kn_coefficient, the overlap whose spring force is sigma a_bar: with k_n proportional to sigma,
  the overlaps are statistically stress-independent in these units), ``lubrication`` (delta / (xi + delta)
  in (0, 1]: the squeeze resistance 1/(xi + delta) of physics.md, frozen at xi = 0 in contact like the
  dashpot), ``log_lubrication`` (log(1/(xi + delta)), the tangential resistance), ``nxny`` (n_x n_y, the
  shear-stress projection of a pair stresslet), ``nxx_nyy`` (n_x^2 - n_y^2, the normal-stress
  difference projection), and the pair's stress contributions that the targets are sums of (physics.md
  §4): ``contact_shear`` = overlap a_bar r n_x n_y and ``contact_normal`` = overlap a_bar r (the spring's
  sym(r F) in units of sigma: with k_n proportional to sigma, the contact stress / sigma is their sum per
  area), ``lubrication_shear`` = a_bar r (n_x n_y)^2 delta / (xi + delta) (the squeeze stresslet of the
  affine flow per unit shear rate, scaled by delta) — summed by the model's pooling, not recomputed;
* stress-conditioned (needs the imposed stress, as every simulation and rheometer knows it):
  ``load`` = asinh(F_n / F_CL) of the contact spring F_n = k_n a_bar overlap (0 when apart).  The
  Critical Load Model makes a contact frictional exactly when F_n > F_CL, i.e. load > asinh(1):
  ``frictional`` is that flag (1 for a frictional contact), whose sum over pairs is N Z_mu / 2;
* contact history (a diagnostic, not from positions: needs the simulator's contact states, which every
  rheograph trajectory records per snapshot): ``tangential_stretch`` (|stretch| of the tangential spring
  in units of delta_sigma, 0 when apart), ``sliding`` (1 for a contact sliding at the Coulomb limit) and
  ``spring_shear`` = kt_ratio a_bar r sym(n (x) stretch)_xy / delta_sigma, the tangential spring's shear
  stresslet in units of sigma: the simulator's spring shear stress is (6 pi / area) sigma times the sum
  over pairs of (spring_shear - contact_shear).  They measure how much of the targets positions cannot
  know (docs/validation/surrogate_accuracy.md).

All features are O(1) numbers on purpose; the model standardises them with statistics of its training
folds anyway.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from rheograph.errors import InputError
from rheograph.sim.contacts import SLIDE
from rheograph.sim.geometry import neighbour_pairs, pair_geometry
from rheograph.sim.integrator import (
    SimState,
    Simulation,
    SimulationBase,
    own_solvers,
    particle_pressure,
    step_together,
)
from rheograph.sim.params import SimParams

PAPER_EDGE_FEATURES = ("gap", "distance", "dx", "dy", "sin", "cos")
PHYSICS_EDGE_FEATURES = (
    "contact",
    "overlap",
    "lubrication",
    "log_lubrication",
    "nxny",
    "nxx_nyy",
    "contact_shear",
    "contact_normal",
    "lubrication_shear",
)
STRESS_EDGE_FEATURES = ("load", "frictional")
HISTORY_EDGE_FEATURES = ("tangential_stretch", "sliding", "spring_shear")
EDGE_FEATURES = PAPER_EDGE_FEATURES + PHYSICS_EDGE_FEATURES + STRESS_EDGE_FEATURES + HISTORY_EDGE_FEATURES


def overlap_unit(kn_coefficient: float) -> float:
    """delta_sigma [a]: overlap at which the normal spring force per a_bar equals the imposed stress.

    k_n = kn_coefficient * sigma / (6 pi) [F_CL / a^2] (physics.md §3.2), so k_n a_bar delta = sigma a_bar
    (delta / delta_sigma) with delta_sigma = 6 pi / kn_coefficient (9.4e-4 a at LF_DEM's 2e4)."""
    return 6.0 * np.pi / kn_coefficient


def check_separations(where: str, positions, radii, lx, ly, le_offset, noise: float = 0.0) -> None:
    """Refuses a configuration (positions (N, 2) [a], wrapped) in which a particle's centre lies within
    another particle: centre distance r <= max(a_i, a_j), an overlap a_i + a_j - r of at least the
    smaller radius.  Pair forces along the line of centres (the contact springs, lubrication) describe
    overlaps small against the radii; the simulator's stay within 0.02 a (0.005 a in the 245 runs of the
    paper-scale training set, 0.02 a in frictionless packings at jamming), and positions imprecise by
    0.05 a per coordinate (the imaging models' widest) make up to 0.28 a (measured: 21 snapshots at
    phi = 0.76, N = 400).  So this threshold catches only particles listed twice, positions in other
    units or a broken file — whose solve would divide by a zero distance or predict from nonsense.
    ``noise`` [a]: the positions' stated precision (``refuse_centres_inside``)."""
    pair_i, pair_j = neighbour_pairs(positions, radii, lx, ly, le_offset, 0.0, 0.0)
    dx = positions[pair_j, 0] - positions[pair_i, 0]
    dy = positions[pair_j, 1] - positions[pair_i, 1]
    across = (dy > 0.5 * ly).astype(np.float64) - (dy < -0.5 * ly)  # the Lees–Edwards image above/below
    dy = dy - across * ly
    dx = dx - across * le_offset
    dx = dx - lx * np.floor(dx / lx + 0.5)
    refuse_centres_inside(where, radii, pair_i, pair_j, np.hypot(dx, dy), noise)


# how far imprecise positions can bring two centres together: 5 standard deviations of the difference of
# two displacements of RMS eps along the line of centres, sqrt(2) eps
NOISE_REACH = 5.0 * np.sqrt(2.0)


def refuse_centres_inside(where: str, radii, pair_i, pair_j, distance, noise: float = 0.0) -> None:
    """Raises InputError naming the worst listed pair (``pair_i``, ``pair_j``) (P,) whose centre
    ``distance`` (P,) [a] is at most the larger radius (``check_separations``, either dimension).  With
    positions imprecise by ``noise`` [a] (RMS per coordinate, the coarsest axis), a touching pair may
    appear up to NOISE_REACH x noise closer: the threshold drops to a_i + a_j - NOISE_REACH x noise where
    that is lower (from noise ~0.14 a on; confocal depth precision of ~0.3 a can bring any two centres
    together, and no check is left)."""
    larger = np.maximum(radii[pair_i], radii[pair_j])
    threshold = np.minimum(larger, radii[pair_i] + radii[pair_j] - NOISE_REACH * noise)
    inside = np.flatnonzero(distance <= threshold)
    if inside.size:
        k = inside[np.argmin(distance[inside] / larger[inside])]
        i, j = int(pair_i[k]), int(pair_j[k])
        raise InputError(
            f"{where}: particles {i} and {j} (radii {radii[i]:g}, {radii[j]:g}) are {distance[k]:.3g} a "
            f"apart, one centre within the other particle ({inside.size} such pair(s)): no contact model "
            "describes that (the simulator's overlaps stay within 0.02 a); is a particle listed twice, or "
            "are the positions in other units than the small radius a?"
        )


def snapshot_pairs(positions, radii, lx, ly, le_offset, cutoff, params) -> dict:
    """Per-pair geometry (P pairs i < j with gap < cutoff, units of a): indices ``i``, ``j``, reduced gap
    ``xi``, distance ``r``, normal ``nx``, ``ny`` (i -> j), ``abar`` = (a_i + a_j)/2, ``overlap`` (units of
    delta_sigma, 0 when apart) and ``lub_gap`` = max(xi, 0) + delta (the regularised lubrication gap).

    ``params`` is the run's parameter mapping (``delta`` and ``kn_coefficient`` are read)."""
    pair_i, pair_j = neighbour_pairs(positions, radii, lx, ly, le_offset, 0.0, cutoff)
    nvec, r, xi, _ = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, le_offset)
    return pair_records(radii, pair_i, pair_j, nvec, r, xi, cutoff, params)


def pair_records(radii, pair_i, pair_j, nvec, r, xi, cutoff, params) -> dict:
    """The per-pair geometry of ``snapshot_pairs`` (2D) and its 3D twin from candidate pairs and their
    geometry: those with surface gap < ``cutoff`` kept, the normal's components ``nx``, ``ny`` (and
    ``nz`` where ``nvec`` has three columns)."""
    keep = r - radii[pair_i] - radii[pair_j] < cutoff
    pair_i, pair_j, nvec, r, xi = pair_i[keep], pair_j[keep], nvec[keep], r[keep], xi[keep]
    abar = 0.5 * (radii[pair_i] + radii[pair_j])
    normal = {name: nvec[:, k] for k, name in enumerate(("nx", "ny", "nz")[: nvec.shape[1]])}
    return {
        "i": pair_i,
        "j": pair_j,
        "xi": xi,
        "r": r,
        **normal,
        "abar": abar,
        "overlap": np.maximum(-xi, 0.0) * abar / overlap_unit(float(params["kn_coefficient"])),
        "lub_gap": np.maximum(xi, 0.0) + float(params["delta"]),
    }


def contact_history(pairs: dict, contacts, n_particles: int, kn_coefficient: float, dim: int = 2) -> dict:
    """Per pair of ``pairs`` (``snapshot_pairs``): the tangential spring ``stretch`` (P, dim)
    [delta_sigma] and ``sliding`` (P,) bool, from the recorded ``contacts`` = (pairs (C, 2), states (C,),
    stretches (C, dim) [a]) of one snapshot of dimension ``dim``; zero for pairs not recorded as touching.
    A recorded pair (j, i) with i < j carries the stretch of i relative to j, hence the sign flip."""
    recorded, states, stretches = contacts
    recorded = np.asarray(recorded, dtype=np.int64).reshape(-1, 2)
    stretches = np.asarray(stretches, dtype=np.float64).reshape(-1, dim)
    flip = recorded[:, 0] > recorded[:, 1]
    key = np.minimum(recorded[:, 0], recorded[:, 1]) * n_particles + np.maximum(
        recorded[:, 0], recorded[:, 1]
    )
    lookup = {int(k): c for c, k in enumerate(key)}
    stretch = np.zeros((pairs["i"].size, dim))
    sliding = np.zeros(pairs["i"].size, dtype=bool)
    unit = overlap_unit(kn_coefficient)
    for p, (i, j) in enumerate(zip(pairs["i"], pairs["j"])):
        c = lookup.get(int(min(i, j)) * n_particles + int(max(i, j)))
        if c is None:
            continue
        sign = -1.0 if flip[c] != (i > j) else 1.0
        stretch[p] = sign * stretches[c] / unit
        sliding[p] = states[c] == SLIDE
    return {"stretch": stretch, "sliding": sliding}


def snapshot_edges(positions, radii, lx, ly, le_offset, cutoff, params, contacts=None):
    """Directed edges (2, 2P) and every edge feature for pairs with gap < cutoff (units of a).

    ``params`` is the run's parameter mapping (``delta``, ``kn_coefficient``, ``stress``, ``kt_ratio`` are
    read); ``contacts`` the snapshot's recorded contact states (see ``contact_history``), needed only by
    the history features (absent: they are not computed).
    Returns (edge_index, features dict of (2P,) float64 arrays, the pair dict of ``snapshot_pairs``).
    Edge k and k + P are the two directions of one pair; the vector of the second is the negative of the
    first, scalar features are shared.
    """
    p = snapshot_pairs(positions, radii, lx, ly, le_offset, cutoff, params)
    xi, r, nx, ny, overlap, lub_gap = p["xi"], p["r"], p["nx"], p["ny"], p["overlap"], p["lub_gap"]
    abar = p["abar"]
    # F_n / F_CL = k_n a_bar overlap = stress * a_bar * overlap (overlap in units of delta_sigma)
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
        "lubrication": (float(params["delta"]) / lub_gap, 1.0),
        "log_lubrication": (-np.log(lub_gap), 1.0),
        "nxny": (nx * ny, 1.0),
        "nxx_nyy": (nx * nx - ny * ny, 1.0),
        "contact_shear": (overlap * abar * r * nx * ny, 1.0),
        "contact_normal": (overlap * abar * r, 1.0),
        "lubrication_shear": (abar * r * (nx * ny) ** 2 * float(params["delta"]) / lub_gap, 1.0),
        "load": (load, 1.0),
        "frictional": ((load > np.arcsinh(1.0)).astype(np.float64), 1.0),
    }
    if contacts is not None:
        history = contact_history(p, contacts, radii.size, float(params["kn_coefficient"]))
        sx, sy = history["stretch"][:, 0], history["stretch"][:, 1]
        pair_features["tangential_stretch"] = (np.hypot(sx, sy), 1.0)
        pair_features["sliding"] = (history["sliding"].astype(np.float64), 1.0)
        # n and the stretch both flip with the pair's direction: their product does not
        shear = float(params["kt_ratio"]) * abar * r * 0.5 * (nx * sy + ny * sx)
        pair_features["spring_shear"] = (shear, 1.0)
    edge_index = np.stack([np.r_[p["i"], p["j"]], np.r_[p["j"], p["i"]]])
    feats = {name: np.r_[value, sign * value] for name, (value, sign) in pair_features.items()}
    return edge_index, feats, p


# ---- per-snapshot physics descriptors (the no-message-passing baseline) --------------------------
DESCRIPTORS = (
    "contact_number",  # 2 N_contacts / N from h < 0
    "mean_overlap",  # mean overlap over contacts [delta_sigma]
    "contact_shear",  # sum over contacts of overlap a_bar r n_x n_y per area: sigma_xy^contact / sigma
    "contact_pressure",  # sum over contacts of overlap a_bar r per area: the contact pressure / sigma
    "contact_fabric",  # mean n_x n_y over contacts (anisotropy of the contact network)
    "lubrication_shear",  # sum over pairs of a_bar r (n_x n_y)^2 / (xi + delta) per area
    "lubrication_sum",  # sum over pairs of 1 / (xi + delta) per particle
    "near_contact_number",  # 2 N_pairs(xi < 0.05) / N: pairs about to touch
)


def snapshot_descriptors(pairs: dict, n_particles: int, area: float) -> np.ndarray:
    """Eight per-snapshot descriptors (``DESCRIPTORS``) from the pair dict of ``snapshot_pairs``.

    The contact and lubrication sums are the stress expressions of physics.md §4 with the force replaced
    by what positions determine (overlap in units of delta_sigma, resistance 1/(xi + delta)): with k_n
    proportional to sigma they are the contact stress in units of sigma and the lubrication stress per
    unit shear rate up to prefactors."""
    touching = pairs["xi"] < 0
    nxny = pairs["nx"] * pairs["ny"]
    overlap, abar, r = pairs["overlap"], pairs["abar"], pairs["r"]
    n_contacts = int(touching.sum())
    return np.array(
        [
            2.0 * n_contacts / n_particles,
            overlap[touching].mean() if n_contacts else 0.0,
            np.sum((overlap * abar * r * nxny)[touching]) / area,
            np.sum((overlap * abar * r)[touching]) / area,
            nxny[touching].mean() if n_contacts else 0.0,
            np.sum(abar * r * nxny**2 / pairs["lub_gap"]) / area,
            np.sum(1.0 / pairs["lub_gap"]) / n_particles,
            2.0 * np.sum(pairs["xi"] < 0.05) / n_particles,
        ]
    )


NODE_FEATURES = 2  # columns of node_features: the one-hot radius


# how far a radius may lie from its species' size (relative) for the one-hot species input: real
# particles and estimated radii (rheograph.graphs.radii_estimate) spread by up to ~20 % about their species
SPECIES_BAND = 0.3


def species_size(radii, size_ratio: float) -> np.ndarray:
    """The size (N,) [a] of each particle's species, 1 or ``size_ratio``: the one nearer its radius on a
    log scale (the species the one-hot input gives it)."""
    return np.where(np.asarray(radii, dtype=np.float64) > np.sqrt(size_ratio), size_ratio, 1.0)


def node_features(radii, size_ratio):
    """One-hot species (N, 2): column 0 small (a = 1), column 1 large (a = size_ratio), each radius
    assigned to the species nearer on a log scale (radii spread about their species' size, such as a
    polydisperse sample's or estimated ones, keep their species; the edges and physics inputs read the
    radii themselves).  A radius farther than SPECIES_BAND from both sizes is refused."""
    radii = np.asarray(radii, dtype=np.float64)
    nearest = species_size(radii, size_ratio)
    large = nearest == size_ratio
    outside = np.abs(radii / nearest - 1.0) > SPECIES_BAND
    if np.any(outside):
        raise InputError(
            f"radii must lie within {SPECIES_BAND:.0%} of 1 or size_ratio={size_ratio} for the one-hot "
            f"species input (found {np.unique(np.round(radii[outside], 6))[:5].tolist()})"
        )
    return np.stack([~large, large], axis=1).astype(np.float32)


# ---- graph-level inputs ---------------------------------------------------------------------------
# Known for every snapshot of a run: log(sigma/sigma0), the imposed stress on a log scale (it spans
# 0.5-200), and phi for models pooled over area fractions.  Computed from the snapshot's positions and the
# imposed stress (COMPUTED_GRAPH_INPUTS): solve_viscosity (solve_viscosity() below, on the eta_r target's
# asinh scale) and frictional_coordination, 2 x (pairs whose normal spring force exceeds the critical
# load) / N — the CLM's frictional contacts counted, i.e. Z_mu itself: with the CLM, Z_mu is a count that
# positions and sigma fix exactly (tests/test_learning.py), not something to learn — and spring_pressure,
# the contact-spring pressure per imposed stress (2 pi / A) sum r a_bar overlap / delta_sigma on the Pi
# target's asinh scale: with k_n proportional to sigma it is what positions fix of Pi / sigma.
# A relaxed snapshot (relax_positions) adds what the relaxation itself measured (RELAXED_GRAPH_INPUTS): the
# instantaneous eta_r of its last step (``relaxed_viscosity``) and of its first step past a quarter of the
# strain (``relaxed_viscosity_early``), both on the eta_r target's asinh scale, the particle pressure per
# imposed stress of its last step (``relaxed_pressure``, on the Pi target's asinh scale) and its counted
# frictional contacts (``relaxed_coordination``, 2 x frictional / N).  Unlike the one-solve, whose
# tangential springs start unstretched, these steps carry the springs the relaxation has loaded: at
# phi = 0.76, N = 400, after noise of 0.001 a and a 0.01 strain, the last step's eta_r scores R^2 log
# eta_r 0.984 against the snapshot's recorded eta_r once one mean offset is removed (the one-solve of
# the same relaxed positions: 0.968), and on exact positions the early one 0.999 with no offset
# (docs/validation/position_noise.md, "What the relaxation measures").
COMPUTED_GRAPH_INPUTS = ("solve_viscosity", "frictional_coordination", "spring_pressure")
RELAXED_GRAPH_INPUTS = (
    "relaxed_viscosity",
    "relaxed_viscosity_early",
    "relaxed_pressure",
    "relaxed_coordination",
)

# Structure that survives imprecise positions (the imaging inputs): pair statistics in gap shells
# h < w whose widths w [a] reach above the position noise, instead of overlaps of ~1e-3 a.  Per shell:
# ``shell_pairs_w`` = 2 x pairs / N (a coordination number counted to the shell), ``shell_fabric_w`` =
# mean n_x n_y of its pairs (the shear anisotropy of the near-contact network: negative along the
# compressive axis of the flow) and ``shell_normal_w`` = mean n_x^2 - n_y^2 (its normal-stress
# anisotropy).  A Gaussian noise of eps per coordinate blurs a gap by about 2 eps (its difference
# along n has standard deviation sqrt(2) eps), so a shell keeps its meaning while w >~ 2 eps; the network
# is told eps (``position_noise``) and learns which shells to trust.
SHELL_WIDTHS = (0.01, 0.03, 0.1, 0.3)
SHELL_INPUTS = tuple(f"shell_{kind}_{w:g}" for w in SHELL_WIDTHS for kind in ("pairs", "fabric", "normal"))
# known conditions of a snapshot: log(sigma/sigma0), phi, and the RMS position error per coordinate [a]
# (0 for simulator output; an experimenter's tracking precision), in 3D also the RMS error along the
# microscope's optical axis (``axial_noise``: confocal tracking is several times coarser in depth)
KNOWN_GRAPH_INPUTS = ("log_stress", "phi", "position_noise", "axial_noise")
GRAPH_INPUTS = (*KNOWN_GRAPH_INPUTS, *COMPUTED_GRAPH_INPUTS, *RELAXED_GRAPH_INPUTS, *SHELL_INPUTS)


def shell_inputs(pairs: dict, n_particles: int) -> dict:
    """The ``SHELL_INPUTS`` of one snapshot from the pair dict of ``snapshot_pairs`` (whose cutoff must
    reach the widest shell)."""
    gap = pairs["xi"] * pairs["abar"]  # surface gap h [a]
    nxny = pairs["nx"] * pairs["ny"]
    normal = pairs["nx"] ** 2 - pairs["ny"] ** 2
    out = {}
    for w in SHELL_WIDTHS:
        inside = gap < w
        count = int(inside.sum())
        out[f"shell_pairs_{w:g}"] = 2.0 * count / n_particles
        out[f"shell_fabric_{w:g}"] = float(nxny[inside].mean()) if count else 0.0
        out[f"shell_normal_{w:g}"] = float(normal[inside].mean()) if count else 0.0
    return out


def solve_viscosity(positions, radii, lx, ly, le_offset, params: dict, passes: int = 2) -> float:
    """Relative viscosity eta_r [-] of one stress-controlled resistance solve on a snapshot.

    What the simulator's implicit step (rheograph.sim.integrator) computes from the positions (N, 2) [a]
    and the run's parameters ``params`` (imposed stress, k_n, mu, ...) alone: lubrication from the gaps,
    normal contact springs from the overlaps, the CLM's frictional contacts from the normal loads, the
    tangential springs unstretched (their history is not in a snapshot) but the stick contacts resisting
    through the implicit scheme's stiffness dt k_t — which is what makes a frictional network rigid in
    one solve.  The shear rate is the one that meets the imposed stress exactly, eta_r = sigma / shear
    rate.  dt is set as a running simulation sets it: each of ``passes`` solves assumes DT_GROWTH x the dt
    the previous one would step with (the first, the simulator's start value disp_max).  Measured at
    phi = 0.70, N = 400 (600 snapshots): its within-state fluctuation correlates with the recorded eta_r
    at 0.92 after one pass, 0.944 after two, 0.946 after three; with the recorded springs, 0.978 (a
    one-off measurement; the reproducible effect: docs/validation/surrogate_accuracy.md, the contact history).
    """
    sim_params, sim = snapshot_simulation(positions, radii, (lx, ly, le_offset), params)
    return one_solve_viscosity(sim_params, sim.solve_configuration(passes))


def snapshot_simulation(positions, radii, box, params: dict, solver="auto") -> tuple[SimParams, Simulation]:
    """A stress-controlled implicit ``Simulation`` started from one snapshot (no contact history):
    positions (N, 2) [a], box = (lx, ly, le_offset) [a], ``params`` the run's parameter mapping,
    ``solver`` its sparse solver (``rheograph.sim.solver``)."""
    lx, ly, le_offset = box
    sim_params = SimParams.from_mapping({**params, "integrator": "implicit", "control": "stress"})
    snapshot = SimState(
        positions=np.array(positions, dtype=np.float64),
        radii=np.asarray(radii, dtype=np.float64),
        lx=lx,
        ly=ly,
        le_offset=le_offset,
    )
    return sim_params, Simulation(sim_params, snapshot, solver)


def one_solve_viscosity(sim_params, result) -> float:
    """eta_r = sigma / shear rate of a snapshot's one solve (``result``, the last pass's step)."""
    if result.shear_rate == 0.0:
        raise InputError("solve_viscosity: the snapshot's resistance solve gives a zero shear rate")
    return sim_params.stress / result.shear_rate


# Step budget of relax_positions: a flowing packing shears 0.01 strain in 50-90 steps at N = 400 (phi
# 0.76-0.78, sigma/sigma0 0.5-200, after noise of 0.01 a); an arrested one (phi = 0.80 at sigma/sigma0 =
# 200) creeps, ~2000 steps; one that does not move at all would never get there.
RELAX_MAX_STEPS = 4000


def _viscosity(stress: float, shear_rate: float) -> float:
    """eta_r = sigma / shear rate of a stress-controlled step; a packing that does not move at all has
    none, and the (finite) largest float stands for it."""
    return stress / shear_rate if shear_rate else math.copysign(np.finfo(np.float64).max, stress)


class Relaxation(NamedTuple):
    """What ``relax_positions`` returns: the relaxed ``positions`` (N, 2) [a], the Lees–Edwards
    ``le_offset`` [a] and the ``strain`` reached, and the observables the relaxation measured on the way
    (each a resistance solve at the imposed stress with the tangential springs it has loaded):
    ``viscosity`` eta_r [-], ``pressure`` Pi [sigma0] and ``z_mu`` (2 x frictional contacts / N) of the
    relaxed configuration itself, and ``viscosity_early``, eta_r at the first step past a quarter of the
    strain."""

    positions: np.ndarray
    le_offset: float
    strain: float
    viscosity: float
    pressure: float
    z_mu: float
    viscosity_early: float


def relax_positions(
    positions, radii, lx, ly, le_offset, params: dict, strain: float = 0.01, max_steps: int | None = None
) -> Relaxation:
    """A snapshot sheared by ``strain`` under the run's own dynamics at its imposed stress (``params`` as
    for ``solve_viscosity``, disp_max included), or as far as ``max_steps`` (default ``RELAX_MAX_STEPS``)
    steps take an arrested packing (the strain reached then falls short, and callers flag it).

    A projection of an imprecise configuration onto one the contact model can hold: Gaussian position
    noise of eps creates overlaps of ~eps, far beyond the ~delta_sigma = 9e-4 a the springs sustain at
    the imposed stress, and opens contacts that carried load; a short stretch of the flow pushes the
    false overlaps apart and lets the load-bearing ones close, after which the exact inputs (one-solve,
    loads, spring sum) read a configuration with physical overlaps again.  The flow also moves the
    configuration on (its correlation strain is ~0.08 at phi >= 0.76), so ``strain`` trades what is
    repaired against what is forgotten.  The repair takes more strain in looser packings: after noise of
    0.01 a the largest overlap is back at the simulator's own after 0.01 strain at phi = 0.76 (N = 400)
    and after 0.05 at phi = 0.72 (tests/test_imaging.py)."""
    _, sim = snapshot_simulation(positions, radii, (lx, ly, le_offset), params)
    return relax_simulations([sim], strain, max_steps, particle_pressure)[0]


def relax_simulations(
    sims: list[SimulationBase], strain: float, max_steps: int | None, pressure, solve_batch=own_solvers
) -> list[Relaxation]:
    """``relax_positions`` of fresh stress-controlled simulations ``sims`` of either dimension, stepped
    together (``step_together``: ``solve_batch`` solves their linear problems, by default each its own
    sparse solver); ``pressure`` maps a recorded ``StepResult`` to Pi [sigma0].  Each simulation stops
    at ``strain`` or after the step budget, as it would alone."""
    viscosity_early = [math.nan] * len(sims)
    moving = list(range(len(sims)))
    for _ in range(RELAX_MAX_STEPS if max_steps is None else max_steps):
        moving = [k for k in moving if sims[k].state.strain < strain]
        if not moving:
            break
        results = step_together([sims[k] for k in moving], solve_batch)
        for k, result in zip(moving, results):
            if math.isnan(viscosity_early[k]) and sims[k].state.strain >= 0.25 * strain:
                viscosity_early[k] = _viscosity(sims[k].params.stress, result.shear_rate)
    relaxed = [
        (sim.state.positions.copy(), float(sim.state.le_offset), float(sim.state.strain)) for sim in sims
    ]
    # the observables of the relaxed configurations: one more solve, whose move is discarded
    results = step_together(sims, solve_batch, record=True)
    relaxations = []
    for sim, state, early, result in zip(sims, relaxed, viscosity_early, results):
        stress = sim.params.stress
        if math.isnan(early):  # a creeping packing short of a quarter of the strain
            early = _viscosity(stress, result.shear_rate)
        relaxations.append(
            Relaxation(
                *state,
                viscosity=_viscosity(stress, result.shear_rate),
                pressure=pressure(result),
                z_mu=2.0 * result.n_frictional / sim.state.radii.size,
                viscosity_early=early,
            )
        )
    return relaxations


# ---- target transforms ---------------------------------------------------------------------------
# eta_r and Pi are learned on a log-like scale.  Pi can be <= 0 at low stress (and eta_r < 0 when the
# instantaneous shear rate reverses near jamming), where log is undefined; asinh(x / s) is defined on all
# reals, odd, invertible, and equals log(2 x / s) + O((s/x)^2) for x >> s, i.e. the paper's log scaling
# up to a constant once x is a few s.


def forward_transform(value, scale):
    return np.arcsinh(np.asarray(value, dtype=np.float64) / scale)


def inverse_transform(value, scale):
    return np.sinh(np.asarray(value, dtype=np.float64)) * scale
