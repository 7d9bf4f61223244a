"""bench/lfdem_snapshots.py on the LF_DEM fixture run: the noise it adds is drawn, declared to the model
and seeded; the lookup row is the rheograph runs' mean at the run's stress; bad input ends in one line."""

import re

import pytest
from conftest import ROOT, load_bench_script

PAR = ROOT / "tests" / "data" / "lfdem_run_small" / "par_conf_params_stress10cl_shear.dat"


def declared_noise(text: str) -> float:
    """The per-run table's 'position noise declared' cell of the one run."""
    row = next(line for line in text.splitlines() if re.match(r"\| 10 \| ", line))
    return float(row.split("|")[4])


def test_lfdem_snapshots_add_and_declare_position_noise(capsys):
    bench = load_bench_script("lfdem_snapshots")
    common = ["--runs", str(PAR), "--model", "N400_phi0.76_imaging", "--min-strain", "0",
              "--timing-snapshots", "2", "--no-write"]  # fmt: skip
    assert bench.main(common) == 0
    exact = capsys.readouterr().out
    assert declared_noise(exact) < 1e-4  # LF_DEM's 6-digit rounding alone (1e-5 a here)
    assert bench.main([*common, "--noise", "0.01", "--seed", "3"]) == 0
    noisy = capsys.readouterr().out
    assert "ε = 0.01 a" in noisy and declared_noise(noisy) == pytest.approx(0.01, rel=1e-3)
    assert bench.main([*common, "--noise", "0.01", "--seed", "3"]) == 0
    again = capsys.readouterr().out
    scores = [line for line in noisy.splitlines() if line.startswith("| graph network")]
    assert scores == [line for line in again.splitlines() if line.startswith("| graph network")]
    with pytest.raises(SystemExit, match="--noise -1"):
        bench.main([*common, "--noise", "-1"])


def test_lfdem_snapshots_lookup_is_the_rheograph_mean_at_the_stress():
    import numpy as np

    from rheograph.io.snapshots import read_snapshots

    bench = load_bench_script("lfdem_snapshots")
    multirun = ROOT / "data" / "paper" / "multirun"
    runs = sorted(multirun.glob("N400_phi0.76_s10_seed*/trajectory.h5"))
    means = bench.state_means([str(p) for p in runs], min_strain=1.0)
    assert list(means) == [10.0]
    phi, n, mean = means[10.0]
    assert (phi, n) == (0.76, 400)
    # geometric means of eta_r and Pi, arithmetic of Z_mu, over the flowing snapshots at strain >= 1
    t = np.concatenate([(s.targets[(s.strain >= 1.0) & ~s.jammed]) for s in map(read_snapshots, runs)])
    expected = [np.exp(np.log(t[:, 0]).mean()), np.exp(np.log(t[:, 1]).mean()), t[:, 2].mean()]
    assert mean == pytest.approx(expected, rel=1e-12)
    # two state points at one stress are not one lookup
    with pytest.raises(SystemExit, match="mixes state points"):
        bench.state_means([str(multirun / "N*_phi0.76_s10_seed1_*/trajectory.h5")], min_strain=1.0)
    args = ["--runs", str(PAR), "--model", "N400_phi0.76", "--min-strain", "0.05", "--timing-snapshots", "2",
            "--no-write"]  # fmt: skip
    # the start of a run can hold Π <= 0, which has no logarithm: the lookup asks for a later window
    start = [*args[:4], "--min-strain", "0", *args[6:]]
    with pytest.raises(SystemExit, match="Π <= 0 at strain 0 .*raise --min-strain"):
        bench.main([*start, "--lookup", str(multirun / "N400_phi0.76_s10_seed1_*/trajectory.h5")])
    # the fixture run is N = 100: a lookup of N = 400 runs is another state point
    with pytest.raises(SystemExit, match="N = 400; .* N = 100"):
        bench.main([*args, "--lookup", str(multirun / "N400_phi0.76_s10_seed*/trajectory.h5")])
    with pytest.raises(SystemExit, match="matches no file"):
        bench.main([*args, "--lookup", "no/such/*.h5"])
    with pytest.raises(SystemExit, match="no trajectory at σ/σ0 = 10"):
        bench.main([*args, "--lookup", str(multirun / "N400_phi0.76_s2_seed1*/trajectory.h5")])
