"""Random initial configuration relaxed to no overlap with soft frictionless springs (no shear)."""

import numpy as np
from numba import njit

from rheograph.errors import StatePointError
from rheograph.sim.geometry import minimum_image, neighbour_pairs, wrap_positions
from rheograph.sim.radii import bidisperse_radii


@njit(cache=True)
def _overlap_step(pos, radii, pair_i, pair_j, lx, ly, step):
    """One gradient-descent step on E = 1/2 sum overlap^2; returns the max overlap before the step."""
    disp = np.zeros_like(pos)
    max_overlap = 0.0
    for p in range(pair_i.shape[0]):
        i = pair_i[p]
        j = pair_j[p]
        dx, dy = minimum_image(pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], lx, ly, 0.0)
        r = np.sqrt(dx * dx + dy * dy)
        ov = radii[i] + radii[j] - r
        if ov > 0.0:
            max_overlap = max(max_overlap, ov)
            if r < 1e-12:  # coincident centres: push apart along x
                dx, dy, r = 1.0, 0.0, 1.0
            ux = dx / r
            uy = dy / r
            disp[i, 0] -= step * ov * ux
            disp[i, 1] -= step * ov * uy
            disp[j, 0] += step * ov * ux
            disp[j, 1] += step * ov * uy
    pos += disp
    return max_overlap


def random_configuration(
    n_small: int,
    n_large: int,
    size_ratio: float,
    box_length: float,
    seed: int,
    tolerance: float = 1e-4,
    min_gap: float = 0.01,
    max_iterations: int = 200_000,
    radii: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Uniform random centres in the square box, overlaps removed by overdamped soft repulsion.

    Relaxation runs with radii inflated by (1 + min_gap) (as LF_DEM's generator does; less above an
    area fraction of 0.80), so that the configuration starts with open gaps rather than a crowd of
    marginal contacts.

    Returns (positions (N, 2), radii (N,)).  Raises StatePointError if the overlaps cannot be relaxed
    below ``tolerance`` (the area fraction is above random close packing).
    """
    rng = np.random.default_rng(seed)
    # ``radii`` (N,): any radii (``rheograph.sim.radii``); None: bidisperse (n_small, n_large, size_ratio)
    true_radii = bidisperse_radii(n_small, n_large, size_ratio) if radii is None else np.asarray(radii)
    # inflate, but never beyond an area fraction of 0.80, which soft spheres still relax quickly
    phi = np.pi * np.sum(true_radii**2) / box_length**2
    inflate = min(1.0 + min_gap, max(1.0, np.sqrt(0.80 / phi)))
    radii = true_radii * inflate
    pos = (rng.random((radii.shape[0], 2)) - 0.5) * box_length
    edges = (float(box_length), float(box_length))
    kernels = (neighbour_pairs, _overlap_step, wrap_positions)
    relax_overlaps(pos, radii, edges, kernels, tolerance, max_iterations, phi, "area fraction", "jamming")
    return pos, true_radii


def relax_overlaps(pos, radii, edges, kernels, tolerance, max_iterations, phi, fraction, packing) -> None:
    """Remove the overlaps of particles of ``radii`` (N,) at ``pos`` (N, d) [a] in place by gradient
    descent on E = 1/2 sum overlap^2, in an unsheared periodic box of ``edges`` (d,) [a]; any dimension
    d, whose kernels are ``kernels`` = (neighbour_pairs(pos, radii, *edges, le_offset, gap, skin),
    overlap_step(pos, radii, pair_i, pair_j, *edges, step), wrap_positions(pos, *edges, le_offset)).

    Done when the largest overlap, checked on a fresh neighbour list, is below ``tolerance`` [a]; raises
    StatePointError after ``max_iterations`` steps, naming the ``fraction`` ``phi`` and that it is too
    close to ``packing``.
    """
    neighbour_pairs, overlap_step, wrap_positions = kernels
    max_overlap = np.inf
    pairs = None
    for it in range(max_iterations):
        # large early overlaps move particles far: rebuild every step until they are small
        if pairs is None or max_overlap > 0.02 or it % 10 == 0:
            pairs = neighbour_pairs(pos, radii, *edges, 0.0, 0.0, 0.5)
        max_overlap = overlap_step(pos, radii, pairs[0], pairs[1], *edges, 0.25)
        wrap_positions(pos, *edges, 0.0)
        if max_overlap < tolerance:
            fresh = neighbour_pairs(pos, radii, *edges, 0.0, 0.0, 0.5)
            if overlap_step(pos.copy(), radii, fresh[0], fresh[1], *edges, 0.0) < tolerance:
                return
            pairs = fresh
    raise StatePointError(
        f"sim.phi: could not relax the initial configuration at {fraction} {phi:.4g}: max overlap "
        f"{max_overlap:.2e} > sim.relax_tolerance={tolerance:.1e} after {max_iterations} iterations "
        f"(too close to {packing}: lower sim.phi or raise sim.relax_tolerance)"
    )


def initial_configuration(params, generator=random_configuration) -> tuple[np.ndarray, np.ndarray, float]:
    """The start of a state point: (positions (N, 2), radii (N,), box length) for a ``SimParams``, from its
    seed — what ``Simulation(params)`` starts from, and what the LF_DEM comparison writes for LF_DEM.
    ``generator``: the dimension's ``random_configuration`` (``init_config3d``'s for (N, 3) in a cube)."""
    n_small, n_large = params.species_counts()
    box = params.box_length()
    pos, radii = generator(
        n_small,
        n_large,
        params.size_ratio,
        box,
        params.seed,
        params.relax_tolerance,
        params.initial_min_gap,
        radii=params.particle_radii(),
    )
    return pos, radii, box
