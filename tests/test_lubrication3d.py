"""Pair-level checks of the 3D lubrication resistance: Jeffrey & Onishi's near-contact forms along arbitrary
directions, symmetry, zero modes, E-consistency, rotation covariance and reduction to the 2D blocks."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rheograph.sim import lubrication as lub2d
from rheograph.sim.lubrication import N_COEFF, pair_coefficients, singular_factors
from rheograph.sim.lubrication3d import contact_block, pair_block, strain_force
from rheograph.sim.stress import _add_lubrication_stresslet
from rheograph.sim.stress3d import add_lubrication_stresslet

RADII = [(1.0, 1.0), (1.0, 1.4), (1.4, 1.0)]
RNG = np.random.default_rng(55)
DIRECTIONS = [v / np.linalg.norm(v) for v in RNG.normal(size=(3, 3))] + [np.array([0.0, 0.0, 1.0])]

# Jeffrey & Onishi (1984) leading near-contact coefficients for a_i = 1, as the coefficient of c (X
# functions) or ln c (Y functions), in the order 11, 12, 21, 22: equal spheres exactly, a_j = 1.4 to 6 digits
JEFFREY_ONISHI = {
    1.0: {
        "XA": (1 / 4, -1 / 4, -1 / 4, 1 / 4),
        "YA": (1 / 6, -1 / 6, -1 / 6, 1 / 6),
        "YB": (-1 / 6, 1 / 6, -1 / 6, 1 / 6),
        "YC": (4 / 15, 1 / 15, 1 / 15, 4 / 15),
    },
    1.4: {
        "XA": (0.283565, -0.283565, -0.283565, 0.283565),
        "YA": (0.197685, -0.197685, -0.197685, 0.197685),
        "YB": (-0.175000, 0.175000, -0.299444, 0.299444),
        "YC": (0.311111, 0.108889, 0.108889, 0.609778),
    },
}


def coefficients(ai, aj, xi, delta=1e-3):
    c, ell = singular_factors(xi, delta)
    out = np.zeros(N_COEFF)
    pair_coefficients(ai, aj, c, ell, out)
    return out, c, ell


def block(ai, aj, xi, n):
    coeff, c, ell = coefficients(ai, aj, xi)
    return pair_block(coeff, n, np.empty((12, 12))), coeff, c, ell


def tangent(n):
    t = np.cross(n, [0.3, -0.5, 0.8])
    return t / np.linalg.norm(t)


def cross_matrix(n):
    return np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])


@pytest.mark.parametrize("aj", [1.0, 1.4])
@pytest.mark.parametrize("k", range(len(DIRECTIONS)))
def test_blocks_reproduce_jeffrey_onishi_near_contact_forms(aj, k):
    """Projected on n and on a tangent t, each 3x3 sub-block of the 12x12 block is X^A c, Y^A ln c,
    Y^B ln c (on n x w) or Y^C ln c with Jeffrey & Onishi's coefficients, for any direction n."""
    n = DIRECTIONS[k]
    t = tangent(n)
    b = np.cross(n, t)
    R, _, c, ell = block(1.0, aj, 0.01, n)
    ref = JEFFREY_ONISHI[aj]
    for idx, (a, bb) in enumerate([(0, 0), (0, 1), (1, 0), (1, 1)]):
        A = R[6 * a : 6 * a + 3, 6 * bb : 6 * bb + 3]
        C = R[6 * a + 3 : 6 * a + 6, 6 * bb + 3 : 6 * bb + 6]
        assert n @ A @ n == pytest.approx(ref["XA"][idx] * c, rel=2e-6)
        assert t @ A @ t == pytest.approx(ref["YA"][idx] * ell, rel=2e-6)
        assert b @ A @ b == pytest.approx(ref["YA"][idx] * ell, rel=2e-6)
        assert t @ A @ n == pytest.approx(0.0, abs=1e-12 * c)
        assert t @ C @ t == pytest.approx(ref["YC"][idx] * ell, rel=2e-6)
        assert n @ C @ n == pytest.approx(0.0, abs=1e-12)  # no singular twist resistance (X^C)
        # -dF_a/dw_b = YB_ba N: the force on a from the rotation w_b = t of b is -YB_ba n x t
        force_from_rotation = -R[6 * a : 6 * a + 3, 6 * bb + 3 : 6 * bb + 6] @ t
        expected = -ref["YB"][2 * bb + a] * ell * np.cross(n, t)
        np.testing.assert_allclose(force_from_rotation, expected, rtol=2e-6)


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("k", range(len(DIRECTIONS)))
def test_squeeze_force_closed_form(ai, aj, k):
    """Approach along n at speed v and gap h: F = 6 pi eta0 (a_i a_j / (a_i + a_j))^2 v / (h + delta
    a_bar)."""
    n = DIRECTIONS[k]
    abar = 0.5 * (ai + aj)
    h = 0.02
    R, _, _, _ = block(ai, aj, h / abar, n)
    v = np.zeros(12)
    v[6:9] = -0.3 * n  # j approaches i
    force_on_j = -(R @ v)[6:9]
    expected = (ai * aj / (ai + aj)) ** 2 * 0.3 / (h + 1e-3 * abar)
    np.testing.assert_allclose(force_on_j, expected * n, rtol=1e-12)


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("xi", [1e-4, 0.05, 0.4])
def test_pair_block_is_symmetric_psd_with_seven_zero_modes_at_contact(ai, aj, xi):
    n = DIRECTIONS[0]
    R, _, _, _ = block(ai, aj, xi, n)
    np.testing.assert_allclose(R, R.T, rtol=0, atol=1e-13 * np.abs(R).max())
    eig = np.linalg.eigvalsh(R)
    assert eig.min() > -1e-10 * eig.max()
    # at contact separation: 3 translations, 2 rigid rotations normal to n and the 2 spins about n
    R0, _, _, _ = block(ai, aj, 0.0, n)
    eig0 = np.linalg.eigvalsh(R0)
    assert np.sum(np.abs(eig0) < 1e-10 * eig0.max()) == 7


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("k", range(len(DIRECTIONS)))
def test_rigid_motion_of_a_touching_pair_is_free(ai, aj, k):
    """A touching pair translating and rotating rigidly about any point feels no force or torque."""
    n = DIRECTIONS[k]
    R, _, _, _ = block(ai, aj, 0.0, n)
    xi_pos = np.array([0.3, -0.2, 0.5])
    xj_pos = xi_pos + (ai + aj) * n
    for _ in range(3):
        u0, omega = RNG.normal(size=3), RNG.normal(size=3)
        v = np.r_[u0 + np.cross(omega, xi_pos), omega, u0 + np.cross(omega, xj_pos), omega]
        np.testing.assert_allclose(R @ v, 0.0, atol=1e-11 * np.abs(R).max())


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("k", range(len(DIRECTIONS)))
def test_strain_force_is_minus_the_resistance_to_affine_strain_at_contact(ai, aj, k):
    """(G, H) = -R_pair (E x_i, 0, E x_j, 0) with x_j - x_i = (a_i + a_j) n, for any symmetric E."""
    n = DIRECTIONS[k]
    R, coeff, _, _ = block(ai, aj, 0.05, n)
    e = RNG.normal(size=(3, 3))
    e = e + e.T
    x_i = np.array([0.4, 0.1, -0.7])
    x_j = x_i + (ai + aj) * n
    affine = np.r_[e @ x_i, np.zeros(3), e @ x_j, np.zeros(3)]
    g = strain_force(coeff, n, e, np.empty(12))
    np.testing.assert_allclose(g, -R @ affine, atol=1e-11 * np.abs(R).max())


@pytest.mark.parametrize("ai,aj", RADII)
def test_blocks_forces_and_stresslets_are_rotation_covariant(ai, aj):
    """For a random proper rotation Q: R(Qn) = diag(Q,Q,Q,Q) R(n) diag(Q,Q,Q,Q)^T, forces from Q E Q^T
    rotate as vectors and stresslets as tensors; swapping the labels i <-> j changes nothing."""
    n = DIRECTIONS[0]
    q = Rotation.random(random_state=7).as_matrix()
    big = np.kron(np.eye(4), q)
    R, coeff, _, _ = block(ai, aj, 0.03, n)
    Rq = pair_block(coeff, q @ n, np.empty((12, 12)))
    np.testing.assert_allclose(Rq, big @ R @ big.T, atol=1e-12 * np.abs(R).max())
    Rc = contact_block(coeff, n, ai, aj, 50.0, 20.0, np.empty((12, 12)))
    Rcq = contact_block(coeff, q @ n, ai, aj, 50.0, 20.0, np.empty((12, 12)))
    np.testing.assert_allclose(Rcq, big @ Rc @ big.T, atol=1e-12 * np.abs(Rc).max())
    e = RNG.normal(size=(3, 3))
    e = e + e.T
    g = strain_force(coeff, n, e, np.empty(12))
    gq = strain_force(coeff, q @ n, q @ e @ q.T, np.empty(12))
    np.testing.assert_allclose(gq, big @ g, atol=1e-12 * np.abs(g).max())
    ui, uj, wi, wj = RNG.normal(size=(4, 3))
    s = np.zeros(6)
    add_lubrication_stresslet(s, coeff, n, ui, uj, wi, wj, e)
    sq = np.zeros(6)
    add_lubrication_stresslet(sq, coeff, q @ n, q @ ui, q @ uj, q @ wi, q @ wj, q @ e @ q.T)
    full = lambda v: np.array([[v[0], v[1], v[2]], [v[1], v[3], v[4]], [v[2], v[4], v[5]]])  # noqa: E731
    np.testing.assert_allclose(full(sq), q @ full(s) @ q.T, atol=1e-12 * np.abs(s).max())
    # label swap: the pair (j, i) with normal -n is the same physical pair
    swapped, _, _, _ = block(aj, ai, 0.03, -n)
    perm = np.r_[6:12, 0:6]
    np.testing.assert_allclose(swapped, R[np.ix_(perm, perm)], atol=1e-12 * np.abs(R).max())


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("xi", [0.01, -0.01])
def test_planar_pair_reduces_to_the_2d_blocks(ai, aj, xi):
    """n in the xy-plane: the (U_x, U_y, w_z) sub-block is the 2D block (dashpot and implicit springs
    included), it is uncoupled from (U_z, w_x, w_y), and forces and stresslets from an in-plane strain
    are the 2D ones with no out-of-plane part."""
    theta = 0.83
    n = np.array([np.cos(theta), np.sin(theta), 0.0])
    coeff, _, _ = coefficients(ai, aj, xi)
    inplane = [0, 1, 5, 6, 7, 11]
    outplane = [2, 3, 4, 8, 9, 10]
    for kn, kt in [(0.0, 0.0), (40.0, 15.0)]:
        R3 = contact_block(coeff, n, ai, aj, kn, kt, np.empty((12, 12)))
        R2 = lub2d.contact_block(coeff, n[0], n[1], ai, aj, kn, kt, np.empty((6, 6)))
        np.testing.assert_allclose(R3[np.ix_(inplane, inplane)], R2, rtol=1e-13, atol=1e-13)
        assert np.all(R3[np.ix_(inplane, outplane)] == 0.0)
    e = np.array([[0.0, 0.5, 0.0], [0.5, 0.0, 0.0], [0.0, 0.0, 0.0]])
    g3 = strain_force(coeff, n, e, np.empty(12))
    g2 = lub2d.strain_force(coeff, n[0], n[1], 0.0, 0.5, 0.0, np.empty(6))
    np.testing.assert_allclose(g3[inplane], g2, rtol=1e-13, atol=1e-15)
    assert np.all(g3[outplane] == 0.0)
    ui, uj = np.r_[RNG.normal(size=2), 0.0], np.r_[RNG.normal(size=2), 0.0]
    wi, wj = np.array([0.0, 0.0, 0.3]), np.array([0.0, 0.0, -0.7])
    s3 = np.zeros(6)
    add_lubrication_stresslet(s3, coeff, n, ui, uj, wi, wj, e)
    s2 = np.zeros(3)
    _add_lubrication_stresslet(s2, coeff, n[0], n[1], ui[:2], uj[:2], 0.3, -0.7, 0.0, 0.5, 0.0, True)
    np.testing.assert_allclose(s3[[0, 1, 3]], s2, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(s3[[2, 4, 5]], 0.0, atol=1e-15)


def test_stresslet_reciprocity_with_the_strain_force_for_equal_spheres():
    """E : S(U, w) = -(R_FE : E) . (U, w) for equal spheres (LF_DEM's Y^M in the rotation term equals
    Jeffrey & Onishi's Y^H only in pair sum at lambda = 1), for any E and motion."""
    n = DIRECTIONS[1]
    coeff, _, _ = coefficients(1.0, 1.0, 0.02)
    e = RNG.normal(size=(3, 3))
    e = e + e.T
    g = strain_force(coeff, n, e, np.empty(12))
    for _ in range(3):
        v = RNG.normal(size=12)
        s = np.zeros(6)
        add_lubrication_stresslet(s, coeff, n, v[0:3], v[6:9], v[3:6], v[9:12], np.zeros((3, 3)))
        contraction = (
            s[0] * e[0, 0]
            + s[3] * e[1, 1]
            + s[5] * e[2, 2]
            + 2 * (s[1] * e[0, 1] + s[2] * e[0, 2] + s[4] * e[1, 2])
        )
        assert contraction == pytest.approx(-g @ v, rel=1e-12)
