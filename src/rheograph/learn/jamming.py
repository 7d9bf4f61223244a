"""Shear jamming: the surrogate's documented rule, and its accuracy on held-out trajectories.

Whether a run arrests is not written in one snapshot: at φ = 0.80, σ/σ0 = 50 the flowing snapshots and
the arrested packing have the same Z_μ (2.5–2.9) and η_r ~ 10³–10⁴ with bursts
(docs/validation/time_step.md), and an arrest is a property of the trajectory as much as of the state point.
So the rule is a map of the training data: the share of training trajectories at the state point that
ended jammed.  A prediction at (φ, σ) reports that share at the nearest trained state point (nearest φ,
then nearest log σ); a state point is called jammed when at least half its training trajectories jammed.
Its accuracy is the share of held-out trajectories whose outcome (jammed or not) the rule gets right.

A trajectory counts as jammed when any of its snapshots is labelled jammed
(``rheograph.io.hdf5.jammed_snapshots``: the arrested packing); η_r is never scored on those snapshots.
"""

from __future__ import annotations

import numpy as np


def _runs(phi, stress, run_id, jammed):
    """Per trajectory: (phi, sigma, jammed?) from per-snapshot arrays (S,)."""
    phi, stress, run_id = np.asarray(phi, float), np.asarray(stress, float), np.asarray(run_id)
    jammed = np.asarray(jammed, dtype=bool)
    out = []
    for run in np.unique(run_id):
        at = run_id == run
        out.append((float(phi[at][0]), float(stress[at][0]), bool(jammed[at].any())))
    return out


def fit_jam_map(phi, stress, run_id, jammed) -> dict:
    """Trajectories and jammed trajectories per trained state point (plain lists: stored in bundles)."""
    counts: dict[tuple[float, float], list[int]] = {}
    for p, s, jam in _runs(phi, stress, run_id, jammed):
        entry = counts.setdefault((round(p, 6), round(s, 6)), [0, 0])
        entry[0] += 1
        entry[1] += int(jam)
    keys = sorted(counts)
    return {
        "phi": [k[0] for k in keys],
        "stress": [k[1] for k in keys],
        "runs": [counts[k][0] for k in keys],
        "jammed_runs": [counts[k][1] for k in keys],
    }


def jammed_fraction(jam_map: dict, phi, stress) -> np.ndarray:
    """(S,) share of training trajectories that jammed at the nearest trained state point."""
    phi, stress = np.atleast_1d(np.asarray(phi, float)), np.atleast_1d(np.asarray(stress, float))
    table_phi, table_stress = np.array(jam_map["phi"]), np.array(jam_map["stress"])
    share = np.array(jam_map["jammed_runs"], float) / np.maximum(np.array(jam_map["runs"], float), 1.0)
    out = np.empty(phi.size)
    for k, (p, s) in enumerate(zip(phi, stress)):
        nearest_phi = table_phi[np.argmin(np.abs(table_phi - p))]
        at = np.flatnonzero(np.isclose(table_phi, nearest_phi))
        out[k] = share[at[np.argmin(np.abs(np.log(table_stress[at]) - np.log(s)))]]
    return out


def jam_rule_scores(jam_map: dict, phi, stress, run_id, jammed) -> dict:
    """Accuracy of the rule (jammed when >= half the training trajectories jammed) over held-out
    trajectories, with the counts it rests on."""
    runs = _runs(phi, stress, run_id, jammed)
    if not runs:
        return {"jam_accuracy": float("nan"), "n_runs": 0, "n_jammed_runs": 0}
    predicted = jammed_fraction(jam_map, [r[0] for r in runs], [r[1] for r in runs]) >= 0.5
    actual = np.array([r[2] for r in runs])
    return {
        "jam_accuracy": float(np.mean(predicted == actual)),
        "n_runs": len(runs),
        "n_jammed_runs": int(actual.sum()),
    }
