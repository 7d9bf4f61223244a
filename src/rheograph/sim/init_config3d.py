"""Random initial configuration of spheres in a cubic box, relaxed to no overlap (no shear)."""

import numpy as np
from numba import njit

from rheograph.sim import init_config
from rheograph.sim.geometry3d import minimum_image, neighbour_pairs, wrap_positions
from rheograph.sim.radii import bidisperse_radii

# inflated radii are capped at this volume fraction: soft spheres still relax quickly there
INFLATED_PHI_MAX = 0.60


@njit(cache=True)
def _overlap_step(pos, radii, pair_i, pair_j, lx, ly, lz, step):
    """One gradient-descent step on E = 1/2 sum overlap^2; returns the max overlap before the step."""
    disp = np.zeros_like(pos)
    max_overlap = 0.0
    for p in range(pair_i.shape[0]):
        i = pair_i[p]
        j = pair_j[p]
        dx, dy, dz = minimum_image(
            pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], pos[j, 2] - pos[i, 2], lx, ly, lz, 0.0
        )
        r = np.sqrt(dx * dx + dy * dy + dz * dz)
        ov = radii[i] + radii[j] - r
        if ov > 0.0:
            max_overlap = max(max_overlap, ov)
            if r < 1e-12:  # coincident centres: push apart along x
                dx, dy, dz, r = 1.0, 0.0, 0.0, 1.0
            for c, d in enumerate((dx, dy, dz)):
                disp[i, c] -= step * ov * d / r
                disp[j, c] += step * ov * d / r
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
    """Uniform random centres in the cube, overlaps removed by overdamped soft repulsion with radii
    inflated by (1 + min_gap) (less if that would exceed a volume fraction of ``INFLATED_PHI_MAX``), so
    that the start has open gaps rather than a crowd of marginal contacts.

    Returns (positions (N, 3), radii (N,)).  Raises StatePointError if the overlaps cannot be relaxed
    below ``tolerance`` (too close to random close packing).
    """
    rng = np.random.default_rng(seed)
    # ``radii`` (N,): any radii (``rheograph.sim.radii``); None: bidisperse (n_small, n_large, size_ratio)
    true_radii = bidisperse_radii(n_small, n_large, size_ratio) if radii is None else np.asarray(radii)
    phi = 4.0 * np.pi / 3.0 * np.sum(true_radii**3) / box_length**3
    inflate = min(1.0 + min_gap, max(1.0, (INFLATED_PHI_MAX / phi) ** (1.0 / 3.0)))
    radii = true_radii * inflate
    pos = (rng.random((radii.shape[0], 3)) - 0.5) * box_length
    edges = (float(box_length),) * 3
    kernels = (neighbour_pairs, _overlap_step, wrap_positions)
    init_config.relax_overlaps(
        pos, radii, edges, kernels, tolerance, max_iterations, phi, "volume fraction", "random close packing"
    )
    return pos, true_radii


def initial_configuration(params) -> tuple[np.ndarray, np.ndarray, float]:
    """The start of a 3D state point: (positions (N, 3), radii (N,), cube edge) for a ``SimParams3D``."""
    return init_config.initial_configuration(params, random_configuration)
