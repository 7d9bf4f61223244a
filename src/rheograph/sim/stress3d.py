"""Particle stress in 3D: lubrication stresslets and the contact (spring + dashpot) virial; the solvent's
2 eta0 E is added by the integrator.

Stresslet sums are in F_CL * a; dividing by the box volume Lx Ly Lz and multiplying by 6 pi converts to
sigma0 = F_CL / (6 pi a^2) (``stress.stress_unit_factor``).  Symmetric tensors are stored as their upper
triangle (xx, xy, xz, yy, yz, zz); ``COMPONENTS`` names them.  As in 2D the lubrication stresslets are not
made traceless (they contribute to the particle pressure), and the rotation term uses Y^M where Jeffrey &
Onishi have Y^H, as LF_DEM does (identical in pair sum for equal spheres only).
"""

import numpy as np
from numba import njit

from rheograph.sim.contacts import NONE
from rheograph.sim.lubrication import XG, XM, YG, YM
from rheograph.sim.lubrication3d import contact_block

COMPONENTS = ("xx", "xy", "xz", "yy", "yz", "zz")
XX, XY, XZ, YY, YZ, ZZ = range(6)
_ROW = (0, 0, 0, 1, 1, 2)
_COL = (0, 1, 2, 1, 2, 2)


@njit(cache=True)
def _add_sym(out, n, v, c_nn):
    """out += c_nn nn + sym(n (x) v), in upper-triangle storage."""
    for k in range(6):
        a = _ROW[k]
        b = _COL[k]
        out[k] += c_nn * n[a] * n[b] + 0.5 * (n[a] * v[b] + n[b] * v[a])


@njit(cache=True)
def add_lubrication_stresslet(out, coeff, n, ui, uj, wi, wj, e):
    """Add the stresslet S_i + S_j of one lubricated pair to ``out`` (6,), for non-affine velocities
    ui, uj, angular velocities wi, wj (3,) and rate of strain ``e`` (3, 3).

    S_a = -(XG_a1 U_i.n + XG_a2 U_j.n) nn - 2 [YG_a1 tau(U_i) + YG_a2 tau(U_j)]
          - 2 [YM_a1 rho(w_i) + YM_a2 rho(w_j)]
          + 3/2 (n.E.n)(XM_a1 + XM_a2) nn + 2 (YM_a1 + YM_a2)[sym(n (x) E.n) - (n.E.n) nn]
    with tau(u) = sym(n (x) u) - (n.u) nn and rho(w) = sym(n (x) (w x n)).  Every term is c nn +
    sym(n (x) v) for some scalar c and vector v, which is how it is accumulated.
    """
    en = np.empty(3)
    for r in range(3):
        en[r] = e[r, 0] * n[0] + e[r, 1] * n[1] + e[r, 2] * n[2]
    nen = n[0] * en[0] + n[1] * en[1] + n[2] * en[2]
    v = np.empty(3)
    for a in range(2):
        k1 = 2 * a  # coefficient index a1
        k2 = 2 * a + 1  # coefficient index a2
        un_i = ui[0] * n[0] + ui[1] * n[1] + ui[2] * n[2]
        un_j = uj[0] * n[0] + uj[1] * n[1] + uj[2] * n[2]
        c_nn = -(coeff[XG + k1] * un_i + coeff[XG + k2] * un_j)
        c_nn += 1.5 * nen * (coeff[XM + k1] + coeff[XM + k2])
        ym = 2.0 * (coeff[YM + k1] + coeff[YM + k2])
        for r in range(3):
            v[r] = -2.0 * (coeff[YG + k1] * ui[r] + coeff[YG + k2] * uj[r]) + ym * en[r]
        # tau's -(n.u) nn and the strain part's -(n.E.n) nn
        c_nn -= n[0] * v[0] + n[1] * v[1] + n[2] * v[2]
        # rho(w): the vector paired with n is w x n, weighted by -2 YM
        ym1 = -2.0 * coeff[YM + k1]
        ym2 = -2.0 * coeff[YM + k2]
        v[0] += ym1 * (wi[1] * n[2] - wi[2] * n[1]) + ym2 * (wj[1] * n[2] - wj[2] * n[1])
        v[1] += ym1 * (wi[2] * n[0] - wi[0] * n[2]) + ym2 * (wj[2] * n[0] - wj[0] * n[2])
        v[2] += ym1 * (wi[0] * n[1] - wi[1] * n[0]) + ym2 * (wj[0] * n[1] - wj[1] * n[0])
        _add_sym(out, n, v, c_nn)


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
    e_unit,
):
    """Sums of pair stresslets (6,) for the two parts of the solution: the velocities at zero shear rate
    ``vel_const`` (6N) and per unit shear rate ``vel_rate`` (6N) with the affine flow at unit rate (rate
    of strain ``e_unit``); the stress at rate g is S(const) + g S(rate).

    Returns (lubrication, dashpot) at zero rate and (lubrication, dashpot) per unit rate.  The dashpot
    force on i, F_i = -[R_pair (v + affine)]_i (with the implicit springs' change over the step, which
    is part of the contact block), enters the contact virial sym(r_ij (x) F_i), r_ij from i to j.
    """
    lub = np.zeros((2, 6))
    dash = np.zeros((2, 6))
    zero_e = np.zeros((3, 3))
    vp = np.empty(12)
    f = np.empty(3)
    R = np.empty((12, 12))
    for p in range(pair_i.shape[0]):
        i = pair_i[p]
        j = pair_j[p]
        n_p = nvec[p]
        if lubricated[p]:
            for part in range(2):
                vel = vel_const if part == 0 else vel_rate
                add_lubrication_stresslet(
                    lub[part], coeff[p], n_p, vel[6 * i : 6 * i + 3], vel[6 * j : 6 * j + 3],
                    vel[6 * i + 3 : 6 * i + 6], vel[6 * j + 3 : 6 * j + 6], zero_e if part == 0 else e_unit,
                )  # fmt: skip
        elif in_contact[p]:
            contact_block(coeff[p], n_p, radii[i], radii[j], k_normal[p], k_tangential[p], R)
            for part in range(2):
                vel = vel_const if part == 0 else vel_rate
                for q in range(6):
                    vp[q] = vel[6 * i + q]
                    vp[6 + q] = vel[6 * j + q]
                if part == 1:  # the affine flow at unit rate
                    vp[6] += dy[p]
                    vp[5] -= 0.5
                    vp[11] -= 0.5
                for c in range(3):
                    fc = 0.0
                    for q in range(12):
                        fc -= R[c, q] * vp[q]
                    f[c] = fc
                for k in range(6):
                    a = _ROW[k]
                    b = _COL[k]
                    dash[part, k] += 0.5 * r[p] * (n_p[a] * f[b] + n_p[b] * f[a])
    return lub[0], dash[0], lub[1], dash[1]


@njit(cache=True)
def spring_stress(pair_i, nvec, r, f_on_i, state):
    """Contact-spring virial sum of sym(r_ij (x) F_i) (6,)."""
    out = np.zeros(6)
    for p in range(pair_i.shape[0]):
        if state[p] == NONE:
            continue
        for k in range(6):
            a = _ROW[k]
            b = _COL[k]
            out[k] += 0.5 * r[p] * (nvec[p, a] * f_on_i[p, b] + nvec[p, b] * f_on_i[p, a])
    return out


def particle_pressure(stress: np.ndarray) -> float:
    """Pi = -(sigma_xx + sigma_yy + sigma_zz) / 3 of a stress (6,) in upper-triangle storage."""
    return -(stress[XX] + stress[YY] + stress[ZZ]) / 3.0


def normal_stress_differences(stress: np.ndarray) -> tuple[float, float]:
    """(N1, N2) = (sigma_xx - sigma_yy, sigma_yy - sigma_zz) [sigma0] of a stress (6,) in upper-triangle
    storage (x the flow, y the gradient, z the vorticity direction)."""
    return float(stress[XX] - stress[YY]), float(stress[YY] - stress[ZZ])
