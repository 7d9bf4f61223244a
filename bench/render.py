"""Draw every published table and figure of the docs pages from its JSON record.

Each record under docs/results/bench/ (see :mod:`bench.records`) names its page and its marked section;
this writes the section between the page's ``<!-- name:start -->`` and ``<!-- name:end -->`` markers from
the record alone, and redraws every published figure from the record of the numbers it plots (the table
:data:`bench.figures.FIGURES`).  With ``--check`` it writes nothing and exits 1, naming every section
whose page text differs from what its record gives (or whose markers are missing) and every figure that
has no record, does not redraw from it, or was not drawn from its record's numbers (how that is told
without comparing pixels: :mod:`bench.figures`)::

    python -m bench.render            # rewrite the marked sections and redraw the figures from the records
    python -m bench.render --check    # the pages and figures as the records give them? (make bench)
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

from bench import figures
from bench.records import DOCS, RECORDS, load_records, render_section
from rheograph.io.pages import replace_section


def section_text(page_text: str, name: str) -> str | None:
    """The text between a section's markers on a page (None where the markers are absent)."""
    m = re.search(
        rf"<!-- {re.escape(name)}:start -->\n(.*?)\n<!-- {re.escape(name)}:end -->", page_text, re.S
    )
    return m.group(1) if m else None


def differences(records: list[dict], docs: Path = DOCS) -> list[str]:
    """One line per section whose page does not hold what its record gives."""
    out, pages = [], {}
    for record in records:
        page = Path(docs) / record["page"]
        if page not in pages:
            pages[page] = page.read_text() if page.exists() else ""
        found = section_text(pages[page], record["section"])
        if found is None:
            out.append(f"{record['page']}: section {record['section']} has no markers")
        elif found != render_section(record):
            out.append(f"{record['page']}: section {record['section']} differs from its record")
    return out


def render(records: list[dict], docs: Path = DOCS) -> int:
    """Write every record's section into its page; the number of sections that changed."""
    changed = differences(records, docs)
    for record in records:
        replace_section(Path(docs) / record["page"], record["section"], render_section(record))
    return len(changed)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="write nothing; exit 1 where a page differs")
    ap.add_argument("--records", default=str(RECORDS), help="the folder of section and figure records")
    ap.add_argument(
        "--docs", default=str(DOCS), help="the docs folder the records' pages and figures are under"
    )
    args = ap.parse_args(argv)
    records = load_records(Path(args.records))
    docs, folder = Path(args.docs), Path(args.records)
    if args.check:
        diff = differences(records, docs)
        drawn = figures.differences(docs, folder)
        for line in diff + drawn:
            print(line, file=sys.stderr)
        print(f"{len(records)} sections checked, {len(diff)} differ from their records")
        print(f"{len(figures.FIGURES)} figures checked, {len(drawn)} problems")
        return 1 if diff or drawn else 0
    changed = render(records, docs)
    print(f"{len(records)} sections rendered, {changed} changed")
    print(f"{len(figures.FIGURES)} figures drawn, {figures.render(docs, folder)} from changed records")
    return 0


if __name__ == "__main__":
    sys.exit(main())
