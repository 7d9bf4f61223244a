"""bench/vs_lfdem.py without LF_DEM: the no-binary path, the configuration and parameter files it writes for
LF_DEM, and where its results go in docs/validation/speed.md."""

import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import load_bench_script

from rheograph.sim.init_config import initial_configuration
from rheograph.sim.params import SimParams

ROOT = Path(__file__).resolve().parents[1]
REFERENCE_PARAMS = ROOT / "tests" / "data" / "lfdem_phi0.76" / "parameters_clm2d.txt"


@pytest.fixture(scope="module")
def vs_lfdem():
    return load_bench_script("vs_lfdem")


def run_script(*args):
    env = {k: v for k, v in os.environ.items() if k != "LFDEM_BINARY"}
    return subprocess.run(
        [sys.executable, "-m", "bench.vs_lfdem", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
    )


@pytest.mark.parametrize("how", ["none", "missing", "not_executable"])
def test_without_lfdem_binary_it_says_so_and_exits_zero(tmp_path, how):
    args = []
    if how == "missing":
        args = ["--lfdem", str(tmp_path / "LF_DEM")]
    elif how == "not_executable":
        (tmp_path / "LF_DEM").write_text("")
        args = ["--lfdem", str(tmp_path / "LF_DEM")]
    proc = run_script(*args)
    assert proc.returncode == 0, proc.stderr
    assert "LF_DEM binary not given or not executable" in proc.stdout
    assert "outside the repository" in proc.stdout
    assert "Nothing was run" in proc.stdout


def test_configuration_file_reads_back_exactly(tmp_path, vs_lfdem):
    rng = np.random.default_rng(3)
    lx, ly = 46.7888238643245, 46.7888238643245
    positions = (rng.random((50, 2)) - 0.5) * lx  # rheograph's box is centred on the origin
    positions[0] = [-1e-17, -0.5 * ly]  # wraps to [0, 0] (np.mod would round the first to L)
    radii = np.concatenate([np.ones(33), np.full(17, 1.4)])
    path = tmp_path / "conf.dat"
    vs_lfdem.write_lfdem_configuration(path, positions, radii, lx, ly)

    conf = vs_lfdem.read_lfdem_configuration(path)
    wrapped = vs_lfdem.wrap(positions, lx, ly)
    assert np.array_equal(conf["positions"], wrapped)
    assert np.all((wrapped >= 0) & (wrapped < [lx, ly]))
    shift = np.mod(conf["positions"] - positions + 0.5 * lx, lx) - 0.5 * lx  # a whole number of periods
    assert np.allclose(shift, 0.0, atol=1e-12)
    assert np.array_equal(conf["radii"], radii)
    assert (conf["lx"], conf["ly"]) == (lx, ly)
    assert conf["vf"] == pytest.approx(np.pi * np.sum(radii**2) / (lx * ly), rel=1e-12)
    # LF_DEM's text format: two header lines of as many keys as values, then "x y z radius", y = 0
    lines = path.read_text().splitlines()
    assert lines[0] == "# np1 np2 vf lx ly lz vf1 vf2 disp"
    assert lines[1].split()[1:3] == ["33", "17"] and lines[1].split()[5] == "0"
    assert all(len(line.split()) == 4 and line.split()[1] == "0" for line in lines[2:])


def test_configuration_of_simparams_is_what_the_simulation_starts_from(vs_lfdem):
    from rheograph.sim import Simulation

    params = SimParams(n_particles=64, phi=0.72, seed=5)
    pos, radii, box = initial_configuration(params)
    state = Simulation(params).state
    assert np.array_equal(pos, state.positions) and np.array_equal(radii, state.radii)
    assert box == state.lx == state.ly


def test_parameter_file_follows_the_reference(vs_lfdem):
    def entries(text):
        """{key: value}, numbers as (float, unit suffix): "2e4s" == "20000s"."""
        body = "\n".join(line for line in text.splitlines() if not line.startswith("/*"))
        out = {}
        for entry in body.split(";"):
            if "=" in entry:
                key, value = (x.strip() for x in entry.split("="))
                number = re.match(r"^[-+0-9.eE]+", value)
                out[key] = (float(number.group()), value[number.end() :]) if number else value
        return out

    ours = entries(vs_lfdem.lfdem_parameters(SimParams(disp_max=2e-3), 5.0))
    reference = entries(REFERENCE_PARAMS.read_text())
    assert ours == reference


REPLAY = ROOT / "tests" / "data" / "lfdem_replay" / "replay_lfdem.py"


def test_bench_reads_checks_and_tabulates_replayed_lfdem_runs(vs_lfdem, tmp_path, capsys):
    """The whole measurement path with LF_DEM replaced by a stand-in that replays committed output of
    real LF_DEM runs from the configuration the bench writes (N = 100): reading its files, the same-start
    check against rheograph's first step, the differenced steps per strain and the table."""
    vs_lfdem.main(
        [
            "--lfdem", str(REPLAY), "--n", "100", "--strains", "0.02", "0.04", "--repeats", "1",
            "--schemes", "euler-lagged", "--lfdem-disp", "2e-3", "--no-write",
        ]
    )  # fmt: skip
    out = capsys.readouterr().out
    check = re.search(r"initial γ̇ LF_DEM ([0-9.]+) vs rheograph ([0-9.]+)", out)
    assert check and abs(float(check[1]) / float(check[2]) - 1) < 1e-5  # LF_DEM prints 6 digits
    rows = {
        line.split("|")[2].strip(): line.split("|") for line in out.splitlines() if line.startswith("| 100 |")
    }
    # LF_DEM's t_*.dat: 24 steps to strain 0.02, 54 to 0.04 -> (54 - 24) / 0.02 = 1500 steps per strain
    assert float(rows["LF_DEM"][6]) == pytest.approx(1500.0)
    # rheograph with LF_DEM's discretisation takes about as many steps from the same start
    assert float(rows["rheograph"][6]) == pytest.approx(1500.0, rel=0.1)
    assert rows["rheograph"][9].strip() not in ("–", "")  # the CPU ratio against LF_DEM is filled in


def test_same_start_check_refuses_another_first_shear_rate(vs_lfdem, tmp_path):
    run = tmp_path / "lfdem"
    run.mkdir()
    for path in (REPLAY.parent / "end0.01").iterdir():
        text = path.read_text()
        if path.name.startswith("data_"):  # the first row's shear rate (column 3) off by 1e-3
            lines = text.splitlines()
            first = next(k for k, line in enumerate(lines) if line.strip() and not line.startswith("#"))
            cols = lines[first].split()
            cols[2] = repr(float(cols[2]) * 1.001)
            lines[first] = " ".join(cols)
            text = "\n".join(lines) + "\n"
        (run / path.name).write_text(text)
    lf = vs_lfdem.read_lfdem_run(run)
    params = SimParams(n_particles=100, phi=0.76, stress=10.0, seed=1, strain=0.01)
    pos, radii, box = initial_configuration(params)
    from rheograph.sim import Simulation

    rate0 = Simulation(params).step().shear_rate
    rg = dict(positions0=pos, radii=radii, lx=box, rate0=rate0)
    with pytest.raises(RuntimeError, match="first shear rate"):
        vs_lfdem.check_same_start(100, REPLAY.parent / "conf.dat", lf, rg, params)
    lf_true = vs_lfdem.read_lfdem_run(REPLAY.parent / "end0.01")
    assert "same start checked" in vs_lfdem.check_same_start(
        100, REPLAY.parent / "conf.dat", lf_true, rg, params
    )
