"""Where the suspension jams: the frictionless and frictional jamming area fractions from steady flow.

    python -m rheograph.analysis.jamming_points data/paper/index.json data/jamming/index.json \\
        --out docs/jamming.md --figure docs/figures/phase_diagram.png

Two fits of the steady relative viscosity of every finished trajectory (``summary/viscosity``, strain
>= 1), per system size N, each with a bootstrap over trajectories (resampled within each state point):

* **Divergence on a branch**: eta_r = A (phi_J - phi)^(-beta) on the frictionless branch (mu = 0 runs,
  and the frictional set's runs at sigma/sigma0 <= 0.5 whose Z_mu is below 0.02: no contact there
  reaches the critical load) -> phi_J^0; and on the high-stress plateau (the largest stress of the set,
  friction saturated) -> phi_J^mu.  beta fixed at 2 and fitted.
* **Wyart–Cates** over every flowing state point: eta_r = A (1 - phi / phi_m)^(-2) with
  phi_m = f phi_J^mu + (1 - f) phi_J^0 and f = Z_mu / Z, the measured fraction of frictional contacts of
  each trajectory (not a model of f(sigma)).

Jammed runs have no viscosity and enter neither fit; the phase diagram marks them.  A state point with
one trajectory has nothing to resample; with ``--single-run-error`` its eta_r is drawn from its block
standard error instead (for a set of one seed per state point, such as the 3D plateau so far).

Near jamming LF_DEM's stick–slip rule needs a finer step than elastic unloading (docs/jamming.md): where a
state point was run with both rules, ``--mixed-rules unloading`` keeps its elastic-unloading
trajectories only and ``--mixed-rules pooled`` keeps both; without either, such a state point is refused.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, minimize_scalar

from rheograph.errors import InputError, one_line_errors
from rheograph.io.figures import save_png
from rheograph.io.pages import render_blocks, replace_section, table_block, write_record

FRICTIONLESS_Z_MU = 0.02  # a sigma <= 0.5 run below this frictional coordination is on the mu = 0 branch
BOOTSTRAP = 400
# 1 / (logistic width): 1e4 is a width of 1e-4 in phi, a step at the resolution of any phi grid run
MAX_ARREST_RATE = 1e4


def read_runs(index_paths) -> list[dict]:
    """One record per trajectory of the indexes: N, phi, sigma/sigma0, seed, mu, status, the strain it
    reached (where it arrested, for a jammed run), steady eta_r, Z_mu, Z and Pi/sigma0 (NaN where the
    run did not flow), and the dimension (2 for the monolayer, whose files carry no ``dim``; 3)."""
    runs = []
    for path in index_paths:
        try:
            index = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise InputError(
                f"{path}: not a readable run index ({exc}); make one with rheograph.runs.sweep_index"
            ) from exc
        for entry in index.get("runs", []):
            p, s = entry["params"], entry.get("summary") or {}
            runs.append(
                {
                    "n": int(p["n_particles"]),
                    "phi": float(p["phi"]),
                    "stress": float(p["stress"]),
                    "seed": int(p["seed"]),
                    "mu": float(p["mu"]),
                    "status": entry["status"],
                    "strain": float(entry.get("strain") or np.nan),
                    "eta": float(s.get("viscosity") or np.nan),
                    "eta_se": float(s.get("viscosity_se") or np.nan),
                    "z_mu": float(s.get("z_mu") if s.get("z_mu") is not None else np.nan),
                    "z": float(s.get("z") if s.get("z") is not None else np.nan),
                    "pressure": float(s.get("pressure") if s.get("pressure") is not None else np.nan),
                    "dim": int(p.get("dim", 2)),
                    "elastic_unloading": bool(p.get("elastic_unloading", False)),
                }
            )
    return runs


def finished(run: dict) -> bool:
    """A run that reached its end: completed in flow, or arrested (not one stopped short of either)."""
    return run["status"] in ("completed", "jammed")


MIXED_RULES = ("unloading", "pooled")


def state_point(run: dict) -> tuple:
    """What makes two trajectories repeats of one state point: dimension, N, phi, stress and mu."""
    return (run["dim"], run["n"], run["phi"], run["stress"], run["mu"])


def select_rules(runs: list[dict], mixed: str | None) -> tuple[list[dict], list[dict]]:
    """(the runs the fits read, the runs left out) where a state point holds finished trajectories
    (completed or arrested) of both stick–slip rules (``elastic_unloading`` and LF_DEM's):
    ``mixed="unloading"`` keeps the elastic-unloading ones there, ``"pooled"`` keeps both as repeats;
    None refuses such a state point (the two rules differ near jamming at the same step, so pooling
    them must be asked for).  A run still under way decides nothing."""
    if mixed is not None and mixed not in MIXED_RULES:
        raise InputError(f"mixed rules {mixed!r}: allowed {', '.join(MIXED_RULES)}")
    rules: dict[tuple, set[bool]] = {}
    for r in runs:
        if finished(r):  # a run still under way supersedes nothing yet
            rules.setdefault(state_point(r), set()).add(r["elastic_unloading"])
    mixed_points = sorted(k for k, v in rules.items() if len(v) == 2)
    if not mixed_points or mixed == "pooled":
        return runs, []
    if mixed is None:
        dim, n, phi, stress, _ = mixed_points[0]
        raise InputError(
            f"N = {n} ({dim}D) phi {phi:g} sigma/sigma0 {stress:g} (and {len(mixed_points) - 1} more state "
            "points) holds runs with and without elastic unloading: pass --mixed-rules unloading (keep "
            "the elastic-unloading runs there) or --mixed-rules pooled (keep both)"
        )
    mixed_set = set(mixed_points)
    kept = [r for r in runs if state_point(r) not in mixed_set or r["elastic_unloading"]]
    left_out = [r for r in runs if state_point(r) in mixed_set and not r["elastic_unloading"]]
    return kept, left_out


def rule_comparison(runs: list[dict]) -> list[dict]:
    """One record per state point run with both stick–slip rules, one of them to its end: its (dim, N,
    phi, sigma/sigma0) and, per rule (``lfdem``, ``unloading``), the runs' count, the mean eta_r and Z_mu
    of those that completed in flow with the standard error of that mean (between seeds; one run's block
    error), the strains at which runs arrested and those at which runs stopped short of either."""
    groups: dict[tuple, dict[str, list[dict]]] = {}
    for r in runs:
        rule = "unloading" if r["elastic_unloading"] else "lfdem"
        groups.setdefault(state_point(r), {"lfdem": [], "unloading": []})[rule].append(r)
    records = []
    for (dim, n, phi, stress, _), by_rule in sorted(groups.items()):
        decided = [r for members in by_rule.values() for r in members if finished(r)]
        if not (by_rule["lfdem"] and by_rule["unloading"] and decided):
            continue
        record = {"dim": dim, "n": n, "phi": phi, "stress": stress}
        for rule, members in by_rule.items():
            flows = [r for r in members if flowing(r)]
            eta = np.array([r["eta"] for r in flows])
            if len(flows) > 1:
                eta_se = float(np.std(eta, ddof=1) / np.sqrt(len(flows)))
            else:
                eta_se = float(flows[0]["eta_se"]) if flows else np.nan
            record[rule] = {
                "runs": len(members),
                "eta": float(eta.mean()) if flows else np.nan,
                "eta_se": eta_se,
                "z_mu": float(np.mean([r["z_mu"] for r in flows])) if flows else np.nan,
                "arrested_at": sorted(r["strain"] for r in members if r["status"] == "jammed"),
                "stopped_at": sorted(r["strain"] for r in members if not finished(r)),
            }
        records.append(record)
    return records


def two_digits(x: float) -> str:
    """``x`` rounded to two significant digits, written out (420, 38, 4.2; not 4.2e+02)."""
    if x == 0:
        return "0"
    return f"{round(x, 1 - int(np.floor(np.log10(abs(x))))):g}"


def rule_comparison_block(records: list[dict]) -> dict:
    """The table of :func:`rule_comparison` (cells as published)."""

    def cells(side: dict) -> list[str]:
        parts = []
        if np.isfinite(side["eta"]):
            error = f" ± {two_digits(side['eta_se'])}" if np.isfinite(side["eta_se"]) else ""
            parts.append(f"{side['eta']:.4g}{error}")
        if side["arrested_at"]:
            parts.append("arrested at strain " + ", ".join(f"{x:.3f}" for x in side["arrested_at"]))
        if side["stopped_at"]:
            parts.append("undecided, stopped at strain " + ", ".join(f"{x:.3g}" for x in side["stopped_at"]))
        z_mu = f"{side['z_mu']:.2f}" if np.isfinite(side["z_mu"]) else "—"
        return [str(side["runs"]), "; ".join(parts), z_mu]

    header = ["N", "φ", "σ/σ0", "runs", "η_r, LF_DEM's rule", "Z_μ", "runs", "η_r, elastic unloading", "Z_μ"]
    header += ["ratio"]
    body = []
    for r in records:
        ratio = r["unloading"]["eta"] / r["lfdem"]["eta"]
        body.append(
            [size_label(r["n"], r["dim"]), f"{r['phi']:g}", f"{r['stress']:g}"]
            + cells(r["lfdem"])
            + cells(r["unloading"])
            + [f"{ratio:.2f}" if np.isfinite(ratio) else "—"]
        )
    return table_block(header, body)


def add_mixed_rules_argument(ap: argparse.ArgumentParser) -> None:
    """The ``--mixed-rules`` option of every command that reads run indexes into fits."""
    ap.add_argument(
        "--mixed-rules",
        choices=MIXED_RULES,
        help="a state point run both with and without elastic unloading: keep its elastic-unloading "
        "runs only (unloading) or both as repeats (pooled); without it such a state point is refused",
    )


def flowing(run: dict) -> bool:
    return run["status"] == "completed" and np.isfinite(run["eta"]) and run["eta"] > 0


def frictionless_branch(runs: list[dict], n: int, flowing_only: bool = True) -> list[dict]:
    """Runs at N on the frictionless branch: mu = 0, or sigma/sigma0 <= 0.5 with (almost) no frictional
    contact; the flowing ones, or (``flowing_only=False``) every mu = 0 run, arrested ones included (a
    sigma <= 0.5 run that arrested has no steady Z_mu to place it by)."""
    return [
        r
        for r in runs
        if r["n"] == n
        and (flowing(r) or (not flowing_only and r["mu"] == 0.0))
        and (r["mu"] == 0.0 or (r["stress"] <= 0.5 and r["z_mu"] < FRICTIONLESS_Z_MU))
    ]


def plateau_branch(runs: list[dict], n: int, flowing_only: bool = True) -> tuple[list[dict], float]:
    """Frictional runs at the largest stress of the set at this N (the flowing ones, or every one), and
    that stress."""
    frictional = [r for r in runs if r["n"] == n and r["mu"] > 0]
    if not frictional:
        return [], np.nan
    top = max(r["stress"] for r in frictional)
    return [r for r in frictional if r["stress"] == top and (flowing(r) or not flowing_only)], top


def arrest_bracket(branch: list[dict]) -> tuple[float, float, int] | None:
    """(phi_low, phi_high, runs between them): the highest area fraction at which every finished run of
    the branch flows, below the lowest at which every one arrested (runs stopped early count for
    neither).  The jamming point of this box lies between them, whatever the form of the divergence;
    None where no area fraction arrested every run."""
    decided = [r for r in branch if finished(r)]
    by_phi: dict[float, list[str]] = {}
    for r in decided:
        by_phi.setdefault(r["phi"], []).append(r["status"])
    arrested = [phi for phi, s in by_phi.items() if all(x == "jammed" for x in s)]
    if not arrested:
        return None
    high = min(arrested)
    flows = [phi for phi, s in by_phi.items() if phi < high and all(x == "completed" for x in s)]
    if not flows:
        return None
    low = max(flows)
    return low, high, sum(low <= r["phi"] <= high for r in decided)


def arrest_probability(branch: list[dict]) -> dict | None:
    """The area fraction phi_1/2 at which a run of the branch arrests within a common strain window with
    probability 1/2, and its 68 % interval.

    Maximum likelihood of a logistic p(phi) = 1 / (1 + exp(-(phi - phi_1/2) / w)), w >= 0 (arrest never
    gets less likely with phi), over the decided runs; the interval is that of the profile likelihood of
    phi_1/2 (2 Delta log L <= 1).  The window is the strain of the shortest run that flowed to its end: a
    run that arrested later counts as flowing within it, so every run is observed over the same strain
    (arrest is absorbing, so a longer window moves phi_1/2 down).  Where the outcomes separate perfectly
    in phi the likelihood is flat over the gap, phi_1/2 is its middle and the interval the gap: the
    arrest bracket.  None without both an arrested and a flowing run.

    Returns dict(phi_half, interval=(low, high), window, runs, arrested, phi_range)."""
    decided = [r for r in branch if finished(r)]
    completed = [r["strain"] for r in decided if r["status"] == "completed"]
    if not completed:
        return None
    window = min(completed)
    phi = np.array([r["phi"] for r in decided])
    arrested = np.array([r["status"] == "jammed" and r["strain"] < window for r in decided])
    if arrested.all() or not arrested.any():
        return None

    def nll(phi_half: float, rate: float) -> float:
        # -log L with logit = rate (phi - phi_half); logaddexp keeps the saturated terms finite
        logit = rate * (phi - phi_half)
        return float(np.sum(np.where(arrested, np.logaddexp(0.0, -logit), np.logaddexp(0.0, logit))))

    def profile(phi_half: float) -> float:
        # convex in the rate at fixed phi_1/2 (the logit is linear in it)
        return minimize_scalar(
            lambda rate: nll(phi_half, rate), bounds=(0.0, MAX_ARREST_RATE), method="bounded"
        ).fun

    grid = np.arange(phi.min() - 0.02, phi.max() + 0.02, 2e-5)
    profiled = np.array([profile(x) for x in grid])
    best = profiled.min()
    inside = grid[2.0 * (profiled - best) <= 1.0]
    flat = grid[profiled - best <= 1e-9]
    return {
        "phi_half": float(flat.mean()),
        "interval": (float(inside.min()), float(inside.max())),
        "window": float(window),
        "runs": len(decided),
        "arrested": int(arrested.sum()),
        "phi_range": (float(phi.min()), float(phi.max())),
    }


def fit_divergence(phi, eta, beta: float | None = None) -> dict:
    """Least squares in log eta_r of eta_r = A (phi_J - phi)^(-beta) (beta fitted when None)."""
    phi, log_eta = np.asarray(phi, float), np.log(np.asarray(eta, float))
    if np.unique(phi).size < (3 if beta is None else 2):
        raise InputError(f"a divergence fit needs at least {3 if beta is None else 2} area fractions")
    top = phi.max()

    def residual(x):
        phi_j, log_a = x[0], x[1]
        b = beta if beta is not None else x[2]
        return log_eta - (log_a - b * np.log(phi_j - phi))

    x0 = [top + 0.02, 0.0] + ([2.0] if beta is None else [])
    lower = [top + 1e-5, -np.inf] + ([0.1] if beta is None else [])
    upper = [1.0, np.inf] + ([10.0] if beta is None else [])
    fit = least_squares(residual, x0, bounds=(lower, upper))
    out = {"phi_j": float(fit.x[0]), "prefactor": float(np.exp(fit.x[1]))}
    out["beta"] = float(beta if beta is not None else fit.x[2])
    out["rms_log"] = float(np.sqrt(np.mean(fit.fun**2)))
    return out


def wyart_cates(f, phi_0, phi_mu):
    """phi_m = f phi_mu + (1 - f) phi_0: the jamming fraction at a frictional-contact fraction f."""
    return f * phi_mu + (1.0 - f) * phi_0


def fit_wyart_cates(phi, f, eta, beta: float | None = 2.0, prefactor_in_f: bool = False) -> dict:
    """Least squares in log eta_r of eta_r = A (1 - phi / phi_m(f))^(-beta), phi_m of ``wyart_cates``
    (beta fitted when None).  With ``prefactor_in_f`` the prefactor interpolates between the two
    branches like the jamming fraction, log A = (1 - f) log A_0 + f log A_mu: the frictionless and the
    frictional divergences need not share an amplitude."""
    phi, f, log_eta = (np.asarray(v, float) for v in (phi, f, eta))
    log_eta = np.log(log_eta)
    n_log_a = 2 if prefactor_in_f else 1

    def residual(x):
        phi_m = wyart_cates(f, x[0], x[1])
        gap = np.maximum(1.0 - phi / phi_m, 1e-9)
        log_a = x[2] + (x[3] - x[2]) * f if prefactor_in_f else x[2]
        b = beta if beta is not None else x[2 + n_log_a]
        return log_eta - (log_a - b * np.log(gap))

    x0 = [0.84, 0.80] + [0.0] * n_log_a + ([2.0] if beta is None else [])
    lower = [0.5, 0.5] + [-np.inf] * n_log_a + ([0.1] if beta is None else [])
    upper = [1.0, 1.0] + [np.inf] * n_log_a + ([10.0] if beta is None else [])
    fit = least_squares(residual, x0, bounds=(lower, upper))
    out = {
        "phi_j0": float(fit.x[0]),
        "phi_jmu": float(fit.x[1]),
        "prefactor": float(np.exp(fit.x[2])),
        "beta": float(beta if beta is not None else fit.x[2 + n_log_a]),
        "rms_log": float(np.sqrt(np.mean(fit.fun**2))),
    }
    if prefactor_in_f:
        out["prefactor_mu"] = float(np.exp(fit.x[3]))
    return out


def bootstrap(
    runs: list[dict], fit, keys, rng, n_boot: int = BOOTSTRAP, single_run_error: bool = False
) -> dict:
    """(median, 16th, 84th percentile) of ``fit(runs)[key]`` over trajectories resampled with replacement
    within each (phi, sigma) state point.  A state point with one trajectory is held fixed (resampling
    one run returns it), unless ``single_run_error``: then its eta_r is drawn log-normal about its
    steady mean with the relative width of its block standard error (``eta_se``), the time-sampling
    error that a second seed would otherwise show."""
    groups: dict = {}
    for r in runs:
        groups.setdefault((r["phi"], r["stress"], r["mu"]), []).append(r)
    values = {k: [] for k in keys}
    for _ in range(n_boot):
        sample = [g[i] for g in groups.values() for i in rng.integers(0, len(g), len(g))]
        if single_run_error:
            sample = [
                {**r, "eta": r["eta"] * np.exp(rng.normal(0.0, r["eta_se"] / r["eta"]))}
                if len(groups[(r["phi"], r["stress"], r["mu"])]) == 1 and r["eta_se"] > 0
                else r
                for r in sample
            ]
        try:
            result = fit(sample)
        except InputError:
            continue
        for k in keys:
            values[k].append(result[k])
    return {k: tuple(float(q) for q in np.percentile(v, [50, 16, 84])) for k, v in values.items()}


def near(branch: list[dict], window: float) -> list[dict]:
    """The runs of a branch within ``window`` below its highest flowing area fraction: a power law holds
    only close to the divergence (far below it eta_r grows more slowly, and a fit over the whole range
    returns a smaller exponent and a different phi_J)."""
    if not branch:
        return branch
    top = max(r["phi"] for r in branch)
    return [r for r in branch if r["phi"] >= top - window - 1e-9]


def systems(runs: list[dict]):
    """(dim, N, the runs of that dimension and size) for each system of the runs, 2D first: a 2D and a
    3D set are fitted apart even where their N coincide (the jamming point is a packing fraction of
    discs in one, of spheres in the other)."""
    for dim, n in sorted({(r.get("dim", 2), r["n"]) for r in runs}):
        yield dim, n, [r for r in runs if r.get("dim", 2) == dim and r["n"] == n]


def size_label(n: int, dim: int) -> str:
    """How a system is named in tables and titles: its N, marked (3D) for spheres."""
    return f"{n}" if dim == 2 else f"{n} (3D)"


def jamming_table(
    runs: list[dict],
    seed: int = 0,
    window: float = 0.05,
    n_boot: int = BOOTSTRAP,
    single_run_error: bool = False,
) -> list[dict]:
    """Fit rows per system (dimension and N; method, branch, phi_J with its 68 % interval over
    ``n_boot`` bootstrap samples, beta, rms); the divergence fits use the packing fractions within
    ``window`` of the branch's highest (``near``).  ``single_run_error``: see ``bootstrap``."""
    rng = np.random.default_rng(seed)
    rows = []
    for dim, n, system in systems(runs):
        branches = [
            (
                "phi_J^0",
                "frictionless (mu = 0; sigma/sigma0 <= 0.5 with Z_mu < 0.02)",
                frictionless_branch(system, n),
            )
        ]
        plateau, top = plateau_branch(system, n)
        branches.append(("phi_J^mu", f"high-stress plateau (sigma/sigma0 = {top:g})", plateau))
        for name, everyone in (
            ("phi_J^0", frictionless_branch(system, n, flowing_only=False)),
            ("phi_J^mu", plateau_branch(system, n, flowing_only=False)[0]),
        ):
            bracket = arrest_bracket(everyone)
            if bracket:
                low, high, count = bracket
                rows.append(
                    {
                        "n": n,
                        "dim": dim,
                        "quantity": name,
                        "method": "arrest bracket: every run flows / every run arrests",
                        "data": next(label for q, label, _ in branches if q == name),
                        "trajectories": count,
                        "phi_range": (low, high),
                        "phi_j": 0.5 * (low + high),
                        "phi_j_ci": (low, high),
                        "beta": np.nan,
                        "beta_ci": None,
                        "rms_log": np.nan,
                    }
                )
            crossing = arrest_probability(everyone)
            if crossing:
                rows.append(
                    {
                        "n": n,
                        "dim": dim,
                        "quantity": name,
                        "method": f"arrest probability 1/2 within {crossing['window']:.3g} strain "
                        f"({crossing['arrested']} of {crossing['runs']} arrest; logistic, profile)",
                        "data": next(label for q, label, _ in branches if q == name),
                        "trajectories": crossing["runs"],
                        "phi_range": crossing["phi_range"],
                        "phi_j": crossing["phi_half"],
                        "phi_j_ci": crossing["interval"],
                        "beta": np.nan,
                        "beta_ci": None,
                        "rms_log": np.nan,
                    }
                )
        for name, label, branch in branches:
            branch = near(branch, window)
            if len({r["phi"] for r in branch}) < 3:
                continue
            phi = [r["phi"] for r in branch]
            eta = [r["eta"] for r in branch]
            for beta in (2.0, None):
                fit = fit_divergence(phi, eta, beta)
                spread = bootstrap(
                    branch,
                    lambda s, b=beta: fit_divergence([r["phi"] for r in s], [r["eta"] for r in s], b),
                    ["phi_j", "beta"],
                    rng,
                    n_boot,
                    single_run_error,
                )
                rows.append(
                    {
                        "n": n,
                        "dim": dim,
                        "quantity": name,
                        "method": "divergence, beta = 2" if beta else "divergence, beta fitted",
                        "data": label,
                        "trajectories": len(branch),
                        "phi_range": (min(phi), max(phi)),
                        "phi_j": fit["phi_j"],
                        "phi_j_ci": spread["phi_j"][1:],
                        "beta": fit["beta"],
                        "beta_ci": spread["beta"][1:] if beta is None else None,
                        "rms_log": fit["rms_log"],
                    }
                )
        everything = [r for r in system if flowing(r) and np.isfinite(r["z_mu"]) and r["z"] > 0]
        if len({r["phi"] for r in everything}) >= 3 and any(r["z_mu"] > 0 for r in everything):
            for beta, per_branch in ((2.0, False), (None, False), (None, True)):

                def wc(sample, b=beta, p=per_branch):
                    return fit_wyart_cates(
                        [r["phi"] for r in sample],
                        [r["z_mu"] / r["z"] for r in sample],
                        [r["eta"] for r in sample],
                        b,
                        prefactor_in_f=p,
                    )

                fit = wc(everything)
                spread = bootstrap(
                    everything, wc, ["phi_j0", "phi_jmu", "beta"], rng, n_boot, single_run_error
                )
                for name, key in (("phi_J^0", "phi_j0"), ("phi_J^mu", "phi_jmu")):
                    rows.append(
                        {
                            "n": n,
                            "dim": dim,
                            "quantity": name,
                            "method": "Wyart–Cates, f = Z_mu / Z, "
                            + ("log A linear in f, " if per_branch else "")
                            + ("beta = 2" if beta else "beta fitted"),
                            "data": "every flowing state point",
                            "trajectories": len(everything),
                            "phi_range": (
                                min(r["phi"] for r in everything),
                                max(r["phi"] for r in everything),
                            ),
                            "phi_j": fit[key],
                            "phi_j_ci": spread[key][1:],
                            "beta": fit["beta"],
                            "beta_ci": spread["beta"][1:] if beta is None else None,
                            "rms_log": fit["rms_log"],
                            "wyart_cates": fit,
                        }
                    )
    return rows


def section_blocks(rows: list[dict], command: str, rules: list[dict] | None = None) -> list[dict]:
    """The published section: the fits as a table (cells as printed), the state points run with both
    stick–slip rules (``rules``, :func:`rule_comparison`; where there are any) and the command."""
    header = [
        "N",
        "quantity",
        "method",
        "data",
        "trajectories",
        "φ range",
        "φ_J (interval)",
        "β",
        "rms log η_r",
    ]
    body = []
    for r in rows:
        low, high = r["phi_j_ci"]
        beta = (
            "—"
            if not np.isfinite(r["beta"])
            else f"{r['beta']:.2f}"
            + (f" ({r['beta_ci'][0]:.2f}–{r['beta_ci'][1]:.2f})" if r["beta_ci"] else "")
        )
        rms = "—" if not np.isfinite(r["rms_log"]) else f"{r['rms_log']:.3f}"
        body.append(
            [size_label(r["n"], r["dim"]), r["quantity"], r["method"], r["data"], f"{r['trajectories']}"]
            + [f"{r['phi_range'][0]:g}–{r['phi_range'][1]:g}", f"{r['phi_j']:.4f} ({low:.4f}–{high:.4f})"]
            + [beta, rms]
        )
    blocks = [table_block(header, body)]
    if rules:
        blocks += [
            {
                "text": "\nState points run with both stick–slip rules at the same step (η_r ± the standard "
                "error of the mean over seeds, or one run's block error; the fits above read the runs "
                "of the rule `--mixed-rules` keeps):\n"
            },
            rule_comparison_block(rules),
        ]
    return blocks + [{"text": f"\nCommand: `{command}`"}]


def docs_page(path: Path) -> str:
    """``path`` as a page of the docs folder it is in (``docs/jamming.md`` -> ``jamming.md``)."""
    parts = Path(path).resolve().parts
    if "docs" not in parts:
        return str(path)
    return "/".join(parts[len(parts) - parts[::-1].index("docs") :])


DPI = 130  # dots per inch of the phase diagram
BRANCHES = ("phi_J^0", "phi_J^mu")


def phase_diagram_data(runs: list[dict], rows: list[dict]) -> dict:
    """The numbers of :func:`draw_phase_diagram`, per N (``sizes``): the (φ, σ/σ0) of the frictional
    runs that flow and of those that shear-jam; the Wyart–Cates jamming line φ_m(f) of the best-fitting
    Wyart–Cates row (β fitted) at each flowing stress, f the mean measured Z_μ / Z there (null without
    such a fit); per branch (``phi_J^0``, ``phi_J^mu``) the divergence's φ_J (β fitted) and the 68 %
    interval of arrest probability 1/2 (null where not fitted)."""
    sizes = []
    for dim, n, system in systems(runs):
        rows_here = [r for r in rows if r["dim"] == dim]
        frictional = [r for r in system if r["mu"] > 0]
        states = {
            status: [[r["phi"], r["stress"]] for r in frictional if r["status"] == status]
            for status in ("completed", "jammed")
        }
        candidates = [r for r in rows_here if r["n"] == n and "wyart_cates" in r and r["beta_ci"]]
        best = min(candidates, key=lambda r: r["rms_log"]) if candidates else None
        line = None
        if best and best["wyart_cates"]:
            fit = best["wyart_cates"]
            stresses = sorted({r["stress"] for r in frictional if flowing(r)})
            f = [
                np.nanmean([r["z_mu"] / r["z"] for r in frictional if r["stress"] == s and flowing(r)])
                for s in stresses
            ]
            line = {
                "phi_m": wyart_cates(np.array(f), fit["phi_j0"], fit["phi_jmu"]).tolist(),
                "stress": stresses,
                "prefactor_in_f": "prefactor_mu" in fit,
            }
        divergence, arrest = {}, {}
        for quantity in BRANCHES:
            mine = [r for r in rows_here if r["n"] == n and r["quantity"] == quantity]
            row = next((r for r in mine if r["method"] == "divergence, beta fitted"), None)
            divergence[quantity] = row["phi_j"] if row else None
            crossing = next((r for r in mine if r["method"].startswith("arrest probability")), None)
            arrest[quantity] = list(crossing["phi_j_ci"]) if crossing else None
        size = {
            "n": n,
            "flows": states["completed"],
            "jammed": states["jammed"],
            "wyart_cates": line,
            "divergence": divergence,
            "arrest": arrest,
        }
        if dim != 2:  # the 2D records predate the key: a system without it is a monolayer
            size["dim"] = dim
        sizes.append(size)
    return {"sizes": sizes}


def draw_phase_diagram(data: dict):
    """(φ, σ/σ0) plane from :func:`phase_diagram_data`: flowing and jammed state points per N, the
    Wyart–Cates jamming line, the branch divergences and the arrest-probability intervals."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sizes = data["sizes"]
    fig, axes = plt.subplots(1, len(sizes), figsize=(4.2 * len(sizes), 3.8), squeeze=False, sharey=True)
    for ax, size in zip(axes[0], sizes):
        for key, marker, color, label in (
            ("flows", "o", "tab:blue", "flows"),
            ("jammed", "x", "tab:red", "shear-jammed"),
        ):
            if size[key]:
                p, s = np.array(size[key]).T
                ax.scatter(p, s, marker=marker, color=color, s=22, label=label, alpha=0.6)
        line = size["wyart_cates"]
        if line:
            ax.plot(
                line["phi_m"],
                line["stress"],
                "k-",
                label=r"$\phi_m(f)$, Wyart–Cates"
                + (r" ($\log A$ linear in $f$)" if line["prefactor_in_f"] else r" ($\beta$ fitted)"),
            )
        for quantity, style in zip(BRANCHES, (":", "--")):
            symbol = r"$\phi_J^0$" if quantity == "phi_J^0" else r"$\phi_J^\mu$"
            if size["divergence"][quantity] is not None:
                ax.axvline(
                    size["divergence"][quantity], color="0.4", ls=style, label=f"{symbol} (divergence)"
                )
            if size["arrest"][quantity] is not None:
                ax.axvspan(
                    *size["arrest"][quantity],
                    color="tab:red" if quantity == "phi_J^mu" else "tab:purple",
                    alpha=0.2,
                    label=f"{symbol}: arrest probability 1/2 (68 %)",
                )
        ax.set_xscale("linear")
        ax.set_yscale("log")
        ax.set_xlabel(r"$\phi$")
        ax.set_title(f"N = {size_label(size['n'], size.get('dim', 2))}")
    axes[0][0].set_ylabel(r"$\sigma/\sigma_0$")
    handles, labels = axes[0][0].get_legend_handles_labels()
    # one panel is too narrow for four legend columns: two, and room below for their rows
    columns = 4 if len(sizes) > 1 else 2
    fig.legend(handles, labels, loc="lower center", ncol=columns, fontsize=8, frameon=False)
    fig.tight_layout(rect=(0, 0.08 if len(sizes) > 1 else 0.2, 1, 1))
    return fig


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("indexes", nargs="+", help="run indexes (python -m rheograph.runs.sweep_index)")
    ap.add_argument("--out", help="markdown file whose <!-- SECTION:start/end --> section gets the table")
    ap.add_argument(
        "--section",
        default="jamming_fits",
        help="name of the marked section (default jamming_fits; the 3D set's is jamming_fits_3d)",
    )
    ap.add_argument(
        "--record",
        help="JSON record of the section and of the phase diagram's numbers (docs/results/bench/"
        "jamming_fits.json: what python -m bench.render draws both from)",
    )
    ap.add_argument("--figure", help="phase-diagram PNG")
    ap.add_argument("--seed", type=int, default=0, help="bootstrap seed")
    ap.add_argument(
        "--window", type=float, default=0.05, help="divergence fits: area fractions within this of the top"
    )
    ap.add_argument(
        "--single-run-error",
        action="store_true",
        help="bootstrap: draw the eta_r of a state point with one trajectory from its block standard "
        "error (default: held fixed, so a set of one seed per state point has no interval)",
    )
    add_mixed_rules_argument(ap)
    args = ap.parse_args(argv)
    if args.record and not args.out:
        raise InputError("--record: give the page too (--out), whose section the record draws")
    if not 0.0 < args.window < 0.5:
        raise InputError(f"--window {args.window}: allowed 0 < window < 0.5")
    everything = read_runs(args.indexes)
    runs, left_out = select_rules(everything, args.mixed_rules)
    for r in left_out:
        print(
            f"left out (LF_DEM's rule where elastic unloading ran too): N = {r['n']} phi {r['phi']:g} "
            f"sigma/sigma0 {r['stress']:g} seed {r['seed']}",
            file=sys.stderr,
        )
    rows = jamming_table(runs, args.seed, args.window, single_run_error=args.single_run_error)
    if not rows:
        raise InputError(f"{args.indexes}: no branch with three area fractions of flowing runs to fit")
    command = "python -m rheograph.analysis.jamming_points " + " ".join(
        argv if argv is not None else sys.argv[1:]
    )
    blocks = section_blocks(rows, command, rule_comparison(everything))
    text = render_blocks(blocks)
    print(text)
    if args.out:
        replace_section(Path(args.out), args.section, text)
    figure = phase_diagram_data(runs, rows)
    if args.record:
        record = {
            "section": args.section,
            "page": docs_page(args.out),
            "command": command,
            "blocks": blocks,
            "figure": figure,
        }
        write_record(Path(args.record), record)
    if args.figure:
        save_png(draw_phase_diagram(figure), Path(args.figure), DPI, drawn_from=figure)


if __name__ == "__main__":
    with one_line_errors("python -m rheograph.analysis.jamming_points"):
        main()
