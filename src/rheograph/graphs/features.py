"""Graph features of a sheared-suspension snapshot (pure numpy/numba; no torch here).

Nodes are particles, with the one-hot of their radius (small, large) as features.  Edges join pairs whose
surface gap h = r - a_i - a_j is below ``cutoff`` (in units of the small radius a), found with the
Lees–Edwards images; both directions are present.  Edge features (seed paper): dimensionless gap
h / a_bar, centre distance r, its components (dx, dy), and sin, cos of its angle to the flow direction.
"""

from __future__ import annotations

import numpy as np

from rheograph.sim.geometry import neighbour_pairs, pair_geometry

EDGE_FEATURES = ("gap", "distance", "dx", "dy", "sin", "cos")


def snapshot_edges(positions, radii, lx, ly, le_offset, cutoff):
    """Directed edges (2, 2P) and per-edge geometry for pairs with gap < cutoff (units of a).

    Returns (edge_index, features dict of (2P,) arrays).  Edge k and k + P are the two directions of one
    pair; the vector of the second is the negative of the first.
    """
    pair_i, pair_j = neighbour_pairs(positions, radii, lx, ly, le_offset, 0.0, cutoff)
    nvec, r, xi, _ = pair_geometry(positions, radii, pair_i, pair_j, lx, ly, le_offset)
    gap = r - radii[pair_i] - radii[pair_j]
    keep = gap < cutoff
    pair_i, pair_j, nvec, r, xi = pair_i[keep], pair_j[keep], nvec[keep], r[keep], xi[keep]
    dx, dy = nvec[:, 0] * r, nvec[:, 1] * r
    edge_index = np.stack([np.r_[pair_i, pair_j], np.r_[pair_j, pair_i]])
    feats = {
        "gap": np.r_[xi, xi],
        "distance": np.r_[r, r],
        "dx": np.r_[dx, -dx],
        "dy": np.r_[dy, -dy],
        "sin": np.r_[nvec[:, 1], -nvec[:, 1]],
        "cos": np.r_[nvec[:, 0], -nvec[:, 0]],
    }
    return edge_index, feats


def node_features(radii, size_ratio):
    """One-hot (N, 2): column 0 small (a = 1), column 1 large (a = size_ratio)."""
    large = np.isclose(radii, size_ratio)
    small = np.isclose(radii, 1.0)
    if not np.all(large | small):
        raise ValueError("radii must be 1 or size_ratio for the one-hot node features")
    return np.stack([small, large], axis=1).astype(np.float32)


# ---- target transforms ---------------------------------------------------------------------------
# eta_r and Pi are learned on a log-like scale.  Pi can be <= 0 at low stress (and eta_r < 0 when the
# instantaneous shear rate reverses near jamming), where log is undefined; asinh(x / s) is defined on all
# reals, odd, invertible, and equals log(2 x / s) + O((s/x)^2) for x >> s, i.e. the paper's log scaling
# up to a constant once x is a few s.


def forward_transform(value, scale):
    return np.arcsinh(np.asarray(value, dtype=np.float64) / scale)


def inverse_transform(value, scale):
    return np.sinh(np.asarray(value, dtype=np.float64)) * scale
