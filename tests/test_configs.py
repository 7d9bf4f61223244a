"""Every simulation campaign sweeps only valid state points (the datasets' at the converged step of their
area fraction, docs/validation/time_step.md), every training experiment composes and runs, and neither group
is accepted by the other entry point."""

import dataclasses
import itertools
from pathlib import Path

import pytest
import torch
from hydra import compose, initialize_config_dir
from omegaconf import OmegaConf

from rheograph.cli.hydra_apps import register_resolvers
from rheograph.errors import InputError
from rheograph.sim.params3d import params_from_mapping

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGNS = sorted(p.stem for p in (ROOT / "conf" / "campaign").glob("*.yaml"))
EXPERIMENTS = sorted(p.stem for p in (ROOT / "conf" / "experiment").glob("*.yaml"))


def sweep(name: str):
    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="simulate", overrides=[f"campaign={name}"], return_hydra_config=True)
    params = {k: str(v).split(",") for k, v in cfg.hydra.sweeper.params.items() if k.startswith("sim.")}
    for values in itertools.product(*params.values()):
        sim = OmegaConf.to_container(cfg.sim, resolve=True)
        sim.update({k.removeprefix("sim."): float(v) for k, v in zip(params, values)})
        sim["seed"] = int(sim["seed"])
        yield params_from_mapping(sim)  # SimParams, or SimParams3D for a 3D campaign


def test_the_two_groups_hold_what_their_entry_point_runs():
    """Campaigns configure simulations (``sim``), experiments training (``data``, ``model``, ...)."""
    assert len(CAMPAIGNS) >= 10 and len(EXPERIMENTS) >= 10
    for name in CAMPAIGNS:
        text = (ROOT / "conf" / "campaign" / f"{name}.yaml").read_text()
        assert "\nsim:" in text or "sim." in text, name
        assert "\nmodel:" not in text and "\ndata:" not in text, name
    for name in EXPERIMENTS:
        text = (ROOT / "conf" / "experiment" / f"{name}.yaml").read_text()
        assert "\nsim:" not in text, name


@pytest.mark.parametrize(
    "config, override, group",
    [("simulate", "experiment=demo", "experiment"), ("train", "campaign=large_n", "campaign")],
)
def test_an_entry_point_refuses_the_other_ones_group(config, override, group):
    from hydra.errors import ConfigCompositionException

    from rheograph.errors import hydra_error_line

    register_resolvers()
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        with pytest.raises(ConfigCompositionException, match=group) as refused:
            compose(config_name=config, overrides=[override])
    # the one line the entry point prints names the group's owner, not Hydra's advice to append it with +
    line = hydra_error_line(refused.value)
    owner = {"experiment": "train.py", "campaign": "simulate.py"}[group]
    assert line.startswith(f"{group}=...") and f"belong to {owner}" in line and "+" not in line


@pytest.mark.parametrize("name", CAMPAIGNS)
def test_campaigns_sweep_valid_state_points(name):
    points = list(sweep(name))  # params_from_mapping refuses an invalid one
    assert points
    if name.startswith("dataset_"):
        for p in points:
            assert p.integrator == "implicit"
            # phi = 0.80 needs 1e-3 (2e-3 slides spuriously near jamming); below, 2e-3 is converged
            assert p.disp_max == (1e-3 if p.phi == pytest.approx(0.80) else 2e-3), (name, p.phi)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_training_experiments_compose(name, tiny_files):
    """Every training experiment composes, passes the run checks, and its graph and model options build
    and run: the graphs of a tiny run with the experiment's features go through its model to one finite
    row of three targets per graph -- a typo or a shape mismatch fails here, not after the data."""
    from hydra.utils import instantiate
    from torch_geometric.data import Batch

    from rheograph.graphs.dataset import snapshot_graphs
    from rheograph.learn.train import check_run_settings, folds_to_train, graph_settings, input_sizes

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=[f"experiment={name}"])
    if cfg.trainer.accelerator == "gpu" and not torch.cuda.is_available():  # a GPU experiment, CPU machine
        with pytest.raises(InputError, match="no CUDA GPU"):
            check_run_settings(cfg)
    else:
        check_run_settings(cfg)
    assert folds_to_train(cfg)
    settings = graph_settings(cfg)
    module = instantiate(cfg.model, net=input_sizes(settings), _convert_="all")
    # the tiny runs end at strain 0.3, before the experiments' steady-state windows
    graphs = snapshot_graphs(tiny_files[1], dataclasses.replace(settings, min_strain=0.0), 0)[:2]
    with torch.no_grad():
        out = module.eval()(Batch.from_data_list(graphs))
    assert out.shape == (2, 3) and torch.isfinite(out).all()


@pytest.mark.parametrize(
    "search,inputs",
    [
        ("held_out_phi076", "physics"),
        ("held_out_phi076", "paper"),
        ("held_out_phi076", "physics_positions"),
        ("held_out_phi076_solve", "physics_solve"),
    ],
)
def test_search_configs_compose_one_study_per_input_variant(search, inputs):
    """Each study's fixed overrides and every corner of its search space compose a valid training
    config, and the study is named after its input variant (one study per variant)."""
    from rheograph.learn.train import folds_to_train, graph_settings
    from rheograph.learn.tune import _override, fixed_overrides

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="tune", overrides=[f"hparams_search={search}", f"inputs={inputs}"])
        assert cfg.tune.study_name == f"{inputs}_phi076"
        base = fixed_overrides(cfg)
        assert f"graph={inputs}" in base
        space = OmegaConf.to_container(cfg.tune.search_space)
        for corner in ("low", "high"):
            sampled = []
            for name, spec in space.items():
                value = spec[corner] if corner in spec else spec["choices"][0 if corner == "low" else -1]
                sampled.append(_override(name, list(value) if isinstance(value, list) else value))
            train = compose(config_name="train", overrides=base + sampled)
            assert folds_to_train(train) == [0]
            graph_settings(train)  # the graph settings and targets the corner trains with are valid
            assert (
                train.graph.edge_features
                == compose(config_name="train", overrides=[f"graph={inputs}"]).graph.edge_features
            )


def test_folds_to_train_accepts_all_one_or_a_list_and_names_the_range():
    from rheograph.errors import InputError
    from rheograph.learn.train import folds_to_train

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        assert folds_to_train(compose(config_name="train")) == [0, 1, 2, 3, 4]
        assert folds_to_train(compose(config_name="train", overrides=["fold=3"])) == [3]
        assert folds_to_train(compose(config_name="train", overrides=["fold=[0,2]"])) == [0, 2]
        for bad in ("fold=5", "fold=[0,7]", "fold=[]", "fold=-1"):
            with pytest.raises(InputError, match=r"fold=.*0\.\.4"):
                folds_to_train(compose(config_name="train", overrides=[bad]))


def test_leave_one_phi_out_has_one_fold_per_committed_area_fraction():
    """The pooled experiment runs on the committed index: one fold per area fraction it holds at its
    system size (a stale count stops every fold with the data.num_folds message)."""
    from rheograph.io.index import read_index

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=["experiment=pooled_leave_phi_out"])
    runs = read_index(ROOT / cfg.data.files)["runs"]
    phis = {
        round(e["params"]["phi"], 6)
        for e in runs
        if e["params"]["n_particles"] == cfg.data.n_particles and e["status"] != "running"
    }
    assert cfg.data.num_folds == len(phis), sorted(phis)


def test_every_surrogate_study_variant_composes_valid_graph_settings():
    """The study's variants are override lists: each must compose and give graph settings the dataset
    accepts (e.g. Pi in units of sigma only where sigma is an input), with Pi in sigma0 for the
    positions-only variants."""
    from conftest import load_bench_script

    from rheograph.learn.train import graph_settings

    study = load_bench_script("training")
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        for name, overrides in study.VARIANTS.items():
            settings = graph_settings(compose(config_name="train", overrides=overrides))
            knows_stress = "log_stress" in settings.graph_inputs
            assert settings.targets.pi.per_stress == (knows_stress and name != "physics_pi_sigma0"), name


def test_fingerprint_ignores_later_options_at_their_neutral_value_only():
    """Runs trained before an option existed (data.train_fraction, model.net.global_mixing, the graph's
    corrections) keep their fingerprint at its neutral value (they resume and report as before); any
    other value changes it — also the corrections' non-neutral default of graph=physics_solve.  The
    target specification enters in the form of earlier versions (graph booleans and scales): a config of
    that form fingerprints as the specification does."""
    from rheograph.graphs.targets import LEGACY_GRAPH_KEYS, TargetSpec
    from rheograph.learn.module import LEGACY_NET_OPTIONS
    from rheograph.learn.train import NEUTRAL_LATER_OPTIONS, config_fingerprint

    options = [(g, k, v) for g, k, v in NEUTRAL_LATER_OPTIONS if k not in LEGACY_GRAPH_KEYS]
    # the network's options live under model.net (the fingerprint reads them flat, as they were)
    path = {(g, k): f"{g}.net" if g == "model" and k in LEGACY_NET_OPTIONS else g for g, k, _ in options}
    neutral = [f"{path[group, key]}.{key}={str(value).lower()}" for group, key, value in options]
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=["~logger", *neutral, "graph=physics"])
    current = config_fingerprint(cfg)
    earlier = OmegaConf.to_container(cfg)
    for group, key, _ in options:
        node = earlier[group]["net"] if path[group, key] != group else earlier[group]
        node.pop(key)
    net = earlier["model"].pop("net")  # the network's options flat, as before model.net
    earlier["model"].update({k: v for k, v in net.items() if not k.startswith("_")})
    legacy = TargetSpec.from_config(earlier["graph"].pop("targets")).legacy_options()
    assert legacy["pressure_per_stress"] is True and not legacy["viscosity_on_solve"]
    later = {k for g, k, _ in NEUTRAL_LATER_OPTIONS if k in LEGACY_GRAPH_KEYS}
    earlier["graph"].update({k: v for k, v in legacy.items() if k not in later})  # before they existed
    assert config_fingerprint(OmegaConf.create(earlier)) == current
    for override in (
        "data.train_fraction=0.5",
        "model.net.global_mixing=virtual_node",
        "graph.targets.z_mu.relative_to=frictional_coordination",
        "graph.targets.eta_r.relative_to=solve_viscosity",
        "graph.targets.eta_r.relative_to=relaxed_viscosity",
        "graph.targets.pi.per_stress=false",
        "graph.targets.eta_r.scale=2.0",
        "graph.noise_range=[0.001,0.01]",
        "graph.noise_copies=2",
        "graph.relax_strain=0.01",
        "graph.stress_known=false",
        "model.on_state_mean=true",
    ):
        changed_overrides = [
            "~logger",
            *[o for o in neutral if o.split("=")[0] != override.split("=")[0]],
            "graph=physics",
        ]
        with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
            changed = compose(config_name="train", overrides=[*changed_overrides, override])
        assert config_fingerprint(changed) != current, override


@pytest.mark.parametrize("experiment", [None, "demo", "paper", "physics_solve_phi076_best"])
def test_a_config_with_the_network_flat_fingerprints_as_its_nested_form(experiment):
    """Runs trained before model.net held their network's options flat among the model's
    (``model.hidden``, ...): the same settings in either form give one fingerprint, so those runs resume
    and report; another network class (model.net._target_) or option gives another."""
    from rheograph.learn.train import config_fingerprint

    overrides = ["~logger"] + ([f"experiment={experiment}"] if experiment else [])
    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=overrides)
    nested = OmegaConf.to_container(cfg)
    net = nested["model"].pop("net")
    assert net.pop("_target_") == "rheograph.learn.model.ResGCN" and net.pop("_partial_") is True
    flat = {**nested, "model": {**nested["model"], **net}}
    assert "hidden" in flat["model"] and "net" not in flat["model"]
    assert config_fingerprint(OmegaConf.create(flat)) == config_fingerprint(cfg)
    other = OmegaConf.to_container(cfg)
    other["model"]["net"]["_target_"] = "mypackage.MyNet"
    assert config_fingerprint(OmegaConf.create(other)) != config_fingerprint(cfg)
    other = OmegaConf.to_container(cfg)
    other["model"]["net"]["hidden"] += 1
    assert config_fingerprint(OmegaConf.create(other)) != config_fingerprint(cfg)


def test_an_experiment_with_the_network_flat_is_refused_by_name():
    """An experiment file written before model.net (``model: {hidden: 32}``) is refused in one line
    naming the new key, before any work."""
    from rheograph.learn.train import check_run_settings

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train", overrides=["~logger", "+model.hidden=32"])
    with pytest.raises(InputError, match=r"model.hidden is an option of the network: set model.net.hidden"):
        check_run_settings(cfg)


def test_every_graph_and_model_option_is_in_the_default_config():
    """`graph.X=...` and `model.X=...` work for every option of GraphSettings and SurrogateModule (a key
    missing from the default config would be refused as a misspelling)."""
    import inspect

    from rheograph.graphs.dataset import GraphSettings
    from rheograph.learn.model import ResGCN
    from rheograph.learn.module import SurrogateModule

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(config_name="train")
    assert {f.name for f in dataclasses.fields(GraphSettings)} <= set(cfg.graph)
    # set by train.setup_fold from the data and the graph settings, not options of their own
    derived = {"self", "node_in", "edge_in", "global_in", "targets", "graph_inputs"}
    derived |= {"state_mean_by_stress"}
    options = set(inspect.signature(SurrogateModule.__init__).parameters) - derived
    assert options <= set(cfg.model), options - set(cfg.model)
    # the network's own options, but for its output width and MLP depth (fixed: three targets)
    net = set(inspect.signature(ResGCN.__init__).parameters) - derived - {"out_channels", "mlp_layers"}
    assert net <= set(cfg.model.net), net - set(cfg.model.net)


def test_the_configuration_reference_gives_every_key_a_meaning():
    """docs/reference/config.md (generated at docs build) lists every key of the three entry points with
    its default and a meaning taken from the config files or the classes behind the keys: a key added
    without a comment fails here."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("reference_hook", ROOT / "docs" / "hooks" / "reference.py")
    hook = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(hook)
    rows = [line for line in hook.config_page().splitlines() if line.startswith("| `")]
    assert len(rows) > 150
    undocumented = [row.split("|")[1].strip() for row in rows if row.rstrip().endswith("|  |")]
    assert not undocumented, undocumented
