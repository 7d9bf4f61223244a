"""bench.unloading_continuation continues a committed 3D run with elastic unloading without touching it."""

import hashlib
from pathlib import Path

import pytest

from bench.unloading_continuation import continuation

ROOT = Path(__file__).resolve().parents[1]
RUN = ROOT / "data/flow_curves_3d/multirun/N500_phi0.5_s10_seed1_d0.002_implicit_3d/trajectory.h5"

pytestmark = pytest.mark.slow  # compiles the 3D step


def test_a_continuation_reads_the_run_leaves_it_as_it_was_and_averages_over_its_blocks():
    before = hashlib.sha256(RUN.read_bytes()).hexdigest()
    out = continuation(RUN, strain=0.01, disp_max=None)
    assert hashlib.sha256(RUN.read_bytes()).hexdigest() == before
    assert out["strain_window"][0] == pytest.approx(3.0, abs=0.02)
    assert out["strain_window"][1] - out["strain_window"][0] >= 0.01
    assert len(out["eta_r_blocks"]) == 5
    # the whole window's time average lies within its blocks' (each a time average over 1/5 of it)
    assert min(out["eta_r_blocks"]) <= out["eta_r"] <= max(out["eta_r_blocks"])
    assert out["run_window"][0] >= 1.0 and 20 < out["run_eta_r"] < 60  # phi 0.50, sigma/sigma0 10: ~36
    # the run's own last 0.002 strain (--strain / 5) or, its rows being sparser, its last two rows
    a, b = out["run_last_block_window"]
    assert b == pytest.approx(out["run_window"][1]) and 0.002 <= b - a < 0.05
    assert 10 < out["run_last_block_eta_r"] < 100
    assert not out["stopped_at_max_steps"] and out["elastic_unloading"]


def test_a_packing_at_rest_ends_at_max_steps_and_says_so():
    """The committed phi 0.60 run has come to rest: the continuation stops at --max-steps instead of
    hanging, and with LF_DEM's rule its shear rate flips sign every step (the chatter)."""
    rest = ROOT / "data/flow_curves_3d/multirun/N500_phi0.6_s200_seed1_d0.002_implicit_3d/trajectory.h5"
    out = continuation(rest, strain=0.01, disp_max=None, unloading=False, max_steps=6)
    assert out["stopped_at_max_steps"] and out["steps"] == 6
    rates = out["first_shear_rates"]
    assert all(a * b < 0 for a, b in zip(rates, rates[1:]))


def test_a_2d_run_is_refused_in_one_line(capsys):
    paper = next((ROOT / "data/paper/multirun").glob("N400_phi0.76_s10_seed1_*/trajectory.h5"))
    with pytest.raises(SystemExit, match="is a 2D run"):
        continuation(paper, strain=0.01, disp_max=None)
