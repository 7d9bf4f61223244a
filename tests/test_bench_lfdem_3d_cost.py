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


def test_the_table_names_the_start_it_was_run_from():
    """The N = 2000 reference run (LF_DEM's start of that size, stopped at strain 0.25): the section
    states N and φ read from the start file and that its means are not steady ones; its steps per strain
    come from LF_DEM's own dt column."""
    bench = load_bench_script("lfdem_3d_cost")
    reference = bench.REFERENCE.parent / "phi0.56_n2000"
    start = bench.read_configuration(reference / "D3N2000VF0.56Bidi1.4_0.5Cubic_1_.dat")
    cpu = json.loads((reference / "lfdem_cpu.json").read_text())
    row = bench.lfdem_row(reference, "s10_disp1e-3", 10.0, 0.05, cpu)
    assert row["window"] == (0.05, 0.25) and row["cpu_per_strain"] == cpu["s10_disp1e-3"]["cpu_per_strain"]
    assert 1_000 < row["steps_per_strain"] < 100_000
    text = "".join(b.get("text", "") for b in bench.section(10.0, start, 0.05, [row], "cmd").blocks())
    assert "(N = 2000, φ = 0.56)" in text and "not yet steady" in text
    with pytest.raises(SystemExit, match="--configuration .*: not found"):
        bench.main(["--stress", "10", "--configuration", "missing.dat", "--no-write"])


def test_a_row_of_another_solver_says_which(tmp_path):
    """The committed N = 2000 runs of ours by the direct solver (reports from before ``--solver``: they
    ran by ``auto``, then the direct solver at N = 2000) and by ``solver=amg``: the same steps per strain
    and means to the multigrid's tolerance, each row labelled with the solver that ran; an amg report is
    not read as one of the settings' default."""
    bench = load_bench_script("lfdem_3d_cost")
    ours = bench.REFERENCE.parent / "phi0.56_n2000" / "rheograph"
    direct = bench.our_row(ours / "ours_s10_implicit1e-3.json", 10.0, 0.05)
    multigrid = bench.our_row(ours / "ours_s10_implicit1e-3_amg.json", 10.0, 0.05)
    assert direct["scheme"] == "implicit, 0.001, cholmod" and multigrid["scheme"] == "implicit, 0.001, amg"
    assert multigrid["steps_per_strain"] == pytest.approx(direct["steps_per_strain"], rel=1e-4)
    for key in ("viscosity", "pressure_over_sigma", "z_mu"):
        assert multigrid["steady"][key] == pytest.approx(direct["steady"][key], rel=1e-4), key
    report = json.loads((ours / "ours_s10_implicit1e-3_amg.json").read_text())
    report["settings"]["solver"] = "auto"
    relabelled = tmp_path / "relabelled.json"
    relabelled.write_text(json.dumps(report))
    assert bench.our_row(relabelled, 10.0, 0.05)["scheme"] == "implicit, 0.001, cholmod"
    report["cost_ours"]["solver"] = "amg"  # a report that names the solver auto took
    relabelled.write_text(json.dumps(report))
    assert bench.our_row(relabelled, 10.0, 0.05)["scheme"] == "implicit, 0.001, amg"
    vs = load_bench_script("vs_lfdem_3d")
    args = vs.argparse.Namespace(**{**report["settings"], "solver": "amg"})
    with pytest.raises(SystemExit, match="not the settings asked for"):
        vs.earlier_series(relabelled, args)
