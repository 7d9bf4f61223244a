"""Sparse resistance matrix R_FU of the 3D problem, upper-triangular CSC, assembled into its data array.

Degrees of freedom: 6 per particle, ordered [U_0 (3), w_0 (3), U_1 (3), ...].  The pattern is
``rheograph.sim.assembly.build_pattern(pair_i, pair_j, n, block=6)``: the 6x6 diagonal blocks (upper
part) and one 6x6 block (rows of i, columns of j) per candidate pair of the neighbour list, explicit
zeros for pairs that do not interact this step, so the symbolic factorisation lives as long as the list.
"""

import numpy as np
from numba import njit

from rheograph.sim.lubrication3d import contact_block, one_body_resistance, pair_block, strain_force

# the imposed rate of strain at unit shear rate (u = y e_x): E_xy = E_yx = 1/2
UNIT_STRAIN_RATE = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])


@njit(cache=True)
def _add_diag_block(data, indptr, slot, j, R, off):
    for q in range(6):
        base = indptr[6 * j + q] + slot
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
    e_unit,
):
    """Matrix data of R_FU and the unit-shear-rate right-hand side (6N,).

    R_FU = one-body Stokes drag + lubrication blocks (0 < xi < cut-off) + contact blocks (dashpot, plus
    dt * spring stiffness ``k_normal``, ``k_tangential`` per pair for the implicit integrator).  The
    right-hand side holds R_FE : E for lubricated pairs and, for contacts, -R_pair . (affine relative
    motion at unit rate), since the dashpot and the implicit springs act on the *total* relative motion:
    j moves by dy e_x relative to i and both rotate at -1/2 e_z.  ``e_unit`` (3, 3) is the rate of
    strain at unit shear rate (``UNIT_STRAIN_RATE``).
    """
    n = radii.shape[0]
    data = np.zeros(nnz)
    rhs_rate = np.zeros(6 * n)
    R = np.empty((12, 12))  # scratch block and strain force, reused for every pair
    g = np.empty(12)
    for j in range(n):
        a = radii[j]
        for q in range(6):
            base = indptr[6 * j + q] + diag_slot[j]
            data[base + q] += one_body_resistance(a, q)
    for p in range(pair_i.shape[0]):
        if not active[p]:
            continue
        i = pair_i[p]
        j = pair_j[p]
        n_p = nvec[p]
        if in_contact[p]:
            contact_block(coeff[p], n_p, radii[i], radii[j], k_normal[p], k_tangential[p], R)
        else:
            pair_block(coeff[p], n_p, R)
        _add_diag_block(data, indptr, diag_slot[i], i, R, 0)
        _add_diag_block(data, indptr, diag_slot[j], j, R, 6)
        for q in range(6):
            base = indptr[6 * j + q] + pair_slot[p]
            for r in range(6):
                data[base + r] += R[r, 6 + q]
        if in_contact[p]:
            for r in range(12):
                f = -(R[r, 6] * dy[p] + R[r, 5] * -0.5 + R[r, 11] * -0.5)
                if r < 6:
                    rhs_rate[6 * i + r] += f
                else:
                    rhs_rate[6 * j + r - 6] += f
        else:
            strain_force(coeff[p], n_p, e_unit, g)
            for r in range(6):
                rhs_rate[6 * i + r] += g[r]
                rhs_rate[6 * j + r] += g[6 + r]
    return data, rhs_rate
