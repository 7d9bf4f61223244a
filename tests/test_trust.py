"""Untrusted files never run code (docs/faults.md, "What is trusted"): a model folder's bundles name their
network class but never make the loader import it; graph caches and training resume checkpoints holding
pickled objects are rebuilt or restarted, never unpickled; and no reader in the package, the benchmarks or
the scripts unpickles a file (a static check of the source)."""

import ast
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from conftest import tiny_training_overrides

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings, SnapshotGraphDataset
from rheograph.learn.registry import MODELS_DIR

ROOT = Path(__file__).resolve().parents[1]


class Payload:
    """Pickles as a call that writes ``marker``: unpickling this object is running the call."""

    def __init__(self, marker):
        self.marker = str(marker)

    def __reduce__(self):
        return (exec, (f"open({self.marker!r}, 'w').write('ran')",))


def plant_payload(path: Path, marker: Path) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    torch.save(Payload(marker), path)


def model_folder_naming(folder: Path, class_name: str) -> None:
    """``folder`` as a model folder whose fold bundles (a shipped model's, otherwise intact) name
    ``class_name`` as their network class."""
    folder.mkdir(parents=True, exist_ok=True)
    for k in range(2):
        bundle = torch.load(MODELS_DIR / "N400_phi0.76" / f"fold{k}.pt", weights_only=True)
        bundle["module_class"] = class_name
        torch.save(bundle, folder / f"fold{k}.pt")


def evil_model_folder(parent: Path) -> tuple[Path, Path]:
    """``parent/evil_model``: a model folder carrying a package of its own (``evil_model/__init__.py``,
    whose import writes a marker file) and bundles naming ``evil_model:Net``; returns (folder, marker)."""
    folder, marker = parent / "evil_model", parent / "payload_ran"
    model_folder_naming(folder, "evil_model:Net")
    (folder / "__init__.py").write_text(
        f"open({str(marker)!r}, 'w').write('ran')\n"
        "from rheograph.learn.module import SurrogateModule\n\n\n"
        "class Net(SurrogateModule):\n    pass\n"
    )
    return folder, marker


def test_a_model_folder_carrying_its_own_module_cannot_make_the_loader_import_it(tmp_path, monkeypatch):
    """Loaded by name from the folder that holds it, with that folder on the import path (as in an
    interactive session or ``python -m``): refused in one line saying how to register a class, and the
    folder's module is never imported."""
    import rheograph

    _, marker = evil_model_folder(tmp_path)
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    with pytest.raises(InputError) as refused:
        rheograph.load_model("evil_model")
    message = str(refused.value)
    assert "'evil_model:Net' is not registered" in message and "\n" not in message
    assert "register_network" in message and "rheograph.networks" in message
    assert not marker.exists() and "evil_model" not in sys.modules


def test_predict_refuses_a_model_folder_naming_its_own_module_in_one_line(tmp_path):
    """``python -m rheograph.cli.console predict`` (the current directory on the import path) from the folder
    that holds the model folder: one line, exit status 1, and the folder's module never runs."""
    _, marker = evil_model_folder(tmp_path)
    done = subprocess.run(
        [sys.executable, "-m", "rheograph.cli.console", "predict", "--models", "evil_model"]
        + ["--input", "snapshot.npz", "--out", "p.csv"],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        timeout=300,
        # this tree's package, whatever is installed
        env={
            **os.environ,
            "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), os.environ.get("PYTHONPATH", "")]),
        },
    )
    output = done.stdout + done.stderr
    assert done.returncode == 1, output
    assert "Traceback" not in output
    errors = [line for line in output.splitlines() if "error:" in line]
    assert len(errors) == 1 and "'evil_model:Net' is not registered" in errors[0], output
    assert not marker.exists()


@pytest.mark.parametrize(
    "name",
    [
        "os:system",  # any installed module: importing is running it
        "this:x",  # whose import prints
        "rheograph.learn.model:ResGCN",  # a class of the package, not a registered network
        "rheograph.learn.module:SurrogateModule.__init__",
        "x" * 500,
    ],
)
def test_a_bundle_naming_any_unregistered_class_is_refused_and_nothing_is_imported(
    tmp_path, name, monkeypatch
):
    from rheograph.learn.predict import load_model

    monkeypatch.delitem(sys.modules, "this", raising=False)
    model_folder_naming(tmp_path / "model", name)
    with pytest.raises(InputError, match="is not registered") as refused:
        load_model(tmp_path / "model")
    assert "\n" not in str(refused.value) and len(str(refused.value)) < 600
    assert "this" not in sys.modules


def test_only_surrogate_module_subclasses_can_be_registered():
    from rheograph.learn.model import ResGCN
    from rheograph.learn.networks import register_network

    for bad in (ResGCN, "rheograph.learn.module:SurrogateModule", print):
        with pytest.raises(InputError, match="not a subclass of rheograph.learn.module.SurrogateModule"):
            register_network(bad)


def test_a_bare_snapshot_file_holding_pickled_objects_is_refused_unread(tmp_path):
    import numpy as np

    from rheograph.io.snapshots import read_snapshots

    marker = tmp_path / "payload_ran"
    positions = np.empty(1, dtype=object)
    positions[0] = Payload(marker)
    np.savez(tmp_path / "s.npz", positions=positions, radii=np.ones(4), box=np.ones(2))
    with pytest.raises(InputError, match="s.npz: not a readable .npz file") as refused:
        read_snapshots(tmp_path / "s.npz")
    assert "\n" not in str(refused.value) and not marker.exists()


@pytest.mark.parametrize("planted", ["processed/graphs.pt", "processed/pre_transform.pt", "parts/0.pt"])
def test_a_pickle_payload_in_the_graph_cache_never_runs_and_the_cache_is_rebuilt(
    tiny_files, tmp_path, planted, caplog
):
    """A cache directory copied from elsewhere holding pickled objects — as its whole set of graphs, as
    PyG's record of a pre-transform, or as the part a killed build left — is rebuilt (with a warning where
    a file is unreadable), and the objects are never unpickled."""
    settings = GraphSettings(min_strain=0.05)
    whole = SnapshotGraphDataset(tiny_files, settings, tmp_path / "whole")
    root = Path(SnapshotGraphDataset(tiny_files, settings, tmp_path / "cache").root)
    marker = tmp_path / "payload_ran"
    if planted != "processed/graphs.pt":  # the parts are read only while the set is built
        (root / "processed" / "graphs.pt").unlink()
    plant_payload(root / planted, marker)
    with caplog.at_level("WARNING", logger="rheograph.graphs"):
        again = SnapshotGraphDataset(tiny_files, settings, tmp_path / "cache")
    assert not marker.exists()
    assert len(again) == len(whole)
    for a, b in zip(again, whole):
        assert torch.equal(a.edge_attr, b.edge_attr) and torch.equal(a.y_raw, b.y_raw)
    if planted != "processed/pre_transform.pt":  # never read: nothing to warn of
        warnings = [r.message for r in caplog.records if "unreadable" in r.message]
        assert warnings and "objects other than tensors and plain values" in warnings[0]


@pytest.mark.parametrize("planted", ["last.ckpt", "best/best.ckpt"])
def test_a_pickle_payload_in_a_resume_checkpoint_never_runs_and_the_fold_starts_again(
    tiny_files, tmp_path, planted, caplog
):
    """A fold cut short leaves its resume point and best-so-far weights in ``fold<k>_resume/``; either
    replaced by a pickled object is never unpickled: the fold starts again from epoch 0, with a warning."""
    from hydra import compose, initialize_config_dir
    from lightning.pytorch.callbacks import Callback

    from rheograph.learn.train import train_folds

    class Stop(Callback):
        def on_train_epoch_start(self, trainer, module):
            if trainer.current_epoch == 2:
                raise RuntimeError("stopped mid-fold")

    class Epochs(Callback):
        def __init__(self):
            self.trained = []

        def on_train_epoch_start(self, trainer, module):
            self.trained.append(trainer.current_epoch)

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(
            "train",
            overrides=[
                *tiny_training_overrides(tiny_files, tmp_path),
                "trainer.max_epochs=3",
                "trainer.enable_progress_bar=false",
                "~logger",
                "report=false",
                "fold=0",
                "model.net.hidden=8",
                "threads=1",
            ],
        )
    run_dir, marker = tmp_path / "run", tmp_path / "payload_ran"
    with pytest.raises(RuntimeError, match="stopped mid-fold"):
        train_folds(cfg, run_dir, fold_callbacks=lambda position, k: [Stop()])
    assert (run_dir / "fold0_resume" / planted).exists()
    plant_payload(run_dir / "fold0_resume" / planted, marker)
    epochs = Epochs()
    with caplog.at_level("WARNING", logger="rheograph.train"):
        train_folds(cfg, run_dir, fold_callbacks=lambda position, k: [epochs])
    assert not marker.exists()
    assert epochs.trained == [0, 1, 2]
    warnings = [r.getMessage() for r in caplog.records if "unreadable" in r.getMessage()]
    assert len(warnings) == 1 and "objects other than tensors and plain values" in warnings[0]
    assert "the fold starts again" in warnings[0]


@pytest.mark.parametrize("flag", ["--experimental-rerun", "--experimental-rerun=", "--exp"])
def test_hydras_rerun_flag_which_unpickles_its_file_is_refused_in_one_line(tmp_path, monkeypatch, flag):
    """``--experimental-rerun FILE`` (or an abbreviation argparse accepts) would unpickle FILE: every
    Hydra entry point refuses it before Hydra reads the file."""
    import pickle

    from rheograph.cli.console import _hydra_app
    from rheograph.errors import run_hydra_app

    marker, planted = tmp_path / "payload_ran", tmp_path / "config.pickle"
    planted.write_bytes(pickle.dumps(Payload(marker)))
    argv = [f"{flag}{planted}"] if flag.endswith("=") else [flag, str(planted)]
    monkeypatch.setattr(sys, "argv", ["rheograph train", *argv])
    with pytest.raises(SystemExit) as refused:
        run_hydra_app(_hydra_app("train"), "rheograph train")
    message = str(refused.value.code)
    assert (
        message.startswith(f"rheograph train: error: {flag.rstrip('=')}: not accepted")
        and "\n" not in message
    )
    assert not marker.exists()


# ---- static check: no reader unpickles ---------------------------------------------------------------
UNPICKLING_MODULES = {"pickle", "cPickle", "_pickle", "dill", "cloudpickle", "shelve", "marshal", "joblib"}


def _dotted(node) -> str:
    """``a.b.c`` of a Name / Attribute chain ('' for anything else)."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        parts.append(node.id)
        return ".".join(reversed(parts))
    return ""


def _keyword(call: ast.Call, name: str):
    """The value of keyword ``name`` of ``call``: its constant, its expression node when not a constant
    (also a ``**`` mapping, which may hold it), ``...`` when absent."""
    for keyword in call.keywords:
        if keyword.arg == name:
            return keyword.value.value if isinstance(keyword.value, ast.Constant) else keyword.value
        if keyword.arg is None:  # **kwargs: anything may be in it
            return keyword.value
    return ...


def _constant_string_tables(tree: ast.Module) -> set[str]:
    """Module-level names bound to a dict literal of string constants (a fixed command table)."""
    tables = set()
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.value, ast.Dict):
            if all(isinstance(v, ast.Constant) and isinstance(v.value, str) for v in node.value.values):
                tables |= {t.id for t in node.targets if isinstance(t, ast.Name)}
    return tables


def unsafe_reads(source: str, filename: str) -> list[str]:
    """Every place in ``source`` that may unpickle a file or run code named by data: ``torch.load``
    without ``weights_only=True``, a pickling module imported or called, ``numpy.load`` with
    ``allow_pickle`` other than False, ``yaml.load`` without a safe loader (and yaml's unsafe readers),
    ``eval`` / ``exec``, and a module imported by a name that is not a constant or a constant table's."""
    tree = ast.parse(source, filename)
    tables = _constant_string_tables(tree)
    found = []
    for node in ast.walk(tree):
        where = f"{filename}:{getattr(node, 'lineno', '?')}"
        if isinstance(node, ast.Import | ast.ImportFrom):
            names = [node.module or ""] if isinstance(node, ast.ImportFrom) else [a.name for a in node.names]
            if isinstance(node, ast.ImportFrom) and node.module in ("torch", "numpy", "yaml"):
                if any(a.name in ("load", "unsafe_load", "full_load") for a in node.names):
                    found.append(
                        f"{where}: from {node.module} import load (checked only as {node.module}.load)"
                    )
            for name in names:
                if name.split(".")[0] in UNPICKLING_MODULES:
                    found.append(f"{where}: imports {name}")
        if not isinstance(node, ast.Call):
            continue
        called = _dotted(node.func)
        last = called.rsplit(".", 1)[-1]
        if (
            called in ("torch.load", "torch.serialization.load")
            and _keyword(node, "weights_only") is not True
        ):
            found.append(f"{where}: {called} without weights_only=True")
        elif called in ("np.load", "numpy.load") and _keyword(node, "allow_pickle") not in (..., False):
            found.append(f"{where}: {called} with allow_pickle other than False")
        elif called in ("yaml.unsafe_load", "yaml.full_load", "yaml.load_all", "yaml.unsafe_load_all"):
            found.append(f"{where}: {called}")
        elif called == "yaml.load":
            loader = _keyword(node, "Loader")
            if loader is ... and len(node.args) > 1:
                loader = node.args[1]
            if _dotted(loader) not in ("yaml.SafeLoader", "yaml.CSafeLoader", "SafeLoader", "CSafeLoader"):
                found.append(f"{where}: yaml.load without a safe loader")
        elif called in ("eval", "exec", "builtins.eval", "builtins.exec", "__import__"):
            found.append(f"{where}: {called}")
        elif called.split(".")[0] in UNPICKLING_MODULES or last in ("read_pickle", "torch_load"):
            found.append(f"{where}: {called}")
        elif last == "import_module" and node.args:
            name = node.args[0]
            fixed = isinstance(name, ast.Constant) or (
                isinstance(name, ast.Subscript)
                and isinstance(name.value, ast.Name)
                and name.value.id in tables
            )
            if not fixed:
                found.append(f"{where}: import_module of a name that is not a constant")
    return found


def checked_sources() -> list[Path]:
    """The package, the benchmarks and the entry-point scripts at the repository root."""
    return sorted([*(ROOT / "src").rglob("*.py"), *(ROOT / "bench").rglob("*.py"), *ROOT.glob("*.py")])


def test_no_reader_in_the_package_benchmarks_or_scripts_unpickles_or_runs_named_code():
    sources = checked_sources()
    assert len(sources) > 50 and ROOT / "src" / "rheograph" / "learn" / "predict.py" in sources
    found = [hit for path in sources for hit in unsafe_reads(path.read_text(), str(path.relative_to(ROOT)))]
    assert not found, "\n".join(found)


@pytest.mark.parametrize(
    "line",
    [
        "torch.load(path)",
        "torch.load(path, weights_only=False)",
        "torch.load(path, **options)",
        "torch.load(path, weights_only=flag)",
        "import pickle",
        "from dill import loads",
        "import joblib.numpy_pickle",
        "joblib.load(path)",
        "np.load(path, allow_pickle=True)",
        "numpy.load(path, allow_pickle=flag)",
        "yaml.load(text)",
        "yaml.load(text, Loader=yaml.Loader)",
        "yaml.unsafe_load(text)",
        "eval(text)",
        "exec(text)",
        "importlib.import_module(name)",
        "importlib.import_module(bundle['module_class'])",
        "from torch import load",
    ],
)
def test_the_static_check_catches_each_unsafe_read(line):
    assert unsafe_reads(line, "x.py"), line


def test_the_static_check_passes_safe_reads():
    safe = """
TOOLS = {"predict": "rheograph.learn.predict"}
torch.load(path, map_location="cpu", weights_only=True)
np.load(path)
np.load(path, allow_pickle=False)
yaml.load(text, Loader=yaml.SafeLoader)
importlib.import_module(TOOLS[command])
importlib.import_module("rheograph.cli.hydra_apps")
"""
    assert unsafe_reads(safe, "x.py") == []
