"""Lees–Edwards periodic geometry and neighbour search in a 3D box (numba kernels).

Axes as in the 2D code, extended by the vorticity axis: flow along x, gradient along y, vorticity along z,
so the affine velocity is u = shear_rate * y e_x and the affine angular velocity -shear_rate/2 e_z.  A
planar system (all centres at one z) is then exactly the 2D monolayer.  LF_DEM shears along x with the
gradient along z and vorticity along y; its frame maps onto ours by the proper rotation
(x, y, z)_ours = (x, z, -y)_LF_DEM (so sigma_xy ours = sigma_xz LF_DEM, sigma_zz ours = sigma_yy LF_DEM).

The box is [-Lx/2, Lx/2) x [-Ly/2, Ly/2) x [-Lz/2, Lz/2).  ``le_offset`` is the x-shift of the image box
above (y + Ly), grows by shear_rate * Ly * dt and is kept in [-Lx/2, Lx/2); z is plainly periodic.
All lengths in units of the small radius a.
"""

import numpy as np
from numba import njit

from rheograph.sim import geometry
from rheograph.sim.geometry import _append, _cell_of, _sort_pairs


@njit(cache=True)
def minimum_image(dx, dy, dz, lx, ly, lz, le_offset):
    """Minimum-image pair vector with Lees–Edwards images: (x, y) as in 2D (y first, with the offset, then
    x), then z, plainly periodic."""
    dx, dy = geometry.minimum_image(dx, dy, lx, ly, le_offset)
    dz -= lz * np.floor(dz / lz + 0.5)
    return dx, dy, dz


@njit(cache=True)
def wrap_positions(pos, lx, ly, lz, le_offset):
    """Wrap positions (N, 3) into the primary box in place: (x, y) as in 2D (crossing the top/bottom y
    face shifts x by -/+ le_offset), then z."""
    geometry.wrap_positions(pos, lx, ly, le_offset)
    for i in range(pos.shape[0]):
        pos[i, 2] -= lz * np.floor(pos[i, 2] / lz + 0.5)


@njit(cache=True)
def neighbour_pairs(pos, radii, lx, ly, lz, le_offset, max_gap_scaled, skin):
    """All pairs i < j with centre distance r < (a_i + a_j)(1 + max_gap_scaled/2) + skin.

    Cell list (27-cell stencil) whose y-layers wrap with the Lees–Edwards shift: for a neighbouring layer
    across the top or bottom face the x-columns are taken around x -/+ le_offset.  Falls back to all pairs
    when any direction holds fewer than 3 cells (the stencil would visit a cell twice).

    Returns (pair_i, pair_j) int64 arrays sorted by (j, i).
    """
    n = pos.shape[0]
    rc = 2.0 * radii.max() * (1.0 + 0.5 * max_gap_scaled) + skin
    ncx = int(lx // rc)
    ncy = int(ly // rc)
    ncz = int(lz // rc)
    if ncx < 3 or ncy < 3 or ncz < 3:
        return brute_force_pairs(pos, radii, lx, ly, lz, le_offset, max_gap_scaled, skin)
    wx = lx / ncx
    wy = ly / ncy
    wz = lz / ncz
    head = -np.ones(ncx * ncy * ncz, dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    for i in range(n):
        cx = _cell_of(pos[i, 0], -0.5 * lx, wx, ncx)
        cy = _cell_of(pos[i, 1], -0.5 * ly, wy, ncy)
        cz = _cell_of(pos[i, 2], -0.5 * lz, wz, ncz)
        c = (cz * ncy + cy) * ncx + cx
        nxt[i] = head[c]
        head[c] = i
    pi = np.empty(32 * n, dtype=np.int64)
    pj = np.empty(32 * n, dtype=np.int64)
    npair = 0
    for i in range(n):
        xi = pos[i, 0]
        cy = _cell_of(pos[i, 1], -0.5 * ly, wy, ncy)
        cz = _cell_of(pos[i, 2], -0.5 * lz, wz, ncz)
        for dcy in range(-1, 2):
            ry = cy + dcy
            shift = 0.0
            if ry < 0:
                ry += ncy
                shift = -le_offset  # images of the top layer seen from below sit at x - offset
            elif ry >= ncy:
                ry -= ncy
                shift = le_offset
            # a particle j in layer ry appears at x_j + shift; we need |x_i - x_j - shift| < rc
            cx = _cell_of(xi - shift, -0.5 * lx, wx, ncx)
            for dcz in range(-1, 2):
                rz = (cz + dcz) % ncz
                for dcx in range(-1, 2):
                    rx = (cx + dcx) % ncx
                    j = head[(rz * ncy + ry) * ncx + rx]
                    while j >= 0:
                        if j > i:
                            dx, dy, dz = minimum_image(
                                pos[j, 0] - xi, pos[j, 1] - pos[i, 1], pos[j, 2] - pos[i, 2],
                                lx, ly, lz, le_offset,
                            )  # fmt: skip
                            cut = (radii[i] + radii[j]) * (1.0 + 0.5 * max_gap_scaled) + skin
                            if dx * dx + dy * dy + dz * dz < cut * cut:
                                pi, pj = _append(pi, pj, npair, i, j)
                                npair += 1
                        j = nxt[j]
    return _sort_pairs(pi[:npair], pj[:npair], n)


@njit(cache=True)
def brute_force_pairs(pos, radii, lx, ly, lz, le_offset, max_gap_scaled, skin):
    """O(N^2) reference for ``neighbour_pairs`` (also its fallback in small boxes)."""
    n = pos.shape[0]
    pi = np.empty(max(n, 1), dtype=np.int64)
    pj = np.empty(max(n, 1), dtype=np.int64)
    npair = 0
    for i in range(n):
        for j in range(i + 1, n):
            dx, dy, dz = minimum_image(
                pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], pos[j, 2] - pos[i, 2], lx, ly, lz, le_offset
            )
            cut = (radii[i] + radii[j]) * (1.0 + 0.5 * max_gap_scaled) + skin
            if dx * dx + dy * dy + dz * dz < cut * cut:
                pi, pj = _append(pi, pj, npair, i, j)
                npair += 1
    return _sort_pairs(pi[:npair], pj[:npair], n)


@njit(cache=True)
def pair_geometry(pos, radii, pair_i, pair_j, lx, ly, lz, le_offset):
    """Per pair: unit normal n (i -> j), distance r, reduced gap xi = h / a_bar, and y-separation dy.

    Shapes: n (P, 3), r (P,), xi (P,), dy (P,).  dy (minimum image, Lees–Edwards aware) gives the affine
    relative velocity shear_rate * dy e_x of j with respect to i.
    """
    npair = pair_i.shape[0]
    nvec = np.empty((npair, 3))
    r = np.empty(npair)
    xi = np.empty(npair)
    dyv = np.empty(npair)
    for p in range(npair):
        i = pair_i[p]
        j = pair_j[p]
        dx, dy, dz = minimum_image(
            pos[j, 0] - pos[i, 0], pos[j, 1] - pos[i, 1], pos[j, 2] - pos[i, 2], lx, ly, lz, le_offset
        )
        d = np.sqrt(dx * dx + dy * dy + dz * dz)
        r[p] = d
        nvec[p, 0] = dx / d
        nvec[p, 1] = dy / d
        nvec[p, 2] = dz / d
        xi[p] = (d - radii[i] - radii[j]) / (0.5 * (radii[i] + radii[j]))
        dyv[p] = dy
    return nvec, r, xi, dyv
