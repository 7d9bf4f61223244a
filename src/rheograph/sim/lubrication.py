"""Pairwise lubrication resistance (leading singular terms of Jeffrey & Onishi 1984), LF_DEM conventions.

Units: forces in F_CL, lengths in a, velocities in a * shear-rate unit; resistances are in units of
6 pi eta0 (so one-body drag is a_i on translation and 4 a_i^3 / 3 on rotation).

For a pair (i, j) with n pointing from i to j and t = (-n_y, n_x), each scalar function carries four
indices 11, 12, 21, 22 (stored as [0..3]).  With the *same* n for both particles (LF_DEM's convention):

    F_i = -[XA11 U_i.n + XA12 U_j.n] n - [YA11 U_i.t + YA12 U_j.t] t + [YB11 w_i + YB21 w_j] t + G_i
    F_j = -[XA21 U_i.n + XA22 U_j.n] n - [YA21 U_i.t + YA22 U_j.t] t + [YB12 w_i + YB22 w_j] t + G_j
    T_i =  YB11 U_i.t + YB12 U_j.t - YC11 w_i - YC12 w_j + H_i
    T_j =  YB21 U_i.t + YB22 U_j.t - YC21 w_i - YC22 w_j + H_j

which makes the 6x6 pair block symmetric (R_{F_i, w_j} = R_{T_j, U_i}^T).
"""

import numpy as np
from numba import njit

# index layout of the per-pair coefficient array (P, 36): nine functions x four index pairs
XA, YA, YB, YC, XG, YG, YH, XM, YM = 0, 4, 8, 12, 16, 20, 24, 28, 32
N_COEFF = 36


@njit(cache=True)
def size_ratio_functions(lam):
    """The 13 size-ratio prefactors g(lambda) of physics.md §3.1 for lambda = a_j / a_i."""
    l1 = 1.0 + lam
    l1_2 = l1 * l1
    l1_3 = l1_2 * l1
    g1_xa = 2.0 * lam * lam / l1_3
    g2_ya = (4.0 / 15.0) * lam * (2.0 + lam + 2.0 * lam * lam) / l1_3
    g2_yb = -0.2 * lam * (4.0 + lam) / l1_2
    g2_yc = 0.4 * lam / l1
    g4_yc = 0.8 * lam * lam / (l1_2 * l1_2)
    g1_xg = 3.0 * lam * lam / l1_3
    g2_yg = 0.1 * lam * (4.0 - lam + 7.0 * lam * lam) / l1_3
    g2_yh = 0.1 * lam * (2.0 - lam) / l1_2
    g5_yh = 0.05 * lam * lam * (1.0 + 7.0 * lam) / l1_2
    g1_xm = 1.2 * lam * lam / l1_3
    g4_xm = 1.2 * lam * lam * lam / l1_3
    g2_ym = 0.24 * lam * (1.0 - lam + 4.0 * lam * lam) / l1_3
    g5_ym = 0.06 * lam * lam * (7.0 - 10.0 * lam + 7.0 * lam * lam) / l1_3
    return (g1_xa, g2_ya, g2_yb, g2_yc, g4_yc, g1_xg, g2_yg, g2_yh, g5_yh, g1_xm, g4_xm, g2_ym, g5_ym)


@njit(cache=True)
def singular_factors(xi, delta):
    """Regularised squeeze factor c = 1/(xi + delta) and log factor l = ln c (0 when c <= 1).

    In contact (xi <= 0) the resistance is frozen at xi = 0 (the contact dashpot), so that it is continuous.
    """
    if xi < 0.0:
        xi = 0.0
    c = 1.0 / (xi + delta)
    ell = np.log(c) if c > 1.0 else 0.0
    return c, ell


@njit(cache=True)
def pair_coefficients(ai, aj, c, ell, out):
    """Fill ``out`` (length 36) with XA, YA, YB, YC, XG, YG, YH, XM, YM [11, 12, 21, 22] for one pair."""
    lam = aj / ai
    g = size_ratio_functions(lam)
    h = size_ratio_functions(1.0 / lam)
    ai2 = ai * ai
    aj2 = aj * aj
    ai3 = ai2 * ai
    aj3 = aj2 * aj
    # X^A: squeeze
    out[XA + 0] = ai * g[0] * c
    out[XA + 1] = -ai * g[0] * c
    out[XA + 2] = out[XA + 1]
    out[XA + 3] = aj * h[0] * c
    # Y^A: shear
    out[YA + 0] = ai * g[1] * ell
    out[YA + 1] = -ai * g[1] * ell
    out[YA + 2] = out[YA + 1]
    out[YA + 3] = aj * h[1] * ell
    # Y^B: translation-rotation coupling
    out[YB + 0] = (2.0 / 3.0) * ai2 * g[2] * ell
    out[YB + 1] = -(2.0 / 3.0) * ai2 * g[2] * ell
    out[YB + 2] = (2.0 / 3.0) * aj2 * h[2] * ell
    out[YB + 3] = -(2.0 / 3.0) * aj2 * h[2] * ell
    # Y^C: rotation
    out[YC + 0] = (4.0 / 3.0) * ai3 * g[3] * ell
    out[YC + 1] = ((ai + aj) ** 3 / 6.0) * g[4] * ell
    out[YC + 2] = out[YC + 1]
    out[YC + 3] = (4.0 / 3.0) * aj3 * h[3] * ell
    # X^G, Y^G: force from the imposed strain rate / stresslet from translation
    out[XG + 0] = (2.0 / 3.0) * ai2 * g[5] * c
    out[XG + 1] = -(2.0 / 3.0) * ai2 * g[5] * c
    out[XG + 2] = (2.0 / 3.0) * aj2 * h[5] * c
    out[XG + 3] = -(2.0 / 3.0) * aj2 * h[5] * c
    out[YG + 0] = (2.0 / 3.0) * ai2 * g[6] * ell
    out[YG + 1] = -(2.0 / 3.0) * ai2 * g[6] * ell
    out[YG + 2] = (2.0 / 3.0) * aj2 * h[6] * ell
    out[YG + 3] = -(2.0 / 3.0) * aj2 * h[6] * ell
    # Y^H: torque from the imposed strain rate
    out[YH + 0] = (4.0 / 3.0) * ai3 * g[7] * ell
    out[YH + 1] = (4.0 / 3.0) * ai3 * g[8] * ell
    out[YH + 2] = (4.0 / 3.0) * aj3 * h[8] * ell
    out[YH + 3] = (4.0 / 3.0) * aj3 * h[7] * ell
    # X^M, Y^M: stresslet from the imposed strain rate
    out[XM + 0] = (10.0 / 9.0) * ai3 * g[9] * c
    out[XM + 1] = (10.0 / 9.0) * ai3 * g[10] * c
    out[XM + 2] = out[XM + 1]
    out[XM + 3] = (10.0 / 9.0) * aj3 * h[9] * c
    out[YM + 0] = (10.0 / 9.0) * ai3 * g[11] * ell
    out[YM + 1] = (10.0 / 9.0) * ai3 * g[12] * ell
    out[YM + 2] = out[YM + 1]
    out[YM + 3] = (10.0 / 9.0) * aj3 * h[11] * ell


@njit(cache=True)
def lubrication_resistance(radii, pair_i, pair_j, xi, active, delta):
    """Coefficient table (P, 36) for the pairs flagged ``active`` (zeros elsewhere).

    ``xi`` is the reduced gap h / a_bar; pairs in contact (xi <= 0) get the frozen-at-contact values used by
    the contact dashpot.
    """
    npair = pair_i.shape[0]
    coeff = np.zeros((npair, N_COEFF))
    for p in range(npair):
        if active[p]:
            c, ell = singular_factors(xi[p], delta)
            pair_coefficients(radii[pair_i[p]], radii[pair_j[p]], c, ell, coeff[p])
    return coeff


@njit(cache=True)
def pair_block(coeff, nx, ny, R):
    """Fill ``R`` (6, 6) with the dense symmetric resistance block in the order [Ux_i, Uy_i, w_i, Ux_j,
    Uy_j, w_j] and return it.  Callers pass one scratch block for all pairs: an allocation per pair
    cost as much as the arithmetic (docs/validation/speed.md)."""
    tx = -ny
    ty = nx
    for a in range(2):
        for b in range(2):
            ia = 3 * a
            ib = 3 * b
            k = 2 * a + b  # 11 -> 0, 12 -> 1, 21 -> 2, 22 -> 3
            xa = coeff[XA + k]
            ya = coeff[YA + k]
            R[ia + 0, ib + 0] = xa * nx * nx + ya * tx * tx
            R[ia + 0, ib + 1] = xa * nx * ny + ya * tx * ty
            R[ia + 1, ib + 0] = xa * ny * nx + ya * ty * tx
            R[ia + 1, ib + 1] = xa * ny * ny + ya * ty * ty
            # force on a from rotation of b: -YB[b a] t ; torque on a from translation of b: -YB[a b] t
            yb_f = coeff[YB + 2 * b + a]
            yb_t = coeff[YB + k]
            R[ia + 0, ib + 2] = -yb_f * tx
            R[ia + 1, ib + 2] = -yb_f * ty
            R[ia + 2, ib + 0] = -yb_t * tx
            R[ia + 2, ib + 1] = -yb_t * ty
            R[ia + 2, ib + 2] = coeff[YC + k]
    return R


@njit(cache=True)
def strain_force(coeff, nx, ny, exx, exy, eyy, out):
    """Force/torque on (i, j) from the imposed rate of strain E (R_FE : E), written into ``out`` (6,)
    as [Fx_i, Fy_i, T_i, Fx_j, Fy_j, T_j] and returned.
    """
    tx = -ny
    ty = nx
    nen = nx * (exx * nx + exy * ny) + ny * (exy * nx + eyy * ny)
    ten = tx * (exx * nx + exy * ny) + ty * (exy * nx + eyy * ny)
    gx_i = coeff[XG + 0] + coeff[XG + 2]
    gy_i = 2.0 * (coeff[YG + 0] + coeff[YG + 2])
    gx_j = coeff[XG + 1] + coeff[XG + 3]
    gy_j = 2.0 * (coeff[YG + 1] + coeff[YG + 3])
    out[0] = gx_i * nen * nx + gy_i * ten * tx
    out[1] = gx_i * nen * ny + gy_i * ten * ty
    out[2] = 2.0 * (coeff[YH + 0] + coeff[YH + 2]) * ten
    out[3] = gx_j * nen * nx + gy_j * ten * tx
    out[4] = gx_j * nen * ny + gy_j * ten * ty
    out[5] = 2.0 * (coeff[YH + 1] + coeff[YH + 3]) * ten
    return out


@njit(cache=True)
def contact_block(coeff, nx, ny, ai, aj, k_normal, k_tangential, R):
    """Fill ``R`` (6, 6) with the resistance block of a contact and return it: the dashpot (lubrication
    frozen at contact, in ``coeff``) plus, for the linearly implicit integrator, the spring stiffness
    times dt (``k_normal``, ``k_tangential`` in F_CL / (a gamma0_dot); zero for explicit Euler).

    The springs change over a step by dt * K (U_total): normal overlap by -n.(U_j - U_i), tangential
    stretch by the sliding velocity g.U with g = [-t, -a_i, t, -a_j]; the generalised force on the
    pair is -dt K g (g.U), i.e. a symmetric positive semi-definite block k g g^T.
    """
    pair_block(coeff, nx, ny, R)
    if k_normal == 0.0 and k_tangential == 0.0:  # explicit Euler: the dashpot alone
        return R
    tx = -ny
    ty = nx
    gn = (-nx, -ny, 0.0, nx, ny, 0.0)
    gt = (-tx, -ty, -ai, tx, ty, -aj)
    for r in range(6):
        for q in range(6):
            R[r, q] += k_normal * gn[r] * gn[q] + k_tangential * gt[r] * gt[q]
    return R
