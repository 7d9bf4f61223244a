"""The Optuna studies behind the surrogate's defaults, as one section of docs/validation/surrogate_accuracy.md
(``tune_report``): per study (one per input variant, ``conf/hparams_search/held_out_phi076.yaml``) the
trial counts by state, the best objective, the median trial time, the best values, the five best
trials and the parameter importances (fANOVA over the completed trials).

    python -m bench.tune_report                         # every study in docs/results/tune/optuna.db
    python -m bench.tune_report --studies physics_phi076 paper_phi076

The objective is the best-epoch unweighted validation loss on held-out trajectories (fold 0 of the
phi = 0.76, N = 400 set, 30 epochs); lower is better.  It ranks configurations; their R² on all five
folds at the full budget is measured by bench/surrogate_study.py (variants ``<inputs>_tuned``).
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

import numpy as np
import optuna

from bench.publishing import publish

ROOT = Path(__file__).resolve().parents[1]
STORAGE = f"sqlite:///{ROOT / 'docs' / 'results' / 'tune' / 'optuna.db'}"


def short(name: str) -> str:
    return name.removeprefix("model.").removeprefix("data.").removeprefix("graph.")


def fmt(value) -> str:
    if isinstance(value, float):
        return f"{value:.3g}"
    return str(value)


def study_section(study: optuna.Study) -> str:
    trials = study.get_trials(deepcopy=False)
    states = {s.name.lower(): sum(t.state == s for t in trials) for s in optuna.trial.TrialState}
    complete = [t for t in trials if t.state == optuna.trial.TrialState.COMPLETE]
    if not complete:
        return f"**{study.study_name}**: no completed trial yet ({states})."
    minutes = [t.duration.total_seconds() / 60 for t in trials if t.duration is not None]
    best = study.best_trial
    counts = ", ".join(f"{n} {s}" for s, n in states.items() if n)
    lines = [
        f"**{study.study_name}**: {len(trials)} trials ({counts}); median trial {np.median(minutes):.1f} "
        f"min on one core; best objective {best.value:.4g} (trial {best.number}); median of the "
        f"completed {np.median([t.value for t in complete]):.4g}.",
        "",
    ]
    names = list(best.params)
    lines += [
        "| rank | trial | objective | " + " | ".join(short(n) for n in names) + " |",
        "|---" * (3 + len(names)) + "|",
    ]
    for rank, t in enumerate(sorted(complete, key=lambda t: t.value)[:5], start=1):
        values = " | ".join(fmt(t.params.get(n, "–")) for n in names)
        lines.append(f"| {rank} | {t.number} | {t.value:.4g} | {values} |")
    if len(complete) >= 10:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            importance = optuna.importance.get_param_importances(
                study, evaluator=optuna.importance.FanovaImportanceEvaluator(seed=0)
            )
        top = ", ".join(f"{short(k)} {v:.2f}" for k, v in list(importance.items())[:6])
        lines += ["", f"Importance (fANOVA, share of the objective's variance): {top}."]
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--storage", default=STORAGE)
    ap.add_argument("--studies", nargs="*", help="study names (default: every study in the storage)")
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args(argv)
    names = args.studies or sorted(s.study_name for s in optuna.get_all_study_summaries(args.storage))
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sections = [study_section(optuna.load_study(study_name=n, storage=args.storage)) for n in names]
    text = "\n\n".join(
        [
            "Objective: best-epoch `val/target_loss` (unweighted sum of the per-target Huber losses of "
            "the transformed targets in units of their training spread; a study stored with the "
            "objective on the standardised learned targets gives the same number unless Π is learned "
            "per σ or a target as a correction) on the validation trajectories of fold 0, φ = 0.76, "
            "N = 400, 30 epochs (cosine schedule); TPE sampler, median pruner per epoch (after 5 trials "
            "and 10 "
            "epochs).  Categorical values shown as sampled.",
            *sections,
            "Command: `python tune.py hparams_search=held_out_phi076 inputs=<physics|paper|"
            "physics_positions>` and `python tune.py hparams_search=held_out_phi076_solve` (resumable; "
            "a study name is refused for a search space other than its trials'), then "
            "`python -m bench.tune_report`; the best trial of each study: "
            "`conf/experiment/<inputs>_phi076_best.yaml`.",
        ]
    )
    publish("tune_report", text, write=not args.no_write)


if __name__ == "__main__":
    main()
