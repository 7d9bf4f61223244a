"""Sparse resistance matrix R_FU in upper-triangular CSC form, assembled straight into its data array.

Degrees of freedom: 3 per particle, ordered [Ux_0, Uy_0, w_0, Ux_1, ...] (``assembly3d`` uses the same
pattern with 6).  The sparsity pattern holds the 3x3 diagonal blocks (upper part) and one 3x3 block (rows
of i, columns of j) for every candidate pair i < j of the neighbour list; candidate pairs that do not
interact this step hold explicit zeros, so the pattern (and the symbolic factorisation) survives until
the neighbour list is rebuilt.
"""

import numpy as np
from numba import njit

from rheograph.sim.lubrication import contact_block, pair_block, strain_force


@njit(cache=True)
def build_pattern(pair_i, pair_j, n_particles, block=3):
    """CSC pattern (indptr, indices) of the upper triangle and, per pair, the slot of its block in a column.

    ``block`` is the number of degrees of freedom per particle (3 in 2D, 6 in 3D).  Pairs must be sorted
    by (j, i).  For pair p = (i, j) the entry (b i + r, b j + q) lives at ``indptr[b j + q] + pair_slot[p]
    + r``; particle j's diagonal entry (b j + r, b j + q), r <= q, lives at ``indptr[b j + q] +
    diag_slot[j] + r``.
    """
    ndof = block * n_particles
    count = np.zeros(n_particles, dtype=np.int64)
    npair = pair_i.shape[0]
    pair_slot = np.empty(npair, dtype=np.int64)
    for p in range(npair):
        j = pair_j[p]
        pair_slot[p] = block * count[j]
        count[j] += 1
    indptr = np.empty(ndof + 1, dtype=np.int64)
    indptr[0] = 0
    for j in range(n_particles):
        for q in range(block):
            indptr[block * j + q + 1] = indptr[block * j + q] + block * count[j] + q + 1
    indices = np.empty(indptr[ndof], dtype=np.int64)
    diag_slot = block * count
    for p in range(npair):
        i = pair_i[p]
        j = pair_j[p]
        for q in range(block):
            base = indptr[block * j + q] + pair_slot[p]
            for r in range(block):
                indices[base + r] = block * i + r
    for j in range(n_particles):
        for q in range(block):
            base = indptr[block * j + q] + diag_slot[j]
            for r in range(q + 1):
                indices[base + r] = block * j + r
    return indptr, indices.astype(np.int32), pair_slot, diag_slot


@njit(cache=True)
def _add_diag_block(data, indptr, slot, j, R, off):
    for q in range(3):
        base = indptr[3 * j + q] + slot
        for r in range(q + 1):
            data[base + r] += R[off + r, off + q]


@njit(cache=True)
def assemble_resistance(
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
):
    """Matrix data of R_FU and the unit-shear-rate right-hand side.

    R_FU = one-body Stokes drag + lubrication blocks (0 < xi < gap cut-off) + contact-dashpot blocks (in
    contact).  The unit-rate right-hand side (length 3N) holds R_FE : E_hat for lubricated pairs and, for
    dashpots, -R_pair . (affine relative motion at unit rate), because the dashpot acts on the *total*
    relative velocity.  E_hat has E_xy = E_yx = 1/2 and the affine rotation is -1/2 about z.
    Contact blocks include dt * spring stiffness (``k_normal``, ``k_tangential`` per pair) for the linearly
    implicit integrator (zeros for explicit Euler); like the dashpot, they act on the total motion.
    """
    n = radii.shape[0]
    data = np.zeros(nnz)
    rhs_rate = np.zeros(3 * n)
    R = np.empty((6, 6))  # scratch block and strain force, reused for every pair
    g = np.empty(6)
    for j in range(n):
        a = radii[j]
        for q in range(3):
            base = indptr[3 * j + q] + diag_slot[j]
            if q < 2:
                data[base + q] += a
            else:
                data[base + 2] += (4.0 / 3.0) * a * a * a
    for p in range(pair_i.shape[0]):
        if not active[p]:
            continue
        i = pair_i[p]
        j = pair_j[p]
        nx = nvec[p, 0]
        ny = nvec[p, 1]
        if in_contact[p]:
            contact_block(coeff[p], nx, ny, radii[i], radii[j], k_normal[p], k_tangential[p], R)
        else:
            pair_block(coeff[p], nx, ny, R)
        _add_diag_block(data, indptr, diag_slot[i], i, R, 0)
        _add_diag_block(data, indptr, diag_slot[j], j, R, 3)
        for q in range(3):
            base = indptr[3 * j + q] + pair_slot[p]
            for r in range(3):
                data[base + r] += R[r, 3 + q]
        if in_contact[p]:
            # affine motion at unit rate: j moves by dy e_x relative to i, both rotate at -1/2
            for r in range(6):
                f = -(R[r, 3] * dy[p] + R[r, 2] * -0.5 + R[r, 5] * -0.5)
                if r < 3:
                    rhs_rate[3 * i + r] += f
                else:
                    rhs_rate[3 * j + r - 3] += f
        else:
            strain_force(coeff[p], nx, ny, 0.0, 0.5, 0.0, g)
            for r in range(3):
                rhs_rate[3 * i + r] += g[r]
                rhs_rate[3 * j + r] += g[3 + r]
    return data, rhs_rate


def dense_from_upper_csc(data, indices, indptr, ndof):
    """Dense symmetric matrix from the upper CSC arrays (for tests and debugging only)."""
    dense = np.zeros((ndof, ndof))
    for col in range(ndof):
        for k in range(indptr[col], indptr[col + 1]):
            row = indices[k]
            dense[row, col] += data[k]
            if row != col:
                dense[col, row] += data[k]
    return dense
