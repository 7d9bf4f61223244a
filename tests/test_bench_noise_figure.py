"""bench/noise_figure.py reads the published noise tables cell for cell and refuses a page without them."""

import pytest
from conftest import load_bench_script


def test_noise_figure_reads_the_published_tables_and_draws_them(tmp_path):
    bench = load_bench_script("noise_figure")
    page = (bench.ROOT / "docs" / "benchmarks.md").read_text()
    section = "snapshot_noise_imaging"
    eps, rows = bench.section_tables(page, section)
    assert eps == [0.0, 0.001, 0.003, 0.01, 0.03, 0.05]
    # every row the figure draws is there, one value per noise level, each the table's own cell
    for _, name, exact, imaging, extra in bench.PANELS:
        levels, table = bench.section_tables(page, name)
        for run, predictor, _ in bench.curves(exact, imaging, extra):
            for metric, _ in bench.TARGETS:
                assert len(table[(run, predictor, metric)]) == len(levels)
    start = page.index(f"<!-- {section}:start -->")
    line = next(
        s for s in page[start:].splitlines() if s.startswith("| graph network | R² log η_r |")
    )  # the first run of the section, its network's log eta_r row
    first_run = next(s for s in page[start:].splitlines() if s.startswith("**")).split("**")[1]
    assert rows[(first_run, "graph network", "R² log η_r")] == [
        float(c) for c in line.strip("| \n").split("|")[2:]
    ]
    out = tmp_path / "noise.png"
    assert bench.main(["--out", str(out)]) == 0 and out.stat().st_size > 10_000


def test_noise_figure_names_a_missing_section(tmp_path):
    bench = load_bench_script("noise_figure")
    page = tmp_path / "benchmarks.md"
    page.write_text("# Benchmarks\n")
    with pytest.raises(SystemExit, match="no section snapshot_noise_phi070"):
        bench.main(["--page", str(page), "--out", str(tmp_path / "x.png")])
    with pytest.raises(SystemExit, match="--page .*: no such file"):
        bench.main(["--page", str(tmp_path / "absent.md"), "--out", str(tmp_path / "x.png")])
