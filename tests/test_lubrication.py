"""Pair-level checks of the lubrication/dashpot resistance (validation ladder rung 1)."""

import numpy as np
import pytest

from rheograph.sim.lubrication import (
    N_COEFF,
    XA,
    YA,
    contact_block,
    pair_block,
    pair_coefficients,
    singular_factors,
    strain_force,
)
from rheograph.sim.stress import _add_lubrication_stresslet

RADII = [(1.0, 1.0), (1.0, 1.4), (1.4, 1.0), (1.4, 1.4)]


def coefficients(ai, aj, xi, delta=1e-3):
    c, ell = singular_factors(xi, delta)
    out = np.zeros(N_COEFF)
    pair_coefficients(ai, aj, c, ell, out)
    return out, c, ell


def unit(theta):
    return np.cos(theta), np.sin(theta)


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("xi", [1e-4, 0.01, 0.3, -0.01])
def test_pair_block_is_symmetric_positive_semidefinite(ai, aj, xi):
    coeff, _, _ = coefficients(ai, aj, xi)
    nx, ny = unit(0.7)
    R = pair_block(coeff, nx, ny, np.empty((6, 6)))
    np.testing.assert_allclose(R, R.T, rtol=0, atol=1e-12 * np.abs(R).max())
    # with the one-body drag added, the pair system is positive definite
    drag = np.diag([ai, ai, 4 * ai**3 / 3, aj, aj, 4 * aj**3 / 3])
    assert np.linalg.eigvalsh(R + drag).min() > 0
    # the leading-order lubrication block alone is positive semi-definite (up to round-off)
    assert np.linalg.eigvalsh(R).min() > -1e-9 * np.abs(R).max()


@pytest.mark.parametrize("ai,aj", RADII)
def test_uniform_translation_gives_no_force(ai, aj):
    coeff, _, _ = coefficients(ai, aj, 0.01)
    R = pair_block(coeff, *unit(1.1), np.empty((6, 6)))
    for u in ([1.0, 0.0], [0.0, 1.0]):
        v = np.array([u[0], u[1], 0.0, u[0], u[1], 0.0])
        np.testing.assert_allclose(R @ v, 0.0, atol=1e-10 * np.abs(R).max())


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("theta", [0.0, 0.9, 2.5])
def test_rigid_rotation_of_a_touching_pair_gives_no_force_or_torque(ai, aj, theta):
    """A pair at centre distance a_i + a_j rotating rigidly feels nothing (any rotation centre)."""
    coeff, _, _ = coefficients(ai, aj, 0.0)
    nx, ny = unit(theta)
    r = ai + aj
    xi_pos = np.array([0.3, -0.2])
    xj_pos = xi_pos + r * np.array([nx, ny])
    omega = 0.37

    def rigid(x):
        return omega * np.array([-x[1], x[0]])

    v = np.concatenate([rigid(xi_pos), [omega], rigid(xj_pos), [omega]])
    f = pair_block(coeff, nx, ny, np.empty((6, 6))) @ v
    np.testing.assert_allclose(f, 0.0, atol=1e-10 * np.abs(pair_block(coeff, nx, ny, np.empty((6, 6)))).max())


@pytest.mark.parametrize("ai,aj", RADII)
def test_squeeze_closed_form(ai, aj):
    """X^A_11 = 2 a_i^2 a_j^2 / (a_i + a_j)^3 * c, and for equal spheres F = (3/2) pi eta0 a^2 v / h."""
    xi = 1e-3
    coeff, c, _ = coefficients(ai, aj, xi, delta=1e-12)
    assert coeff[XA] == pytest.approx(2 * ai**2 * aj**2 / (ai + aj) ** 3 * c, rel=1e-12)
    if ai == aj:
        h = xi * ai
        v = 0.3  # j approaches i along -n
        R = pair_block(coeff, 1.0, 0.0, np.empty((6, 6)))
        f_i = -(R @ np.array([0, 0, 0, -v, 0, 0]))[0]
        # force on i pushes it away (-x); 6 pi eta0 units: (3/2) pi a^2 v / h / (6 pi) = a^2 v / (4 h)
        assert f_i == pytest.approx(-(ai**2) * v / (4 * h), rel=1e-6)


def test_equal_sphere_tangential_force_closed_form():
    a = 1.0
    coeff, _, ell = coefficients(a, a, 0.02)
    nx, ny = unit(0.4)
    t = np.array([-ny, nx])
    rng = np.random.default_rng(0)
    v = rng.normal(size=6)
    f = -(pair_block(coeff, nx, ny, np.empty((6, 6))) @ v)
    expected = (a * ell / 6) * ((v[3:5] - v[0:2]) @ t - a * (v[2] + v[5]))
    assert f[0:2] @ t == pytest.approx(expected, rel=1e-12)


@pytest.mark.parametrize("ai,aj", RADII)
def test_strain_force_is_the_resistance_to_affine_separation(ai, aj):
    """Extension along n pulls the pair apart: R_FE : E is +n on i and -n on j, equal and opposite."""
    coeff, _, _ = coefficients(ai, aj, 0.01)
    nx, ny = 1.0, 0.0
    g = strain_force(coeff, nx, ny, 1.0, 0.0, -1.0, np.empty(6))  # E = diag(1, -1): n.E.n = 1
    assert g[0] > 0 and g[3] < 0  # the flow pulls the particles apart: lubrication holds them together
    np.testing.assert_allclose(g[0], -g[3], rtol=1e-12)


@pytest.mark.parametrize("ai,aj", RADII)
def test_stresslet_reciprocity_translation(ai, aj):
    """R_SU = R_FE^T: the stresslet produced by translation equals (minus) the force produced by strain."""
    coeff, _, _ = coefficients(ai, aj, 0.02)
    nx, ny = unit(0.8)
    e = np.array([0.0, 0.5, 0.0])  # simple shear, unit rate
    rng = np.random.default_rng(3)
    for _ in range(3):
        u = rng.normal(size=6)
        u[2] = u[5] = 0.0  # translation only
        s = np.zeros(3)
        _add_lubrication_stresslet(s, coeff, nx, ny, u[0:2], u[3:5], 0.0, 0.0, 0.0, 0.0, 0.0, True)
        s_dot_e = s[1]  # S : E_hat = S_xy for E_xy = E_yx = 1/2
        g = strain_force(coeff, nx, ny, *e, np.empty(6))
        assert s_dot_e == pytest.approx(-(g @ u), rel=1e-10, abs=1e-12)


def test_stresslet_reciprocity_rotation_equal_spheres():
    """For equal spheres LF_DEM's Y^M rotation term equals Jeffrey-Onishi's Y^H one: full reciprocity."""
    coeff, _, _ = coefficients(1.0, 1.0, 0.02)
    nx, ny = unit(0.8)
    s = np.zeros(3)
    w = 0.6
    _add_lubrication_stresslet(s, coeff, nx, ny, np.zeros(2), np.zeros(2), w, w, 0.0, 0.0, 0.0, True)
    g = strain_force(coeff, nx, ny, 0.0, 0.5, 0.0, np.empty(6))
    assert s[1] == pytest.approx(-(g[2] + g[5]) * w, rel=1e-10)


def test_contact_block_adds_positive_stiffness():
    coeff, _, _ = coefficients(1.0, 1.4, -0.001)
    nx, ny = unit(0.3)
    base = pair_block(coeff, nx, ny, np.empty((6, 6)))
    stiff = contact_block(coeff, nx, ny, 1.0, 1.4, 5.0, 2.0, np.empty((6, 6)))
    diff = stiff - base
    np.testing.assert_allclose(diff, diff.T, atol=1e-12)
    eig = np.linalg.eigvalsh(diff)
    assert eig.min() > -1e-12 and np.sum(eig > 1e-9) == 2  # one normal and one tangential mode
    # explicit Euler (no implicit springs) is the dashpot alone, bit for bit, and a reused scratch block
    # is fully overwritten (no value of the previous pair leaks into the next)
    scratch = np.full((6, 6), np.nan)
    np.testing.assert_array_equal(contact_block(coeff, nx, ny, 1.0, 1.4, 0.0, 0.0, scratch), base)
    np.testing.assert_array_equal(pair_block(coeff, nx, ny, stiff), base)


def sym_outer(n, f):
    """(xx, xy, yy) of sym(n (x) f)."""
    return np.array([n[0] * f[0], 0.5 * (n[0] * f[1] + n[1] * f[0]), n[1] * f[1]])


def rotate_tensor(q, s):
    """(xx, xy, yy) of Q S Q^T."""
    m = q @ np.array([[s[0], s[1]], [s[1], s[2]]]) @ q.T
    return np.array([m[0, 0], m[0, 1], m[1, 1]])


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("xi", [1e-4, 0.05, 0.4])
def test_strain_stresslet_is_the_virial_of_the_strain_force(ai, aj, xi):
    """Particles held still (U = 0) in a rate of strain E: the pair stresslet, all three components, is
    minus the virial of the force the strain exerts on j with the contact lever arm a_i + a_j,
    S = -(a_i + a_j) sym(n (x) F_j), at every gap: pins the squeeze (X^M) and shear (Y^M) stresslet
    coefficients to the force coefficients X^G, Y^G, which the reciprocity test ties to the velocity
    terms and test_squeeze_closed_form to X^A.  E here is any symmetric tensor, trace included."""
    coeff, _, _ = coefficients(ai, aj, xi)
    rng = np.random.default_rng(11)
    for _ in range(4):
        n = np.array(unit(rng.uniform(0, 2 * np.pi)))
        exx, exy, eyy = rng.normal(size=3)
        s = np.zeros(3)
        _add_lubrication_stresslet(s, coeff, *n, np.zeros(2), np.zeros(2), 0.0, 0.0, exx, exy, eyy, True)
        f_j = strain_force(coeff, *n, exx, exy, eyy, np.empty(6))[3:5]
        np.testing.assert_allclose(
            s, -(ai + aj) * sym_outer(n, f_j), rtol=1e-10, atol=1e-10 * np.abs(s).max()
        )


@pytest.mark.parametrize("ai,aj", RADII)
def test_full_stresslet_reciprocity_for_any_strain(ai, aj):
    """R_SU = R_FE^T on the whole tensor: for any E (extension, shear, compression) the stresslet that
    translations U add, contracted with E (S_xx E_xx + 2 S_xy E_xy + S_yy E_yy), is -U . (R_FE : E).
    Checks the xx and yy components, which carry the particle pressure Pi."""
    coeff, _, _ = coefficients(ai, aj, 0.02)
    rng = np.random.default_rng(5)
    for _ in range(4):
        n = np.array(unit(rng.uniform(0, 2 * np.pi)))
        e = rng.normal(size=3)
        u = rng.normal(size=6)
        u[2] = u[5] = 0.0
        s = np.zeros(3)
        _add_lubrication_stresslet(s, coeff, *n, u[0:2], u[3:5], 0.0, 0.0, 0.0, 0.0, 0.0, True)
        g = strain_force(coeff, *n, *e, np.empty(6))
        assert s[0] * e[0] + 2 * s[1] * e[1] + s[2] * e[2] == pytest.approx(-(g @ u), rel=1e-10)


def test_stresslet_rotates_with_the_pair():
    """Objectivity: rotating the line of centres, the velocities and the strain rate by Q rotates the
    whole stresslet, S(Qn, QU, w, Q E Q^T) = Q S Q^T (2D spins are unchanged)."""
    coeff, _, _ = coefficients(1.0, 1.4, 0.01)
    rng = np.random.default_rng(2)
    n = np.array(unit(0.4))
    ui, uj, e = rng.normal(size=2), rng.normal(size=2), rng.normal(size=3)
    wi, wj = rng.normal(size=2)
    s = np.zeros(3)
    _add_lubrication_stresslet(s, coeff, *n, ui, uj, wi, wj, *e, True)
    for angle in (0.7, 2.0, np.pi):
        q = np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        e_rot = rotate_tensor(q, e)
        s_rot = np.zeros(3)
        _add_lubrication_stresslet(s_rot, coeff, *(q @ n), q @ ui, q @ uj, wi, wj, *e_rot, True)
        np.testing.assert_allclose(s_rot, rotate_tensor(q, s), rtol=1e-10, atol=1e-12 * np.abs(s).max())


@pytest.mark.parametrize("ai,aj", RADII)
@pytest.mark.parametrize("xi", [1e-4, 0.05, 0.4])
def test_strain_force_is_the_resistance_to_the_affine_relative_velocity(ai, aj, xi):
    """Particles held still in a rate of strain E feel what they would feel approaching and shearing
    past each other at the affine relative velocity across the contact distance, (a_i + a_j) E n:
    F_j = -(a_i + a_j) [X^A_11 (n.E.n) n + Y^A_11 (t.E.n) t], F_i = -F_j, at every gap.  Pins the strain
    coefficients X^G, Y^G to X^A, Y^A (test_squeeze_closed_form, the equal-sphere tangential closed form)."""
    coeff, _, _ = coefficients(ai, aj, xi)
    rng = np.random.default_rng(13)
    for _ in range(4):
        n = np.array(unit(rng.uniform(0, 2 * np.pi)))
        t = np.array([-n[1], n[0]])
        exx, exy, eyy = rng.normal(size=3)
        en = np.array([exx * n[0] + exy * n[1], exy * n[0] + eyy * n[1]])
        f = strain_force(coeff, *n, exx, exy, eyy, np.empty(6))
        expected = -(ai + aj) * (coeff[XA] * (n @ en) * n + coeff[YA] * (t @ en) * t)
        np.testing.assert_allclose(f[3:5], expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())
        np.testing.assert_allclose(f[0:2], -expected, rtol=1e-10, atol=1e-12 * np.abs(expected).max())


@pytest.mark.parametrize("ai,aj", RADII)
def test_shear_resistance_closed_form(ai, aj):
    """Leading log term of Jeffrey & Onishi (1984) for unequal spheres, lambda = a_j / a_i:
    Y^A_11 = (4/15) a_i lambda (2 + lambda + 2 lambda^2) / (1 + lambda)^3 ln(1/xi) -- 1/6 a ln(1/xi) for
    equal spheres (the closed form above); Y^A_12 = -Y^A_11 (momentum conservation)."""
    xi = 1e-3
    coeff, _, ell = coefficients(ai, aj, xi, delta=1e-12)
    lam = aj / ai
    assert ell == pytest.approx(np.log(1 / xi), rel=1e-8)
    expected = (4 / 15) * ai * lam * (2 + lam + 2 * lam**2) / (1 + lam) ** 3 * ell
    assert coeff[YA] == pytest.approx(expected, rel=1e-12)
    assert coeff[YA + 1] == pytest.approx(-expected, rel=1e-12)


@pytest.mark.parametrize("ai, aj", RADII)
def test_contact_block_stiffness_modes_closed_form(ai, aj):
    """The implicit springs add dt k_n g_n g_n^T + dt k_t g_t g_t^T to the contact block, g_n the relative
    normal displacement and g_t the sliding displacement per unit generalised velocity: two modes with
    eigenvalues 2 k_n (|g_n|^2 = 2) and k_t (2 + a_i^2 + a_j^2) (|g_t|^2), on exactly those vectors; the
    other four modes are the dashpot's alone.  A swapped or mis-scaled k_n / k_t fails."""
    coeff, _, _ = coefficients(ai, aj, -0.001)
    nx, ny = unit(0.7)
    k_normal, k_tangential = 5.0, 2.0
    base = pair_block(coeff, nx, ny, np.empty((6, 6)))
    diff = contact_block(coeff, nx, ny, ai, aj, k_normal, k_tangential, np.empty((6, 6))) - base
    eig = np.sort(np.linalg.eigvalsh(diff))
    expected = np.sort([2.0 * k_normal, k_tangential * (2.0 + ai**2 + aj**2)])
    np.testing.assert_allclose(eig[-2:], expected, rtol=1e-12)
    assert np.abs(eig[:4]).max() < 1e-12
    g_n = np.array([-nx, -ny, 0.0, nx, ny, 0.0])
    g_t = np.array([ny, -nx, -ai, -ny, nx, -aj])  # t = (-n_y, n_x): -t on i, +t on j, -a omega on both
    np.testing.assert_allclose(diff @ g_n, 2.0 * k_normal * g_n, atol=1e-12)
    np.testing.assert_allclose(diff @ g_t, k_tangential * (g_t @ g_t) * g_t, atol=1e-12)


def test_implicit_stiffness_is_the_step_times_the_spring_constants():
    """The integrator puts dt k_n a_bar into every contact and dt k_t a_bar into sticking contacts only
    (sliding and frictionless contacts have no tangential spring to stiffen), dt the step it assumes."""
    from conftest import sheared_frictional_problem

    from rheograph.sim import contacts

    sim, lp, _ = sheared_frictional_problem()
    s, p = sim.state, sim.params
    state = s.contact_state.copy()
    contacts.critical_load_update(
        s.radii, s.pair_i, s.pair_j, lp.nvec, lp.xi, s.stretch.copy(), state, p.kn, p.kt, p.mu, 1.0
    )
    abar = 0.5 * (s.radii[s.pair_i] + s.radii[s.pair_j])
    touching = lp.xi <= 0
    stick = state == contacts.STICK
    assert touching.sum() > 20 and stick.sum() > 5 and (touching & ~stick).sum() > 0
    np.testing.assert_allclose(lp.k_normal, np.where(touching, p.kn * abar * s.dt_assumed, 0.0), rtol=1e-14)
    np.testing.assert_allclose(lp.k_tangential, np.where(stick, p.kt * abar * s.dt_assumed, 0.0), rtol=1e-14)


@pytest.mark.parametrize("ai, aj", RADII)
@pytest.mark.parametrize("xi", [-2e-3, -1e-4, 0.0, 1e-4, 1e-3, 3e-2, 0.4])
def test_regularised_squeeze_and_shear_at_production_delta(ai, aj, xi):
    """At the production delta = 1e-3: X^A_11 = a_i g_XA / (xi + delta) and Y^A_11 = a_i g_YA ln(1 /
    (xi + delta)) for a gap xi >= 0, frozen at their xi = 0 values under contact (the dashpot), with
    g_XA = 2 lambda^2 / (1 + lambda)^3, g_YA = (4/15) lambda (2 + lambda + 2 lambda^2) / (1 + lambda)^3."""
    delta = 1e-3
    coeff, _, _ = coefficients(ai, aj, xi, delta=delta)
    lam = aj / ai
    gap = max(xi, 0.0) + delta
    assert coeff[XA] == pytest.approx(ai * 2 * lam**2 / (1 + lam) ** 3 / gap, rel=1e-13)
    g_ya = (4 / 15) * lam * (2 + lam + 2 * lam**2) / (1 + lam) ** 3
    assert coeff[YA] == pytest.approx(ai * g_ya * np.log(1 / gap), rel=1e-13)
    # momentum: the force on j from squeezing is the opposite of that on i
    assert coeff[XA + 1] == pytest.approx(-coeff[XA], rel=1e-13)


def test_resistance_is_continuous_through_contact():
    below, _, _ = coefficients(1.0, 1.4, -1e-12)
    above, _, _ = coefficients(1.0, 1.4, 1e-12)
    np.testing.assert_allclose(below, above, rtol=1e-8)


def test_rotational_modes_at_size_ratio_1_4_match_jeffrey_onishi():
    """Y^B, Y^C, Y^H, Y^M of a 1 : 1.4 pair against the leading log terms of Jeffrey & Onishi (1984) and
    Jeffrey (1992), lambda = a_j / a_i, written out here independently of the kernel, in its
    normalisation (units of 6 pi eta0: Y^B by (2/3) a^2, Y^C_11 by (4/3) a^3, Y^C_12 by (a_i + a_j)^3 / 6,
    Y^H by (4/3) a^3, Y^M by (10/9) a^3): for both orderings of the pair (lambda = 1.4 and 1/1.4)."""
    from rheograph.sim.lubrication import YB, YC, YH, YM

    xi = 1e-3
    for ai, aj in ((1.0, 1.4), (1.4, 1.0)):
        lam, inv = aj / ai, ai / aj
        coeff, _, ell = coefficients(ai, aj, xi, delta=1e-12)
        assert ell == pytest.approx(np.log(1 / xi), rel=1e-8)

        def yb(l):
            return -(1 / 5) * l * (4 + l) / (1 + l) ** 2

        def yc(l):
            return (2 / 5) * l / (1 + l)

        def yh(l):
            return (1 / 10) * l * (2 - l) / (1 + l) ** 2

        def yh12(l):
            return (1 / 20) * l**2 * (1 + 7 * l) / (1 + l) ** 2

        def ym(l):
            return (6 / 25) * l * (1 - l + 4 * l**2) / (1 + l) ** 3

        ym12 = (3 / 50) * lam**2 * (7 - 10 * lam + 7 * lam**2) / (1 + lam) ** 3
        yc12 = (4 / 5) * lam**2 / (1 + lam) ** 4
        expected = {
            YB + 0: (2 / 3) * ai**2 * yb(lam),
            YB + 1: -(2 / 3) * ai**2 * yb(lam),
            YB + 2: (2 / 3) * aj**2 * yb(inv),
            YB + 3: -(2 / 3) * aj**2 * yb(inv),
            YC + 0: (4 / 3) * ai**3 * yc(lam),
            YC + 1: (ai + aj) ** 3 / 6 * yc12,
            YC + 3: (4 / 3) * aj**3 * yc(inv),
            YH + 0: (4 / 3) * ai**3 * yh(lam),
            YH + 1: (4 / 3) * ai**3 * yh12(lam),
            YH + 2: (4 / 3) * aj**3 * yh12(inv),
            YH + 3: (4 / 3) * aj**3 * yh(inv),
            YM + 0: (10 / 9) * ai**3 * ym(lam),
            YM + 1: (10 / 9) * ai**3 * ym12,
            YM + 3: (10 / 9) * aj**3 * ym(inv),
        }
        for index, value in expected.items():
            assert coeff[index] == pytest.approx(value * ell, rel=1e-12), index
        # the (a_i + a_j)^3 / 6 normalisation and lambda^2 / (1 + lambda)^4 are symmetric in i, j
        assert coeff[YC + 2] == coeff[YC + 1]
