"""``model.net``: the graph network as a nested target, its record in model files, and the one adapter
from the flat network options of earlier model files (formats 2, 3 and 4)."""

import sys
from pathlib import Path

import pytest
import torch
from conftest import resgcn
from hydra import compose, initialize_config_dir

from rheograph.errors import InputError
from rheograph.graphs.dataset import GraphSettings

ROOT = Path(__file__).resolve().parents[1] / "src" / "rheograph"
DOMAIN = {"phi": [0.76, 0.76], "stress": [0.5, 200.0], "n_particles": [400], "size_ratio": [1.4],
          "edge_min": [0.0] * 6, "edge_max": [1.0] * 6}  # fmt: skip
# a network of non-default options everywhere the defaults could hide a lost key
OPTIONS = {"hidden": 24, "num_layers": 3, "aggr": "add", "pool": "area", "head_layers": 2, "dropout": 0.0}


def _module(**options):
    from rheograph.learn.module import SurrogateModule

    torch.manual_seed(0)
    module = SurrogateModule(net=resgcn(6, 1, **{**OPTIONS, **options}), graph_inputs=["log_stress"]).eval()
    with torch.no_grad():  # buffers away from their initial values, so that losing them shows
        module.net.set_edge_scaling(torch.linspace(0.1, 0.6, 6), torch.linspace(1.0, 2.0, 6))
        module.target_mean.copy_(torch.tensor([0.5, -0.2, 1.0]))
    return module


def _batch():
    from torch_geometric.data import Batch, Data

    generator = torch.Generator().manual_seed(1)
    graphs = []
    for n in (5, 7):
        edges = torch.combinations(torch.arange(n)).T
        graphs.append(
            Data(
                x=torch.eye(2)[torch.randint(0, 2, (n,), generator=generator)],
                edge_index=torch.cat([edges, edges.flip(0)], dim=1),
                edge_attr=torch.rand(2 * edges.shape[1], 6, generator=generator),
                u=torch.rand(1, 1, generator=generator),
                area=torch.tensor([30.0]),
                stress=torch.tensor([2.0]),
                phi=torch.tensor([0.76]),
            )
        )
    return Batch.from_data_list(graphs)


def _save(module, path: Path) -> None:
    from rheograph.learn.bundle import save_bundle

    save_bundle(path, module, GraphSettings(graph_inputs=("log_stress",)), 0, "random", DOMAIN)


def _as_earlier_format(path: Path, fmt: str) -> None:
    """The bundle at ``path`` rewritten as an earlier version wrote it: the network's options flat among
    the module's hyperparameters; format 3 and 2 also the targets in their earlier form."""
    bundle = torch.load(path, weights_only=True)
    hparams = dict(bundle["hyper_parameters"])
    net = hparams.pop("net")
    hparams.update(net["kwargs"])
    if fmt != "rheograph-surrogate-4":
        targets = hparams.pop("targets")
        hparams.pop("graph_inputs")
        hparams.update(viscosity_scale=targets["eta_r"]["scale"], pressure_scale=targets["pi"]["scale"])
        hparams.update(pressure_per_stress=False, z_mu_input=-1, viscosity_input=-1, pressure_input=-1)
        graph = {k: v for k, v in bundle["graph"].items() if k != "targets"}
        bundle["graph"] = {**graph, "viscosity_scale": 1.0, "pressure_scale": 0.1}
    bundle["format"] = fmt
    if fmt == "rheograph-surrogate-2":
        del bundle["hyper_parameters"]
        bundle["hparams"] = hparams
    else:
        bundle["hyper_parameters"] = hparams
    torch.save(bundle, path)


def test_model_net_composes_with_an_override_and_builds_the_network_it_names():
    from hydra.utils import instantiate

    from rheograph.learn.model import ResGCN
    from rheograph.learn.train import graph_settings, input_sizes

    with initialize_config_dir(config_dir=str(ROOT / "conf"), version_base="1.3"):
        cfg = compose(
            config_name="train", overrides=["~logger", "model.net.hidden=8", "model.net.num_layers=1"]
        )
    settings = graph_settings(cfg)
    module = instantiate(cfg.model, net=input_sizes(settings), graph_inputs=list(settings.graph_inputs))
    assert type(module.net) is ResGCN and len(module.net.layers) == 1
    assert module.net.node_encoder.out_features == 8
    assert module.net.edge_encoder.in_features == len(settings.edge_features)
    record = module.hparams["net"]
    assert record["name"] == "rheograph.learn.model:ResGCN"
    assert record["kwargs"]["hidden"] == 8 and record["kwargs"]["global_in"] == len(settings.graph_inputs)
    assert not any(k in module.hparams for k in ("hidden", "num_layers", "edge_in"))  # the net's own


def test_a_save_load_round_trip_keeps_the_network_and_its_predictions(tmp_path):
    from rheograph.learn.bundle import BUNDLE_FORMAT, load_bundle
    from rheograph.learn.module import SurrogateModule

    module, batch = _module(), _batch()
    _save(module, tmp_path / "fold0.pt")
    raw = torch.load(tmp_path / "fold0.pt", weights_only=True)  # plain values: no class, no partial
    assert raw["format"] == BUNDLE_FORMAT and raw["hyper_parameters"]["net"] == module.hparams["net"]
    loaded, _, _ = load_bundle(tmp_path / "fold0.pt")
    lightning = SurrogateModule.load_from_checkpoint(tmp_path / "fold0.pt", weights_only=True).eval()
    with torch.no_grad():
        expected = module(batch)
        for rebuilt in (loaded, lightning):
            assert rebuilt.hparams["net"] == module.hparams["net"]
            assert len(rebuilt.net.layers) == 3 and rebuilt.net.node_encoder.out_features == 24
            assert torch.equal(rebuilt(batch), expected)


@pytest.mark.parametrize("fmt", ["rheograph-surrogate-2", "rheograph-surrogate-3", "rheograph-surrogate-4"])
def test_a_bundle_of_an_earlier_format_loads_as_its_own_network(tmp_path, fmt):
    """The flat network options of formats 2-4 are read by the one adapter (upgraded_hparams): every
    option kept (not the defaults), the same predictions bit for bit."""
    from rheograph.learn.bundle import load_bundle, read_bundle
    from rheograph.learn.module import LEGACY_NET_OPTIONS

    module, batch = _module(), _batch()
    path = tmp_path / "fold0.pt"
    _save(module, path)
    _as_earlier_format(path, fmt)
    upgraded = read_bundle(path)["hyper_parameters"]
    # every option the network was built with (the rest at the defaults it had)
    assert upgraded["net"]["name"] == module.hparams["net"]["name"]
    assert upgraded["net"]["kwargs"].items() >= module.hparams["net"]["kwargs"].items()
    assert not set(upgraded) & set(LEGACY_NET_OPTIONS)
    loaded, _, _ = load_bundle(path)
    with torch.no_grad():
        assert torch.equal(loaded(batch), module(batch))


@pytest.mark.parametrize("fmt", ["rheograph-surrogate-3", "rheograph-surrogate-4"])
def test_lightning_loads_an_earlier_format_as_its_own_network_not_the_defaults(tmp_path, fmt):
    """Lightning's load_from_checkpoint drops the flat options the constructor no longer takes:
    on_load_checkpoint rebuilds the checkpoint's network (through the same adapter) before its weights."""
    from rheograph.learn.module import SurrogateModule

    module, batch = _module(), _batch()
    path = tmp_path / "fold0.pt"
    _save(module, path)
    _as_earlier_format(path, fmt)
    rebuilt = SurrogateModule.load_from_checkpoint(path, weights_only=True).eval()
    kwargs = rebuilt.hparams["net"]["kwargs"]
    assert kwargs["hidden"] == 24 and kwargs["num_layers"] == 3 and kwargs["global_in"] == 1
    assert rebuilt.net.node_encoder.out_features == 24 and len(rebuilt.net.layers) == 3
    with torch.no_grad():
        assert torch.equal(rebuilt(batch), module(batch))


@pytest.mark.parametrize("name", ["os:system", "this:x", "rheograph.learn.module:SurrogateModule"])
def test_a_bundle_naming_an_unregistered_network_is_refused_in_one_line(tmp_path, name, monkeypatch):
    from rheograph.learn.bundle import load_bundle

    monkeypatch.delitem(sys.modules, "this", raising=False)
    path = tmp_path / "fold0.pt"
    _save(_module(), path)
    bundle = torch.load(path, weights_only=True)
    bundle["hyper_parameters"]["net"]["name"] = name
    torch.save(bundle, path)
    with pytest.raises(InputError, match="its graph network .* is not registered") as refused:
        load_bundle(path)
    assert "\n" not in str(refused.value) and str(refused.value).startswith(str(path))
    assert "this" not in sys.modules


class TinyNet(torch.nn.Module):
    """A graph network of the user's: the mean edge feature per graph through one linear layer."""

    def __init__(self, node_in: int, edge_in: int, global_in: int = 0):
        super().__init__()
        self.linear = torch.nn.Linear(edge_in, 3)

    def set_edge_scaling(self, mean, std) -> None:
        pass

    def forward(self, x, edge_index, edge_attr, batch, u=None, area=None):
        from torch_geometric.nn import global_mean_pool

        return self.linear(global_mean_pool(edge_attr, batch[edge_index[0]]))


def test_a_network_class_must_be_registered_to_be_trained_and_loaded(tmp_path, monkeypatch):
    from functools import partial

    from rheograph.learn import nets
    from rheograph.learn.bundle import load_bundle
    from rheograph.learn.module import SurrogateModule

    monkeypatch.setattr(nets, "_graph_networks", dict(nets._graph_networks))
    net = partial(TinyNet, node_in=2, edge_in=6, global_in=0)
    with pytest.raises(InputError, match=r"model.net._target_=test_net.TinyNet is not a registered graph"):
        SurrogateModule(net=net)
    with pytest.raises(InputError, match="is not a graph network"):
        nets.register_graph_network(SurrogateModule)
    assert nets.register_graph_network(TinyNet) is TinyNet
    module = SurrogateModule(net=net).eval()
    _save(module, tmp_path / "fold0.pt")
    loaded, _, _ = load_bundle(tmp_path / "fold0.pt")
    assert type(loaded.net) is TinyNet
    with torch.no_grad():
        assert torch.equal(loaded(_batch()), module(_batch()))
    monkeypatch.setattr(nets, "_graph_networks", {})
    with pytest.raises(InputError, match="'test_net:TinyNet' is not registered"):
        load_bundle(tmp_path / "fold0.pt")
