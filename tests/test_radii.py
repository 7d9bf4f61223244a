"""Radii estimated from a configuration (rheograph.graphs.radii_estimate): exact on touching lattices in 2D
and 3D (closed form: every pair at 2a), and on the committed polydisperse runs a fraction of the error of
the nominal radii; bad input refused by name.  A bare file of nominal radii and a measured phi: read when
it declares them (radii_nominal, predict.py --radii estimated-mean) and predicted as the benchmark's path,
refused in one line when it does not or when its phi lies beyond the tolerance."""

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from rheograph.errors import InputError
from rheograph.graphs.radii_estimate import (
    declared_precision,
    estimate_radii,
    estimate_scatter,
    near_pairs,
    snapshots_with_estimated_radii,
)
from rheograph.io.configurations import area_fraction
from rheograph.io.hdf5 import read_run_info
from rheograph.io.snapshots import read_snapshots, write_bare

ROOT = Path(__file__).resolve().parents[1]
POLYDISPERSE = ROOT / "data" / "polydisperse" / "multirun"
PAPER_RUN = ROOT / "data" / "paper" / "multirun" / "N400_phi0.76_s10_seed1_d0.002_implicit" / "trajectory.h5"


def lattice(dim: int, cells: int, spacing: float) -> tuple[np.ndarray, tuple]:
    """A square (cubic) lattice of cells^dim sites ``spacing`` [a] apart filling a periodic box, centred."""
    axes = [np.arange(cells) * spacing for _ in range(dim)]
    positions = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, dim)
    side = cells * spacing
    return positions - side / 2 + spacing / 2, (side,) * dim + (0.0,)


@pytest.mark.parametrize("dim", [2, 3])
def test_touching_lattice_gives_back_its_radius(dim):
    """Discs (spheres) of radius 1.05 touching on a lattice, nominal radius 1: every pair is 2.1 a apart,
    so the estimate is 1.05 for each, whatever the ridge (the scaling to phi restores it exactly)."""
    positions, box = lattice(dim, 6, 2.1)
    n = positions.shape[0]
    volume = np.prod(box[:dim])
    phi = n * (np.pi * 1.05**2 if dim == 2 else 4.0 * np.pi / 3.0 * 1.05**3) / volume
    radii = estimate_radii(positions, np.ones(n), box, phi)
    assert radii == pytest.approx(np.full(n, 1.05), rel=1e-12)


def nominal_of(path: Path, snaps) -> np.ndarray:
    """The species' nominal radii of a polydisperse run (its first particles are the small ones)."""
    params = read_run_info(path)["params"]
    n_large = round(params["n_particles"] / (1.0 + params["size_ratio"] ** 2))
    return np.where(np.arange(snaps.n_particles) < params["n_particles"] - n_large, 1.0, params["size_ratio"])


@pytest.mark.parametrize("spread", [0.05, 0.1])
def test_estimate_is_a_fraction_of_the_nominal_radii_error_on_polydisperse_runs(spread):
    """N = 400, phi = 0.76, sigma/sigma0 = 20, the last snapshot: the nominal radii are off by the spread
    (4.2 %, 8.5 % RMS); the estimate by under a third of that (measured 1.2 %, 2.1 %)."""
    path = POLYDISPERSE / f"N400_phi0.76_s20_poly{spread:g}_seed1_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    nominal = nominal_of(path, snaps)
    k = len(snaps) - 1
    box = (snaps.lx, snaps.ly, float(snaps.le_offset[k]))
    estimate = estimate_radii(snaps.positions[k], nominal, box, snaps.phi)

    def error(radii):
        return float(np.sqrt(np.mean((radii / snaps.radii - 1.0) ** 2)))

    assert error(nominal) == pytest.approx(0.85 * spread, rel=0.1)
    assert error(estimate) < error(nominal) / 3.0


def test_exact_radii_of_a_bidisperse_snapshot_come_back_to_the_estimators_floor():
    """The gaps of near pairs (lubricated, up to the last shell of 0.02 a) set a floor of ~1 % (1.2 %
    measured on this snapshot)."""
    snaps = read_snapshots(PAPER_RUN)
    k = len(snaps) - 1
    estimate = estimate_radii(
        snaps.positions[k], snaps.radii, (snaps.lx, snaps.ly, snaps.le_offset[k]), snaps.phi
    )
    assert np.sqrt(np.mean((estimate / snaps.radii - 1.0) ** 2)) < 0.015


@pytest.mark.parametrize(
    "nominal, phi, message",
    [(np.ones(3), 0.5, r"found \(3,\) radii"), (np.zeros(36), 0.5, "> 0"), (np.ones(36), 1.2, "phi = 1.2")],
)
def test_bad_input_is_refused_by_name(nominal, phi, message):
    positions, box = lattice(2, 6, 2.1)
    with pytest.raises(InputError, match=message):
        estimate_radii(positions, nominal, box, phi)


def polydisperse_with_nominal_radii(spread: float, count: int = 3):
    """The last ``count`` snapshots of a polydisperse run (sigma/sigma0 = 20), with each particle's
    species' nominal radius instead of its own (what a microscope gives), and the true radii."""
    path = POLYDISPERSE / f"N400_phi0.76_s20_poly{spread:g}_seed1_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    snaps = snaps.select(slice(len(snaps) - count, len(snaps)))
    return dataclasses.replace(snaps, radii=nominal_of(path, snaps)), snaps.radii


def test_estimated_radii_per_snapshot_and_their_mean():
    nominal, true = polydisperse_with_nominal_radii(0.1)
    parts, _ = snapshots_with_estimated_radii(nominal)
    assert len(parts) == 3 and all(len(p) == 1 for p in parts)
    (mean,), _ = snapshots_with_estimated_radii(nominal, mean=True)
    assert len(mean) == 3 and mean.radii == pytest.approx(np.mean([p.radii for p in parts], axis=0))

    def error(radii):
        return np.sqrt(np.mean((radii / true - 1.0) ** 2))

    assert error(mean.radii) < min(error(p.radii) for p in parts)  # averaging frames helps
    with pytest.raises(InputError, match="give the nominal radii"):
        snapshots_with_estimated_radii(dataclasses.replace(nominal, radii=true))
    with pytest.raises(InputError, match="holds 1 snapshot"):
        snapshots_with_estimated_radii(nominal.select(slice(0, 1)))


def test_scatter_of_noisy_lattice_estimates_is_their_radius_error():
    """Discs of radius 1.05 touching on a lattice, seen in 12 snapshots with fresh position noise of
    0.005 a each: every estimate errs by the noise, the mean by far less, so the estimates' scatter about
    their mean is the single-snapshot RMS error [a] (which the true radii give)."""
    positions, box = lattice(2, 8, 2.1)
    n = positions.shape[0]
    phi = n * np.pi * 1.05**2 / np.prod(box[:2])
    rng = np.random.default_rng(7)
    estimates = np.array(
        [
            estimate_radii(positions + rng.normal(0.0, 0.005, positions.shape), np.ones(n), box, phi)
            for _ in range(12)
        ]
    )
    error = np.sqrt(np.mean((estimates - 1.05) ** 2))
    assert 1e-3 < error < 1e-2  # the noise moves the radii (a check on the test, not the estimator)
    assert estimate_scatter(estimates) == pytest.approx(error, rel=0.1)
    with pytest.raises(InputError, match="at least 2 snapshots"):
        estimate_scatter(estimates[:1])


@pytest.mark.parametrize("spread", [0.05, 0.1])
def test_scatter_on_polydisperse_runs_is_most_of_one_estimates_error(spread):
    """The 20 steady snapshots (strain >= 1) of a polydisperse run (sigma/sigma0 = 20): the scatter [a],
    measured without the true radii, is most of one snapshot's true RMS error (measured 0.92 of it at a 5 %
    spread, 0.73 at 10 %, where more of the error persists over the snapshots and is not seen)."""
    nominal, true = polydisperse_with_nominal_radii(spread, count=20)
    parts, uncertainty = snapshots_with_estimated_radii(nominal)
    error = np.sqrt(np.mean([(p.radii - true) ** 2 for p in parts]))
    assert 0.65 * error < uncertainty <= 1.05 * error


def test_one_snapshots_estimate_opens_its_contacts_and_the_mean_keeps_more():
    """5 % spread, sigma/sigma0 = 100, the 20 steady snapshots: a snapshot's own estimate is fitted to its
    gaps and sets its near pairs to about equal gaps, so few overlap (measured 0.7 overlapping pairs per
    particle against the true 2.3); the mean estimate, fitted mostly to other snapshots, keeps more
    (1.2): why the single-snapshot estimate makes a model read a looser suspension (docs/imaging.md)."""
    path = POLYDISPERSE / "N400_phi0.76_s100_poly0.05_seed1_d0.002_implicit" / "trajectory.h5"
    snaps = read_snapshots(path)
    snaps = dataclasses.replace(snaps.select(snaps.strain >= 1.0), radii=nominal_of(path, snaps))
    true = read_snapshots(path).radii
    parts, _ = snapshots_with_estimated_radii(snaps)
    (mean,), _ = snapshots_with_estimated_radii(snaps, mean=True)

    def overlapping(radii, k):  # overlapping pairs per particle in snapshot k
        _, _, distance = near_pairs(snaps.positions[k], radii, (snaps.lx, snaps.ly, snaps.le_offset[k]), 0.0)
        return 2.0 * distance.size / snaps.n_particles

    count = {
        name: np.mean([overlapping(radii_of(k), k) for k in range(len(snaps))])
        for name, radii_of in [
            ("true", lambda k: true),
            ("own", lambda k: parts[k].radii),
            ("mean", lambda k: mean.radii),
        ]
    }
    assert count["own"] < 0.4 * count["true"] and count["mean"] > 1.4 * count["own"]


def test_declared_precision_adds_the_radii_uncertainty_to_the_positions():
    """The precision a model is told grows with the radii's uncertainty: exact positions take it whole,
    stated ones in quadrature, per-snapshot ones each; an unstated one stays unstated; on the runs, the
    wider spread's worse estimate is told a coarser precision."""
    assert declared_precision(0.0, 0.02) == pytest.approx(0.02)
    assert declared_precision(0.03, 0.04) == pytest.approx(0.05)
    assert declared_precision(np.array([0.0, 0.03]), 0.04) == pytest.approx([0.04, 0.05])
    assert declared_precision(None, 0.02) is None
    told = {}
    for spread in (0.05, 0.1):
        nominal, _ = polydisperse_with_nominal_radii(spread, count=20)
        nominal.position_noise = 0.01
        parts, uncertainty = snapshots_with_estimated_radii(nominal)
        (mean,), _ = snapshots_with_estimated_radii(nominal, mean=True)
        assert [p.position_noise for p in parts] == pytest.approx([np.hypot(0.01, uncertainty)] * 20)
        assert mean.position_noise == pytest.approx(np.hypot(0.01, uncertainty))
        told[spread] = uncertainty
    assert told[0.1] > 1.3 * told[0.05]


def test_a_model_given_spread_radii_predicts_and_flags_them():
    """The exact shipped model on a 10 % polydisperse suspension: given the true radii it predicts (the
    species one-hot by size, the one-solve with the true radii) and flags the spread; given estimated
    radii it flags them too."""
    import rheograph

    nominal, true = polydisperse_with_nominal_radii(0.1, count=2)
    model = rheograph.load_model("N400_phi0.76")
    given = model.predict_snapshots(dataclasses.replace(nominal, radii=true))
    assert np.isfinite(given["eta_pred"]).all() and not given["in_domain"].any()
    assert "radii spread about the two species' sizes (8.3% RMS)" in given["notes"][0]
    estimated = model.predict_with_estimated_radii(nominal)
    assert list(estimated["snapshot"]) == [0, 1] and not estimated["in_domain"].any()
    assert "radii spread" in estimated["notes"][1]
    # told the radii's uncertainty as position noise (the source's positions are exact), which an exact
    # model flags too
    assert estimated["position_noise"] == pytest.approx(estimated["radii_uncertainty"])
    assert 0.005 < estimated["radii_uncertainty"][0] < 0.05
    assert "positions known to" in estimated["notes"][0]


# ---- a bare file of nominal radii and a measured phi ----------------------------------------------
NOMINAL_RUN = POLYDISPERSE / "N400_phi0.76_s20_poly0.1_seed1_d0.002_implicit" / "trajectory.h5"


@pytest.fixture(scope="module")
def microscope_file(tmp_path_factory):
    """What a microscope gives of the 10 % polydisperse run at sigma/sigma0 = 20: its last 3 snapshots
    with each particle's species' nominal radius (1 or 1.4) and the sample's true phi 0.76 (measured
    apart; the nominal radii give 0.7505), written as a bare file without the declaration; with the
    snapshots the benchmark gives the models (bench/unknown_radii.py)."""
    import bench.unknown_radii as bench

    snaps = read_snapshots(NOMINAL_RUN)
    given = bench._with_radii(snaps, nominal_of(NOMINAL_RUN, snaps))
    given.position_noise = 0.0  # the simulator's positions are exact
    keep = np.arange(len(snaps)) >= len(snaps) - 3
    path = tmp_path_factory.mktemp("microscope") / "nominal.npz"
    write_bare(path, given.select(keep))
    return path, given, keep


def declared(path: Path, tmp_path: Path, **change) -> Path:
    """A copy of the bare file ``path`` declaring its radii nominal, with keys changed."""
    values = dict(np.load(path))
    values.update({"radii_nominal": 1, **change})
    out = tmp_path / "declared.npz"
    np.savez(out, **values)
    return out


def test_a_file_declaring_nominal_radii_predicts_as_the_benchmark_with_the_true_phi(
    microscope_file, tmp_path
):
    """Read from a bare file that declares its radii nominal (radii_nominal = 1), the measured phi
    stands: the mean radius estimate is scaled to it and the imaging model predicts what the
    benchmark's 'radii estimated, mean' row predicts from the trajectory's own phi, to round-off."""
    import bench.unknown_radii as bench
    import rheograph

    path, given, keep = microscope_file
    snaps = read_snapshots(declared(path, tmp_path))
    assert snaps.radii_nominal and snaps.phi == 0.76
    assert area_fraction(snaps.radii, snaps.lx, snaps.ly) == pytest.approx(0.7505, abs=1e-4)
    model = rheograph.load_model("N400_phi0.76_imaging")
    table = model.predict_with_estimated_radii(snaps, mean=True)
    expected, _, _, told = bench.predict(model, given, keep, "radii estimated, mean")
    predicted = np.stack([table[f"{t}_pred"] for t in ("eta", "pressure", "z_mu")], axis=1)
    np.testing.assert_allclose(predicted, expected, rtol=1e-9)
    assert table["position_noise"] == pytest.approx(np.full(3, told), rel=1e-12)
    assert (table["phi"] == 0.76).all()


def test_predict_cli_estimating_radii_declares_them_nominal(microscope_file, tmp_path):
    """predict.py --radii estimated-mean reads the undeclared file's radii as nominal and its phi as
    measured (the same predictions as the declared file); --radii given refuses it in one line."""
    import csv

    import rheograph
    from rheograph.learn.predict import main

    path, _, _ = microscope_file
    out = tmp_path / "p.csv"
    main(
        [
            "--models",
            "N400_phi0.76_imaging",
            "--input",
            str(path),
            "--out",
            str(out),
            "--radii",
            "estimated-mean",
        ]
    )
    rows = list(csv.DictReader(line for line in out.read_text().splitlines() if not line.startswith("#")))
    model = rheograph.load_model("N400_phi0.76_imaging")
    table = model.predict_with_estimated_radii(read_snapshots(declared(path, tmp_path)), mean=True)
    assert [float(r["eta_pred"]) for r in rows] == pytest.approx(table["eta_pred"], rel=1e-6)
    with pytest.raises(InputError, match=r"phi = 0\.76 but the radii and box give an area fraction 0\.7505"):
        main(["--models", "N400_phi0.76_imaging", "--input", str(path), "--out", str(out)])


def test_nominal_radii_and_a_measured_phi_undeclared_are_refused_in_one_line(microscope_file):
    path, _, _ = microscope_file
    with pytest.raises(InputError) as refused:
        read_snapshots(path)
    text = str(refused.value)
    assert "\n" not in text and text.startswith(
        f"{path}: phi = 0.76 but the radii and box give an area fraction 0.7505"
    )
    assert "radii_nominal = 1" in text and "--radii estimated-mean" in text


@pytest.mark.parametrize("phi, accepted", [(0.785, True), (0.73, True), (0.80, False), (0.71, False)])
def test_a_declared_nominal_file_is_held_to_five_per_cent_of_its_radii_phi(
    microscope_file, tmp_path, phi, accepted
):
    """The nominal radii give 0.7505: a measured phi within 5 % of it (0.785: +4.6 %, 0.73: -2.7 %) is
    taken, one beyond (0.80: +6.6 %, 0.71: -5.4 %) is refused in one line naming both."""
    path = declared(microscope_file[0], tmp_path, phi=phi)
    if accepted:
        assert read_snapshots(path).phi == phi
        return
    with pytest.raises(
        InputError, match=rf"phi = {phi:g} but the nominal radii and box give an area fraction 0\.7505"
    ) as refused:
        read_snapshots(path)
    assert "\n" not in str(refused.value) and "beyond the 5%" in str(refused.value)


@pytest.mark.parametrize(
    "value, message",
    [
        (2, "radii_nominal = 2: allowed 0 or 1"),
        (-1, "radii_nominal = -1: allowed 0 or 1"),
        (0.5, "radii_nominal = 0.5: allowed 0 or 1"),
        (np.nan, "'radii_nominal' = nan is not finite"),
        ("yes", "'radii_nominal' must be numbers"),
        (np.array([1, 1]), "'radii_nominal' must be one number"),
        (np.ones(3, dtype=complex), "'radii_nominal' must be real numbers"),
    ],
)
def test_a_bad_radii_nominal_value_is_one_line(microscope_file, tmp_path, value, message):
    path = declared(microscope_file[0], tmp_path, radii_nominal=value)
    with pytest.raises(InputError, match=message) as refused:
        read_snapshots(path)
    assert "\n" not in str(refused.value) and str(refused.value).startswith(f"{path}: ")


def test_declared_nominal_radii_are_not_read_as_given_and_round_trip(microscope_file, tmp_path):
    """A model is not given radii declared nominal as though they were each particle's own (it names
    the estimate); write_bare keeps the declaration; radii_nominal = 0 is the strict default."""
    import rheograph

    snaps = read_snapshots(declared(microscope_file[0], tmp_path))
    with pytest.raises(InputError, match="declared nominal .*--radii estimated-mean"):
        rheograph.load_model("N400_phi0.76_imaging").predict_snapshots(snaps)
    write_bare(tmp_path / "again.npz", snaps)
    assert read_snapshots(tmp_path / "again.npz").radii_nominal
    with pytest.raises(InputError, match="radii_nominal = 1"):
        read_snapshots(declared(microscope_file[0], tmp_path, radii_nominal=0))
