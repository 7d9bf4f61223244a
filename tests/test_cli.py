"""The Hydra entry point: config composition, run directory naming, resume by re-running."""

import subprocess
import sys
from pathlib import Path

import pytest
from hydra import compose, initialize_config_dir

from rheograph.cli.hydra_apps import register_resolvers, simulate_main
from rheograph.io.hdf5 import read_run_info
from rheograph.sim.params import ParameterError, SimParams

ROOT = Path(__file__).resolve().parents[1]


def compose_sim(overrides):
    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        return compose(config_name="simulate", overrides=overrides)


@pytest.mark.parametrize("preset", ["tiny", "n400", "n2000", "lfdem"])
def test_presets_compose_into_valid_parameters(preset):
    cfg = compose_sim([f"sim={preset}"])
    params = SimParams.from_mapping(dict(cfg.sim))
    assert params == SimParams(**dict(cfg.sim))
    if preset == "n400":  # physics.md's physics with the converged numerics
        assert params == SimParams(integrator="implicit", disp_max=2e-3, snapshot_interval=0.1)
    if preset == "lfdem":  # LF_DEM's discretisation
        assert params == SimParams(
            integrator="euler", lagged_step_control=True, disp_max=1e-3, snapshot_interval=0.1
        )


def test_every_parameter_is_configurable():
    cfg = compose_sim(["sim=n400"])
    assert set(cfg.sim) == set(SimParams().to_dict())


def test_unknown_key_in_sim_config_is_an_error(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    cfg = compose_sim(["sim=tiny", "+sim.temperature=3"])
    with pytest.raises(ParameterError, match="temperature"):
        simulate_main(cfg)


def test_simulate_script_writes_and_resumes(tmp_path):
    cmd = [
        sys.executable,
        str(ROOT / "simulate.py"),
        "sim=tiny",
        "sim.strain=0.05",
        f"output_root={tmp_path}",
        "progress=false",
    ]
    subprocess.run(cmd, check=True, capture_output=True, cwd=tmp_path)
    files = list(tmp_path.glob("N64_phi0.7_s10_seed1_d0.002_implicit/trajectory.h5"))
    assert len(files) == 1
    assert read_run_info(files[0])["status"] == "completed"
    # running it again with a longer strain continues the same file
    done = subprocess.run(
        cmd[:3] + ["sim.strain=0.08"] + cmd[4:], check=True, capture_output=True, text=True, cwd=tmp_path
    )
    assert "status completed after strain 0.08" in done.stderr + done.stdout
    assert read_run_info(files[0])["strain"] >= 0.08


@pytest.mark.parametrize(
    "override,message",
    [
        ("sim.phi=0.95", "sim.phi=0.95 is invalid: allowed 0 < phi <= 0.86"),
        ("sim.phi=abc", "sim.phi='abc' is invalid: expected a number"),  # also names its run directory
        ("solver=umfpack", "solver='umfpack' is unknown: allowed 'auto' or one of"),
    ],
)
def test_bad_override_fails_with_the_parameter_name(tmp_path, override, message):
    cmd = [sys.executable, str(ROOT / "simulate.py"), "sim=tiny", override, f"output_root={tmp_path}"]
    done = subprocess.run(cmd, capture_output=True, text=True, cwd=tmp_path)
    assert done.returncode != 0
    assert message in done.stderr
    assert "Traceback" not in done.stderr
    assert not list(tmp_path.rglob("*.h5"))  # nothing half-written


def test_scheme_labels_round_trip_and_name_runs_apart():
    from rheograph.naming import run_name
    from rheograph.sim.params import INTEGRATORS, SimParams, scheme_name, scheme_settings

    names = set()
    for integrator in INTEGRATORS:
        for lagged in (False, True):
            label = scheme_name(integrator, lagged)
            assert scheme_settings(label) == {"integrator": integrator, "lagged_step_control": lagged}
            names.add(run_name(SimParams(**scheme_settings(label))))
    assert len(names) == 4  # a lagged run never resumes a default run's file


def test_rheograph_command_runs_the_entry_points_outside_the_repository(tmp_path):
    """The console script composes the configuration shipped inside the package from any folder."""
    import subprocess
    import sys

    def run(*args):
        return subprocess.run(
            [sys.executable, "-m", "rheograph.cli.console", *args],
            cwd=tmp_path,
            capture_output=True,
            text=True,
        )

    simulate = run("simulate", "--cfg", "job")
    assert simulate.returncode == 0 and "integrator: implicit" in simulate.stdout
    train = run("train", "experiment=imaging", "--cfg", "job")
    assert train.returncode == 0 and "on_state_mean: true" in train.stdout
    bad = run("simulate", "sim.phi=2")
    assert bad.returncode != 0 and bad.stderr.strip().splitlines()[-1].startswith(
        "rheograph simulate: error:"
    )
    unknown = run("simulat")
    assert unknown.returncode == 2 and "unknown command 'simulat'" in unknown.stderr


def test_every_shipped_fold_bundle_is_one_file_that_lightning_loads_too():
    """One file per fold model: ``load_from_checkpoint`` rebuilds the network the bundle holds, with its
    weights, and no second copy of them lies beside it."""
    import torch

    from rheograph.learn.module import SurrogateModule
    from rheograph.learn.registry import MODELS_DIR, list_models

    for name in list_models():
        assert sorted((MODELS_DIR / name).glob("fold*.pt")), name
        assert not list((MODELS_DIR / name).glob("*.ckpt")), name
    path = MODELS_DIR / "N400_phi0.76" / "fold2.pt"
    bundle = torch.load(path, map_location="cpu", weights_only=True)
    module = SurrogateModule.load_from_checkpoint(path, map_location="cpu", weights_only=True)
    assert all(torch.equal(v, module.state_dict()[k]) for k, v in bundle["state_dict"].items())
    # an earlier format (the network's options flat): rebuilt as its own network, not the defaults
    assert module.hparams.net["kwargs"]["hidden"] == bundle["hyper_parameters"]["hidden"]
    assert module.hparams.net["kwargs"]["edge_in"] == bundle["hyper_parameters"]["edge_in"] == 14


def test_shipping_under_a_taken_name_is_refused_and_replace_swaps_the_model_whole(tmp_path, monkeypatch):
    """A model folder never mixes two runs: a second ship under the same name is refused; with
    ``replace`` the new run's folds, error model and card replace the old ones, none of them kept."""
    import shutil

    from rheograph.errors import InputError
    from rheograph.learn import registry

    # a finished five-fold run: the committed run's records with the shipped model's weights
    five_folds = tmp_path / "five_folds"
    shutil.copytree(ROOT / "docs/results/pressure_on_spring/N400_phi0.76", five_folds)
    for fold in sorted((registry.MODELS_DIR / "N400_phi0.76").glob("fold*.pt")):
        shutil.copy(fold, five_folds / fold.name)
    monkeypatch.setattr(registry, "MODELS_DIR", tmp_path / "models")
    registry.ship(five_folds, "m")
    assert len(list((tmp_path / "models/m").glob("fold*.pt"))) == 5
    one_fold = tmp_path / "run"  # the same run cut to its first fold, without an error model
    one_fold.mkdir()
    for name in ("fold0.pt", "fold0_split.json", "metrics.json"):
        shutil.copy(five_folds / name, one_fold / name)
    with pytest.raises(InputError, match="--name m: a model of that name is shipped"):
        registry.ship(one_fold, "m")
    assert len(list((tmp_path / "models/m").glob("fold*.pt"))) == 5
    registry.ship(one_fold, "m", replace=True)
    shipped = sorted(p.name for p in (tmp_path / "models/m").iterdir())
    assert [p for p in shipped if p.startswith("fold")] == ["fold0.pt"]
    assert "error_model.json" not in shipped and "card.json" in shipped
    assert sorted(p.name for p in (tmp_path / "models").iterdir()) == ["m"]  # no staging folder left
    # a replacement cut between its two renames: the old model is restored, not lost to the next ship
    (tmp_path / "models/m").rename(tmp_path / "models/.m.replaced")
    with pytest.raises(InputError, match="a model of that name is shipped"):
        registry.ship(five_folds, "m")
    assert registry.list_models() == ["m"] and len(list((tmp_path / "models/m").glob("fold*.pt"))) == 1
    for bad in ("../elsewhere", ".hidden", "a b"):
        with pytest.raises(InputError, match="a model name is letters, digits"):
            registry.ship(one_fold, bad)


def test_the_top_level_names_are_listed_and_each_resolves_to_its_documented_object():
    """``dir(rheograph)`` shows the public names (they are imported lazily, so without ``__dir__`` an
    interactive user sees none), and each resolves to the object the API reference documents."""
    import rheograph
    from rheograph.io.snapshots import read_snapshots
    from rheograph.learn.nets import register_graph_network
    from rheograph.learn.networks import register_network
    from rheograph.learn.predict import load_model
    from rheograph.learn.registry import list_models

    assert set(rheograph.__all__) <= set(dir(rheograph))
    documented = {
        "list_models": list_models,
        "load_model": load_model,
        "read_snapshots": read_snapshots,
        "register_graph_network": register_graph_network,
        "register_network": register_network,
    }
    assert {name: getattr(rheograph, name) for name in rheograph.__all__} == documented
    api = (ROOT / "docs" / "reference" / "api.md").read_text()
    for name, obj in documented.items():
        assert f"::: {obj.__module__}.{name}" in api, f"{name} is missing from the API reference"


def test_the_model_list_names_each_models_dimension(capsys):
    """``predict.py --list-models``: every shipped model with its dimension, from its card (the models
    written before 3D models existed record none and read as 2D; the 3D ones carry _3d in their name)."""
    from rheograph.learn.predict import main as predict_main
    from rheograph.learn.registry import list_models

    predict_main(["--list-models"])
    lines = capsys.readouterr().out.splitlines()
    assert len(lines) == len(list_models())
    for line in lines:
        name = line.split(":")[0]
        assert f": {3 if '_3d' in name else 2}D, phi " in line, line
