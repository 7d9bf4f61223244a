"""``make bench-quick``: the quick benchmarks run end to end into a folder of their own, each writing a
section record of the right schema, and leave the published records alone."""

import pytest

from bench import quick
from bench.records import RECORDS, load_records


@pytest.mark.slow
def test_quick_benchmarks_write_records_of_the_right_schema_elsewhere(tmp_path):
    before = {p.name: p.read_bytes() for p in RECORDS.glob("*.json")}
    assert quick.run(tmp_path) == []
    written = {r["section"]: r for r in load_records(tmp_path)}
    expected = {section for section, *_ in quick.RUNS}
    if not quick.cholmod_available():
        expected.discard("factor_scaling")
    assert set(written) == expected
    assert {p.name: p.read_bytes() for p in RECORDS.glob("*.json")} == before
