"""A few cheap benchmarks rerun at small size into a temporary folder (``make bench-quick``): each must
run end to end and write a section record of the right schema, with a table; the published pages and
records are not touched.  Those that only read committed results (the campaign cost, the finite-size
table, the large-N cost, three training-cost tables from their saved rows) must give back their
published sections exactly.

    python -m bench.quick [--keep DIR]
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

from bench import campaign_cost, factor_scaling, finite_size, large_n, simulate_speed, train_speed
from bench.publishing import OUT_ENV, read_result_record
from bench.records import check_record, render_section

# (section, module, arguments at small size, whether the result must equal the published record)
RUNS = [
    (
        "campaign_cost",
        campaign_cost,
        ["--index", "data/paper/index.json", "--extra", "data/scheme_phi080/*/trajectory.h5"],
        True,
    ),
    ("finite_size", finite_size, ["data/paper/multirun", "data/large_n/multirun"], True),
    ("large_n_cost", large_n, ["data/large_n/multirun"], True),
    # the training-cost tables drawn again from their saved rows (no training; these draw no figure)
    *(
        (f"train_speed_{what}", train_speed, [what, "--reuse"], True)
        for what in ("levers", "folds", "inference")
    ),
    (
        "simulate_speed",
        simulate_speed,
        ["--n", "100", "--disp", "2e-3", "--integrators", "euler", "--solvers", "qdldl", "--windows", "1"]
        + ["--warmup", "0.01", "--particle-steps", "2e4"],
        False,
    ),
    (
        "factor_scaling",
        factor_scaling,
        ["--n", "100", "400", "--warmup", "2", "--windows", "1", "--particle-factorisations", "400"],
        False,
    ),
]


def cholmod_available() -> bool:
    from rheograph.sim.solver import cholmod_available as available

    return available()


def run(out: Path) -> list[str]:
    """Run every quick benchmark with its records going to ``out``; one line per failure."""
    failures = []
    previous = os.environ.get(OUT_ENV)
    os.environ[OUT_ENV] = str(out)
    try:
        for section, module, argv, exact in RUNS:
            if module is factor_scaling and not cholmod_available():
                print(f"{section}: skipped (no CHOLMOD)")
                continue
            start = time.time()
            try:
                module.main(argv)
                record = read_result_record(section, out)
                check_record(record, section)
                if not any("table" in b for b in record["blocks"]):
                    failures.append(f"{section}: its record holds no table")
                if exact and render_section(record) != render_section(read_result_record(section)):
                    failures.append(f"{section}: differs from its published record")
            except Exception as error:  # noqa: BLE001 - reported, and the other benchmarks still run
                failures.append(f"{section}: {type(error).__name__}: {error}")
            print(f"{section}: {time.time() - start:.1f} s", file=sys.stderr)
    finally:
        if previous is None:
            os.environ.pop(OUT_ENV, None)
        else:
            os.environ[OUT_ENV] = previous
    return failures


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--keep", default=None, help="write the records here (kept), not to a temporary folder")
    args = ap.parse_args(argv)
    if args.keep:
        Path(args.keep).mkdir(parents=True, exist_ok=True)
        failures = run(Path(args.keep))
    else:
        with tempfile.TemporaryDirectory(prefix="bench-quick-") as tmp:
            failures = run(Path(tmp))
    for line in failures:
        print(line, file=sys.stderr)
    print(f"{len(RUNS)} quick benchmarks, {len(failures)} failed")
    return 1 if failures else 0


if __name__ == "__main__":
    sys.exit(main())
