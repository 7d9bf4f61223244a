"""Particle radii estimated from a dense configuration, for snapshots whose individual sizes are unknown.

A microscope locates particles but does not measure each radius, and real particles spread in size by
several per cent about their species' nominal radius.  In a dense sheared suspension most particles
touch or nearly touch their neighbours (lubricated gaps of ~1e-3-1e-2 a, contact overlaps of ~1e-3 a),
so the centre distance of a near pair is a_i + a_j to within such a gap: with a few near neighbours per
particle, the radii follow from the distances by least squares.  The pairs are selected by their gap
under the current estimate, in a shell that narrows as the estimate improves (the nominal radii are off
by the spread, ~0.1 a at 10 %, so the first shell must be wider than that); a ridge term keeps each radius
near its nominal value where its neighbours do not fix it (a rattler, a particle without near
neighbours); the result is scaled uniformly so that the radii give the sample's stated area (volume)
fraction, which removes the small bias of the gaps.  On the committed polydisperse runs (N = 400, φ 0.76)
one snapshot's estimate cuts the radii's error to a third or less: 4.2 % → 1.1–1.4 % RMS at a 5 %
spread, 8.5 % → 2.1–2.7 % at 10 % (``tests/test_radii.py``); the mean over a trajectory's 20 steady
snapshots, 0.6 % and 1.7 %.  The floor, from the gaps, is ~1 % (1.2 % on an exactly bidisperse snapshot).

A radius error acts on the gaps as position noise of the same size (``declared_precision``), and a model
that reads the positions' precision is told the two combined, the radii's uncertainty measured from the
estimates' scatter over a trajectory (``estimate_scatter``).  One snapshot's estimate is fitted to that
snapshot's own gaps: it sets its near pairs to about equal gaps, so its contacts open (on the 5 % runs at
σ/σ0 = 100, 0.7 overlapping pairs per particle against the true 2.3) and a model reads a looser
suspension than there is.  The mean over a trajectory is fitted mostly to other configurations than the
one it is applied to, and its error acts as noise (1.2 overlapping pairs per particle there, with half
the error).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spl

from rheograph.errors import InputError
from rheograph.graphs.features import species_size
from rheograph.io.configurations import Snapshots
from rheograph.sim import geometry, geometry3d

# gap shells [a] of the successive least-squares passes: the first wider than the radii's spread
SHELLS = (0.2, 0.1, 0.05, 0.02, 0.02)
# weight of each radius's pull towards its nominal value, against one near pair's distance equation
RIDGE = 0.1


def near_pairs(positions, radii, box, shell: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(i, j, centre distance) [a] of the pairs whose surface gap under ``radii`` is below ``shell`` [a];
    ``box`` (lx, ly, le_offset) in 2D, (lx, ly, lz, le_offset) in 3D."""
    if positions.shape[1] == 3:
        lx, ly, lz, offset = box
        i, j = geometry3d.neighbour_pairs(positions, radii, lx, ly, lz, offset, 0.0, shell)
        _, distance, _, _ = geometry3d.pair_geometry(positions, radii, i, j, lx, ly, lz, offset)
    else:
        lx, ly, offset = box
        i, j = geometry.neighbour_pairs(positions, radii, lx, ly, offset, 0.0, shell)
        _, distance, _, _ = geometry.pair_geometry(positions, radii, i, j, lx, ly, offset)
    near = distance - radii[i] - radii[j] < shell
    return i[near], j[near], distance[near]


def estimate_radii(positions, nominal, box, phi: float) -> np.ndarray:
    """Each particle's radius [a] (N,) estimated from the configuration (module docstring).

    ``positions`` (N, 2) or (N, 3) [a], wrapped into the box; ``nominal`` (N,) the radii of the particles'
    species [a] (what the sample's recipe says); ``box`` (lx, ly, le_offset) or (lx, ly, lz, le_offset)
    [a]; ``phi`` the sample's area (volume) fraction, which the estimate is scaled to give."""
    positions = np.ascontiguousarray(positions, dtype=np.float64)
    nominal = np.asarray(nominal, dtype=np.float64)
    dim = positions.shape[1]
    if nominal.shape != (positions.shape[0],) or not np.all(nominal > 0) or not 0 < phi < 1:
        raise InputError(
            f"estimate_radii: nominal radii (N,) > 0 for N = {positions.shape[0]} positions and 0 < phi < 1 "
            f"are needed (found {nominal.shape} radii, phi = {phi:g})"
        )
    n = nominal.size
    radii = nominal.copy()
    for shell in SHELLS:
        i, j, distance = near_pairs(positions, radii, box, shell)
        rows = np.arange(i.size)
        # one equation a_i + a_j = r_ij per near pair, plus the ridge pull towards the nominal radii
        incidence = sp.csr_matrix((np.ones(2 * i.size), (np.r_[rows, rows], np.r_[i, j])), shape=(i.size, n))
        normal = (incidence.T @ incidence + RIDGE * sp.identity(n)).tocsc()
        radii = spl.spsolve(normal, incidence.T @ distance + RIDGE * nominal)
    volume = np.prod(box[:dim])
    measure = np.pi * np.sum(radii**2) if dim == 2 else 4.0 * np.pi / 3.0 * np.sum(radii**3)
    return radii * (phi * volume / measure) ** (1.0 / dim)


def species_spread(radii, size_ratio: float) -> float:
    """RMS relative deviation of ``radii`` (N,) [a] from their species' sizes, 1 and ``size_ratio`` (each
    radius taken as of the species nearer on a log scale, as the one-hot species input takes it)."""
    radii = np.asarray(radii, dtype=np.float64)
    return float(np.sqrt(np.mean((radii / species_size(radii, size_ratio) - 1.0) ** 2)))


def estimate_scatter(estimates) -> float:
    """RMS deviation [a] of single-snapshot radius estimates (S, N) from their mean over the S >= 2
    snapshots (unbiased: x S / (S - 1)), the estimates of the same particles in the same order.

    What one snapshot's estimate is uncertain by: its error comes from the gaps of that snapshot's near
    pairs, which change as the suspension flows, so its scatter over a trajectory measures it without
    the true radii.  On the committed polydisperse runs (the 20 snapshots at strain >= 1 of each) it is
    0.011-0.013 a against a true RMS error of 0.012-0.014 a at a 5 % spread, 0.019-0.023 a against
    0.027-0.029 a at 10 % (part of the error there persists: below).  The mean's error is 0.006 a at 5 %
    but 0.019-0.021 a at 10 %, about the scatter: what persists from snapshot to snapshot (a particle's
    environment; a radius so far off its nominal value that the first shell misses its neighbours, 2-3 %
    of the particles at 10 %) does not average out and cannot be seen in the scatter."""
    estimates = np.asarray(estimates, dtype=np.float64)
    if estimates.ndim != 2 or estimates.shape[0] < 2:
        raise InputError(
            f"estimate_scatter: estimates of at least 2 snapshots (S, N) are needed (found shape "
            f"{estimates.shape})"
        )
    deviation = estimates - estimates.mean(axis=0)
    return float(np.sqrt(np.sum(deviation**2) / (deviation.size - estimates.shape[1])))


def declared_precision(stated, radii_uncertainty: float):
    """The position precision [a] (RMS per coordinate) to tell a model reading estimated radii: the
    positions' own ``stated`` precision (one for all snapshots, or (S,)) and the radii's RMS uncertainty
    [a] in quadrature.

    An error d_i in a radius shifts the surface gap of each pair (i, j) by -(d_i + d_j), variance
    2 s**2 for independent errors of RMS s; noise of eps per coordinate in the positions shifts it by the
    difference of two displacements along the pair's normal, variance 2 eps**2.  So radii uncertain by s
    blur the gaps as positions uncertain by eps = s do.  None (precision not stated) stays None: a model
    that reads the precision then asks for it."""
    if stated is None:
        return None
    combined = np.hypot(stated, radii_uncertainty)
    return float(combined) if np.ndim(combined) == 0 else combined


def snapshots_with_estimated_radii(snaps: Snapshots, mean: bool = False) -> tuple[list[Snapshots], float]:
    """(``snaps`` with radii estimated from the configurations (``estimate_radii``), the RMS uncertainty
    [a] of the radii given them).  The radii ``snaps`` holds are taken as each particle's species' nominal
    radius (1 or its size ratio; other radii are refused) and its ``phi`` the sample's (measured)
    fraction, which the estimates are scaled to give.  One single-snapshot copy per snapshot, each
    with its own estimate; with ``mean``, one copy of all the snapshots with the mean estimate over them.
    Either way the snapshots must show the same particles in the same order (a simulation's, or linked
    tracks): the uncertainty is the estimates' scatter over them (``estimate_scatter``; at least 2
    snapshots), and the copies' stated position precision (and axial one, 3D) is combined with it
    (``declared_precision``), so that a model reading the precision reads the radii's error as the
    position noise it equals."""
    size_ratio = float(snaps.params.get("size_ratio", snaps.radii.max()))
    if species_spread(snaps.radii, size_ratio) > 1e-9:
        raise InputError(
            f"{snaps.source}: estimating the radii starts from each particle's species' nominal radius (1 or "
            f"the size ratio {size_ratio:g}); these radii spread about them: give the nominal radii"
        )
    if len(snaps) < 2:
        raise InputError(
            f"{snaps.source}: holds {len(snaps)} snapshot(s); the estimated radii's uncertainty is measured "
            "from their scatter over snapshots of the same particles: give at least 2 (a trajectory or "
            "linked tracks)"
        )
    boxes = [
        (snaps.lx, snaps.ly, *(() if snaps.lz is None else (snaps.lz,)), float(offset))
        for offset in snaps.le_offset
    ]
    estimates = [estimate_radii(p, snaps.radii, box, snaps.phi) for p, box in zip(snaps.positions, boxes)]
    uncertainty = estimate_scatter(estimates)
    precision = {"position_noise": declared_precision(snaps.position_noise, uncertainty)}
    if snaps.axial_noise is not None:
        precision["axial_noise"] = declared_precision(snaps.axial_noise, uncertainty)
    # the copies' radii are estimates of each particle's own, no longer the nominal ones
    declared = dataclasses.replace(snaps, radii_nominal=False, **precision)
    if mean:
        parts = [dataclasses.replace(declared, radii=np.mean(estimates, axis=0), contacts=None)]
    else:
        parts = [
            dataclasses.replace(declared.select(slice(k, k + 1)), radii=radii)
            for k, radii in enumerate(estimates)
        ]
    return parts, uncertainty
