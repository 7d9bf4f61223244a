"""Lees–Edwards geometry and neighbour search (validation: cell list == brute force)."""

import numpy as np
import pytest

from rheograph.sim.geometry import (
    brute_force_pairs,
    minimum_image,
    neighbour_pairs,
    pair_geometry,
    wrap_positions,
)
from rheograph.sim.init_config import random_configuration


def random_system(n, box, seed):
    rng = np.random.default_rng(seed)
    pos = (rng.random((n, 2)) - 0.5) * box
    radii = np.where(rng.random(n) < 0.5, 1.0, 1.4)
    return pos, radii


@pytest.mark.parametrize("offset", [0.0, 3.3, -7.1, 12.49])
@pytest.mark.parametrize("seed", [0, 1])
def test_cell_list_equals_brute_force_with_lees_edwards_offset(offset, seed):
    box = 25.0
    pos, radii = random_system(300, box, seed)
    got = neighbour_pairs(pos, radii, box, box, offset, 0.5, 0.4)
    ref = brute_force_pairs(pos, radii, box, box, offset, 0.5, 0.4)
    assert got[0].shape[0] > 100
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_array_equal(got[1], ref[1])


def test_pairs_across_the_sheared_boundary_are_found():
    """Two particles at the top and bottom, aligned only through the Lees–Edwards image."""
    lx = ly = 20.0
    offset = 5.0
    pos = np.array([[0.0, -9.5], [5.0 - 0.0, 9.0]])  # image of 1 below: (5 - offset, 9 - 20) = (0, -11)
    radii = np.array([1.0, 1.0])
    dx, dy = minimum_image(pos[1, 0] - pos[0, 0], pos[1, 1] - pos[0, 1], lx, ly, offset)
    assert (dx, dy) == pytest.approx((0.0, -1.5))
    pi, pj = neighbour_pairs(pos, radii, lx, ly, offset, 0.5, 0.0)
    assert list(zip(pi, pj)) == [(0, 1)]
    # without the offset they are far apart in x
    assert neighbour_pairs(pos, radii, lx, ly, 0.0, 0.5, 0.0)[0].shape[0] == 0


def test_wrap_shifts_x_by_the_offset():
    lx = ly = 10.0
    pos = np.array([[1.0, 5.2], [2.0, -5.5]])
    wrap_positions(pos, lx, ly, 3.0)
    np.testing.assert_allclose(pos, [[-2.0, -4.8], [5.0 - 10.0, 4.5]])


def test_pair_geometry_gap_and_normal():
    pos = np.array([[0.0, 0.0], [2.4 + 0.12, 0.0]])
    radii = np.array([1.0, 1.4])
    n, r, xi, dy = pair_geometry(pos, radii, np.array([0]), np.array([1]), 50.0, 50.0, 0.0)
    assert r[0] == pytest.approx(2.52)
    assert xi[0] == pytest.approx(0.12 / 1.2)
    np.testing.assert_allclose(n[0], [1.0, 0.0])
    assert dy[0] == 0.0


def test_initial_configuration_is_reproducible_and_overlap_free():
    a = random_configuration(265, 135, 1.4, 46.79, seed=4)
    b = random_configuration(265, 135, 1.4, 46.79, seed=4)
    np.testing.assert_array_equal(a[0], b[0])
    pos, radii = a
    pi, pj = brute_force_pairs(pos, radii, 46.79, 46.79, 0.0, 0.0, 0.0)
    assert pi.shape[0] == 0  # no pair closer than contact
    c = random_configuration(265, 135, 1.4, 46.79, seed=5)
    assert not np.allclose(a[0], c[0])
