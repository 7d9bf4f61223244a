"""From a microscope frame to a snapshot (rheograph.microscope): rendered frames of a few well-separated
particles are tracked back to their positions and species, once each also across the periodic and
Lees–Edwards boundaries; a µm table converts to units of a; bad input and lost particles are refused in
one line naming the parameter; a missing trackpy is named with how to install it."""

from __future__ import annotations

import builtins

import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.microscope import (
    check_particle_count,
    from_micrometres,
    min_image,
    render_frame,
    snapshot_from_frame,
    track_frame,
)

PIXEL = 0.15  # [a per pixel]: a 1 µm-radius particle over ~13 pixels
BOX = (24.0, 24.0)  # 160 x 160 pixels
PARAMS = {"mu": 0.5, "kn_coefficient": 2e4, "kt_ratio": 0.5, "delta": 1e-3, "lub_max_gap": 0.5}


def frame_of(positions, radii, le_offset=0.0, seed=0):
    return render_frame(
        positions, radii, BOX, PIXEL, psf_sigma=0.2, photons=100, background=10,
        rng=np.random.default_rng(seed), le_offset=le_offset, dyed_fraction=0.5,
    )  # fmt: skip


def lattice(seed=1):
    """16 particles on a jittered 4 x 4 lattice of spacing 6 a (well separated), half of each species."""
    rng = np.random.default_rng(seed)
    grid = np.stack(np.meshgrid(np.arange(4), np.arange(4)), axis=-1).reshape(-1, 2) * 6.0 - 9.0
    positions = grid + rng.uniform(-1.0, 1.0, grid.shape)
    radii = np.where(rng.permutation(16) < 8, 1.0, 1.4)
    return positions, radii


def matched_errors(found, truth, le_offset=0.0):
    """For each true particle, the distance [a] to the nearest tracked one (minimum image)."""
    gaps = min_image(found[:, None] - truth[None], *BOX, le_offset)
    distance = np.hypot(gaps[..., 0], gaps[..., 1])
    return distance.min(axis=0), distance.argmin(axis=0)


def test_render_and_track_recover_the_positions():
    """Centroid error of a core of ~5 pixels radius at ~100 photons per pixel: the shot noise alone gives
    ~0.05 pixel (< 0.01 a); the PSF-blurred edge on the pixel grid (pixel locking) adds as much.  0.03 a
    (0.2 pixel) is three times the ~0.01 a the benchmark measures on dense frames."""
    positions, radii = lattice()
    tracked = track_frame(frame_of(positions, radii), PIXEL, 13)
    assert len(tracked.positions) == len(positions)
    error, _ = matched_errors(tracked.positions, positions)
    assert error.max() < 0.03
    assert tracked.box == pytest.approx(BOX)
    assert 0 < tracked.precision < 0.03  # trackpy's own estimate, of the same order


def test_species_are_exact_on_a_clean_frame():
    positions, radii = lattice(seed=2)
    tracked = track_frame(frame_of(positions, radii), PIXEL, 13, radii=(1.0, 1.4))
    _, nearest = matched_errors(tracked.positions, positions)
    assert np.array_equal(tracked.radii[nearest], radii)


@pytest.mark.parametrize("le_offset", [0.0, 7.3])
def test_a_particle_straddling_the_boundary_is_found_once(le_offset):
    """One large particle cut by the top edge (and, on the second, by the right edge too), whose image
    below the box is shifted by the Lees–Edwards offset: found once, at its place."""
    positions, radii = lattice(seed=3)
    edge = np.array([[11.6 if le_offset else 3.0, 11.7]])  # y = 11.7: 0.3 a below the top edge
    gaps = min_image(positions - edge, *BOX, le_offset)
    room = np.hypot(gaps[:, 0], gaps[:, 1]) > 4.0  # no neighbour within 4 a, across the edges too
    positions, radii = np.vstack([positions[room], edge]), np.append(radii[room], 1.4)
    tracked = track_frame(frame_of(positions, radii, le_offset), PIXEL, 13, le_offset=le_offset)
    assert len(tracked.positions) == len(positions)
    error, nearest = matched_errors(tracked.positions, positions, le_offset)
    assert error[-1] < 0.03 and tracked.radii[nearest[-1]] == 1.4
    assert len(set(nearest.tolist())) == len(positions)


def test_micrometres_round_trip():
    rng = np.random.default_rng(4)
    small = 0.75  # [µm]
    box_um = np.array([30.0, 22.5])
    xy_um = rng.uniform(0, 1, (20, 2)) * box_um
    radii_um = np.where(rng.random(20) < 0.5, small, 1.4 * small) * rng.normal(1, 0.03, 20)  # 3 % spread
    positions, radii, box = from_micrometres(xy_um, radii_um, box_um, small)
    assert box == pytest.approx(tuple(box_um / small))
    assert set(radii.tolist()) <= {1.0, 1.4}
    assert np.array_equal(radii == 1.4, radii_um > 1.2 * small)
    back = (positions + np.array(box) / 2) * small  # from the box's lower-left corner again, in µm
    assert back == pytest.approx(xy_um)
    centred, _, _ = from_micrometres(xy_um - box_um / 2, radii_um, box_um, small, origin="centre")
    assert centred == pytest.approx(positions)


@pytest.mark.parametrize(
    "change, parameter, reason",
    [
        (lambda xy, r: (xy, np.where(np.arange(len(r)) == 3, -0.5, r)), "radii_um", "positive radii"),
        (
            lambda xy, r: (np.where(np.arange(len(xy))[:, None] == 5, [31.0, 4.0], xy), r),
            "table_xy_um",
            "outside the field of view",
        ),
        (lambda xy, r: (xy, r * 2), "radii_um", "not their diameter"),  # diameters given as radii
    ],
)
def test_bad_micrometre_tables_are_refused_in_one_line(change, parameter, reason):
    rng = np.random.default_rng(5)
    xy, radii = change(rng.uniform(0, 30, (10, 2)), np.full(10, 0.75))
    with pytest.raises(InputError) as err:
        from_micrometres(xy, radii, (30.0, 30.0), 0.75)
    message = str(err.value)
    assert message.startswith(parameter) and reason in message and "\n" not in message


def test_lost_particles_are_refused_not_rescaled():
    """A frame that lost one small particle: its area fraction is 1/N short of the stated φ; refused
    (naming phi) by check_particle_count and by snapshot_from_frame, never with its box rescaled."""
    positions, radii = lattice(seed=6)
    tracked = track_frame(frame_of(positions, radii), PIXEL, 13)
    phi = float(np.pi * np.sum(radii**2) / (BOX[0] * BOX[1]))
    snaps = snapshot_from_frame(tracked, 0.0, 10.0, phi, PARAMS, position_noise=0.01)
    assert (snaps.lx, snaps.ly) == pytest.approx(BOX) and snaps.position_noise == 0.01
    lost = np.flatnonzero(tracked.radii == 1.0)[0]
    tracked.positions = np.delete(tracked.positions, lost, axis=0)
    tracked.radii = np.delete(tracked.radii, lost)
    for call in (
        lambda: check_particle_count(tracked.radii, tracked.box, phi),
        lambda: snapshot_from_frame(tracked, 0.0, 10.0, phi, PARAMS, position_noise=0.01),
    ):
        with pytest.raises(InputError) as err:
            call()
        assert str(err.value).startswith("phi = ") and "\n" not in str(err.value)
        assert "missed, merged or invented about 1 small particle" in str(err.value)


def test_without_trackpy_tracking_says_how_to_install_it(monkeypatch):
    real_import = builtins.__import__

    def no_trackpy(name, *args, **kwargs):
        if name == "trackpy" or name.startswith("trackpy."):
            raise ImportError("No module named 'trackpy'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_trackpy)
    with pytest.raises(InputError) as err:
        track_frame(np.zeros((32, 32)), PIXEL, 13)
    assert "pip install rheograph[microscope]" in str(err.value) and "\n" not in str(err.value)


def test_a_box_of_no_whole_number_of_pixels_is_refused():
    with pytest.raises(InputError, match=r"^pixel_size = 0.17: .* use pixel_size = "):
        render_frame(*lattice(), BOX, 0.17, 0.2, 100, 10, np.random.default_rng(0))
