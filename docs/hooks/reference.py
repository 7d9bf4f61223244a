"""MkDocs hook: the reference pages generated from the code at build time.

* ``reference/config.md``: every key of ``simulate.py``, ``train.py`` and ``tune.py`` with its default
  and its meaning (the comments of ``conf/`` and of the classes behind the keys), and every option of
  every config group;
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
    ("python -m rheograph.runs.sweep_index", "rheograph.runs.sweep_index"),
    ("python -m rheograph.analysis.flow_curves", "rheograph.analysis.flow_curves"),
    ("python -m rheograph.analysis.dataset_card", "rheograph.analysis.dataset_card"),
    ("python -m rheograph.analysis.jamming_points", "rheograph.analysis.jamming_points"),
    ("python -m rheograph.learn.registry", "rheograph.learn.registry"),
    ("python -m rheograph.runs.respace", "rheograph.runs.respace"),
    ("rheograph", "rheograph.cli.console"),
)


def _composed(name: str) -> str:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from rheograph.cli.hydra_apps import register_resolvers

    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(name)
    return OmegaConf.to_yaml(cfg)


def _yaml_comments(path: Path) -> dict[str, str]:
    """Dotted key -> its comment in a YAML file: the comment on the key's line, else the comment lines
    right above it (a config file documents its keys so)."""
    comments, stack, above, header = {}, [], [], True
    for raw in path.read_text().splitlines():
        text = raw.strip()
        if not text:
            above = []
            continue
        if text.startswith("#"):
            above.append(text.lstrip("#").strip())
            continue
        indent = len(raw) - len(raw.lstrip())
        key, sep, rest = text.partition(":")
        if not sep or key.startswith(("-", "_")) or " " in key:
            above = []
            continue
        while stack and stack[-1][0] >= indent:
            stack.pop()
        dotted = ".".join([*(k for _, k in stack), key])
        value, _, inline = rest.partition(" #")
        # the comment opening a file describes the file, not its first key
        comment = inline.strip().lstrip("#").strip() or ("" if header else " ".join(above))
        header = False
        if comment:
            comments[dotted] = comment
        if not value.strip():  # a mapping: its keys follow, indented
            stack.append((indent, key))
        above = []
    return comments


def _field_comments(cls) -> dict[str, str]:
    """Field name -> the comment beside it (or right above it) in a dataclass's source."""
    import inspect

    comments, above = {}, []
    for line in inspect.getsource(cls).splitlines():
        text = line.strip()
        if text.startswith("#"):
            above.append(text.lstrip("#").strip())
            continue
        name, sep, rest = text.partition(":")
        if sep and name.isidentifier() and "=" in rest:
            inline = rest.partition("  #")[2].strip()
            if inline or above:
                comments[name] = inline or " ".join(above)
        above = []
    return comments


def _meanings(group_files: dict[str, list[Path]], top_file: Path) -> dict[str, str]:
    """Dotted key -> meaning: from the entry point's own file, the group files (the chosen option first)
    and, for the simulation and graph settings, the comments of the classes that hold them."""
    from rheograph.graphs.dataset import GraphSettings
    from rheograph.sim.params import SimParams
    from rheograph.sim.params3d import SimParams3D

    def file_comments(group: str, path: Path) -> dict[str, str]:
        root = "" if path.read_text().startswith("# @package _global_") else f"{group}."
        return {f"{root}{k}": v for k, v in _yaml_comments(path).items()}

    # precedence, lowest first: the group's other options, the classes behind the keys, the chosen option
    meanings = {}
    for group, paths in group_files.items():
        for path in reversed(paths[1:]):
            meanings.update(file_comments(group, path))
    for cls, group in ((SimParams3D, "sim"), (SimParams, "sim"), (GraphSettings, "graph")):
        meanings.update({f"{group}.{name}": text for name, text in _field_comments(cls).items()})
    for group, paths in group_files.items():
        if paths[0] is not None:  # the option chosen by default (None: the group has none)
            meanings.update(file_comments(group, paths[0]))
    meanings.update(_yaml_comments(top_file))
    return meanings


def _flat(node, prefix: str = "") -> list[tuple[str, object]]:
    if prefix.startswith("tune.search_space.") and isinstance(node, dict) and "type" in node:
        return [(prefix.rstrip("."), node)]  # one searched parameter: its range in one cell
    if isinstance(node, dict) and node and not {"_target_", "_partial_"} & set(node):
        return [pair for key, value in node.items() for pair in _flat(value, f"{prefix}{key}.")]
    if isinstance(node, dict) and "_target_" in node:
        rest = {k: v for k, v in node.items() if k not in ("_target_", "_partial_")}
        return (
            [(prefix.rstrip("."), node["_target_"]), *_flat(rest, prefix)]
            if rest
            else [(prefix.rstrip("."), node["_target_"])]
        )
    return [(prefix.rstrip("."), node)]


def _text(comment: str) -> str:
    """A comment as table text: no cell breaks, and brackets ([a], [--opt]) not read as links."""
    return comment.replace("|", "/").replace("[", "\\[").replace("]", "\\]")


def _is_target(values: dict, dotted: str) -> bool:
    node = values
    for part in dotted.split("."):
        if not isinstance(node, dict) or part not in node:
            return False
        node = node[part]
    return isinstance(node, dict) and "_target_" in node


def _cell(value) -> str:
    text = "null" if value is None else str(value)
    text = text if len(text) <= 60 else text[:57] + "..."
    return "`" + text.replace("|", "\\|") + "`"


def _key_table(name: str) -> list[str]:
    from hydra import compose, initialize_config_dir
    from omegaconf import OmegaConf

    from rheograph.cli.hydra_apps import register_resolvers

    register_resolvers()
    conf = ROOT / "conf"
    with initialize_config_dir(config_dir=str(conf), version_base="1.3"):
        cfg = compose(name, return_hydra_config=True)
    choices = dict(cfg.hydra.runtime.choices)
    group_files = {}
    for group in {*(key.split(".")[0] for key in cfg if key != "hydra"), *choices}:
        if (conf / group).is_dir():
            chosen = conf / group / f"{choices.get(group)}.yaml"
            others = sorted(p for p in (conf / group).glob("*.yaml") if p != chosen)
            group_files[group] = [chosen, *others] if chosen.is_file() else [None, *others]
    meanings = _meanings(group_files, conf / f"{name}.yaml")
    values = OmegaConf.to_container(cfg, resolve=False)
    values.pop("hydra")
    targets = {key for key, value in _flat(values) if _is_target(values, key)}
    rows = ["| key | default | meaning |", "|---|---|---|"]
    for key, value in _flat(values):
        meaning = meanings.get(key, "")
        if not meaning and key.startswith("tune.search_space."):
            meaning = f"the range searched for `{key.removeprefix('tune.search_space.')}`"
        elif not meaning and isinstance(value, str) and "." in value and key in targets:
            meaning = "the class instantiated (Hydra `_target_`); its keys follow"
        rows.append(f"| `{key}` | {_cell(value)} | {_text(meaning)} |")
    return rows


def _group_options() -> list[str]:
    """Every option of every config group, with the first sentence of the comment that opens its file."""
    lines = ["| group | option | what it is |", "|---|---|---|"]
    for path in sorted((ROOT / "conf").glob("*/*.yaml")):
        head = []
        for raw in path.read_text().splitlines():
            text = raw.strip()
            if text.startswith("# @package"):
                continue
            if not text.startswith("#"):
                break
            head.append(text.lstrip("#").strip())
        about = " ".join(head).split(". ")[0].rstrip(".")
        lines.append(f"| `{path.parent.name}` | `{path.stem}` | {_text(about)} |")
    return lines


def config_page() -> str:
    lines = [
        "# Configuration keys",
        "",
        "Generated from `conf/` and the code when the documentation is built.  Every entry point composes "
        "its configuration with Hydra: override any key on the command line (`sim.phi=0.78`), pick a "
        "group option (`graph=imaging`), or sweep with `-m` and comma-separated values.  Units: lengths "
        "in the small radius a, stresses in σ0, forces in F_CL ([Physics](../physics.md)).  "
        "`python simulate.py --cfg job` prints the composed configuration of a command line.",
        "",
    ]
    for name, entry in (("simulate", "simulate.py"), ("train", "train.py"), ("tune", "tune.py")):
        lines += [f"## `{entry}`: every key, its default and its meaning", "", *_key_table(name), ""]
    lines += ["## Config group options", "", *_group_options(), ""]
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
