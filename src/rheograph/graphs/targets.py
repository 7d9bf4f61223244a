"""What each target (η_r, Π, Z_μ) is learned as: the one specification of the targets.

Per target: its transform (``scale``: asinh(value / scale), log-like above a few times the scale; Z_μ
is learned as it is), the graph input it is learned relative to (``relative_to``: the network learns
the transformed target minus that input, which is transformed like the target; null: the target
itself) and, for Π, whether it is learned per imposed stress (``per_stress``: Π / σ).  The graph
inputs a target may be learned relative to are ``REFERENCES``.

Hydra's ``graph.targets`` (conf/graph/paper.yaml) is read by ``TargetSpec.from_config``; a model
bundle records ``TargetSpec.to_config()``.  ``from_legacy`` is the one adapter from the form of earlier
versions (the booleans ``pressure_per_stress``, ``z_mu_on_count``, ``viscosity_on_solve``,
``viscosity_on_relaxed``, ``pressure_on_spring`` and the scales ``viscosity_scale``,
``pressure_scale`` of the graph settings; the columns ``z_mu_input``, ``viscosity_input``,
``pressure_input`` of the module's hyperparameters), and ``legacy_options`` its inverse, in which run
fingerprints and graph-cache keys stay what they were.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

from rheograph.errors import InputError

TARGET_KEYS = ("eta_r", "pi", "z_mu")  # the order of the targets' columns (G, 3)
# the graph inputs each target may be learned relative to (rheograph.graphs.features.GRAPH_INPUTS)
REFERENCES = {
    "eta_r": ("solve_viscosity", "relaxed_viscosity"),
    "pi": ("spring_pressure",),
    "z_mu": ("frictional_coordination",),
}
# what the correction is to, for messages
_MEANING = {
    "solve_viscosity": "learns eta_r as a correction to the one-solve viscosity",
    "relaxed_viscosity": "learns eta_r as a correction to the relaxation's eta_r",
    "spring_pressure": "learns Pi / sigma as a correction to the contact-spring pressure",
    "frictional_coordination": "learns Z_mu as a correction to the counted frictional contacts",
}
KEY = "graph.targets"  # where the specification lives in the configuration, for messages


@dataclass(frozen=True)
class Target:
    """One target: asinh ``scale`` (None: learned as it is), the graph input it is learned
    ``relative_to`` (None: nothing) and, for Π only, ``per_stress``."""

    scale: float | None = None
    relative_to: str | None = None
    per_stress: bool = False


@dataclass(frozen=True)
class TargetSpec:
    """How the three targets are learned (module docstring).  The defaults are the seed paper's:
    asinh(η_r / 1), asinh(Π / 0.1 σ0), Z_μ, each learned as itself."""

    eta_r: Target = field(default_factory=lambda: Target(scale=1.0))
    pi: Target = field(default_factory=lambda: Target(scale=0.1))
    z_mu: Target = field(default_factory=Target)

    def __post_init__(self):
        for name in TARGET_KEYS:
            target = getattr(self, name)
            if not isinstance(target, Target):
                raise InputError(f"{KEY}.{name}={target!r} is invalid: allowed a mapping of its options")
            if name == "z_mu":
                if target.scale is not None:
                    raise InputError(
                        f"{KEY}.z_mu.scale={target.scale} is invalid: Z_mu is learned as it is (no scale)"
                    )
            elif not (
                isinstance(target.scale, int | float)
                and not isinstance(target.scale, bool)
                and math.isfinite(target.scale)
                and target.scale > 0
            ):
                raise InputError(f"{KEY}.{name}.scale={target.scale} is invalid: allowed a finite value > 0")
            if target.relative_to is not None and target.relative_to not in REFERENCES[name]:
                raise InputError(
                    f"{KEY}.{name}.relative_to={target.relative_to!r} is invalid: allowed null or one of "
                    f"{list(REFERENCES[name])}"
                )
            if target.per_stress and name != "pi":
                raise InputError(f"{KEY}.{name}.per_stress is invalid: only Pi is learned per stress")
        if self.pi.relative_to and not self.pi.per_stress:
            raise InputError(
                f"{KEY}.pi.relative_to={self.pi.relative_to} {_MEANING[self.pi.relative_to]}: needs "
                f"{KEY}.pi.per_stress=true"
            )

    @property
    def viscosity_scale(self) -> float:
        return float(self.eta_r.scale)

    @property
    def pressure_scale(self) -> float:
        return float(self.pi.scale)

    @property
    def pressure_per_stress(self) -> bool:
        return bool(self.pi.per_stress)

    def check_inputs(self, graph_inputs, stress_known: bool = True) -> None:
        """Refuses, in one line naming the key, a specification the graph inputs cannot serve: a
        reference that is not among ``graph_inputs``, Π per stress without the stress (``log_stress``,
        unless ``stress_known`` is false), a positions-only model (``stress_known`` false) learning Π in
        σ0."""
        inputs = list(graph_inputs)
        self.columns(inputs)
        if not stress_known and not self.pi.per_stress:
            raise InputError(
                f"graph.stress_known=false needs {KEY}.pi.per_stress=true: positions determine Pi / sigma, "
                "not Pi in sigma0"
            )
        if self.pi.per_stress and stress_known and "log_stress" not in inputs:
            raise InputError(
                f"{KEY}.pi.per_stress=true learns Pi in units of the imposed stress, which the model must "
                f"then be given: add log_stress to graph.graph_inputs (now {inputs})"
            )

    def columns(self, graph_inputs) -> list[tuple[int, int]]:
        """(target column, graph-input column) of every target learned relative to an input: the one
        place where the references become columns of the graph inputs u (G, len(graph_inputs))."""
        inputs = list(graph_inputs)
        for name in TARGET_KEYS:
            reference = getattr(self, name).relative_to
            if reference is not None and reference not in inputs:
                raise InputError(
                    f"{KEY}.{name}.relative_to={reference} {_MEANING[reference]}: add {reference} to "
                    f"graph.graph_inputs (now {inputs})"
                )
        return [
            (k, inputs.index(getattr(self, name).relative_to))
            for k, name in enumerate(TARGET_KEYS)
            if getattr(self, name).relative_to is not None
        ]

    def to_config(self) -> dict:
        """The specification as plain values, as Hydra's ``graph.targets`` and a bundle hold it."""
        return {
            "eta_r": {"scale": self.eta_r.scale, "relative_to": self.eta_r.relative_to},
            "pi": {
                "scale": self.pi.scale,
                "relative_to": self.pi.relative_to,
                "per_stress": self.pi.per_stress,
            },
            "z_mu": {"relative_to": self.z_mu.relative_to},
        }

    @classmethod
    def from_config(cls, values) -> TargetSpec:
        """A specification from ``graph.targets`` (a mapping of the form of ``to_config``; missing
        entries take their defaults), or a ``TargetSpec`` as it is; anything else refused by key."""
        if isinstance(values, TargetSpec):
            return values
        if values is None:
            return cls()
        if not isinstance(values, Mapping):
            raise InputError(f"{KEY}={values!r} is invalid: allowed a mapping of eta_r, pi, z_mu")
        unknown = sorted(set(values) - set(TARGET_KEYS))
        if unknown:
            raise InputError(f"{KEY}: unknown target(s) {unknown}: allowed {list(TARGET_KEYS)}")
        default = cls()
        targets = {}
        for name in TARGET_KEYS:
            given = values.get(name) or {}
            if not isinstance(given, Mapping):
                raise InputError(f"{KEY}.{name}={given!r} is invalid: allowed a mapping of its options")
            options = ("scale", "relative_to", "per_stress")  # per_stress of eta_r, z_mu: false only
            unknown = sorted(set(given) - set(options))
            if unknown:
                raise InputError(f"{KEY}.{name}: unknown option(s) {unknown}: allowed {list(options)}")
            base = getattr(default, name)
            targets[name] = Target(
                scale=given.get("scale", base.scale),
                relative_to=given.get("relative_to", base.relative_to),
                per_stress=bool(given.get("per_stress", base.per_stress)),
            )
        return cls(**targets)

    def legacy_options(self) -> dict:
        """The specification in the form of earlier versions (the inverse of ``from_legacy``): what run
        fingerprints and graph-cache keys are computed from, so that they do not change."""
        return {
            "viscosity_scale": self.eta_r.scale,
            "pressure_scale": self.pi.scale,
            "pressure_per_stress": self.pi.per_stress,
            "z_mu_on_count": self.z_mu.relative_to == "frictional_coordination",
            "viscosity_on_solve": self.eta_r.relative_to == "solve_viscosity",
            "viscosity_on_relaxed": self.eta_r.relative_to == "relaxed_viscosity",
            "pressure_on_spring": self.pi.relative_to == "spring_pressure",
        }


# the graph settings' target options of earlier versions (graph.<key>), in legacy_options' order
LEGACY_GRAPH_KEYS = tuple(TargetSpec().legacy_options())
# the module hyperparameters of earlier versions that said the same: the scales, Pi per stress, and a
# column of the graph inputs (-1: none) per reference
LEGACY_MODULE_KEYS = (
    "viscosity_scale",
    "pressure_scale",
    "pressure_per_stress",
    "z_mu_input",
    "viscosity_input",
    "pressure_input",
)
_LEGACY_COLUMNS = {"viscosity_input": "eta_r", "pressure_input": "pi", "z_mu_input": "z_mu"}


def from_legacy(graph: Mapping, module: Mapping | None = None) -> TargetSpec:
    """The specification that the graph settings ``graph`` (a bundle's or card's ``graph`` record of an
    earlier version: the target booleans and scales beside ``graph_inputs``) and, where given, the module
    hyperparameters ``module`` of the same model (the scales, ``pressure_per_stress`` and the reference
    columns ``*_input``) stated.  The one place that reads that form; a record whose two halves disagree
    is refused."""
    inputs = list(graph.get("graph_inputs", ()))
    if graph.get("viscosity_on_solve") and graph.get("viscosity_on_relaxed"):
        raise InputError(
            "graph.viscosity_on_solve and graph.viscosity_on_relaxed each set the value eta_r is learned as "
            "a correction to: set one of them to false"
        )
    eta_reference = (
        "solve_viscosity"
        if graph.get("viscosity_on_solve")
        else "relaxed_viscosity"
        if graph.get("viscosity_on_relaxed")
        else None
    )
    spec = TargetSpec(
        eta_r=Target(scale=float(graph.get("viscosity_scale", 1.0)), relative_to=eta_reference),
        pi=Target(
            scale=float(graph.get("pressure_scale", 0.1)),
            relative_to="spring_pressure" if graph.get("pressure_on_spring") else None,
            per_stress=bool(graph.get("pressure_per_stress", False)),
        ),
        z_mu=Target(relative_to="frictional_coordination" if graph.get("z_mu_on_count") else None),
    )
    if module is not None:
        stated = {
            "viscosity_scale": spec.eta_r.scale,
            "pressure_scale": spec.pi.scale,
            "pressure_per_stress": spec.pi.per_stress,
        }
        for key, value in stated.items():
            if key in module and module[key] != value:
                raise InputError(
                    f"the model's {key}={module[key]!r} contradicts its graph settings' {value!r}"
                )
        for key, name in _LEGACY_COLUMNS.items():
            column = int(module.get(key, -1))  # bundles older than pressure_input have none
            reference = getattr(spec, name).relative_to
            expected = inputs.index(reference) if reference in inputs else -1
            if column != expected:
                raise InputError(
                    f"the model's {key}={column} contradicts its graph settings (graph input "
                    f"{reference!r} is column {expected} of {inputs})"
                )
    return spec


def is_legacy(record: Mapping) -> bool:
    """Whether a graph-settings or module-hyperparameter record is in the form of an earlier version."""
    return "targets" not in record and bool(set(record) & {*LEGACY_GRAPH_KEYS, *LEGACY_MODULE_KEYS})


def spec_of_record(graph: Mapping) -> TargetSpec:
    """The specification of a graph-settings record (a bundle's or card's ``graph``) of any version."""
    return from_legacy(graph) if is_legacy(graph) else TargetSpec.from_config(graph.get("targets"))
