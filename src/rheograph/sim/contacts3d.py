"""Frictional contacts between spheres in 3D: linear springs, Critical Load Model (CLM), Coulomb sliding.

Units, states (NONE, FRICTIONLESS, STICK, SLIDE, UNLOADING), elastic unloading and the CLM update
``critical_load_update`` (on stretches of any length) are ``rheograph.sim.contacts``'s: forces in F_CL,
lengths in a.  The tangential stretch is a 3-vector per pair (P, 3): the relative sliding displacement of
j's surface with respect to i's at the contact point.  It is advanced with the sliding velocity (already
tangent) before the particles move, and after they move it is projected onto the plane normal to the new
n, as LF_DEM does: no rigid rotation with the pair, so |stretch| loses a second-order amount when the pair
rolls, and the stretch stays fixed in the lab frame when the pair spins about n.  There is no twisting or
rolling spring.

Degrees of freedom per particle: 6, ordered [U (3), w (3)] (non-affine); the affine flow at shear rate g
is U = g y e_x and w = -g/2 e_z.
"""

import numpy as np
from numba import njit

from rheograph.sim.contacts import FRICTIONLESS, NONE, SLIDE, STICK, UNLOADING, critical_load_update


@njit(cache=True)
def contact_spring_forces(radii, pair_i, pair_j, nvec, xi, stretch, state, kn, kt, out):
    """Add spring forces/torques to ``out`` (6N: F (3), T (3) per particle); return the per-pair force on
    i (P, 3) [F_CL].

    Force on i from j: -F_n n + F_t with F_n = k_n a_bar overlap and F_t = k_t a_bar stretch; on j the
    opposite.  Torques a_i n x F and a_j n x F (the same sign on both: the lever arms and the forces are
    both opposite).
    """
    npair = pair_i.shape[0]
    f_on_i = np.zeros((npair, 3))
    for p in range(npair):
        if state[p] == NONE:
            continue
        i = pair_i[p]
        j = pair_j[p]
        abar = 0.5 * (radii[i] + radii[j])
        n0 = nvec[p, 0]
        n1 = nvec[p, 1]
        n2 = nvec[p, 2]
        fn = kn * abar * (-xi[p] * abar)
        f0 = -fn * n0 + kt * abar * stretch[p, 0]
        f1 = -fn * n1 + kt * abar * stretch[p, 1]
        f2 = -fn * n2 + kt * abar * stretch[p, 2]
        f_on_i[p, 0] = f0
        f_on_i[p, 1] = f1
        f_on_i[p, 2] = f2
        # n x F (the normal part has no moment)
        m0 = n1 * f2 - n2 * f1
        m1 = n2 * f0 - n0 * f2
        m2 = n0 * f1 - n1 * f0
        out[6 * i + 0] += f0
        out[6 * i + 1] += f1
        out[6 * i + 2] += f2
        out[6 * i + 3] += radii[i] * m0
        out[6 * i + 4] += radii[i] * m1
        out[6 * i + 5] += radii[i] * m2
        out[6 * j + 0] -= f0
        out[6 * j + 1] -= f1
        out[6 * j + 2] -= f2
        out[6 * j + 3] += radii[j] * m0
        out[6 * j + 4] += radii[j] * m1
        out[6 * j + 5] += radii[j] * m2
    return f_on_i


@njit(cache=True)
def sliding_velocity(vel, radii, pair_i, pair_j, nvec, dy, shear_rate, p):
    """Relative tangential surface velocity (3-vector) of j with respect to i at the contact point,
    P [(U_j - U_i) - (a_i w_i + a_j w_j) x n], with total velocities.

    ``vel`` holds non-affine velocities (6N); the affine part adds shear_rate * dy e_x to the relative
    translation (Lees–Edwards aware through dy) and -shear_rate/2 e_z to both rotations.
    """
    i = pair_i[p]
    j = pair_j[p]
    n0 = nvec[p, 0]
    n1 = nvec[p, 1]
    n2 = nvec[p, 2]
    du0 = vel[6 * j] - vel[6 * i] + shear_rate * dy[p]
    du1 = vel[6 * j + 1] - vel[6 * i + 1]
    du2 = vel[6 * j + 2] - vel[6 * i + 2]
    # surface rotation: W = a_i w_i + a_j w_j (total angular velocities)
    w0 = radii[i] * vel[6 * i + 3] + radii[j] * vel[6 * j + 3]
    w1 = radii[i] * vel[6 * i + 4] + radii[j] * vel[6 * j + 4]
    w2 = radii[i] * (vel[6 * i + 5] - 0.5 * shear_rate) + radii[j] * (vel[6 * j + 5] - 0.5 * shear_rate)
    v0 = du0 - (w1 * n2 - w2 * n1)
    v1 = du1 - (w2 * n0 - w0 * n2)
    v2 = du2 - (w0 * n1 - w1 * n0)
    vn = v0 * n0 + v1 * n1 + v2 * n2
    return v0 - vn * n0, v1 - vn * n1, v2 - vn * n2


@njit(cache=True)
def max_interaction_speed(vel, radii, pair_i, pair_j, nvec, dy, active, state, shear_rate):
    """Largest relative speed that moves an interaction: the normal approach speed |n.(U_j - U_i)| of
    every interacting pair (total velocities, Lees–Edwards aware) and the sliding speed of every contact."""
    vmax = 0.0
    for p in range(pair_i.shape[0]):
        if not active[p]:
            continue
        i = pair_i[p]
        j = pair_j[p]
        vn = abs(
            (vel[6 * j] - vel[6 * i] + shear_rate * dy[p]) * nvec[p, 0]
            + (vel[6 * j + 1] - vel[6 * i + 1]) * nvec[p, 1]
            + (vel[6 * j + 2] - vel[6 * i + 2]) * nvec[p, 2]
        )
        if vn > vmax:
            vmax = vn
        if state[p] != NONE:
            s0, s1, s2 = sliding_velocity(vel, radii, pair_i, pair_j, nvec, dy, shear_rate, p)
            v = np.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
            if v > vmax:
                vmax = v
    return vmax


@njit(cache=True)
def increment_stretch(
    vel, radii, pair_i, pair_j, nvec, dy, state, stretch, shear_rate, dt, elastic_unloading
):
    """Advance the tangential stretch (P, 3) of every contact by (sliding velocity) * dt, with the
    geometry and Lees–Edwards images of the start of the step, before positions move; with
    ``elastic_unloading`` a sliding contact whose sliding velocity opposes its stretch is marked UNLOADING."""
    for p in range(pair_i.shape[0]):
        if state[p] != NONE:
            s0, s1, s2 = sliding_velocity(vel, radii, pair_i, pair_j, nvec, dy, shear_rate, p)
            if (
                elastic_unloading
                and state[p] == SLIDE
                and s0 * stretch[p, 0] + s1 * stretch[p, 1] + s2 * stretch[p, 2] < 0.0
            ):
                state[p] = UNLOADING
            stretch[p, 0] += s0 * dt
            stretch[p, 1] += s1 * dt
            stretch[p, 2] += s2 * dt


__all__ = [
    "FRICTIONLESS",
    "NONE",
    "SLIDE",
    "STICK",
    "UNLOADING",
    "contact_spring_forces",
    "critical_load_update",
    "increment_stretch",
    "max_interaction_speed",
    "sliding_velocity",
]
