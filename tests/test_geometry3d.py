"""3D Lees–Edwards geometry, neighbour search and the random start in a cube."""

import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.sim.geometry3d import (
    brute_force_pairs,
    minimum_image,
    neighbour_pairs,
    pair_geometry,
    wrap_positions,
)
from rheograph.sim.init_config3d import initial_configuration
from rheograph.sim.params3d import SimParams3D


def random_system(n, box, seed):
    rng = np.random.default_rng(seed)
    pos = (rng.random((n, 3)) - 0.5) * box
    radii = np.where(rng.random(n) < 0.5, 1.0, 1.4)
    return pos, radii


@pytest.mark.parametrize("offset", [0.0, 3.3, -7.1, 9.99])
def test_cell_list_equals_brute_force_with_lees_edwards_offset(offset):
    lx, ly, lz = 20.0, 18.0, 16.0
    pos, radii = random_system(600, 18.0, 3)
    pos[:, 0] *= lx / 18.0
    pos[:, 2] *= lz / 18.0
    got = neighbour_pairs(pos, radii, lx, ly, lz, offset, 0.5, 0.4)
    ref = brute_force_pairs(pos, radii, lx, ly, lz, offset, 0.5, 0.4)
    assert got[0].shape[0] > 300
    np.testing.assert_array_equal(got[0], ref[0])
    np.testing.assert_array_equal(got[1], ref[1])


def nearest_image(delta, lx, ly, lz, offset):
    """Shortest of the 27 Lees–Edwards images of a pair vector, by search."""
    images = [
        delta + np.array([kx * lx + ky * offset, ky * ly, kz * lz])
        for kx in (-1, 0, 1)
        for ky in (-1, 0, 1)
        for kz in (-1, 0, 1)
    ]
    return min(images, key=np.linalg.norm)


def test_minimum_image_is_the_nearest_lees_edwards_image():
    """A pair straddling the sheared face, the vorticity faces or both gives the nearest image, so the
    same r, n and gap as the pair shifted into the interior."""
    lx, ly, lz, offset = 12.0, 11.0, 10.0, 3.7
    rng = np.random.default_rng(1)
    for _ in range(200):
        a, b = (rng.random((2, 3)) - 0.5) * [lx, ly, lz]
        d = np.array(minimum_image(*(b - a), lx, ly, lz, offset))
        ref = nearest_image(b - a, lx, ly, lz, offset)
        if np.linalg.norm(ref) < 0.45 * min(lx, ly, lz):  # unique within interaction range
            np.testing.assert_allclose(d, ref, atol=1e-12)
    # j just above the top face, seen from i near the bottom: the image below is shifted by -offset
    pos = np.array([[0.0, -5.3, 4.9], [offset + 0.5, 4.9, -4.8]])
    n, r, xi, dy = pair_geometry(pos, np.array([1.0, 1.0]), np.array([0]), np.array([1]), lx, ly, lz, offset)
    np.testing.assert_allclose(r[0] * n[0], [0.5, -0.8, 0.3], atol=1e-12)
    assert dy[0] == pytest.approx(-0.8)
    assert xi[0] == pytest.approx(np.sqrt(0.98) - 2.0)


def test_wrap_shifts_x_by_the_offset_across_the_gradient_faces_only():
    lx = ly = lz = 10.0
    pos = np.array([[1.0, 5.2, 0.0], [2.0, -5.5, 0.0], [1.0, 0.0, 5.5]])
    wrap_positions(pos, lx, ly, lz, 3.0)
    np.testing.assert_allclose(pos, [[-2.0, -4.8, 0.0], [-5.0, 4.5, 0.0], [1.0, 0.0, -4.5]])


def test_initial_configuration_is_overlap_free_at_the_volume_fraction_with_equal_species_volumes():
    params = SimParams3D(n_particles=200, phi=0.55, seed=3)
    pos, radii, box = initial_configuration(params)
    assert pos.shape == (200, 3) and np.all(np.abs(pos) <= box / 2)
    assert 4 * np.pi / 3 * np.sum(radii**3) / box**3 == pytest.approx(0.55, rel=1e-12)
    small, large = radii == 1.0, radii == 1.4
    assert np.sum(radii[large] ** 3) == pytest.approx(np.sum(radii[small] ** 3), rel=0.02)
    assert brute_force_pairs(pos, radii, box, box, box, 0.0, 0.0, 0.0)[0].shape[0] == 0


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(phi=0.66), "sim.phi=0.66 is invalid: allowed 0 < phi <= 0.64 (random close packing"),
        (dict(n_particles=40), "sim.n_particles=40 is too small for the interaction cut-off"),
        (dict(control="strain"), "sim.control='strain' is invalid"),
        (dict(control="rate", shear_rate=-1.0), "sim.shear_rate=-1.0 is invalid"),
    ],
)
def test_bad_3d_input_is_refused_in_one_line(kwargs, message):
    with pytest.raises(InputError) as err:
        SimParams3D(**{"n_particles": 300, **kwargs})
    assert str(err.value).startswith(message)
    assert "\n" not in str(err.value)
