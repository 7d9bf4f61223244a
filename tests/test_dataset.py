"""The committed paper-scale dataset (data/paper, docs/dataset.md): its index matches the files, every
flowing snapshot has finite targets, jammed runs are labelled, seeds are independent, counts hold."""

import json
import re
from collections import defaultdict
from pathlib import Path

import h5py
import numpy as np
import pytest

from rheograph.io.index import read_index

ROOT = Path(__file__).resolve().parents[1]
INDEX = ROOT / "data" / "paper" / "index.json"


@pytest.fixture(scope="module")
def index():
    return read_index(INDEX)


def test_index_lists_exactly_the_committed_runs(index):
    listed = {Path(e["path"]).resolve() for e in index["runs"]}
    on_disk = {p.resolve() for p in (ROOT / "data" / "paper").rglob("trajectory.h5")}
    assert listed == on_disk and not index["skipped"]
    for entry in index["runs"]:
        assert entry["params"]["n_particles"] in (400, 2000)
        # the converged step per area fraction (docs/validation/time_step.md): 1e-3 at phi = 0.80, 2e-3 below
        step = 1e-3 if np.isclose(entry["params"]["phi"], 0.80) else 2e-3
        assert entry["params"]["integrator"] == "implicit" and entry["params"]["disp_max"] == step


def test_flowing_snapshots_have_finite_targets_and_jammed_runs_are_labelled(index):
    from rheograph.io.hdf5 import jammed_snapshots

    for entry in index["runs"]:
        with h5py.File(entry["path"], "r") as h5:
            sn = h5["snapshots"]
            strain = sn["strain"][()]
            targets = np.stack([sn[k][()] for k in ("viscosity", "pressure", "z_mu")], axis=1)
            assert sn["positions"].shape[1:] == (entry["params"]["n_particles"], 2)
            jammed = jammed_snapshots(
                entry["status"], strain, h5["timeseries/strain"][()], entry["params"]["jam_intervals"]
            )
            flowing = (strain >= 1.0) & ~jammed
            assert np.isfinite(targets[flowing]).all() and (targets[flowing, 2] >= 0).all()
            if entry["status"] == "jammed":
                assert not np.isfinite(h5["summary"].attrs["viscosity"])  # never averaged
                assert jammed.any()  # the arrested packing: labelled, its Pi and Z_mu valid
                assert np.isfinite(targets[jammed, 1:]).all()
            else:  # finished, or partial and committed to be resumed (N = 2000 spans invocations)
                assert entry["status"] in ("completed", "interrupted", "wall_limit"), entry["path"]


def test_seeds_are_independent_initial_configurations(index):
    """Runs of one state point with different seeds start from different random packings."""
    starts = defaultdict(dict)
    for entry in index["runs"]:
        p = entry["params"]
        with h5py.File(entry["path"], "r") as h5:
            starts[(p["n_particles"], p["phi"], p["stress"])][p["seed"]] = h5["snapshots/positions"][0]
    multi = [s for s in starts.values() if len(s) > 1]
    assert multi
    for by_seed in multi:
        seeds = sorted(by_seed)
        for a, b in zip(seeds, seeds[1:]):
            assert np.abs(by_seed[a] - by_seed[b]).max() > 1.0


def test_each_complete_area_fraction_has_the_papers_snapshot_count(index):
    """Where all ten stresses have three seeds at N = 400, there are >= 380 flowing snapshots."""
    runs = defaultdict(list)
    for entry in index["runs"]:
        p = entry["params"]
        if p["n_particles"] == 400:
            runs[p["phi"]].append(entry)
    complete = [phi for phi, e in runs.items() if len(e) >= 30]
    assert complete, "no complete area fraction"
    for phi in complete:
        counts = 0
        for entry in runs[phi]:
            if entry["status"] != "jammed":
                with h5py.File(entry["path"], "r") as h5:
                    counts += int((h5["snapshots/strain"][()] >= 1.0).sum())
        assert counts >= 380, (phi, counts)
    assert json.loads(INDEX.read_text())["format"] == "rheograph-index-1"


def test_snapshots_are_spaced_by_at_least_the_decorrelation_strain(index):
    """Issue #13 item 4: per (N, phi), the snapshot spacing is at least the median (over flowing runs) 1/e
    decorrelation strain of each instantaneous target, measured over the steady window as the card does."""
    from rheograph.analysis.steady import decorrelation_strain

    taus, spacing = defaultdict(list), defaultdict(set)
    for entry in index["runs"]:
        p = entry["params"]
        key = (p["n_particles"], round(p["phi"], 2))
        spacing[key].add(p["snapshot_interval"])
        if entry["status"] != "completed":
            continue
        with h5py.File(entry["path"], "r") as h5:
            ts = h5["timeseries"]
            steady = ts["strain"][()] >= p["steady_state_strain"]
            series = (np.log(np.abs(ts["viscosity"][()]) + 1e-12), ts["pressure"][()], ts["z_mu"][()])
            taus[key].append([decorrelation_strain(x[steady], p["output_interval"]) for x in series])
    assert len(taus) >= 9
    for key, values in taus.items():
        assert len(spacing[key]) == 1, (key, spacing[key])  # one spacing per (N, phi)
        tau = np.nanmedian(np.array(values), axis=0).max()
        assert spacing[key].pop() >= tau, (key, tau)


def test_jamming_onset_per_seed_names_what_is_still_open():
    """The card's onset per seed: the smallest jammed stress, or 'none up to' the largest completed one
    of *that seed*; an unfinished run below the onset is named instead of being read as flowing."""
    from rheograph.analysis.dataset_card import jamming_onset

    def runs(**status):
        return [{"stress": float(k[1:].replace("_", ".")), "status": v} for k, v in status.items()]

    assert jamming_onset(runs(s10="completed", s20="jammed", s50="jammed")) == "20"
    assert jamming_onset(runs(s10="completed", s20="completed")) == "none up to 20"
    assert jamming_onset(runs(s20="completed", s50="interrupted")) == "none up to 20 (50 unfinished)"
    assert jamming_onset(runs(s14="running", s20="jammed", s100="running")) == "20 (14 unfinished)"
    assert jamming_onset(runs(s0_5="interrupted")) == "none yet (0.5 unfinished)"
    stalling = runs(s20="completed", s100="interrupted")
    stalling[1]["stalled_since"] = 0.884
    assert jamming_onset(stalling) == "none up to 20 (100 unfinished; 100 stalling since strain 0.88)"


def test_stall_start_is_where_the_trailing_slow_rows_begin():
    from rheograph.analysis.steady import stall_start

    strain = np.array([0.85, 0.86, 0.87, 0.88, 0.884, 0.884])
    assert stall_start(strain, [0, 1, 0, 0, 1, 1]) == 0.884
    assert stall_start(strain, [1] * 6) == 0.85
    assert stall_start(strain, [1, 1, 1, 1, 1, 0]) is None
    assert stall_start([], []) is None


def test_flow_curve_cell_reports_the_arrested_packing_instead_of_nan():
    """A state point whose seeds all arrested before the steady window has no steady means: the card
    shows 'jammed' for eta_r and the arrested snapshots' Pi, Z_mu (mean ± standard error), never 'nan'."""
    from rheograph.analysis.dataset_card import flow_curve_cell

    nan = float("nan")
    point = dict(n_particles=400, phi=0.8, mu=0.5, radii="", stress=100.0, jammed=True)
    point.update(viscosity=nan, viscosity_se=nan, pressure=nan, pressure_se=nan, z_mu=nan, z_mu_se=nan)
    arrested = [np.array([200.0, 220.0]), np.array([240.0])]
    same = dict(n=400, phi=0.8, mu=0.5, radii="")
    records = [dict(same, stress=100.0, arrested=dict(pressure=a, z_mu=a / 100)) for a in arrested]
    records.append(dict(same, stress=200.0, arrested=dict(pressure=np.array([1e6]), z_mu=[9])))
    # another suspension at the same state point: spread radii, or frictionless
    for other in (dict(radii="polydisperse 0.1"), dict(mu=0.0)):
        records.append(dict(same, stress=100.0, **other, arrested=dict(pressure=np.array([1e6]), z_mu=[9])))
    assert flow_curve_cell(point, "viscosity", records) == "jammed"
    assert flow_curve_cell(point, "pressure", records) == "220 ± 12 (arrested)"
    assert flow_curve_cell(point, "z_mu", records) == "2.2 ± 0.12 (arrested)"
    flowing = dict(point, jammed=False, pressure=5.0, pressure_se=0.1)
    assert flow_curve_cell(flowing, "pressure", records) == "5 ± 0.1"
    assert flow_curve_cell(flowing, "z_mu", records) == "–"


def test_the_card_counts_snapshots_of_finished_runs_and_marks_provisional_means():
    """An unfinished run (committed with its checkpoint) is listed under *other* and its snapshots are
    left out of the snapshot counts, as the learning leaves them out; a flow-curve mean it enters is
    marked unfinished."""
    from rheograph.analysis.dataset_card import card_markdown

    def record(stress, status, flowing, seed=1):
        return dict(
            n=2000, phi=0.8, mu=0.5, radii="", stress=stress, seed=seed, status=status, n_snapshots=flowing,
            n_flowing_snapshots=flowing, n_jammed_snapshots=0, cpu_seconds=3600.0, bytes=10**6,
            snapshot_interval=0.1, decorrelation=dict(viscosity=0.2, pressure=0.2, z_mu=0.2),
            transient=0.3, arrested=dict(pressure=np.array([]), z_mu=np.array([])),
            log_viscosity_series=(np.array([0.0, 1.0]), np.zeros(2), stress),
        )  # fmt: skip

    records = [
        record(20.0, "completed", 20),
        record(20.0, "completed", 20, seed=2),
        record(50.0, "interrupted", 7),
    ]

    def point(stress, statuses, seeds):
        return dict(
            n_particles=2000, phi=0.8, mu=0.5, radii="", stress=stress, statuses=statuses, n_seeds=seeds,
            jammed=False,
            viscosity=1000.0, viscosity_se=50.0, pressure=40.0, pressure_se=1.0, z_mu=2.5, z_mu_se=0.01,
        )  # fmt: skip

    points = [point(20.0, ["completed"], 2), point(50.0, ["interrupted"], 1)]
    card = card_markdown(records, points, "python simulate.py -m …", 1.0)
    assert "| 2000 | 0.80 | 3 | 2 | 2 | 0 | 1 | 40 | 0 | 3.00 | 3.0 |" in card
    assert "40 snapshots of finished runs" in card and "1 unfinished run(s) (status interrupted" in card
    assert "| 2000 | 0.80 | 20 | 2 | 1000 ± 50 |" in card
    assert "| 2000 | 0.80 | 50 | 1 (unfinished) | 1000 ± 50 |" in card


def test_the_card_reports_the_ensemble_transient_and_the_bias_of_counting_from_strain_1():
    """Two state points x 3 seeds, runs to strain 4 whose log η_r sits 0.2 high until strain 1.2 (noise
    0.1 per row): the card's decorrelation row names the transient (end of the block [1, 1.5), below the
    reference window from 2) and the bias counting from strain 1 adds, 0.2 x 0.2 / 3 = +0.013."""
    from rheograph.analysis.dataset_card import card_markdown

    rng = np.random.default_rng(0)
    strain = np.arange(0.0, 4.0, 0.01)
    records = [
        dict(
            n=400,
            phi=0.7,
            mu=0.5,
            radii="",
            stress=stress,
            seed=seed,
            status="completed",
            n_snapshots=10,
            n_flowing_snapshots=10,
            n_jammed_snapshots=0,
            cpu_seconds=60.0,
            bytes=10**5,
            snapshot_interval=0.2,
            decorrelation=dict(viscosity=0.1, pressure=0.1, z_mu=0.1),
            transient=1.0,
            arrested=dict(pressure=np.array([]), z_mu=np.array([])),
            log_viscosity_series=(
                strain,
                np.where(strain < 1.2, 0.2, 0.0) + 0.1 * rng.normal(size=400),
                stress,
            ),
        )  # fmt: skip
        for stress in (1.0, 2.0)
        for seed in (1, 2, 3)
    ]
    card = card_markdown(records, [], "python simulate.py -m …", 1.0)
    row = next(line for line in card.splitlines() if line.startswith("| 400 | 0.70 | 0.100"))
    assert re.search(r"\| 1\.5 \| \+0\.01[1-5]; largest \+0\.01[1-5] \(σ/σ0 = [12]\) \|", row), row


def test_the_card_keeps_area_fractions_apart_that_two_decimals_would_merge_and_marks_frictionless_runs():
    from rheograph.analysis.dataset_card import series_label

    assert [series_label(phi, 0.5, "") for phi in (0.785, 0.7875, 0.79, 0.795, 0.8)] == [
        "0.785",
        "0.7875",
        "0.79",
        "0.795",
        "0.80",
    ]
    assert series_label(0.8, 0.0, "") == "0.80, μ = 0"
    assert series_label(0.56, 0.5, "polydisperse 0.05") == "0.56, polydisperse 0.05"


def test_thickening_is_named_only_from_two_flowing_stresses():
    """One flowing stress is no flow curve: neither continuous nor discontinuous.  A shear rate that
    falls while the stress rises is the S-shape; one that rises is continuous thickening."""
    from rheograph.analysis.dataset_card import thickening_lines

    def point(stress, eta):
        return dict(n_particles=400, phi=0.8, mu=0.5, radii="", stress=stress, viscosity=eta, jammed=False)

    (one,) = thickening_lines([point(20.0, 2000.0)])
    (rising,) = thickening_lines([point(10.0, 100.0), point(20.0, 150.0)])  # rate 0.1 -> 0.133
    (falling,) = thickening_lines([point(10.0, 100.0), point(20.0, 400.0)])  # rate 0.1 -> 0.05
    assert "one flowing stress" in one and "continuous" not in one
    assert "| continuous |" in rising
    assert "discontinuous (S-shape)" in falling and "10 → 20" in falling


def test_the_card_keeps_runs_of_other_radii_apart_from_the_bidisperse_ones():
    """Runs at one (N, φ) whose radii spread by 5 % and 10 % are two series of the card, never pooled as
    seeds of one: a row each in the counts, the runs per state point and the flow curves."""
    from rheograph.analysis.dataset_card import card_markdown

    def record(radii, seed):
        return dict(
            n=500, phi=0.56, mu=0.5, radii=radii, stress=2.0, seed=seed, status="completed", n_snapshots=20,
            n_flowing_snapshots=20, n_jammed_snapshots=0, cpu_seconds=3600.0, bytes=10**6,
            snapshot_interval=0.1, decorrelation=dict(viscosity=0.1, pressure=0.1, z_mu=0.1), transient=0.2,
            arrested=dict(pressure=np.array([]), z_mu=np.array([])),
            log_viscosity_series=(np.array([0.0, 1.0]), np.zeros(2), 2.0),
        )  # fmt: skip

    def point(radii, eta):
        return dict(
            n_particles=500, phi=0.56, mu=0.5, radii=radii, stress=2.0, statuses=["completed"], n_seeds=1,
            jammed=False, viscosity=eta, viscosity_se=1.0, pressure=10.0, pressure_se=0.1, z_mu=2.0,
            z_mu_se=0.01,
        )  # fmt: skip

    spreads = ("polydisperse 0.05", "polydisperse 0.1")
    records = [record(radii, 2) for radii in spreads] + [record("", seed) for seed in (1, 2, 3)]
    points = [point("", 30.0), point(spreads[0], 32.0), point(spreads[1], 35.0)]
    card = card_markdown(records, points, "python simulate.py -m …", 1.0)
    assert "| 500 | 0.56 | 3 | 3 | 3 | 0 | 0 | 60 | 0 | 3.00 | 3.0 |" in card
    for radii in spreads:
        assert f"| 500 | 0.56, {radii} | 1 | 1 | 1 | 0 | 0 | 20 | 0 | 1.00 | 1.0 |" in card
    assert "| σ/σ0 | φ = 0.56 | φ = 0.56, polydisperse 0.05 | φ = 0.56, polydisperse 0.1 |" in card
    assert "| 2 | 3/3 | 1/1 | 1/1 |" in card
    assert "| 500 | 0.56, polydisperse 0.1 | 2 | 1 | 35 ± 1 |" in card
