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
    n = radii.shape[0]
    pos = (rng.random((n, 2)) - 0.5) * box_length
    lx = ly = float(box_length)
    max_overlap = np.inf
    pairs = None
    for it in range(max_iterations):
        # large early overlaps move particles far: rebuild every step until they are small
        if pairs is None or max_overlap > 0.02 or it % 10 == 0:
            pairs = neighbour_pairs(pos, radii, lx, ly, 0.0, 0.0, 0.5)
        max_overlap = _overlap_step(pos, radii, pairs[0], pairs[1], lx, ly, 0.25)
        wrap_positions(pos, lx, ly, 0.0)
        if max_overlap < tolerance:
            fresh = neighbour_pairs(pos, radii, lx, ly, 0.0, 0.0, 0.5)
            if _overlap_step(pos.copy(), radii, fresh[0], fresh[1], lx, ly, 0.0) < tolerance:
                return pos, true_radii
            pairs = fresh
    raise StatePointError(
        f"sim.phi: could not relax the initial configuration at area fraction {phi:.4g}: max overlap "
        f"{max_overlap:.2e} > sim.relax_tolerance={tolerance:.1e} after {max_iterations} iterations "
        "(too close to jamming: lower sim.phi or raise sim.relax_tolerance)"
    )


def initial_configuration(params) -> tuple[np.ndarray, np.ndarray, float]:
    """The start of a state point: (positions (N, 2), radii (N,), box length) for a ``SimParams``, from its
    seed — what ``Simulation(params)`` starts from, and what the LF_DEM comparison writes for LF_DEM."""
    n_small, n_large = params.species_counts()
    box = params.box_length()
    pos, radii = random_configuration(
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
