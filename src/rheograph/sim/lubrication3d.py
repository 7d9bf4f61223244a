"""Pairwise lubrication resistance of two spheres in 3D: 12 x 12 blocks along any unit vector n.

The scalar functions (X^A, Y^A, Y^B, Y^C, X^G, Y^G, Y^H, X^M, Y^M, each with indices 11, 12, 21, 22) are
dimension independent: they come from ``rheograph.sim.lubrication.lubrication_resistance`` with the
same regularisation c = 1/(xi + delta), log factor ln c and cut-off as the 2D monolayer.  X^C (twist
about n) has no singular term and is left to the one-body rotational drag.

Units: resistances in 6 pi eta0 (one-body drag a_i on translation, 4 a_i^3 / 3 on rotation), lengths in
a, velocities in a * shear-rate unit.  With P = I - nn and N the matrix of n x (N v = n x v), the
force and torque on i and j from the non-affine motion (U, w) and the imposed strain rate E are

    F_i = -A_11 U_i - A_12 U_j - YB_11 n x w_i - YB_21 n x w_j + G_i
    T_i =  YB_11 n x U_i + YB_12 n x U_j - C_11 w_i - C_12 w_j + H_i
    F_j, T_j: the same with the rows 21, 22

where A_ab = XA_ab nn + YA_ab P and C_ab = YC_ab P.  In the plane z = const with w along z these are
the 2D code's equations term by term (n x (w e_z) = -w t, (n x U).e_z = U.t with t = e_z x n).
Degrees of freedom of a pair block: [U_i (3), w_i (3), U_j (3), w_j (3)].
"""

import numpy as np
from numba import njit

from rheograph.sim.lubrication import XA, XG, YA, YB, YC, YG, YH


@njit(cache=True)
def pair_block(coeff, n, R):
    """Fill ``R`` (12, 12) with the symmetric resistance block -d(F_i, T_i, F_j, T_j)/d(U_i, w_i, U_j, w_j)
    of one pair with unit normal ``n`` (3,) and coefficients ``coeff`` (36,), and return it."""
    for a in range(2):
        for b in range(2):
            k = 2 * a + b  # 11 -> 0, 12 -> 1, 21 -> 2, 22 -> 3
            xa = coeff[XA + k]
            ya = coeff[YA + k]
            yc = coeff[YC + k]
            # force on a from the rotation of b carries YB[b a]; torque on a from translation of b, YB[a b]
            yb_f = coeff[YB + 2 * b + a]
            yb_t = coeff[YB + k]
            ra = 6 * a
            rb = 6 * b
            for r in range(3):
                for q in range(3):
                    proj = (1.0 if r == q else 0.0) - n[r] * n[q]
                    R[ra + r, rb + q] = xa * n[r] * n[q] + ya * proj
                    R[ra + 3 + r, rb + 3 + q] = yc * proj
            # N = [[0, -n_z, n_y], [n_z, 0, -n_x], [-n_y, n_x, 0]]; the F-w entries are +YB N and the
            # T-U entries -YB N, so the block is symmetric because N is antisymmetric
            for r in range(3):
                R[ra + r, rb + 3 + r] = 0.0
                R[ra + 3 + r, rb + r] = 0.0
            for r, q, m, sign in ((0, 1, 2, -1.0), (0, 2, 1, 1.0), (1, 0, 2, 1.0),
                                  (1, 2, 0, -1.0), (2, 0, 1, -1.0), (2, 1, 0, 1.0)):  # fmt: skip
                nrq = sign * n[m]  # N[r, q]
                R[ra + r, rb + 3 + q] = yb_f * nrq
                R[ra + 3 + r, rb + q] = -yb_t * nrq
    return R


@njit(cache=True)
def strain_force(coeff, n, e, out):
    """Force/torque on (i, j) from the imposed rate of strain ``e`` (3, 3, symmetric), R_FE : E, written
    into ``out`` (12,) as [F_i, T_i, F_j, T_j] and returned.

    G_i = (XG_11 + XG_21)(n.E.n) n + 2 (YG_11 + YG_21) P.E.n,  H_i = 2 (YH_11 + YH_21) n x E.n, and for j
    the columns 12 + 22.  (G, H) is -R_pair applied to the affine strain motion of the pair at contact.
    """
    en0 = e[0, 0] * n[0] + e[0, 1] * n[1] + e[0, 2] * n[2]
    en1 = e[1, 0] * n[0] + e[1, 1] * n[1] + e[1, 2] * n[2]
    en2 = e[2, 0] * n[0] + e[2, 1] * n[1] + e[2, 2] * n[2]
    nen = n[0] * en0 + n[1] * en1 + n[2] * en2
    pen0 = en0 - nen * n[0]
    pen1 = en1 - nen * n[1]
    pen2 = en2 - nen * n[2]
    # n x E.n
    c0 = n[1] * en2 - n[2] * en1
    c1 = n[2] * en0 - n[0] * en2
    c2 = n[0] * en1 - n[1] * en0
    for a in range(2):
        gx = coeff[XG + a] + coeff[XG + 2 + a]
        gy = 2.0 * (coeff[YG + a] + coeff[YG + 2 + a])
        gh = 2.0 * (coeff[YH + a] + coeff[YH + 2 + a])
        o = 6 * a
        out[o + 0] = gx * nen * n[0] + gy * pen0
        out[o + 1] = gx * nen * n[1] + gy * pen1
        out[o + 2] = gx * nen * n[2] + gy * pen2
        out[o + 3] = gh * c0
        out[o + 4] = gh * c1
        out[o + 5] = gh * c2
    return out


@njit(cache=True)
def contact_block(coeff, n, ai, aj, k_normal, k_tangential, R):
    """Fill ``R`` (12, 12) with the resistance block of a contact and return it: the dashpot (lubrication
    frozen at contact, in ``coeff``) plus, for the linearly implicit integrator, dt times the spring
    stiffnesses (``k_normal``, ``k_tangential``; zero for explicit Euler).

    Over a step the overlap changes by -n.(U_j - U_i) dt and the tangential stretch by G_t (U, w) dt, with
    G_t = [-P, a_i N, P, a_j N] (3 x 12): the sliding velocity P(U_j - U_i) - (a_i w_i + a_j w_j) x n.
    The springs' change adds k_n g_n g_n^T + k_t G_t^T G_t, symmetric positive semi-definite.
    """
    pair_block(coeff, n, R)
    if k_normal == 0.0 and k_tangential == 0.0:  # explicit Euler: the dashpot alone
        return R
    g = np.zeros((4, 12))  # row 0: g_n; rows 1-3: G_t
    for r in range(3):
        g[0, r] = -n[r]
        g[0, 6 + r] = n[r]
        for q in range(3):
            proj = (1.0 if r == q else 0.0) - n[r] * n[q]
            g[1 + r, q] = -proj
            g[1 + r, 6 + q] = proj
    for r, q, m, sign in ((0, 1, 2, -1.0), (0, 2, 1, 1.0), (1, 0, 2, 1.0),
                          (1, 2, 0, -1.0), (2, 0, 1, -1.0), (2, 1, 0, 1.0)):  # fmt: skip
        g[1 + r, 3 + q] = ai * sign * n[m]
        g[1 + r, 9 + q] = aj * sign * n[m]
    for r in range(12):
        for q in range(12):
            R[r, q] += k_normal * g[0, r] * g[0, q] + k_tangential * (
                g[1, r] * g[1, q] + g[2, r] * g[2, q] + g[3, r] * g[3, q]
            )
    return R


@njit(cache=True)
def one_body_resistance(a, dof):
    """Stokes drag of a sphere of radius ``a`` on its degree of freedom ``dof`` (0-2 translation, 3-5
    rotation), in 6 pi eta0: a on translation (6 pi eta0 a), 4 a^3 / 3 on rotation (8 pi eta0 a^3)."""
    return a if dof < 3 else (4.0 / 3.0) * a * a * a


@njit(cache=True)
def one_body_drag(radii):
    """Stokes drag per degree of freedom (6N,) of spheres of ``radii`` (N,), in 6 pi eta0, ordered
    [U_i (3), w_i (3)] per particle."""
    n = radii.shape[0]
    drag = np.empty(6 * n)
    for i in range(n):
        for dof in range(6):
            drag[6 * i + dof] = one_body_resistance(radii[i], dof)
    return drag
