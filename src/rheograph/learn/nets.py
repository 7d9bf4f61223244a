"""The graph networks a surrogate may be built of (Hydra's ``model.net``): ``rheograph.learn.model.ResGCN``
and the ``torch.nn.Module`` classes the user registers.

A model file records its network as a plain record, ``{"name": "<module>:<qualname>", "kwargs": {...}}``
(``net_record``): the name only selects among registered classes and is never imported, so a model
folder cannot make the loader run code of its own (docs/faults.md, "What is trusted"); ``build_net``
rebuilds the network from such a record.  A network class is registered with
``rheograph.register_graph_network(MyNet)`` (also a class decorator), for the process, or declared by
an installed package in the ``rheograph.networks`` entry-point group (as module classes are:
rheograph.learn.networks), which also makes it available to ``predict.py``.

A graph network takes the input sizes ``node_in``, ``edge_in`` and ``global_in`` (the training code fills
them in from the graph settings), is called as ``net(x, edge_index, edge_attr, batch, u, area)`` and
returns (G, 3) standardised outputs; it keeps the training fold's edge-feature standardisation
(``set_edge_scaling(mean, std)``).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping
from importlib.metadata import entry_points

from torch import nn

from rheograph.errors import InputError
from rheograph.learn.model import ResGCN

ENTRY_POINT_GROUP = "rheograph.networks"
KEY = "model.net"  # where the network lives in the configuration, for messages


def class_name(cls: type) -> str:
    """The name a model file records for ``cls``: ``module:qualname``."""
    return f"{cls.__module__}:{cls.__qualname__}"


_graph_networks: dict[str, type] = {class_name(ResGCN): ResGCN}


def entry_point_class(name: str, check) -> type | None:
    """The class of an installed package's ``rheograph.networks`` entry point recorded as ``name``,
    passed through ``check(cls, where)``.  Entry points are the user's installation, so loading them
    (importing their packages) is trusted; one whose value is ``name`` itself is tried first, the others
    only if none is."""
    found = list(entry_points(group=ENTRY_POINT_GROUP))
    for entry in sorted(found, key=lambda e: e.value != name):
        try:
            cls = entry.load()
        except Exception as exc:  # a broken installation: its own error, named
            raise InputError(
                f"entry point {entry.name} = {entry.value} ({ENTRY_POINT_GROUP}) cannot be loaded: "
                f"{type(exc).__name__}: {str(exc).splitlines()[0] if str(exc) else ''}"
            ) from exc
        if isinstance(cls, type) and class_name(cls) == name:
            return check(cls, f"entry point {entry.name} ({ENTRY_POINT_GROUP})")
    return None


def _check_graph_network(cls, where: str) -> type:
    import lightning as L

    if not (isinstance(cls, type) and issubclass(cls, nn.Module)) or issubclass(cls, L.LightningModule):
        raise InputError(
            f"{where}: {cls!r} is not a graph network (a torch.nn.Module subclass; a SurrogateModule "
            "subclass is registered with rheograph.register_network)"
        )
    return cls


def register_graph_network(cls: type) -> type:
    """Lets model files whose network is ``cls`` (``module:qualname``) be rebuilt in this process, and
    ``model.net`` name it; returns ``cls``, so that it also serves as a class decorator."""
    _graph_networks[class_name(_check_graph_network(cls, "register_graph_network"))] = cls
    return cls


def graph_network(name, where: str) -> type:
    """The registered graph-network class recorded as ``name``; any other name is refused in one line
    (and never imported)."""
    if not isinstance(name, str):
        raise InputError(f"{where}: its network is not named (a record of name and kwargs)")
    cls = _graph_networks.get(name) or entry_point_class(name, _check_graph_network)
    if cls is not None:
        return cls
    shown = repr(name) if len(name) <= 120 else repr(name[:120]) + "…"
    raise InputError(
        f"{where}: its graph network {shown} is not registered; a model folder's code is never imported: "
        "call rheograph.register_graph_network(MyNet), or install a package declaring it in the "
        f"{ENTRY_POINT_GROUP} entry-point group"
    )


def net_record(net) -> dict:
    """The plain record ``{"name", "kwargs"}`` of ``net``: a record itself (a model file's) or a
    ``functools.partial`` of a registered graph-network class with keyword arguments only (Hydra's
    ``model.net`` with ``_partial_: true``, its input sizes filled in)."""
    if isinstance(net, Mapping):
        if set(net) != {"name", "kwargs"} or not isinstance(net["kwargs"], Mapping):
            raise InputError(f"{KEY}={dict(net)!r} is invalid: a record holds a name and kwargs only")
        graph_network(net["name"], KEY)
        return {"name": net["name"], "kwargs": dict(net["kwargs"])}
    if isinstance(net, functools.partial) and not net.args and isinstance(net.func, type):
        name = class_name(net.func)
        if (
            _graph_networks.get(name) is not net.func
            and entry_point_class(name, _check_graph_network) is None
        ):
            raise InputError(
                f"{KEY}._target_={net.func.__module__}.{net.func.__qualname__} is not a registered graph "
                "network: its model files could not be loaded; register it "
                "(rheograph.register_graph_network, or the rheograph.networks entry-point group)"
            )
        kwargs = {k: list(v) if isinstance(v, tuple) else v for k, v in net.keywords.items()}
        return {"name": name, "kwargs": kwargs}
    raise InputError(
        f"{KEY}={net!r} is invalid: a network class with its options, given as a partial "
        "(Hydra's _partial_: true, or functools.partial(MyNet, hidden=64, ...)) or a model file's record"
    )


def build_net(record: Mapping, where: str = KEY) -> nn.Module:
    """The network a record (``net_record``) describes, built through the registry only."""
    cls = graph_network(record["name"], where)
    try:
        return cls(**record["kwargs"])
    except TypeError as exc:  # an option the class does not take
        raise InputError(f"{where}: {record['name']}: {exc}") from exc
