"""The network classes a model bundle may be rebuilt as: ``SurrogateModule`` and the subclasses the user
registers.  A bundle records its class by name (``module:qualname``); that name only selects among
registered classes and is never imported, so a model folder cannot make the loader run code of its own
(docs/faults.md, "What is trusted").

A subclass is registered in one of three ways:

* passed to the loader: ``rheograph.load_model(name, network_class=MyModule)``;
* ``rheograph.register_network(MyModule)`` (also usable as a class decorator), for the process;
* declared by an installed package in the ``rheograph.networks`` entry-point group, which is also what
  makes it available to ``predict.py`` and ``rheograph predict``::

      [project.entry-points."rheograph.networks"]
      my_module = "mypackage.networks:MyModule"
"""

from __future__ import annotations

from rheograph.errors import InputError
from rheograph.learn.module import SurrogateModule
from rheograph.learn.nets import ENTRY_POINT_GROUP, class_name, entry_point_class

_registered: dict[str, type] = {}


def _check_network(cls, where: str) -> type:
    if not (isinstance(cls, type) and issubclass(cls, SurrogateModule)):
        raise InputError(f"{where}: {cls!r} is not a subclass of rheograph.learn.module.SurrogateModule")
    return cls


def register_network(cls: type) -> type:
    """Lets bundles that name ``cls`` (``module:qualname``) be rebuilt as it in this process; returns
    ``cls``, so that it also serves as a class decorator."""
    _registered[class_name(_check_network(cls, "register_network"))] = cls
    return cls


def _from_entry_points(name: str) -> type | None:
    """The class of an installed package's ``rheograph.networks`` entry point recorded as ``name``."""
    return entry_point_class(name, _check_network)


def registered_network(name, where, network_class: type | None = None) -> type:
    """The registered class a bundle at ``where`` names (``None``: ``SurrogateModule``); ``network_class``
    is registered for this call only.  A name no registered class has is refused in one line."""
    if name is None:
        return SurrogateModule
    if not isinstance(name, str):
        raise InputError(f"{where}: not a rheograph model bundle (its network class is not a name)")
    if network_class is not None and class_name(_check_network(network_class, "network_class")) == name:
        return network_class
    cls = _registered.get(name) or _from_entry_points(name)
    if cls is not None:
        return cls
    shown = repr(name) if len(name) <= 120 else repr(name[:120]) + "…"
    given = (
        f" (network_class={class_name(network_class)} is another class)" if network_class is not None else ""
    )
    raise InputError(
        f"{where}: its network class {shown} is not registered{given}; a model folder's code is never "
        "imported: pass the class (rheograph.load_model(..., network_class=MyModule)), call "
        f"rheograph.register_network(MyModule), or install a package declaring it in the {ENTRY_POINT_GROUP} "
        "entry-point group"
    )
