"""The markdown tables of a ``bench/gpu.py`` JSON file (for docs/howto/gpu.md).

python -m bench.gpu_report gpu.json            # markdown on stdout
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def _num(value, digits: int = 2) -> str:
    return "–" if value is None else f"{value:.{digits}f}"


def _ms(value) -> str:
    return "–" if value is None else f"{value * 1e3:.0f}"


def epoch_table(part: dict) -> list[str]:
    devices = list(part)
    lines = [
        "| batch | batches built by | " + " | ".join(f"ms/epoch, {d}" for d in devices) + " |",
        "|---|---|" + "---|" * len(devices),
    ]
    keys = [(r["batch_size"], r["loader"]) for r in part[devices[0]]]
    for batch_size, loader in keys:
        cells = []
        for d in devices:
            row = next((r for r in part[d] if (r["batch_size"], r["loader"]) == (batch_size, loader)), None)
            cells.append(_ms(row and row["seconds_per_epoch"]))
        lines.append(f"| {batch_size} | {loader} | " + " | ".join(cells) + " |")
    return lines


def fold_table(part: dict) -> list[str]:
    lines = [
        "| device | settings (batch, rate) | fold | wall s | R² log η_r | R² log Π | R² Z_μ |",
        "|---|---|---|---|---|---|---|",
    ]
    for device, rows in part.items():
        for r in rows:
            lines.append(
                f"| {device} | {r['settings']} ({r['batch_size']}, {r['lr']:g}) | {r['fold']} | "
                f"{_num(r['wall_seconds'], 1)} | {_num(r['r2_log_eta'], 4)} | "
                f"{_num(r['r2_log_pressure'], 4)} | {_num(r['r2_z_mu'], 4)} |"
            )
    return lines


def end_to_end_lines(part: dict) -> list[str]:
    lines = []
    for device, r in part.items():
        if "error" in r:
            lines.append(f"- {device}: failed after {_num(r['wall_seconds'], 1)} s: {' '.join(r['error'])}")
            continue
        lines.append(
            f"- {device}: `{r['command'].split(' ', 1)[1].split(' data.cache_dir')[0]}`, {r['folds']} folds, "
            f"{_num(r['wall_seconds'], 1)} s wall; mean held-out R² {_num(r['r2_log_eta'], 4)} / "
            f"{_num(r['r2_log_pressure'], 4)} / {_num(r['r2_z_mu'], 4)}"
        )
    return lines


def prediction_table(part: dict) -> list[str]:
    lines = [
        "| snapshots | model (fold models) | device | graph processes | physics inputs s | forward s | "
        "predict_snapshots s |",
        "|---|---|---|---|---|---|---|",
    ]
    for device, rows in part.items():
        for r in rows:
            lines.append(
                f"| {r['snapshots']} × {r['case']} | {r['model']} ({r['fold_models']}) | {device} | "
                f"{r['workers']} | {_num(r['physics_seconds'])} | {_num(r['forward_seconds'], 3)} | "
                f"{_num(r['predict_snapshots_seconds'])} |"
            )
    return lines


def render(data: dict) -> str:
    meta, parts = data["meta"], data["parts"]
    out = [
        f"Measured with `bench/gpu.py` on {meta['device_name'] or meta['device']} ({meta['cpu_count']} CPU "
        f"cores; torch {meta['torch']}, Lightning {meta['lightning']}, PyG {meta['torch_geometric']}; "
        f"scikit-sparse {'present' if meta['scikit_sparse'] else 'absent: qdldl'}). The CPU columns use "
        f"{meta['cpu_side_threads']} torch threads (and 2 graph processes) of the same machine, as a 2-core "
        f"machine would; times are medians of {meta['repeats']} after a warm-up.",
        "",
    ]
    if "cache" in parts:
        c = parts["cache"]
        out += [
            f"Graph cache of the demo set ({c['graphs']} graphs, one process): {_num(c['seconds'], 1)} s.",
            "",
        ]
    if "a" in parts:
        graphs = next(iter(parts["a"].values()))[0]["train_graphs"]
        out += [f"Training epoch of fold 0 ({graphs} graphs of N = 400, width 32; validation excluded):", ""]
        out += epoch_table(parts["a"]) + [""]
    if "b" in parts:
        epochs = next(iter(parts["b"].values()))[0]["epochs"]
        out += [f"Each fold, {epochs} epochs (wall: training, test predictions, descriptor baselines):", ""]
        out += fold_table(parts["b"]) + [""]
    if "c" in parts:
        out += ["All folds end to end through `train.py` (graph cache built):", ""]
        out += end_to_end_lines(parts["c"]) + [""]
    if "d" in parts:
        out += [
            "Prediction with the shipped models (five fold models each; physics inputs: graphs with one "
            "resistance solve per snapshot, on the CPU):",
            "",
        ]
        out += prediction_table(parts["d"]) + [""]
    return "\n".join(out)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", help="the JSON file bench/gpu.py wrote")
    args = ap.parse_args(argv)
    print(render(json.loads(Path(args.results).read_text())))


if __name__ == "__main__":
    main()
