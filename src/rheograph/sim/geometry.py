"""Lees–Edwards periodic geometry and neighbour search (numba kernels).

Conventions: the box is [-Lx/2, Lx/2) x [-Ly/2, Ly/2), flow along x, gradient along y, so the affine
velocity is u = shear_rate * y e_x. ``le_offset`` is the x-shift of the image box above (y + Ly); it grows
by shear_rate * Ly * dt and is kept in [-Lx/2, Lx/2).  All lengths in units of the small radius a.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def minimum_image(dx, dy, lx, ly, le_offset):
    """Minimum-image pair vector with Lees–Edwards images: y first, then the offset, then x."""
    if dy > 0.5 * ly:
        dy -= ly
        dx -= le_offset
    elif dy < -0.5 * ly:
        dy += ly
        dx += le_offset
    dx -= lx * np.floor(dx / lx + 0.5)
    return dx, dy


@njit(cache=True)
def wrap_positions(pos, lx, ly, le_offset):
    """Wrap positions into the primary box in place; crossing the top/bottom shifts x by -/+ le_offset."""
    for i in range(pos.shape[0]):
        y = pos[i, 1]
        if y >= 0.5 * ly:
            pos[i, 1] = y - ly
            pos[i, 0] -= le_offset
        elif y < -0.5 * ly:
            pos[i, 1] = y + ly
            pos[i, 0] += le_offset
        pos[i, 0] -= lx * np.floor(pos[i, 0] / lx + 0.5)


@njit(cache=True)
def wrap_offset(le_offset, lx):
    return le_offset - lx * np.floor(le_offset / lx + 0.5)


@njit(cache=True)
def _cell_of(x, origin, width, ncell):
    c = int(np.floor((x - origin) / width))
    if c < 0:
        c += ncell * (1 + (-c) // ncell)
    return c % ncell


@njit(cache=True)
def _append(pi, pj, npair, i, j):
    """Store pair (i, j) at index ``npair`` of the pair arrays, which are doubled when full (the pair
    count is not known in advance); returns the arrays."""
    if npair == pi.shape[0]:
        pi2 = np.empty(2 * npair, dtype=np.int64)
        pj2 = np.empty(2 * npair, dtype=np.int64)
        pi2[:npair] = pi
        pj2[:npair] = pj
        pi = pi2
        pj = pj2
    pi[npair] = i
    pj[npair] = j
    return pi, pj


@njit(cache=True)
def neighbour_pairs(pos, radii, lx, ly, le_offset, max_gap_scaled, skin):
    """All pairs i < j with centre distance r < a_i + a_j + max_gap_scaled * (a_i + a_j)/2 + skin.

    Cell list whose rows wrap in y with the Lees–Edwards shift: for a neighbouring row across the
    top or bottom boundary the column range is taken around x -/+ le_offset.

    Returns (pair_i, pair_j) int64 arrays sorted by (j, i).
    """
    n = pos.shape[0]
    amax = radii.max()
    rc = 2.0 * amax * (1.0 + 0.5 * max_gap_scaled) + skin
    ncx = int(lx // rc)
    ncy = int(ly // rc)
    if ncx < 3 or ncy < 3:
        return brute_force_pairs(pos, radii, lx, ly, le_offset, max_gap_scaled, skin)
    wx = lx / ncx
    wy = ly / ncy
    head = -np.ones(ncx * ncy, dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    for i in range(n):
        cx = _cell_of(pos[i, 0], -0.5 * lx, wx, ncx)
        cy = _cell_of(pos[i, 1], -0.5 * ly, wy, ncy)
        c = cy * ncx + cx
        nxt[i] = head[c]
        head[c] = i
    pi = np.empty(16 * n, dtype=np.int64)
    pj = np.empty(16 * n, dtype=np.int64)
    npair = 0
    for i in range(n):
        xi = pos[i, 0]
        cy = _cell_of(pos[i, 1], -0.5 * ly, wy, ncy)
        for dcy in range(-1, 2):
            ry = cy + dcy
            shift = 0.0
            if ry < 0:
                ry += ncy
                shift = -le_offset  # images of the top row seen from below sit at x - offset
            elif ry >= ncy:
                ry -= ncy
                shift = le_offset
            # a particle j in row ry appears at x_j + shift; we need |x_i - x_j - shift| < rc
            cx = _cell_of(xi - shift, -0.5 * lx, wx, ncx)
            for dcx in range(-1, 2):
                rx = (cx + dcx) % ncx
                j = head[ry * ncx + rx]
                while j >= 0:
                    if j > i:
                        dx, dy = minimum_image(pos[j, 0] - xi, pos[j, 1] - pos[i, 1], lx, ly, le_offset)
                        ai = radii[i]
                        aj = radii[j]
                        cut = (ai + aj) * (1.0 + 0.5 * max_gap_scaled) + skin
                        if dx * dx + dy * dy < cut * cut:
                            pi, pj = _append(pi, pj, npair, i, j)
                            npair += 1
                    j = nxt[j]
    return _sort_pairs(pi[:npair], pj[:npair], n)


@njit(cache=True)
def brute_force_pairs(pos, radii, lx, ly, le_offset, max_gap_scaled, skin):
    """O(N^2) reference for ``neighbour_pairs`` (also used when the box holds fewer than 3 cells)."""
    n = pos.shape[0]
    pi = np.empty(max(n, 1), dtype=np.int64)
    pj = np.empty(max(n, 1), dtype=np.int64)
    npair = 0
    for i in range(n):
        for j in range(i + 1, n):
            dx, dy = minimum_image(pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], lx, ly, le_offset)
            cut = (radii[i] + radii[j]) * (1.0 + 0.5 * max_gap_scaled) + skin
            if dx * dx + dy * dy < cut * cut:
                pi, pj = _append(pi, pj, npair, i, j)
                npair += 1
    return _sort_pairs(pi[:npair], pj[:npair], n)


@njit(cache=True)
def _sort_pairs(pi, pj, n):
    key = pj * n + pi
    order = np.argsort(key)
    return pi[order].copy(), pj[order].copy()


@njit(cache=True)
def pair_geometry(pos, radii, pair_i, pair_j, lx, ly, le_offset):
    """Per pair: unit normal n (i -> j), distance r, reduced gap xi = h / a_bar, and y-separation dy.

    Shapes: n (P, 2), r (P,), xi (P,), dy (P,).  dy (minimum image, Lees–Edwards aware) gives the affine
    relative velocity shear_rate * dy e_x of j with respect to i.
    """
    npair = pair_i.shape[0]
    nvec = np.empty((npair, 2))
    r = np.empty(npair)
    xi = np.empty(npair)
    dyv = np.empty(npair)
    for p in range(npair):
        i = pair_i[p]
        j = pair_j[p]
        dx, dy = minimum_image(pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], lx, ly, le_offset)
        d = np.sqrt(dx * dx + dy * dy)
        r[p] = d
        nvec[p, 0] = dx / d
        nvec[p, 1] = dy / d
        abar = 0.5 * (radii[i] + radii[j])
        xi[p] = (d - radii[i] - radii[j]) / abar
        dyv[p] = dy
    return nvec, r, xi, dyv
