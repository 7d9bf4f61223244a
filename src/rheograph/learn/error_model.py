"""Cross-validated error bars for the surrogate's predictions.

The spread of the fold ensemble is not an error bar: the five models agree with each other more than with
the simulator (docs/validation/surrogate_accuracy.md: 20 % of held-out η_r within ±1 spread).  What the
K-fold run does measure is the error on trajectories a model has never seen — every test snapshot is
predicted by the one model that did not train on its trajectory.  The error model is the root-mean-square
of those held-out residuals per state point (φ, σ), in the scale the targets fluctuate on: log10 for η_r
and Π (multiplicative), linear for Z_μ.  A new snapshot gets the RMS of its state point, interpolated in
log σ at the nearest trained φ (σ and φ are known inputs); beyond the trained σ range the end value holds
(such inputs are flagged out of domain anyway).

Shapes: ``pred``, ``true`` (G, 3) physical [η_r, Π, Z_μ]; ``stress``, ``phi`` (G,).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from rheograph.errors import InputError
from rheograph.io.json_files import read_json
from rheograph.learn.module import LOG_TARGETS, TARGET_NAMES

FILENAME = "error_model.json"


def error_scale(values: np.ndarray, name: str) -> np.ndarray:
    """Targets in the scale their errors are modelled on: log10 for η_r and Π, linear for Z_μ.
    Non-positive η_r or Π (a reversing shear rate, a noisy low-stress Π) map to NaN."""
    values = np.asarray(values, dtype=np.float64)
    if name not in LOG_TARGETS:
        return values
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(values > 0, np.log10(np.where(values > 0, values, 1.0)), np.nan)


def fit_error_model(pred, true, stress, phi, jammed=None, min_count: int = 5) -> dict:
    """RMS of held-out residuals per (φ, σ) and target.  η_r residuals of jammed snapshots are left out
    (η_r is not a target there); state points with fewer than ``min_count`` usable residuals get NaN and
    are filled by interpolation at prediction time."""
    pred, true = np.asarray(pred, dtype=np.float64), np.asarray(true, dtype=np.float64)
    stress, phi = np.asarray(stress, dtype=np.float64), np.asarray(phi, dtype=np.float64)
    jammed = np.zeros(len(pred), dtype=bool) if jammed is None else np.asarray(jammed, dtype=bool)
    points = sorted({(round(float(p), 6), round(float(s), 6)) for p, s in zip(phi, stress)})
    rms = {name: [] for name in TARGET_NAMES}
    counts = []
    for p, s in points:
        at = np.isclose(phi, p) & np.isclose(stress, s)
        counts.append(int(at.sum()))
        for k, name in enumerate(TARGET_NAMES):
            residual = error_scale(pred[at, k], name) - error_scale(true[at, k], name)
            if name == "eta":
                residual = residual[~jammed[at]]
            residual = residual[np.isfinite(residual)]
            rms[name].append(float(np.sqrt(np.mean(residual**2))) if residual.size >= min_count else None)
    return {
        "scale": {name: ("log10" if name in LOG_TARGETS else "linear") for name in TARGET_NAMES},
        "phi": [p for p, _ in points],
        "stress": [s for _, s in points],
        "count": counts,
        "rms": rms,
    }


def predicted_error(model: dict, stress, phi) -> np.ndarray:
    """(S, 3) error bar per snapshot (log10 units for η_r and Π, absolute for Z_μ): the held-out RMS of
    its state point, interpolated in log σ at the nearest trained φ."""
    stress, phi = np.atleast_1d(np.asarray(stress, float)), np.atleast_1d(np.asarray(phi, float))
    table_phi, table_stress = np.array(model["phi"]), np.array(model["stress"])
    trained_phi = np.unique(table_phi)
    out = np.full((len(stress), len(TARGET_NAMES)), np.nan)
    for i, (s, p) in enumerate(zip(stress, phi)):
        nearest = trained_phi[np.argmin(np.abs(trained_phi - p))]
        at = np.isclose(table_phi, nearest)
        order = np.argsort(table_stress[at])
        log_s = np.log10(table_stress[at][order])
        for k, name in enumerate(TARGET_NAMES):
            values = np.array([np.nan if v is None else v for v in np.array(model["rms"][name], object)[at]])
            values = values[order]
            known = np.isfinite(values)
            if known.any():
                out[i, k] = np.interp(np.log10(s), log_s[known], values[known])
    return out


def error_bounds(name: str, prediction, error) -> tuple[np.ndarray, np.ndarray]:
    """(lower, upper) of one target in its physical units: a factor 10^error either side of the
    prediction for η_r and Π (whose bar is in log10 units; NaN where the prediction is not positive, as
    a factor cannot bound it), ± error for Z_μ."""
    prediction, error = np.asarray(prediction, float), np.asarray(error, float)
    if name not in LOG_TARGETS:
        return prediction - error, prediction + error
    factor = 10.0**error
    positive = prediction > 0
    lower = np.where(positive, prediction / factor, np.nan)
    upper = np.where(positive, prediction * factor, np.nan)
    return lower, upper


def write_error_model(run_dir: Path, model: dict) -> Path:
    path = Path(run_dir) / FILENAME
    path.write_text(json.dumps(model, indent=1))
    return path


def read_error_model(run_dir: Path) -> dict | None:
    """The error model of a training run directory, or None (a run trained before it existed, or on a
    random split, whose test snapshots share trajectories with training and would give optimistic bars)."""
    path = Path(run_dir) / FILENAME
    if not path.exists():
        return None
    model = read_json(path, "error model", "; is the model folder damaged?")
    problem = _error_model_problem(model)
    if problem:
        raise InputError(f"{path}: not an error model ({problem}); is the model folder damaged?")
    return model


def _error_model_problem(model) -> str:
    """What makes ``model`` (read from JSON) no error model of ``fit_error_model``'s form; '' if nothing."""
    if not isinstance(model, dict):
        return "not a JSON object"

    def numbers(value, allow_none=False):
        return isinstance(value, list) and all(
            (v is None and allow_none)
            or (isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v))
            for v in value
        )

    phi, stress, rms = model.get("phi"), model.get("stress"), model.get("rms")
    if not (numbers(phi) and numbers(stress) and phi and len(phi) == len(stress)):
        return "phi and stress must be lists of as many numbers, at least one"
    if min(stress) <= 0:
        return "stress must be > 0"
    if not isinstance(rms, dict) or set(TARGET_NAMES) - set(rms):
        return f"rms must hold a list for each of {list(TARGET_NAMES)}"
    for name in TARGET_NAMES:
        values = rms[name]
        if not (numbers(values, allow_none=True) and len(values) == len(phi)):
            return f"rms.{name} must be one number or null per state point ({len(phi)})"
        if any(v is not None and v < 0 for v in values):
            return f"rms.{name} must be >= 0 (a root-mean-square)"
    return ""
