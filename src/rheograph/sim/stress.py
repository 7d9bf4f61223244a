"""Particle stress: lubrication stresslets, contact (spring + dashpot) virial (the solvent's 2 eta0 E is
added by the integrator).

Stresslets are in F_CL * a per unit thickness; dividing by the box area Lx*Ly and multiplying by 6 pi
converts to sigma0 = F_CL / (6 pi a^2) (see ``stress_unit_factor``).  Tensors are stored as
(xx, xy, yy) since sigma_zz = 0 in the monolayer and the tensor is symmetric.
"""

import math

import numpy as np
from numba import njit

from rheograph.sim.contacts import NONE
from rheograph.sim.lubrication import XG, XM, YG, YM, contact_block


@njit(cache=True)
def _add_lubrication_stresslet(out, coeff, nx, ny, ui, uj, wi, wj, exx, exy, eyy, full):
    """Stresslet S_i + S_j of one lubricated pair for non-affine velocities (u, w) and strain rate E.

    S_a = -(XG_a1 U_i.n + XG_a2 U_j.n) nn - 2 [YG_a1 tau(U_i) + YG_a2 tau(U_j)]
          - 2 [YM_a1 rho(w_i) + YM_a2 rho(w_j)]
          + 3/2 (n.E.n)(XM_a1 + XM_a2) nn + 2 (YM_a1 + YM_a2)[sym(n (x) E.n) - (n.E.n) nn]
    with tau(u) = sym(n (x) u) - (n.u) nn and rho(w) = w sym(n (x) t).  LF_DEM uses Y^M in the rotation
    term where Jeffrey & Onishi have Y^H (the sums agree for equal spheres); we follow LF_DEM.
    The tensors are not made traceless, so lubrication contributes to the particle pressure.
    """
    tx = -ny
    ty = nx
    en_x = exx * nx + exy * ny
    en_y = exy * nx + eyy * ny
    nen = nx * en_x + ny * en_y
    sxx = 0.0
    sxy = 0.0
    syy = 0.0
    for a in range(2):
        k1 = 2 * a  # coefficient index a1
        k2 = 2 * a + 1  # coefficient index a2
        # normal (X^G) and strain (X^M) parts along nn
        c_nn = -(coeff[XG + k1] * (ui[0] * nx + ui[1] * ny) + coeff[XG + k2] * (uj[0] * nx + uj[1] * ny))
        c_nn += 1.5 * nen * (coeff[XM + k1] + coeff[XM + k2])
        # tau(U) = sym(n (x) U) - (n.U) nn, combined for both velocities with weights -2 YG
        wx = -2.0 * (coeff[YG + k1] * ui[0] + coeff[YG + k2] * uj[0])
        wy = -2.0 * (coeff[YG + k1] * ui[1] + coeff[YG + k2] * uj[1])
        c_nn -= nx * wx + ny * wy
        # rho(w) = w sym(n (x) t): add -2 (YM_a1 w_i + YM_a2 w_j) t to the vector paired with n
        wrot = -2.0 * (coeff[YM + k1] * wi + coeff[YM + k2] * wj)
        vx = wx + wrot * tx
        vy = wy + wrot * ty
        # strain part: 2 (YM_a1 + YM_a2) [sym(n (x) E.n) - (n.E.n) nn]
        ym = 2.0 * (coeff[YM + k1] + coeff[YM + k2])
        vx += ym * en_x
        vy += ym * en_y
        c_nn -= ym * nen
        # S = c_nn nn + sym(n (x) v)
        sxy += c_nn * nx * ny + 0.5 * (nx * vy + ny * vx)
        if full:
            sxx += c_nn * nx * nx + nx * vx
            syy += c_nn * ny * ny + ny * vy
    out[0] += sxx
    out[1] += sxy
    out[2] += syy


@njit(cache=True)
def pair_stress_sums(
    vel_const,
    vel_rate,
    radii,
    pair_i,
    pair_j,
    nvec,
    r,
    dy,
    coeff,
    lubricated,
    in_contact,
    k_normal,
    k_tangential,
    full,
):
    """Sums of pair stresslets (xx, xy, yy) for the two parts of the solution, the velocities at zero
    shear rate ``vel_const`` (3N) and the velocities per unit shear rate ``vel_rate`` (3N) with the
    affine flow at unit rate: the stress at rate g is S(const) + g S(rate).

    Returns (lubrication, dashpot) at zero rate and (lubrication, dashpot) per unit rate, each (3,).
    One pass over the pairs for both (each pair's contact block is built once).  The dashpot force on
    i, F_i = -[R_pair (v + affine)]_i, enters the contact virial r_ij (x) F_ij (r_ij from i to j, F_ij
    the force on i), symmetrised.  Springs at the start of the step are handled by ``spring_stress``;
    their implicit change over the step (``k_normal``, ``k_tangential``) is part of the contact block
    and so of this force.
    """
    lub = np.zeros((2, 3))
    dash = np.zeros((2, 3))
    ui = np.empty(2)
    uj = np.empty(2)
    vp = np.empty(6)
    R = np.empty((6, 6))
    for p in range(pair_i.shape[0]):
        i = pair_i[p]
        j = pair_j[p]
        nx = nvec[p, 0]
        ny = nvec[p, 1]
        if lubricated[p]:
            for part in range(2):
                vel = vel_const if part == 0 else vel_rate
                ui[0] = vel[3 * i]
                ui[1] = vel[3 * i + 1]
                uj[0] = vel[3 * j]
                uj[1] = vel[3 * j + 1]
                _add_lubrication_stresslet(
                    lub[part],
                    coeff[p],
                    nx,
                    ny,
                    ui,
                    uj,
                    vel[3 * i + 2],
                    vel[3 * j + 2],
                    0.0,
                    0.5 * part,
                    0.0,
                    full,
                )
        elif in_contact[p]:
            contact_block(coeff[p], nx, ny, radii[i], radii[j], k_normal[p], k_tangential[p], R)
            rr = r[p]
            for part in range(2):
                vel = vel_const if part == 0 else vel_rate
                for q in range(3):
                    vp[q] = vel[3 * i + q]
                    vp[3 + q] = vel[3 * j + q]
                if part == 1:  # the affine flow at unit rate
                    vp[3] += dy[p]
                    vp[2] -= 0.5
                    vp[5] -= 0.5
                fx = 0.0
                fy = 0.0
                for q in range(6):
                    fx -= R[0, q] * vp[q]
                    fy -= R[1, q] * vp[q]
                dash[part, 1] += 0.5 * rr * (nx * fy + ny * fx)
                if full:
                    dash[part, 0] += rr * nx * fx
                    dash[part, 2] += rr * ny * fy
    return lub[0], dash[0], lub[1], dash[1]


@njit(cache=True)
def spring_stress(pair_i, nvec, r, f_on_i, state, full):
    """Contact-spring virial sum of sym(r_ij (x) F_ij) as (xx, xy, yy)."""
    out = np.zeros(3)
    for p in range(pair_i.shape[0]):
        if state[p] == NONE:
            continue
        nx = nvec[p, 0]
        ny = nvec[p, 1]
        rr = r[p]
        fx = f_on_i[p, 0]
        fy = f_on_i[p, 1]
        out[1] += 0.5 * rr * (nx * fy + ny * fx)
        if full:
            out[0] += rr * nx * fx
            out[2] += rr * ny * fy
    return out


def stress_unit_factor(*edges: float) -> float:
    """Factor converting a stresslet sum (F_CL a, per unit thickness in 2D) to stress in
    sigma0 = F_CL/(6 pi a^2): 6 pi / the box's area or volume, of ``edges`` (lx, ly[, lz]) [a]."""
    return 6.0 * np.pi / math.prod(edges)
