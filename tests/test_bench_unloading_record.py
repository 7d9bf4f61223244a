"""bench.unloading_continuation --record builds a table of continuations of one checkpoint, one row at a
time, each with the command that made it."""

import pytest

from bench.publishing import OUT_ENV
from bench.records import render_section
from bench.unloading_continuation import record_rows
from rheograph.io.pages import read_record

RUN = "data/flow_curves_3d/multirun/N500_phi0.58_s200_seed1_d0.002_implicit_3d/trajectory.h5"


def result(unloading: bool, disp_max: float, eta_r: float, run: str = RUN) -> dict:
    return {
        "run": run, "elastic_unloading": unloading, "disp_max": disp_max, "strain_window": [3.0, 3.5],
        "stopped_at_max_steps": False, "steps": 1000, "steps_per_strain": 2000.0, "median_dt": 1e-4,
        "first_shear_rates": [1.0], "cpu_seconds": 100.0, "eta_r": eta_r, "eta_r_blocks": [eta_r] * 5,
        "eta_r_se": 10.0, "z_mu": 3.7, "run_eta_r": 1307.0, "run_eta_r_se": 115.0, "run_z_mu": 3.67,
        "run_window": [1.0, 3.0], "run_last_block_window": [2.89, 2.99], "run_last_block_eta_r": 3150.0,
    }  # fmt: skip


def test_rows_accumulate_sorted_a_repeat_replaces_its_row_and_another_run_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv(OUT_ENV, str(tmp_path))
    record_rows("conv", result(True, 1e-3, 4000.0), "cmd unloading 1e-3", page="jamming.md")
    record_rows("conv", result(False, 1e-3, 1500.0), "cmd lfdem 1e-3", page="jamming.md")
    record_rows("conv", result(True, 2e-3, 4100.0), "cmd unloading 2e-3", page="jamming.md")
    rows = read_record(tmp_path / "conv.json", "record")["continuations"]
    # LF_DEM's rule first, then unloading; coarser step first within a rule
    order = [(r["elastic_unloading"], r["disp_max"]) for r in rows]
    assert order == [(False, 1e-3), (True, 2e-3), (True, 1e-3)]
    record_rows("conv", result(True, 1e-3, 3900.0), "cmd unloading 1e-3 again", page="jamming.md")
    rows = read_record(tmp_path / "conv.json", "record")["continuations"]
    assert len(rows) == 3 and rows[2]["eta_r"] == 3900.0 and rows[2]["command"] == "cmd unloading 1e-3 again"
    text = (tmp_path / "conv.json").read_text()
    assert "1307 ± 115" in text and "3900 ± 10" in text and "3900 ± 0" in text and "cmd lfdem 1e-3" in text
    page = render_section(read_record(tmp_path / "conv.json", "record"))
    assert "| the run itself, its last block | | 2.89–2.99 | 3150 |" in page  # against a first block
    with pytest.raises(SystemExit, match="holds continuations of"):
        record_rows("conv", result(True, 1e-3, 1.0, run="other.h5"), "cmd", page="jamming.md")


def test_a_continuation_that_stopped_early_or_another_benchmarks_record_is_refused(tmp_path, monkeypatch):
    monkeypatch.setenv(OUT_ENV, str(tmp_path))
    at_rest = {**result(True, 1e-3, float("inf")), "stopped_at_max_steps": True}
    with pytest.raises(SystemExit, match="stopped at --max-steps; not recorded in conv"):
        record_rows("conv", at_rest, "cmd", page="jamming.md")
    assert not (tmp_path / "conv.json").exists()
    (tmp_path / "other.json").write_text('{"section": "other", "blocks": []}')
    with pytest.raises(SystemExit, match="another benchmark's record"):
        record_rows("other", result(True, 1e-3, 4000.0), "cmd", page="jamming.md")
