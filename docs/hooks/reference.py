"""MkDocs hook: the reference pages generated from the code at build time.

* ``reference/config.md``: the composed default configuration of ``simulate.py``, ``train.py`` and
  ``tune.py`` (every key with its default) and every file of ``conf/`` with its comments;
* ``reference/cli.md``: the ``--help`` of every command-line tool.
"""

from __future__ import annotations

import contextlib
import io
import sys
from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
CLIS = (
    ("predict.py", "rheograph.learn.predict"),
    ("python -m rheograph.collect", "rheograph.collect"),
    ("python -m rheograph.flowcurve", "rheograph.flowcurve"),
    ("python -m rheograph.dataset_card", "rheograph.dataset_card"),
    ("python -m rheograph.jamming_points", "rheograph.jamming_points"),
    ("python -m rheograph.learn.registry", "rheograph.learn.registry"),
    ("python -m rheograph.respace", "rheograph.respace"),
    ("rheograph", "rheograph.console"),
)


def _composed(name: str) -> str:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from rheograph.cli import register_resolvers

    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(name)
    return OmegaConf.to_yaml(cfg)


def config_page() -> str:
    lines = [
        "# Configuration keys",
        "",
        "Generated from `conf/` when the documentation is built.  Every entry point composes its "
        "configuration with Hydra: override any key on the command line (`sim.phi=0.78`), pick a group "
        "option (`graph=imaging`), or sweep with `-m` and comma-separated values.",
        "",
    ]
    for name, entry in (("simulate", "simulate.py"), ("train", "train.py"), ("tune", "tune.py")):
        lines += [f"## `{entry}`: the composed defaults", "", "```yaml", _composed(name).rstrip(), "```", ""]
    lines += ["## Every configuration file", ""]
    for path in sorted((ROOT / "conf").rglob("*.yaml")):
        rel = path.relative_to(ROOT / "conf")
        lines += [f"### `{rel}`", "", "```yaml", path.read_text().rstrip(), "```", ""]
    return "\n".join(lines)


def cli_page() -> str:
    import importlib

    lines = [
        "# Command-line tools",
        "",
        "Generated from the tools' own argument parsers when the documentation is built.  `simulate.py`, "
        "`train.py` and `tune.py` are Hydra applications: their options are the "
        "[configuration keys](config.md).",
        "",
    ]
    for command, module_name in CLIS:
        module = importlib.import_module(module_name)
        out = io.StringIO()
        argv = sys.argv
        try:
            sys.argv = [command]
            with contextlib.redirect_stdout(out), contextlib.suppress(SystemExit):
                module.main(["--help"])
        finally:
            sys.argv = argv
        lines += [f"## `{command}`", "", "```text", out.getvalue().rstrip(), "```", ""]
    return "\n".join(lines)


def on_files(files, config):
    for uri, make in (("reference/config.md", config_page), ("reference/cli.md", cli_page)):
        files.append(File.generated(config, uri, content=make()))
    return files
