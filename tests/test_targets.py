"""The target specification (rheograph.graphs.targets): its rules, refused in one line naming the key;
the adapter from the form of earlier versions (graph booleans and scales, module columns), for every
bundle form and every shipped model; a bundle's round trip."""

import json

import pytest
import torch
from conftest import resgcn

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings
from rheograph.graphs.targets import (
    LEGACY_GRAPH_KEYS,
    LEGACY_MODULE_KEYS,
    Target,
    TargetSpec,
    from_legacy,
    spec_of_record,
)

SOLVE_INPUTS = ("log_stress", "solve_viscosity", "frictional_coordination", "spring_pressure")
PHYSICS_SOLVE = TargetSpec(
    eta_r=Target(scale=1.0, relative_to="solve_viscosity"),
    pi=Target(scale=0.1, relative_to="spring_pressure", per_stress=True),
    z_mu=Target(relative_to="frictional_coordination"),
)


@pytest.mark.parametrize(
    "build, message",
    [
        (lambda: TargetSpec(eta_r=Target(scale=0.0)), r"^graph\.targets\.eta_r\.scale=0\.0 is invalid"),
        (lambda: TargetSpec(pi=Target(scale=float("inf"))), r"^graph\.targets\.pi\.scale=inf is invalid"),
        (lambda: TargetSpec(z_mu=Target(scale=1.0)), r"^graph\.targets\.z_mu\.scale=1\.0 is invalid"),
        (
            lambda: TargetSpec(eta_r=Target(scale=1.0, relative_to="spring_pressure")),
            r"^graph\.targets\.eta_r\.relative_to='spring_pressure' is invalid: allowed null or one of "
            r"\['solve_viscosity', 'relaxed_viscosity'\]",
        ),
        (
            lambda: TargetSpec(eta_r=Target(scale=1.0, per_stress=True)),
            r"^graph\.targets\.eta_r\.per_stress is invalid",
        ),
        (
            lambda: TargetSpec(pi=Target(scale=0.1, relative_to="spring_pressure")),
            r"^graph\.targets\.pi\.relative_to=spring_pressure .*needs graph\.targets\.pi\.per_stress=true",
        ),
        (
            lambda: GraphSettings(
                graph_inputs=("log_stress",),
                targets=TargetSpec(z_mu=Target(relative_to="frictional_coordination")),
            ),
            r"^graph\.targets\.z_mu\.relative_to=frictional_coordination .*add frictional_coordination to "
            r"graph\.graph_inputs",
        ),
        (
            lambda: GraphSettings(
                graph_inputs=("log_stress",),
                targets=TargetSpec(eta_r=Target(scale=1.0, relative_to="solve_viscosity")),
            ),
            r"^graph\.targets\.eta_r\.relative_to=solve_viscosity .*add solve_viscosity",
        ),
        (
            lambda: GraphSettings(
                graph_inputs=("log_stress",),
                targets=TargetSpec(pi=Target(scale=0.1, relative_to="spring_pressure", per_stress=True)),
            ),
            r"^graph\.targets\.pi\.relative_to=spring_pressure .*add spring_pressure",
        ),
        (
            lambda: GraphSettings(targets=TargetSpec(pi=Target(scale=0.1, per_stress=True))),
            r"^graph\.targets\.pi\.per_stress=true .*add log_stress",
        ),
        (
            lambda: GraphSettings(graph_inputs=(), stress_known=False),
            r"^graph\.stress_known=false needs graph\.targets\.pi\.per_stress=true",
        ),
        (lambda: TargetSpec.from_config({"eta": {}}), r"^graph\.targets: unknown target\(s\) \['eta'\]"),
        (
            lambda: TargetSpec.from_config({"pi": {"relative": None}}),
            r"^graph\.targets\.pi: unknown option\(s\) \['relative'\]",
        ),
        (
            lambda: from_legacy({"viscosity_on_solve": True, "viscosity_on_relaxed": True}),
            r"^graph\.viscosity_on_solve and graph\.viscosity_on_relaxed .*set one of them to false",
        ),
    ],
)
def test_every_rule_of_the_specification_is_refused_in_one_line(build, message):
    with pytest.raises(InputError, match=message) as refused:
        build()
    assert "\n" not in str(refused.value)


def test_the_specification_round_trips_through_its_config_and_reads_partial_ones():
    for spec in (
        TargetSpec(),
        PHYSICS_SOLVE,
        TargetSpec(eta_r=Target(scale=2.0, relative_to="relaxed_viscosity")),
    ):
        assert TargetSpec.from_config(spec.to_config()) == spec
        assert TargetSpec.from_config(json.loads(json.dumps(spec.to_config()))) == spec
        assert from_legacy(spec.legacy_options()) == spec  # the adapter and its inverse
    assert TargetSpec.from_config({"pi": {"per_stress": True}}) == TargetSpec(
        pi=Target(scale=0.1, per_stress=True)
    )
    assert PHYSICS_SOLVE.columns(SOLVE_INPUTS) == [(0, 1), (1, 3), (2, 2)]
    assert TargetSpec().columns(()) == []


# the forms earlier versions wrote: (graph record, module hyperparameters) of the physics_solve default
# (format 3), of the relaxed imaging model, of one without pressure_input (before the spring pressure)
LEGACY_RECORDS = [
    (
        {
            "graph_inputs": list(SOLVE_INPUTS),
            "viscosity_scale": 1.0,
            "pressure_scale": 0.1,
            "pressure_per_stress": True,
            "z_mu_on_count": True,
            "viscosity_on_solve": True,
            "viscosity_on_relaxed": False,
            "pressure_on_spring": True,
        },
        {"viscosity_scale": 1.0, "pressure_scale": 0.1, "pressure_per_stress": True, "z_mu_input": 2,
         "viscosity_input": 1, "pressure_input": 3},
        PHYSICS_SOLVE,
    ),
    (
        {
            "graph_inputs": ["log_stress", "position_noise", "relaxed_viscosity"],
            "viscosity_scale": 1.0,
            "pressure_scale": 0.1,
            "pressure_per_stress": True,
            "z_mu_on_count": False,
            "viscosity_on_solve": False,
            "viscosity_on_relaxed": True,
            "pressure_on_spring": False,
        },
        {"viscosity_scale": 1.0, "pressure_scale": 0.1, "pressure_per_stress": True, "z_mu_input": -1,
         "viscosity_input": 2, "pressure_input": -1},
        TargetSpec(
            eta_r=Target(scale=1.0, relative_to="relaxed_viscosity"), pi=Target(scale=0.1, per_stress=True)
        ),
    ),
    (
        {
            "graph_inputs": ["log_stress", "solve_viscosity", "frictional_coordination"],
            "viscosity_scale": 2.0,
            "pressure_scale": 0.5,
            "pressure_per_stress": False,
            "z_mu_on_count": True,
            "viscosity_on_solve": True,
        },
        {"viscosity_scale": 2.0, "pressure_scale": 0.5, "pressure_per_stress": False, "z_mu_input": 2,
         "viscosity_input": 1},
        TargetSpec(
            eta_r=Target(scale=2.0, relative_to="solve_viscosity"),
            pi=Target(scale=0.5),
            z_mu=Target(relative_to="frictional_coordination"),
        ),
    ),
]  # fmt: skip


@pytest.mark.parametrize("graph, hparams, spec", LEGACY_RECORDS)
def test_the_adapter_maps_every_earlier_form_to_the_specification(graph, hparams, spec):
    assert from_legacy(graph) == spec
    assert from_legacy(graph, hparams) == spec
    assert spec_of_record(graph) == spec  # a card of an earlier version
    # the columns the module now derives are those the earlier module was given
    given = [
        (k, hparams.get(key, -1)) for k, key in enumerate(("viscosity_input", "pressure_input", "z_mu_input"))
    ]
    assert spec.columns(graph["graph_inputs"]) == [(k, c) for k, c in given if c >= 0]
    for key, wrong in (("viscosity_input", 0), ("z_mu_input", 0), ("pressure_scale", 7.0)):
        with pytest.raises(InputError, match=f"the model's {key}="):
            from_legacy(graph, {**hparams, key: wrong})


def _legacy_bundle(module, settings, fmt: str, graph: dict, hparams: dict) -> dict:
    """A bundle of ``fmt`` as earlier versions wrote it, with ``module``'s weights."""
    record = {
        "format": fmt,
        "state_dict": module.state_dict(),
        "graph": {**graph, "cutoff": 0.5, "edge_features": list(settings.edge_features), "min_strain": 1.0},
        "fold": 0,
        "split": "random",
        "domain": {"phi": [0.76, 0.76], "stress": [0.5, 200.0], "n_particles": [400], "size_ratio": [1.4],
                   "edge_min": [0.0] * 6, "edge_max": [1.0] * 6},
    }  # fmt: skip
    # earlier versions held the network's options flat among the module's
    network = {k: v for k, v in dict(module.hparams).items() if k not in ("targets", "graph_inputs", "net")}
    network.update(module.hparams["net"]["kwargs"])
    key = "hparams" if fmt == "rheograph-surrogate-2" else "hyper_parameters"
    return {**record, key: {**network, **hparams}}


@pytest.mark.parametrize("fmt", ["rheograph-surrogate-2", "rheograph-surrogate-3"])
@pytest.mark.parametrize("graph, hparams, spec", LEGACY_RECORDS)
def test_bundles_of_earlier_formats_load_with_their_specification(tmp_path, fmt, graph, hparams, spec):
    from rheograph.learn.bundle import load_bundle, read_bundle
    from rheograph.learn.module import SurrogateModule

    inputs = tuple(graph["graph_inputs"])
    module = SurrogateModule(net=resgcn(global_in=len(inputs)), targets=spec, graph_inputs=inputs)
    relax = {"relax_strain": 0.01} if "relaxed_viscosity" in inputs else {}
    graph = {**graph, **relax}
    settings = GraphSettings(graph_inputs=inputs, targets=spec, **relax)
    path = tmp_path / "fold0.pt"
    torch.save(_legacy_bundle(module, settings, fmt, graph, hparams), path)
    upgraded = read_bundle(path)
    assert not set(upgraded["graph"]) & set(LEGACY_GRAPH_KEYS)
    assert not set(upgraded["hyper_parameters"]) & set(LEGACY_MODULE_KEYS)
    loaded, loaded_settings, _ = load_bundle(path)
    assert loaded.targets == spec and loaded_settings.targets == spec
    assert loaded.reference_columns == spec.columns(inputs)
    # a record whose halves disagree is a damaged bundle, named
    torch.save(_legacy_bundle(module, settings, fmt, graph, {**hparams, "viscosity_input": 0}), path)
    with pytest.raises(InputError, match=r"fold0\.pt: a damaged rheograph model bundle .*viscosity_input=0"):
        read_bundle(path)


def test_a_bundle_round_trip_keeps_the_specification(tmp_path):
    from rheograph.learn.bundle import BUNDLE_FORMAT, load_bundle, read_bundle, save_bundle
    from rheograph.learn.module import SurrogateModule

    settings = GraphSettings(graph_inputs=SOLVE_INPUTS, targets=PHYSICS_SOLVE)
    module = SurrogateModule(
        net=resgcn(global_in=len(SOLVE_INPUTS)), targets=PHYSICS_SOLVE, graph_inputs=SOLVE_INPUTS
    )
    domain = {"phi": [0.76, 0.76], "stress": [0.5, 200.0], "n_particles": [400], "size_ratio": [1.4],
              "edge_min": [0.0] * 6, "edge_max": [1.0] * 6}  # fmt: skip
    save_bundle(tmp_path / "fold0.pt", module, settings, 0, "random", domain)
    raw = torch.load(tmp_path / "fold0.pt", map_location="cpu", weights_only=True)
    assert raw["format"] == BUNDLE_FORMAT and raw["graph"]["targets"] == PHYSICS_SOLVE.to_config()
    assert read_bundle(tmp_path / "fold0.pt")["graph"] == raw["graph"]  # the current form: as it is
    loaded, loaded_settings, _ = load_bundle(tmp_path / "fold0.pt")
    assert loaded_settings == settings and loaded.targets == PHYSICS_SOLVE
    assert loaded.reference_columns == [(0, 1), (1, 3), (2, 2)]
    rebuilt = SurrogateModule.load_from_checkpoint(
        tmp_path / "fold0.pt", map_location="cpu", weights_only=True
    )
    assert rebuilt.targets == PHYSICS_SOLVE and rebuilt.reference_columns == loaded.reference_columns


def test_every_shipped_model_reads_as_the_specification_its_records_state():
    """The shipped bundles and their cards give one specification; those of an earlier format give the
    one their booleans and columns said: each reference of the booleans, at the column the module was
    built with."""
    from rheograph.learn.bundle import BUNDLE_FORMAT, load_bundle
    from rheograph.learn.module import SurrogateModule
    from rheograph.learn.registry import MODELS_DIR, list_models

    names = list_models()
    assert names
    for name in names:
        path = MODELS_DIR / name / "fold0.pt"
        raw = torch.load(path, map_location="cpu", weights_only=True)
        graph, hparams = raw["graph"], raw.get("hyper_parameters") or raw["hparams"]
        module, settings, _ = load_bundle(path)
        spec = settings.targets
        assert (
            module.targets
            == spec
            == spec_of_record(json.loads((path.parent / "card.json").read_text())["graph"])
        )
        lightning = SurrogateModule.load_from_checkpoint(path, map_location="cpu", weights_only=True)
        assert lightning.targets == spec and lightning.reference_columns == module.reference_columns, name
        if raw["format"] == BUNDLE_FORMAT:  # written in the current form: the specification as it is
            assert graph["targets"] == spec.to_config(), name
            continue
        assert spec.legacy_options() == {k: graph.get(k, False) for k in LEGACY_GRAPH_KEYS}, name
        old = [(0, hparams.get("viscosity_input", -1)), (1, hparams.get("pressure_input", -1)),
               (2, hparams.get("z_mu_input", -1))]  # fmt: skip
        assert module.reference_columns == [(k, c) for k, c in old if c >= 0], name
