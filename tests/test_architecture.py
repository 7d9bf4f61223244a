"""The package's architecture: its import contracts (pyproject.toml, ``[tool.importlinter]``: the layers
from the command line down to the simulator, training above inference above the model file, the readers
above the formats) hold, and no module imports itself through others."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import grimp

ROOT = Path(__file__).resolve().parents[1]


def test_the_import_contracts_hold():
    lint = Path(sys.executable).with_name("lint-imports")
    result = subprocess.run(
        [str(lint), "--config", str(ROOT / "pyproject.toml"), "--no-cache"],
        capture_output=True,
        text=True,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT / "src")},
    )
    assert result.returncode == 0, result.stdout[-3000:] + result.stderr[-2000:]
    assert "0 broken" in result.stdout and "3 kept" in result.stdout


def import_cycles(graph: grimp.ImportGraph) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan): each is an import cycle."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    cycles = []

    def visit(module: str) -> None:
        index[module] = low[module] = len(index)
        stack.append(module)
        on_stack.add(module)
        for imported in graph.find_modules_directly_imported_by(module):
            if imported not in index:
                visit(imported)
                low[module] = min(low[module], low[imported])
            elif imported in on_stack:
                low[module] = min(low[module], index[imported])
        if low[module] == index[module]:
            component = []
            while True:
                member = stack.pop()
                on_stack.discard(member)
                component.append(member)
                if member == module:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in sorted(graph.modules):
        if module not in index:
            visit(module)
    return cycles


def test_no_module_imports_itself_through_others():
    """Function-local imports included (grimp reads every import statement): a cycle hidden inside a
    function is still a cycle of the design."""
    sys.path.insert(0, str(ROOT / "src"))
    try:
        graph = grimp.build_graph("rheograph", include_external_packages=False, cache_dir=None)
    finally:
        sys.path.remove(str(ROOT / "src"))
    assert len(graph.modules) > 40
    assert import_cycles(graph) == []


def test_a_planted_cycle_is_found():
    graph = grimp.ImportGraph()
    for name in ("pkg", "pkg.a", "pkg.b", "pkg.c", "pkg.d"):
        graph.add_module(name)
    graph.add_import(importer="pkg.a", imported="pkg.b")
    graph.add_import(importer="pkg.b", imported="pkg.c")
    graph.add_import(importer="pkg.c", imported="pkg.a")
    graph.add_import(importer="pkg.d", imported="pkg.a")
    assert import_cycles(graph) == [["pkg.a", "pkg.b", "pkg.c"]]


def test_file_formats_are_read_and_written_in_io_only():
    """``h5py`` is imported by ``rheograph.io`` alone: everything else reads and writes runs through it."""
    sys.path.insert(0, str(ROOT / "src"))
    try:
        graph = grimp.build_graph("rheograph", include_external_packages=True, cache_dir=None)
    finally:
        sys.path.remove(str(ROOT / "src"))
    importers = graph.find_modules_that_directly_import("h5py")
    assert importers and all(m.startswith("rheograph.io.") for m in importers), sorted(importers)
