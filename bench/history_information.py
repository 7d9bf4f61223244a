"""How much of a snapshot's η_r, Π, Z_μ do positions + σ leave unexplained that the contact history holds?

    python -m bench.history_information --phi 0.70 0.76

The instantaneous η_r of a snapshot is fixed by the positions, the imposed stress *and* the tangential
springs' stretches (history the positions do not record).  Gradient-boosted trees (the project's
descriptor baseline) are scored leaving one seed out (whole trajectories held out) on: the eight physics
descriptors + log σ; the same + five spring descriptors from the stored contact states (the tangential
spring stress Σ r sym(n ⊗ ξ)_xy per area, its normal-stress difference, Σ |ξ| per area, the sticking and
sliding fractions); the spring descriptors + log σ alone; and the descriptors + log σ + the one-solve
η_r (``rheograph.graphs.features.solve_viscosity``: the simulator's resistance solve on the positions at
σ, springs unstretched — positions and σ only, no history).  The gain from the springs bounds what any
positions-only surrogate loses to history; the gain from the solve, what the global flow problem holds
that per-snapshot sums miss.  A second table gives, per (φ, σ), the gap log10 η_r − log10 η_solve between
the recorded and the one-solve viscosity (mean and spread within the state point): the stress the
stretched springs carry, which positions cannot know.  Writes the ``history_information`` section of
docs/validation/surrogate_accuracy.md.
"""

from __future__ import annotations

import argparse
import glob
import json
from pathlib import Path

import h5py
import numpy as np

from bench.publishing import publish
from rheograph.graphs.features import snapshot_descriptors, snapshot_pairs, solve_viscosity
from rheograph.learn.module import r2_score
from rheograph.sim.geometry import pair_geometry

ROOT = Path(__file__).resolve().parents[1]
TARGETS = {"log η_r": "viscosity", "log Π": "pressure", "Z_μ": "z_mu"}


def spring_descriptors(positions, radii, lx, ly, le_offset, pairs, stretch, state) -> list[float]:
    """Five per-snapshot descriptors of the tangential springs (units of a, per box area)."""
    if len(pairs) == 0:
        return [0.0] * 5
    nvec, r, _, _ = pair_geometry(positions, radii, pairs[:, 0], pairs[:, 1], lx, ly, le_offset)
    area = lx * ly
    shear = np.sum(r * 0.5 * (nvec[:, 1] * stretch[:, 0] + nvec[:, 0] * stretch[:, 1])) / area
    normal_difference = np.sum(r * (nvec[:, 0] * stretch[:, 0] - nvec[:, 1] * stretch[:, 1])) / area
    magnitude = np.sum(np.hypot(stretch[:, 0], stretch[:, 1])) / area
    return [shear, normal_difference, magnitude, float(np.mean(state == 2)), float(np.mean(state == 3))]


def snapshot_table(n: int, phi: float, min_strain: float = 1.0) -> dict:
    rows = {"seed": [], "log_stress": [], "descriptors": [], "springs": [], "solve": []}
    rows.update({k: [] for k in TARGETS})
    pattern = str(ROOT / f"data/paper/multirun/N{n}_phi{phi:g}_*/trajectory.h5")
    for path in sorted(glob.glob(pattern)):
        with h5py.File(path, "r") as h5:
            if h5.attrs["status"] != "completed":
                continue
            params = json.loads(h5.attrs["params"])
            lx, ly, radii = float(h5.attrs["lx"]), float(h5.attrs["ly"]), h5["radii"][()]
            sn = h5["snapshots"]
            offset = sn["contact_offset"][()]
            for k in np.flatnonzero(sn["strain"][()] >= min_strain):
                positions, le = sn["positions"][k], float(sn["le_offset"][k])
                rows_k = slice(offset[k], offset[k + 1])
                pairs = snapshot_pairs(positions, radii, lx, ly, le, 0.5, params)
                rows["descriptors"].append(snapshot_descriptors(pairs, radii.size, lx * ly))
                rows["springs"].append(
                    spring_descriptors(
                        positions,
                        radii,
                        lx,
                        ly,
                        le,
                        sn["contact_pairs"][rows_k].astype(np.int64),
                        sn["contact_stretch"][rows_k].astype(np.float64),
                        sn["contact_state"][rows_k],
                    )
                )
                rows["solve"].append(np.log10(abs(solve_viscosity(positions, radii, lx, ly, le, params))))
                rows["seed"].append(params["seed"])
                rows["log_stress"].append(np.log(params["stress"]))
                for label, key in TARGETS.items():
                    value = float(sn[key][k])
                    rows[label].append(np.log10(value) if label.startswith("log") and value > 0 else value)
    return {key: np.array(value) for key, value in rows.items()}


def gap_by_stress(table: dict) -> dict:
    """{σ/σ0: (mean, standard deviation)} of log10 η_r − log10 η_solve over the snapshots of each stress."""
    gap = table["log η_r"] - table["solve"]
    stress = np.round(np.exp(table["log_stress"]), 6)
    out = {}
    for value in np.unique(stress):
        g = gap[(stress == value) & np.isfinite(gap)]
        if g.size:
            out[float(value)] = (float(g.mean()), float(g.std(ddof=1)) if g.size > 1 else 0.0)
    return out


def leave_one_seed_out_r2(x: np.ndarray, y: np.ndarray, seed: np.ndarray) -> float:
    from sklearn.ensemble import HistGradientBoostingRegressor

    ok = np.isfinite(y)
    x, y, seed = x[ok], y[ok], seed[ok]
    pred = np.empty_like(y)
    for held_out in np.unique(seed):
        test = seed == held_out
        model = HistGradientBoostingRegressor(max_iter=300, learning_rate=0.05, random_state=0)
        pred[test] = model.fit(x[~test], y[~test]).predict(x[test])
    return r2_score(pred, y)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--phi", type=float, nargs="+", default=[0.70, 0.76])
    ap.add_argument("--n", type=int, default=400)
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    lines = [
        f"N = {args.n}, snapshots at strain ≥ 1 of the completed runs, R² of gradient-boosted trees "
        "leaving one seed out (whole trajectories held out).",
        "",
        "| φ | snapshots | target | descriptors + σ | + spring stretches | springs + σ only "
        "| descriptors + σ + one-solve η_r |",
        "|---|---|---|---|---|---|---|",
    ]
    gaps = {}
    for phi in args.phi:
        table = snapshot_table(args.n, phi)
        if table["seed"].size == 0:
            raise SystemExit(f"no completed runs at N = {args.n}, φ = {phi}")
        gaps[phi] = gap_by_stress(table)
        s = table["log_stress"][:, None]
        inputs = {
            "descriptors": np.c_[table["descriptors"], s],
            "with springs": np.c_[table["descriptors"], s, table["springs"]],
            "springs only": np.c_[table["springs"], s],
            "with solve": np.c_[table["descriptors"], s, table["solve"]],
        }
        for label in TARGETS:
            r2 = [leave_one_seed_out_r2(x, table[label], table["seed"]) for x in inputs.values()]
            lines.append(
                f"| {phi:.2f} | {table['seed'].size} | {label} | " + " | ".join(f"{v:.4f}" for v in r2) + " |"
            )
    stresses = sorted({stress for by_stress in gaps.values() for stress in by_stress})
    lines += [
        "",
        "Gap log10 η_r − log10 η_solve between the recorded and the one-solve viscosity (the springs' "
        "stress, i.e. history), mean (spread within the state point) over the same snapshots, per σ/σ0:",
        "",
        "| φ | " + " | ".join(f"{stress:g}" for stress in stresses) + " |",
        "|---|" + "---|" * len(stresses),
        *(
            f"| {phi:.2f} | "
            + " | ".join(
                f"{by_stress[st][0]:+.3f} ({by_stress[st][1]:.3f})" if st in by_stress else "–"
                for st in stresses
            )
            + " |"
            for phi, by_stress in gaps.items()
        ),
        "",
        f"Command: `python -m bench.history_information --phi {' '.join(map(str, args.phi))}`",
    ]
    publish("history_information", "\n".join(lines), write=not args.no_write)


if __name__ == "__main__":
    main()
