"""Predict η_r, Π, Z_μ for every snapshot of any source — rheograph trajectories, bare snapshot files,
LF_DEM runs (rheograph.io.snapshots) — or for arrays handed over from Python, with an ensemble of fold
models: a shipped model (``--list-models``) or a training run directory.

    python predict.py --models N400_phi0.76 --input trajectory.h5 snapshot.npz par_run.dat --out p.csv
    python predict.py --list-models
    python predict.py --models N400_phi0.76 --input trajectory.h5 --out p.csv --device cuda --workers 8

    import rheograph
    model = rheograph.load_model("N400_phi0.76")          # device="cuda", workers=8: on a GPU, 8 processes
    table = model.predict(positions, radii, box, le_offset, stress=10, phi=0.76, mu=0.5, ...)

Model folders are untrusted input (docs/faults.md, "What is trusted"): bundles (``fold*.pt``) are read
with ``torch.load(weights_only=True)``, so no code is unpickled, and the network class a bundle names is
only looked up among the classes the user registers (``network_class=``, ``rheograph.register_network``
or the ``rheograph.networks`` entry-point group: rheograph.learn.networks), never imported by that name.

A model is trained on one suspension: every physical parameter it depends on (``PHYSICAL_PARAMS``) must
come with the snapshot and equal the model's; an absent or different one is refused in one line, never
filled in (``accept_mismatch`` / ``--accept-mismatch`` predicts anyway, flagged out of domain, and the
output records it).  The step of the one-solve input is the model's own (its bundle), whatever step the
snapshot's simulation used.

One row per snapshot.  Columns: ``source``, ``snapshot`` (index in its source), ``strain``, ``stress``,
``phi``, ``in_domain`` (1: the state point, N, position precision and edge features lie in what the model
was trained on), ``notes`` (why not, and any accepted mismatch); per target ``*_pred`` (ensemble mean),
``*_pred_std`` (spread over the fold models: flags disagreement, too narrow to be an error bar),
``*_pred_err`` (the cross-validated error bar of the model's ``error_model.json``: one RMS of held-out
residuals at the snapshot's state point, log10 units for η_r and Π, absolute for Z_μ), ``*_pred_lower``
and ``*_pred_upper`` (the bar in the target's own units: pred × 10^(∓err) for η_r and Π, pred ∓ err for
Z_μ; on a seed no model had seen they held 78 % of η_r, 74 % of Π and 92 % of Z_μ,
docs/validation/surrogate_accuracy.md "How reliable are its error bars") and ``*_sim`` (the source's own
value, NaN where it has none);
the physics-only values, nothing learned: ``eta_solve`` (η_r of one resistance solve at the imposed
stress; NaN, with the reason in ``notes``, where that solve's shear rate vanishes or runs against the
stress), ``pressure_spring`` (the contact-spring pressure (2π σ / A) Σ r ā δ / δ_σ [σ0]) and
``z_mu_counted`` (the CLM's frictional contacts counted); ``jammed_fraction``: the share of training
trajectories at the nearest trained state point that shear-jammed
(rheograph.learn.jamming; jammed when >= 0.5).  With radii estimated from the configurations (``--radii
estimated``, ``estimated-mean``, which declare the inputs' radii the species' nominal ones, as a bare
file's key ``radii_nominal`` = 1 does): ``radii_uncertainty`` (their RMS uncertainty [a]) and
``position_noise`` (the precision the model was told, the stated one and that uncertainty combined [a]).
"""

from __future__ import annotations

import argparse
import collections
import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import torch

from rheograph.errors import InputError
from rheograph.graphs.batched_solve import PHYSICS_SOLVERS, physics_solver_device
from rheograph.graphs.dataset import SOLVE_NUMERICS, GraphSettings, snapshot_graphs
from rheograph.graphs.radii_estimate import snapshots_with_estimated_radii, species_spread
from rheograph.io.configurations import NOMINAL_PHI_TOLERANCE, PHYSICAL_PARAMS, Snapshots
from rheograph.io.snapshots import read_snapshots, snapshots_from_values
from rheograph.io.tables import write_table
from rheograph.learn.bundle import load_bundle, predict_dataset
from rheograph.learn.error_model import error_bounds, predicted_error, read_error_model
from rheograph.learn.jamming import jammed_fraction
from rheograph.learn.module import TARGET_NAMES
from rheograph.learn.registry import list_models, model_paths, read_card
from rheograph.resources import check_memory, prediction_bytes

# Models trained on simulator output read overlaps of ~1e-3 a exactly (positions stored to 1e-7 a):
# positions known only to a worse RMS precision [a] than this are outside their domain.  Set just above
# the 2.2e-5 a RMS rounding of LF_DEM's 6-digit par files at N = 400, on which the exact model still
# scores R2 log eta_r 0.989 (docs/validation/position_noise.md, "A shipped model on LF_DEM snapshots").
EXACT_POSITION_PRECISION = 3e-5
# the precision of particle tracking in a microscope [a]: which imaging models an exact model's flag names
# when a snapshot's overlaps betray imprecise positions that it did not declare
TRACKING_PRECISION = 0.01

# a reason's snapshot-specific value, kept in that snapshot's note and left out of the summary warning
ROW_VALUE_OPEN = " — this snapshot: "


def trained_noise(domain: dict) -> tuple[float, float]:
    """(eps_min, eps_max) [a] of the position noise a model was trained on; exact models (0, 0)."""
    noise = domain.get("position_noise", 0.0)
    return (float(noise[0]), float(noise[1])) if isinstance(noise, list | tuple) else (0.0, float(noise))


def models_for_noise(phi: float, n_particles: int, noise: float) -> list[str]:
    """Shipped models whose trained domain covers (phi, N) and positions of precision ``noise`` [a]."""
    names = []
    for name in list_models():
        card = read_card(model_paths(name)[0])
        if not card:
            continue
        low, high = trained_noise({"position_noise": card["position_noise"]})
        d = card["domain"]
        covers = d["phi"][0] - 1e-3 <= phi <= d["phi"][1] + 1e-3 and n_particles in d["n_particles"]
        exact_enough = noise <= EXACT_POSITION_PRECISION if high == 0.0 else noise <= high
        if covers and exact_enough and not (high and noise < low and noise <= EXACT_POSITION_PRECISION):
            names.append(name)
    return names


def noise_reason(domain: dict, noise: float, alternatives=()) -> str:
    """Why positions of RMS precision ``noise`` [a] are outside a model's domain ('' if they are not).
    An exact model reads overlaps of ~1e-3 a: precision worse than EXACT_POSITION_PRECISION is outside;
    an imaging model is outside above its trained eps_max (below its eps_min it is used on cleaner
    positions than it saw, which the exact model serves better)."""
    low, high = trained_noise(domain)
    instead = (
        f": use {' or '.join(alternatives)}" if alternatives else " (predict.py --list-models: the domains)"
    )
    if high == 0.0:
        if noise > EXACT_POSITION_PRECISION:
            return (
                f"positions known to {noise:.2g} a, the model was trained on exact positions (it reads "
                f"overlaps of ~1e-3 a){instead if alternatives else ': use an imaging model' + instead}"
            )
        return ""
    if noise > high:
        return (
            f"positions known to {noise:.2g} a, beyond the {high:g} a of the model's noisy training{instead}"
        )
    if noise < low and noise <= EXACT_POSITION_PRECISION:
        return (
            f"positions known to {noise:.2g} a, below the {low:g} a of the model's noisy training: an "
            f"exact model of this suspension is more accurate on them{instead}"
        )
    return ""


def short_relaxation(graphs, settings: GraphSettings) -> np.ndarray:
    """(S,) bool: graphs whose relaxation ran out of steps before ``settings.relax_strain``.

    An arrested packing creeps, so its relaxation stops short of the strain the model's inputs were
    trained on and they read a partly repaired configuration: such a snapshot is out of the model's
    domain.  All False for a model that does not relax."""
    if not settings.relax_strain:
        return np.zeros(len(graphs), dtype=bool)
    reached = np.array([float(getattr(g, "relaxed_strain", np.nan)) for g in graphs])
    return reached < settings.relax_strain * (1.0 - 1e-9)


def domain_report(
    domain: dict, snaps: Snapshots, graphs, settings: GraphSettings, min_strain: float = 0.0
) -> tuple[np.ndarray, list[list[str]]]:
    """Per-snapshot in-domain flags (S,) and, per snapshot, the reasons it lies outside (empty inside);
    ``min_strain``: the strain from which the model's training snapshots were taken."""
    reasons = []  # of every snapshot: the state point, N and the stated precision
    for key, value in (("phi", snaps.phi), ("stress", snaps.stress)):
        if key == "stress" and not np.isfinite(value):  # a positions-only model is not told it
            continue
        low, high = domain[key]
        # phi to the 1e-3 a file's stated value may differ from its radii and box by (check_geometry)
        slack = 1e-3 if key == "phi" else 1e-9 * high
        if not low - slack <= value <= high + slack:
            reasons.append(f"{key} = {value:g} outside the trained [{low:g}, {high:g}]")
    if snaps.n_particles not in domain["n_particles"]:
        reasons.append(f"N = {snaps.n_particles} not among the trained N {domain['n_particles']}")
    spread = species_spread(snaps.radii, float(domain.get("size_ratio", [1.4])[0]))
    if spread > 1e-6:
        reasons.append(
            f"radii spread about the two species' sizes ({spread:.1%} RMS): the model was trained on exactly "
            "two radii"
        )
    noise = snaps.position_noise or 0.0
    axial = noise if snaps.axial_noise is None else snaps.axial_noise
    if "axial_noise" in domain:  # a confocal model: the axial precision has a trained range of its own
        high_axial = float(domain["axial_noise"][1])
        if axial > high_axial:
            reasons.append(
                f"positions known to {axial:.2g} a along the optical axis ({settings.optical_axis}), beyond "
                f"the {high_axial:g} a of the model's noisy training"
            )
    else:  # trained on isotropic noise (or none): the coarsest axis decides
        noise = max(noise, axial)
    elsewhere = [r for r in reasons if r.startswith(("phi", "N ="))]
    if elsewhere:  # name the shipped models whose domain holds this snapshot's (phi, N) and precision
        others = models_for_noise(snaps.phi, snaps.n_particles, noise)
        if others:
            reasons[reasons.index(elsewhere[-1])] += f" (use {' or '.join(others)})"
    reason = noise_reason(domain, noise)
    if reason:
        reason = noise_reason(domain, noise, models_for_noise(snaps.phi, snaps.n_particles, noise))
        reasons.append(reason)
    rows = [list(reasons) for _ in graphs]
    # the start-up transient (strain below the training data's min_strain) is no steady state: a model
    # trained on steady snapshots misreads it (at strain 0, eta_r by a factor ~3); unknown strain: no flag
    early = (snaps.strain < min_strain) & ~np.asarray(snaps.jammed, dtype=bool)  # training kept arrested ones
    for k in np.flatnonzero(early):
        rows[k].append(
            f"strain < {min_strain:g}: the start-up transient, which the model was not trained on (it "
            "learned steady flow)"
        )
    short = short_relaxation(graphs, settings)
    for k in np.flatnonzero(short):
        rows[k].append(
            f"relaxation cut short of its {settings.relax_strain:g} strain by its step budget (an arrested "
            "or creeping packing): its inputs read a partly repaired configuration"
        )
    edge_features = np.asarray(settings.edge_features)
    low, high = np.array(domain["edge_min"]), np.array(domain["edge_max"])
    span = np.maximum(high - low, 1e-12)
    for k, g in enumerate(graphs):
        attr = g.edge_attr.numpy()
        bad = (attr.min(axis=0) < low - 0.05 * span) | (attr.max(axis=0) > high + 0.05 * span)
        if not bad.any():
            continue
        reason = f"edge features {sorted(edge_features[bad].tolist())} beyond their trained range"
        if "overlap" in edge_features[bad] and trained_noise(domain)[1] == 0.0:
            # an exact model's overlaps are the simulator's at the imposed stress (~1e-3 a); larger ones
            # are what undeclared position noise of ~1e-3 a and more makes
            imaging = models_for_noise(snaps.phi, snaps.n_particles, TRACKING_PRECISION)
            reason += (
                "; overlaps beyond the simulator's are what imprecise positions make: if the positions are "
                "measured, state their precision (position_noise) and use "
                + (" or ".join(imaging) if imaging else "an imaging model (predict.py --list-models)")
            )
        rows[k].append(reason)
    return np.array([not r for r in rows], dtype=bool), rows


DEVICES = ("cpu", "cuda", "auto")
RADII_CHOICES = ("given", "estimated", "estimated-mean")  # predict.py --radii
# nodes per forward pass of the prediction batches: many snapshots in one pass (1310 of N = 400), few
# enough that the network's activations stay within a few hundred MB on any device
PREDICT_NODE_BUDGET = 2**19


def resolve_device(device: str | torch.device, where: str = "device") -> torch.device:
    """``cpu``, ``cuda`` (``cuda:K``) or ``auto`` (a CUDA GPU when one is visible, else the CPU) as a
    torch device; a CUDA device without one is refused in one line naming ``where``."""
    name = str(device)
    if name == "auto":
        return torch.device("cuda" if torch.cuda.is_available() else "cpu")
    if name != "cpu" and not name.startswith("cuda"):
        raise InputError(f"{where}={name!r} is invalid: allowed {list(DEVICES)} (or cuda:K)")
    if name.startswith("cuda") and not torch.cuda.is_available():
        raise InputError(
            f"{where}={name}: no CUDA GPU is visible to this process (torch.cuda.is_available() is false): "
            "use cpu, or auto to take a GPU only where there is one"
        )
    try:
        return torch.device(name)
    except RuntimeError as exc:
        raise InputError(f"{where}={name!r} is not a torch device name") from exc


def ensemble_mean_std(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard deviation over axis 0 (the fold models) of finite ``values`` (models, S); for
    values so large that the sum of squares overflows, computed in units of their largest magnitude
    (finite then too)."""
    with np.errstate(over="ignore"):
        mean, std = values.mean(axis=0), values.std(axis=0)
    overflow = ~(np.isfinite(mean) & np.isfinite(std))
    if overflow.any():
        scale = np.abs(values[:, overflow]).max(axis=0)
        unit = values[:, overflow] / scale
        mean[overflow], std[overflow] = unit.mean(axis=0) * scale, unit.std(axis=0) * scale
    return mean, std


class Surrogate:
    """An ensemble of fold models with what they were trained on (``domain``) and, for a shipped model,
    its card; ``load_model`` makes one. ``device``: where the networks run (``resolve_device``);
    ``workers``: processes that build the snapshots' graphs and physics inputs (1: this one);
    ``physics_solver``: how those physics inputs' resistance problems are solved (``auto``: in dense
    batches on a CUDA ``device`` up to ``DENSE_MAX_PARTICLES``, else the sparse solver on the CPU;
    ``sparse``; ``dense``: in dense batches on ``device``, a CPU too; rheograph.graphs.batched_solve)."""

    def __init__(
        self,
        bundle_paths: list[Path],
        label: str,
        network_class: type | None = None,
        device="cpu",
        workers: int = 1,
        physics_solver: str = "auto",
    ):
        if not bundle_paths:
            raise InputError("no model bundles (fold*.pt) given: name a shipped model or a training run")
        if not isinstance(workers, int) or isinstance(workers, bool) or workers < 1:
            raise InputError(f"workers={workers!r} is invalid: allowed an integer >= 1")
        self.label = label
        self.device = resolve_device(device)
        self.workers = workers
        physics_solver_device(physics_solver, self.device, 0)  # an unknown choice refused here
        self.physics_solver = physics_solver
        self.paths = sorted(bundle_paths)
        self.models = [load_bundle(p, network_class) for p in self.paths]
        for module, _, _ in self.models:
            module.to(self.device)
        self.min_strain = min(settings.min_strain for _, settings, _ in self.models)
        self.settings = dataclasses.replace(self.models[0][1], min_strain=0.0)
        if any(dataclasses.replace(s, min_strain=0.0) != self.settings for _, s, _ in self.models):
            raise InputError(f"{label}: the model bundles were trained with different graph settings")
        self.domain = self.models[0][2]
        for key in ("physical_params", "solve_numerics"):
            if key not in self.domain:
                raise InputError(
                    f"{label}: the bundles do not record the suspension they were trained on ({key}); "
                    "make a shipped model of the run (python -m rheograph.learn.registry ship RUN --name X)"
                )
        self.card = read_card(self.paths)
        self.error_model = read_error_model(self.paths[0].parent)

    def physics_device(self, snaps: Snapshots) -> torch.device | None:
        """Where the physics inputs of ``snaps`` are solved in dense batches (None: the sparse solver on
        the CPU, one snapshot after the other), as ``physics_solver`` says for their size."""
        return physics_solver_device(self.physics_solver, self.device, snaps.n_particles)

    @property
    def physical_params(self) -> dict:
        return dict(self.domain["physical_params"])

    def solve_numerics(self, phi: float, n_particles: int) -> dict:
        """The one-solve step the model's training graphs used at the nearest trained φ (then N)."""
        entries = self.domain["solve_numerics"]
        best = min(
            entries, key=lambda e: (abs(e["phi"] - phi), abs(math.log(e["n_particles"] / n_particles)))
        )
        return {k: best[k] for k in SOLVE_NUMERICS}

    def check_params(self, snaps: Snapshots, accept_mismatch: bool) -> list[str]:
        """Notes on accepted mismatches; refuses an absent or different physical parameter unless
        ``accept_mismatch``."""
        wanted = self.physical_params
        missing = [k for k in PHYSICAL_PARAMS if k in wanted and k not in snaps.params]
        if missing:
            raise InputError(
                f"{snaps.source}: the physical parameter(s) {missing} are not given; model {self.label} was "
                f"trained at {', '.join(f'{k}={wanted[k]:g}' for k in missing)}: give them with the snapshot "
                "(file keys, predict.py --param KEY=VALUE, or keyword arguments of model.predict)"
            )
        differ = [
            k for k in wanted if not math.isclose(float(snaps.params[k]), float(wanted[k]), rel_tol=1e-6)
        ]
        if not differ:
            return []
        text = ", ".join(f"{k} = {float(snaps.params[k]):g} (model: {float(wanted[k]):g})" for k in differ)
        if not accept_mismatch:
            raise InputError(
                f"{snaps.source}: another suspension than model {self.label} was trained on: {text}; use a "
                "model of this suspension (predict.py --list-models), or --accept-mismatch to predict anyway "
                "(flagged out of domain)"
            )
        return [f"accepted parameter mismatch: {text}"]

    def predict_with_estimated_radii(
        self, snaps: Snapshots, mean: bool = False, accept_mismatch: bool = False
    ) -> dict:
        """``predict_snapshots`` on ``snaps`` whose radii are the species' nominal ones (a sample whose
        particles spread in size unmeasured), each snapshot with radii estimated from its configuration
        (``rheograph.graphs.radii_estimate``); ``mean``: one estimate, the mean over the snapshots.  The
        snapshots (at least 2) must show the same particles in the same order: the radii's uncertainty
        is measured from the estimates' scatter over them, and the model is told the positions' stated
        precision and that uncertainty combined (``declared_precision``: a radius error blurs the gaps as
        position noise of its size).  The table gains ``radii_uncertainty`` [a] and ``position_noise``,
        the precision the model was told [a] (NaN where the source states none).  The model flags radii
        that spread about the two species: what it makes of them is measured, not trained
        (docs/imaging.md, unknown sizes)."""
        parts, uncertainty = snapshots_with_estimated_radii(snaps, mean)
        table = concatenate([self.predict_snapshots(part, accept_mismatch) for part in parts])
        n = len(table["snapshot"])
        table["snapshot"] = np.arange(n)
        table["radii_uncertainty"] = np.full(n, uncertainty)
        table["position_noise"] = np.concatenate(
            [
                np.broadcast_to(np.nan if p.position_noise is None else p.position_noise, (len(p),))
                for p in parts
            ]
        ).astype(np.float64)
        return table

    def predict_snapshots(self, snaps: Snapshots, accept_mismatch: bool = False) -> dict:
        """One row per snapshot of ``snaps``: a dict of (S,) columns (module docstring)."""
        model_dim = int(self.domain.get("dim", 2))  # bundles written before 3D models are 2D
        if snaps.dim != model_dim:
            raise InputError(
                f"{snaps.source}: {snaps.dim}D snapshots, but model {self.label} is a {model_dim}D model "
                f"(trained on {model_dim}D snapshots): use a {snaps.dim}D model"
            )
        if round(snaps.params.get("size_ratio", 0.0), 6) not in self.domain["size_ratio"]:
            raise InputError(
                f"{snaps.source}: size ratio {snaps.params.get('size_ratio')} but model {self.label} was "
                f"trained on {self.domain['size_ratio']}: its one-hot radius input cannot represent these "
                "particles"
            )
        notes = self.check_params(snaps, accept_mismatch)
        if not len(snaps):
            raise InputError(f"{snaps.source}: holds no snapshot")
        check_memory(
            prediction_bytes(
                snaps.n_particles,
                len(snaps),
                snaps.phi,
                self.settings.cutoff,
                snaps.params["size_ratio"],
                snaps.dim,
            ),
            f"{snaps.source}: predicting {len(snaps)} snapshot(s) of {snaps.n_particles} particles",
            "split the snapshots over several files or calls",
        )
        graphs = snapshot_graphs(
            snaps,
            self.settings,
            run_id=0,
            solve_numerics=self.solve_numerics(snaps.phi, snaps.n_particles),
            training=False,
            workers=self.workers,
            solve_device=self.physics_device(snaps),
        )
        positions_only = not self.settings.stress_known
        if positions_only:
            # the network predicts Pi / sigma: read it out in units of sigma (sigma = 1 for the module's
            # conversion), then in sigma0 where the snapshot states sigma
            for g in graphs:
                g.stress = torch.ones_like(g.stress)
        preds = []
        per_pass = max(1, PREDICT_NODE_BUDGET // snaps.n_particles)
        for module, _, _ in self.models:
            pred, true, meta = predict_dataset(module, graphs, batch_size=per_pass, device=self.device)
            preds.append(pred)
        preds = np.stack(preds)  # (models, S, 3)
        overflow = np.flatnonzero(~np.isfinite(preds).all(axis=(0, 2)))
        extra = {}
        if positions_only:
            per_stress = preds[:, :, 1].copy()
            extra["pressure_per_stress_pred"] = per_stress.mean(axis=0)
            extra["pressure_per_stress_pred_std"] = per_stress.std(axis=0)
            extra["mu_eff_pred"] = (1.0 / per_stress).mean(axis=0)  # sigma / Pi, the bulk friction
            preds[:, :, 1] = per_stress * snaps.stress  # NaN where sigma is unknown
            meta["stress"] = np.full(len(graphs), snaps.stress)
        in_domain, row_reasons = domain_report(self.domain, snaps, graphs, self.settings, self.min_strain)
        if overflow.size:
            k = overflow[0]
            raise InputError(
                f"{snaps.source}: model {self.label}'s prediction for snapshot(s) {overflow[:5].tolist()} is "
                f"not a finite number, their inputs lie that far outside its training (snapshot {k}: "
                f"{'; '.join(row_reasons[k]) or 'no reason found'}); are the positions in units of the small "
                "radius a?"
            )
        # physics only, nothing learned: the one-solve eta_r, the contact-spring pressure, the counted Z_mu
        physics = np.concatenate([g.physics.numpy() for g in graphs]).astype(np.float64)
        # a solve whose shear rate vanishes or runs against the stress has no viscosity to report (a
        # configuration no flowing suspension takes: overlaps far beyond the simulator's); NaN: not solved
        no_viscosity = (physics[:, 0] <= 0) | np.isinf(physics[:, 0])
        for k in np.flatnonzero(no_viscosity):
            row_reasons[k].append(
                "the one-solve gives no viscosity (its shear rate vanishes or runs against the stress): "
                f"eta_solve left empty{ROW_VALUE_OPEN}eta_r = {physics[k, 0]:.3g}"
            )
        physics[no_viscosity, 0] = np.nan
        in_domain &= ~no_viscosity
        row_reasons = [notes + r for r in row_reasons]
        in_domain &= not notes
        if not in_domain.all():
            # each reason once, with how many snapshots it concerns where that is not all of them
            counts = collections.Counter(
                reason.split(ROW_VALUE_OPEN)[0] for r in row_reasons for reason in r
            )  # a row's own value (in its note) left out: one line per reason
            n = len(graphs)
            summary = [text if k == n else f"{text} ({k} of {n} snapshots)" for text, k in counts.items()]
            print(
                f"warning: {snaps.source}: outside model {self.label}'s domain: " + "; ".join(summary),
                file=sys.stderr,
            )
        n = len(graphs)
        out = {
            "source": np.array([snaps.source] * n),
            "snapshot": np.arange(n),
            "strain": snaps.strain.copy(),
            "stress": meta["stress"],
            "phi": meta["phi"],
            "in_domain": in_domain.astype(np.int64),
            "notes": np.array(["; ".join(r) for r in row_reasons]),
        }
        out.update(extra)
        if "jam_map" in self.domain and not positions_only:
            out["jammed_fraction"] = jammed_fraction(self.domain["jam_map"], meta["phi"], meta["stress"])
        out.update(eta_solve=physics[:, 0], pressure_spring=physics[:, 1], z_mu_counted=physics[:, 2])
        errors = (
            predicted_error(self.error_model, meta["stress"], meta["phi"])
            if self.error_model and not positions_only
            else None
        )
        for k, name in enumerate(TARGET_NAMES):
            out[f"{name}_pred"], out[f"{name}_pred_std"] = ensemble_mean_std(preds[:, :, k])
            if errors is not None:
                out[f"{name}_pred_err"] = errors[:, k]
                out[f"{name}_pred_lower"], out[f"{name}_pred_upper"] = error_bounds(
                    name, out[f"{name}_pred"], errors[:, k]
                )
            out[f"{name}_sim"] = true[:, k]
        return out

    def predict(
        self,
        positions,
        radii,
        box,
        le_offset,
        stress: float | None,
        phi: float,
        *,
        strain=None,
        position_noise: float | None = None,
        axial_noise: float | None = None,
        eta_r=None,
        pressure=None,
        z_mu=None,
        accept_mismatch: bool = False,
        **params,
    ) -> dict:
        """Predict for configurations given as arrays (units of the small radius a): ``positions`` (S, N, 2)
        or (N, 2), ``radii`` (N,), ``box`` = (Lx, Ly), ``le_offset`` (S,) or a number (x-shift of the
        periodic image above), ``stress`` σ/σ0 (None: unknown, for a positions-only model), ``phi``
        (a 3D model: positions (S, N, 3) or (N, 3), ``box`` = (Lx, Ly, Lz), ``phi`` the volume fraction), and
        the physical parameters as keyword arguments named as the ``sim.*`` keys (``mu``,
        ``kn_coefficient``, ``kt_ratio``, ``delta``,
        ``lub_max_gap``).  Optional: ``strain`` and the true ``eta_r``, ``pressure``, ``z_mu`` (S,) for the
        ``*_sim`` columns; ``position_noise`` [a], the positions' RMS precision per coordinate (an
        imaging model needs it; exact models take unstated positions as exact) and, for a 3D snapshot
        from a confocal microscope, ``axial_noise`` [a], the precision along the optical axis where it
        differs (the model card names the axis; ``position_noise`` is then the in-plane one).  Returns
        one row per configuration as a dict of columns (``pandas.DataFrame(table)`` makes a data frame)."""
        unknown = sorted(set(params) - set(PHYSICAL_PARAMS))
        if unknown:
            raise InputError(
                f"model.predict: unknown keyword(s) {unknown}; the physical parameters are "
                f"{list(PHYSICAL_PARAMS)}"
            )
        values = {
            "positions": positions,
            "radii": radii,
            "box": box,
            "le_offset": le_offset,
            "stress": stress,
            "phi": phi,
            "position_noise": position_noise,
            "axial_noise": axial_noise,
            **params,
        }
        for key, value in (("strain", strain), ("eta_r", eta_r), ("pressure", pressure), ("z_mu", z_mu)):
            if value is not None:
                values[key] = value
        snaps = snapshots_from_values(values, "model.predict", kind="api")
        return self.predict_snapshots(snaps, accept_mismatch)


def load_model(
    name_or_path: str | Path,
    network_class: type | None = None,
    device="cpu",
    workers: int = 1,
    physics_solver: str = "auto",
) -> Surrogate:
    """A shipped model by name (``rheograph.list_models()``), a training run directory or a bundle.
    ``network_class``: the ``SurrogateModule`` subclass its bundles name, when it is not registered
    otherwise (rheograph.learn.networks); nothing named in the bundles is imported.  ``device`` (``cpu``,
    ``cuda``, ``auto``) runs its networks there, ``workers`` processes build the snapshots' graphs and
    physics inputs (the predictions are the same), solving their resistance problems as
    ``physics_solver`` says (``Surrogate``; the predictions differ by round-off)."""
    paths, label = model_paths(name_or_path)
    return Surrogate(
        paths, label, network_class, device=device, workers=workers, physics_solver=physics_solver
    )


# ---- command line ---------------------------------------------------------------------------------
def _parse_param(text: str) -> tuple[str, float]:
    key, sep, value = text.partition("=")
    if not sep or key not in PHYSICAL_PARAMS:
        raise InputError(f"--param {text}: expected KEY=VALUE with KEY one of {list(PHYSICAL_PARAMS)}")
    try:
        return key, float(value)
    except ValueError as exc:
        raise InputError(f"--param {text}: {value!r} is not a number") from exc


def concatenate(tables: list[dict]) -> dict:
    columns = list(tables[0])
    for table in tables[1:]:
        columns += [c for c in table if c not in columns]
    out = {}
    for c in columns:
        parts = []
        for t in tables:
            n = len(t["snapshot"])
            if c in t:
                parts.append(t[c])
            else:  # a column one model run has and another lacks (e.g. no error model)
                parts.append(np.full(n, np.nan))
        out[c] = np.concatenate(parts)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument(
        "--models", help="a shipped model's name (--list-models), a training run directory or a .pt"
    )
    ap.add_argument(
        "--input", nargs="+", help="snapshot sources: trajectory .h5, bare .npz/.h5, LF_DEM par_*.dat"
    )
    ap.add_argument("--out", help="output .csv or .h5")
    ap.add_argument("--list-models", action="store_true", help="list the shipped models and exit")
    ap.add_argument("--lfdem-params", help="LF_DEM's parameter file for LF_DEM inputs (default: input_*.dat)")
    ap.add_argument(
        "--param", action="append", default=[], metavar="KEY=VALUE", help="a physical parameter of the inputs"
    )
    ap.add_argument(
        "--position-noise",
        type=float,
        metavar="EPS",
        help="RMS precision of the input positions per coordinate [a] (overrides what the inputs state)",
    )
    ap.add_argument(
        "--axial-noise",
        type=float,
        metavar="EPS",
        help="3D: RMS precision along the microscope's optical axis [a] where it differs from "
        "--position-noise, then the in-plane one (the model card names the axis)",
    )
    ap.add_argument(
        "--radii",
        choices=RADII_CHOICES,
        default="given",
        help="given (default): the inputs' radii; estimated: the inputs' radii are the species' nominal ones "
        "(a bare file's phi the measured fraction, which they need give only to within "
        f"{NOMINAL_PHI_TOLERANCE:.0%}%) and each snapshot's are estimated from its configuration (particles "
        "spread in size, unmeasured); "
        "estimated-mean: one estimate, the mean over a file's snapshots.  Either estimate needs at least 2 "
        "snapshots of the same particles per file, adds the radii's uncertainty (their scatter) to the "
        "stated position precision, and is documented in docs/imaging.md (estimated-mean reads better)",
    )
    ap.add_argument(
        "--accept-mismatch",
        action="store_true",
        help="predict for inputs of another suspension than the model's (flagged out of domain)",
    )
    ap.add_argument(
        "--device",
        default="cpu",
        help="where the networks run: cpu (default), cuda (cuda:K) or auto (a GPU when there is one)",
    )
    ap.add_argument(
        "--workers",
        type=int,
        default=1,
        help="processes building the snapshots' graphs and physics inputs (one solve each; default 1)",
    )
    ap.add_argument(
        "--physics-solver",
        choices=PHYSICS_SOLVERS,
        default="auto",
        help="how the physics inputs' resistance problems are solved: auto (default: in dense batches on a "
        "CUDA --device up to N = 2000; else sparse on the CPU), sparse, or dense (in "
        "batches on --device, a CPU too); the predictions differ by round-off",
    )
    args = ap.parse_args(argv)
    if args.list_models:
        for name in list_models():
            card = read_card(model_paths(name)[0])
            d = card["domain"]
            print(  # model files written before 3D record no dimension: 2D
                f"{name}: {d.get('dim', 2)}D, phi {d['phi'][0]:g}-{d['phi'][1]:g}, sigma/sigma0 "
                f"{d['stress'][0]:g}-{d['stress'][1]:g}, N {d['n_particles']}, position noise "
                f"{card['position_noise']} a"
            )
        return
    for name in ("models", "input", "out"):
        if getattr(args, name) is None:
            ap.error(f"--{name} is required (or --list-models)")
    if args.position_noise is not None and not (
        math.isfinite(args.position_noise) and args.position_noise >= 0
    ):
        raise InputError(f"--position-noise {args.position_noise:g}: an RMS precision in units of a, >= 0")
    if args.axial_noise is not None and not (math.isfinite(args.axial_noise) and args.axial_noise >= 0):
        raise InputError(f"--axial-noise {args.axial_noise:g}: an RMS precision in units of a, >= 0")
    out = Path(args.out)
    if out.suffix not in (".csv", ".h5") or not out.parent.is_dir():
        raise InputError(f"--out {out}: must be a .csv or .h5 file in an existing directory")
    device = resolve_device(args.device, "--device")
    if args.workers < 1:
        raise InputError(f"--workers {args.workers}: allowed an integer >= 1")
    model = load_model(args.models, device=device, workers=args.workers, physics_solver=args.physics_solver)
    given = dict(_parse_param(p) for p in args.param)
    tables = []
    for path in args.input:
        # estimating the radii declares the inputs' radii nominal: a bare file's phi is the measured one
        snaps = read_snapshots(path, args.lfdem_params, given, radii_nominal=args.radii != "given")
        if args.position_noise is not None:
            snaps.position_noise = args.position_noise
        if args.axial_noise is not None:
            if snaps.dim != 3 or snaps.position_noise is None:
                what = "a 2D snapshot" if snaps.dim != 3 else "without position_noise"
                raise InputError(
                    f"--axial-noise: {path} is {what}; the axial precision is that of a 3D snapshot, "
                    "beside its in-plane --position-noise"
                )
            snaps.axial_noise = args.axial_noise
        if args.radii == "given":
            tables.append(model.predict_snapshots(snaps, args.accept_mismatch))
        else:
            mean = args.radii == "estimated-mean"
            tables.append(model.predict_with_estimated_radii(snaps, mean, args.accept_mismatch))
    table = concatenate(tables)
    header = {"model": model.label, "inputs": " ".join(args.input)}
    if args.position_noise is not None:
        header["position_noise"] = f"{args.position_noise:g}"
    if args.axial_noise is not None:
        header["axial_noise"] = f"{args.axial_noise:g}"
    if args.radii != "given":
        header["radii"] = args.radii
    if given:
        header["parameters given"] = ", ".join(f"{k}={v:g}" for k, v in given.items())
    if args.accept_mismatch:
        header["accept_mismatch"] = "true"
    write_table(table, out, header)
    n_out = int((table["in_domain"] == 0).sum())
    print(
        f"{len(table['snapshot'])} snapshots ({n_out} outside the model's domain), model {model.label} "
        f"-> {out}"
    )
