"""Frictional contacts: linear springs with the Critical Load Model (CLM) and Coulomb sliding.

Units: forces in F_CL (the critical load), lengths in a.  A pair is in contact while its reduced gap
xi <= 0.  The normal spring is F_n = k_n a_bar overlap; the tangential spring is F_t = k_t a_bar stretch,
where the stretch vector (P, 2) accumulates the relative sliding displacement of j's surface with respect
to i's at the contact point.

Contact states (int8): NONE (not touching), FRICTIONLESS (F_n < F_CL), STICK, SLIDE, and UNLOADING: a
sliding contact whose stretch the last step's sliding velocity turned back (``increment_stretch`` with
``elastic_unloading``), held only from the move to the next CLM update, which makes it stick.

Elastic unloading.  LF_DEM decides stick or slide by the magnitude of the stretch alone.  A sliding contact
exerts its Coulomb force explicitly; when that force spins a weakly held particle, the sliding velocity can
overshoot through zero within one step, and the stretch lands beyond the bound on the other side: the
contact slides back, and the pair flips every step (period-2 chatter, whose speed then bounds dt).  In the
continuous dynamics the tangential load of a contact whose sliding reverses first falls elastically: the
contact sticks.  With ``elastic_unloading`` the CLM update makes such a contact stick, with its stretch on
the bound, so that the implicit integrator's spring takes it over at the next step.
"""

import numpy as np
from numba import njit

NONE = 0
FRICTIONLESS = 1
STICK = 2
SLIDE = 3
UNLOADING = 4


@njit(cache=True)
def critical_load_update(radii, pair_i, pair_j, nvec, xi, stretch, state, kn, kt, mu, critical_load):
    """Apply the CLM at the current geometry, in place on ``stretch`` (P, d) and ``state`` (P,), with the
    unit normals ``nvec`` (P, d) and reduced gaps ``xi`` (P,); the same in any dimension d.

    Pairs that left contact lose their stretch.  In contact the stretch is first projected onto the
    current tangent (plane); if the normal spring force is below the critical load the contact is
    frictionless and the stretch is reset (the CLM's loss of frictional memory); otherwise the tangential
    force is bounded by mu (F_n - F_CL): beyond it the contact slides and the stretch is rescaled onto the
    bound, except that a contact marked UNLOADING sticks there (elastic unloading, module docstring).
    Returns the number of frictional (stick or slide) contacts.
    """
    dim = nvec.shape[1]
    n_frictional = 0
    for p in range(pair_i.shape[0]):
        if xi[p] > 0.0:
            state[p] = NONE
            stretch[p, :] = 0.0
            continue
        abar = 0.5 * (radii[pair_i[p]] + radii[pair_j[p]])
        overlap = -xi[p] * abar
        f_normal = kn * abar * overlap
        sn = stretch[p, 0] * nvec[p, 0]
        for c in range(1, dim):
            sn += stretch[p, c] * nvec[p, c]
        for c in range(dim):
            stretch[p, c] -= sn * nvec[p, c]
        if mu <= 0.0 or f_normal < critical_load:
            state[p] = FRICTIONLESS
            stretch[p, :] = 0.0
            continue
        n_frictional += 1
        capacity = mu * (f_normal - critical_load)
        s2 = stretch[p, 0] ** 2
        for c in range(1, dim):
            s2 += stretch[p, c] ** 2
        f_tan = kt * abar * np.sqrt(s2)
        if f_tan > capacity:
            scale = capacity / f_tan
            for c in range(dim):
                stretch[p, c] *= scale
            state[p] = STICK if state[p] == UNLOADING else SLIDE
        else:
            state[p] = STICK
    return n_frictional


@njit(cache=True)
def contact_spring_forces(radii, pair_i, pair_j, nvec, xi, stretch, state, kn, kt, out):
    """Add spring forces/torques to ``out`` (3N: Fx, Fy, T per particle); return per-pair force on i (P, 2).

    Force on i from j: -F_n n + F_t; on j the opposite.  Torques a_i n x F_t and a_j n x F_t (both signs
    equal, because the lever arms point in opposite directions and so do the forces).
    """
    npair = pair_i.shape[0]
    f_on_i = np.zeros((npair, 2))
    for p in range(npair):
        if state[p] == NONE:
            continue
        i = pair_i[p]
        j = pair_j[p]
        abar = 0.5 * (radii[i] + radii[j])
        nx = nvec[p, 0]
        ny = nvec[p, 1]
        fn = kn * abar * (-xi[p] * abar)
        fx = -fn * nx + kt * abar * stretch[p, 0]
        fy = -fn * ny + kt * abar * stretch[p, 1]
        f_on_i[p, 0] = fx
        f_on_i[p, 1] = fy
        torque_arm = nx * fy - ny * fx  # n x F_t (the normal part has no moment)
        out[3 * i + 0] += fx
        out[3 * i + 1] += fy
        out[3 * i + 2] += radii[i] * torque_arm
        out[3 * j + 0] -= fx
        out[3 * j + 1] -= fy
        out[3 * j + 2] += radii[j] * torque_arm
    return f_on_i


@njit(cache=True)
def sliding_velocity(vel, radii, pair_i, pair_j, nvec, dy, shear_rate, p):
    """Relative tangential surface velocity (2-vector) of j with respect to i at the contact point.

    ``vel`` holds non-affine velocities (3N); the affine part adds shear_rate * dy e_x to the relative
    translation (Lees–Edwards aware through dy) and -shear_rate/2 to both rotations.
    """
    i = pair_i[p]
    j = pair_j[p]
    nx = nvec[p, 0]
    ny = nvec[p, 1]
    tx = -ny
    ty = nx
    dux = vel[3 * j] - vel[3 * i] + shear_rate * dy[p]
    duy = vel[3 * j + 1] - vel[3 * i + 1]
    w_i = vel[3 * i + 2] - 0.5 * shear_rate
    w_j = vel[3 * j + 2] - 0.5 * shear_rate
    vt = dux * tx + duy * ty - (radii[i] * w_i + radii[j] * w_j)
    return vt * tx, vt * ty


@njit(cache=True)
def max_interaction_speed(vel, radii, pair_i, pair_j, nvec, dy, active, state, shear_rate):
    """Largest relative speed that moves an interaction: normal approach speed |n.(U_j - U_i)| of every
    interacting pair (total velocities, Lees–Edwards aware) and sliding speed of every contact (LF_DEM's
    ``max_interaction_vel``)."""
    vmax = 0.0
    for p in range(pair_i.shape[0]):
        if not active[p]:
            continue
        i = pair_i[p]
        j = pair_j[p]
        vn = abs(
            (vel[3 * j] - vel[3 * i] + shear_rate * dy[p]) * nvec[p, 0]
            + (vel[3 * j + 1] - vel[3 * i + 1]) * nvec[p, 1]
        )
        if vn > vmax:
            vmax = vn
        if state[p] != NONE:
            sx, sy = sliding_velocity(vel, radii, pair_i, pair_j, nvec, dy, shear_rate, p)
            v = np.sqrt(sx * sx + sy * sy)
            if v > vmax:
                vmax = v
    return vmax


@njit(cache=True)
def increment_stretch(
    vel, radii, pair_i, pair_j, nvec, dy, state, stretch, shear_rate, dt, elastic_unloading
):
    """Advance the tangential stretch of every contact by (sliding velocity) * dt, before positions move.

    Frictionless contacts accumulate too; the CLM check at the next geometry resets them if F_n < F_CL.
    With ``elastic_unloading`` a sliding contact whose sliding velocity opposes its stretch is marked
    UNLOADING (module docstring).
    """
    for p in range(pair_i.shape[0]):
        if state[p] != NONE:
            sx, sy = sliding_velocity(vel, radii, pair_i, pair_j, nvec, dy, shear_rate, p)
            if elastic_unloading and state[p] == SLIDE and sx * stretch[p, 0] + sy * stretch[p, 1] < 0.0:
                state[p] = UNLOADING
            stretch[p, 0] += sx * dt
            stretch[p, 1] += sy * dt
