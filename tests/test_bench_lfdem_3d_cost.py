"""bench/lfdem_3d_cost.py: LF_DEM's CPU per strain from a monitor log is the interpolated difference over
the window (exact on a log whose CPU time grows linearly in strain); its steps per strain from the dt it
wrote reproduce the committed σ/σ0 = 10 run's count (21 300 per strain, its README); a log that does not
cover the window, or a report of ours at another stress, is refused in one line."""

import json

import pytest
from conftest import load_bench_script


def test_cpu_per_strain_from_a_monitor_log(tmp_path):
    bench = load_bench_script("lfdem_3d_cost")
    log = tmp_path / "cpu_log.txt"
    # 700 CPU s per strain from strain 0.2 on, 300 before; a line without a strain (none written yet)
    lines = ["1000 0.5"] + [f"{1000 + 30 * k} {30.0 * k} {0.1 * k if k <= 2 else 0.2 + (30.0 * k - 60) / 700}"
                            for k in range(1, 80)]  # fmt: skip
    log.write_text("\n".join(lines) + "\n")
    entry = bench.cpu_from_log(log, (1.0, 2.0))
    assert entry["cpu_per_strain"] == pytest.approx(700.0, rel=1e-9)
    assert entry["window"] == [1.0, 2.0] and entry["source"] == "cpu_log.txt"
    with pytest.raises(SystemExit, match="not --window"):
        bench.cpu_from_log(log, (1.0, 9.0))


def test_lfdem_steps_per_strain_of_the_committed_run():
    bench = load_bench_script("lfdem_3d_cost")
    steps = bench.lfdem_steps_per_strain(bench.REFERENCE / "data_s10_disp1e-3.dat", (1.0, 2.54))
    assert steps == pytest.approx(21_300, rel=0.005)


def test_a_report_at_another_stress_is_refused(tmp_path):
    bench = load_bench_script("lfdem_3d_cost")
    report = tmp_path / "ours.json"
    settings = {"stress": 10.0, "control": "stress", "rate": 0.1, "disp_max": 1e-3, "scheme": "euler-lagged"}
    report.write_text(json.dumps({"settings": settings, "series_ours": {}, "cost_ours": {}}))
    with pytest.raises(SystemExit, match="not stress control at σ/σ0 = 200"):
        bench.our_row(report, 200.0, 1.0)
