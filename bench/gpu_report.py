"""The markdown tables of a ``bench/gpu.py`` JSON file (for docs/howto/gpu.md).

python -m bench.gpu_report gpu.json            # markdown on stdout
python -m bench.gpu_report gpu.json --section gpu_solvers_cpu --page howto/gpu.md   # part f, published
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
        "| snapshots | model (fold models) | device | graph processes | physics solved by | "
        "physics inputs s | forward s | predict_snapshots s |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for device, rows in part.items():
        for r in rows:
            lines.append(
                f"| {r['snapshots']} × {r['case']} | {r['model']} ({r['fold_models']}) | {device} | "
                f"{r['workers']} | {r.get('physics_solver', 'sparse, CPU')} | {_num(r['physics_seconds'])} | "
                f"{_num(r['forward_seconds'], 3)} | "
                f"{_num(r['predict_snapshots_seconds'])} |"
            )
    return lines


CROSSOVER_HEADER = [
    "dim",
    "N",
    "rows of R_FU",
    "nonzeros (upper)",
    "sparse, one core, ms",
    "dense batched, ms per problem (batch, device)",
    "sparse / dense",
]


def crossover_rows(rows: list[dict]) -> list[list[str]]:
    return [
        [
            f"{r['dim']}D",
            str(r["n_particles"]),
            str(r["n_dof"]),
            str(r["nonzeros"]),
            _num(r["sparse_ms"]),
            f"{_num(r['dense_ms_per_problem'])} ({r['dense_batch']}, {r['device']})",
            _num(r["sparse_ms"] / r["dense_ms_per_problem"]),
        ]
        for r in rows
    ]


def crossover_table(rows: list[dict]) -> list[str]:
    lines = ["| " + " | ".join(CROSSOVER_HEADER) + " |", "|" + "---|" * len(CROSSOVER_HEADER)]
    return lines + ["| " + " | ".join(cells) + " |" for cells in crossover_rows(rows)]


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
    captions = {
        "d": "Prediction with the shipped models (five fold models each; physics inputs: graphs with one "
        "resistance solve per snapshot, solved as the column says):",
        "f": "One resistance problem solved (factorisation and two right-hand sides): the sparse Cholesky on "
        "one CPU core against the dense batched Cholesky (a batch's time over its problems):",
    }
    for part, draw in (("d", prediction_table), ("f", crossover_table)):
        if part in parts:
            out += [captions[part], ""] + draw(parts[part]) + [""]
    return "\n".join(out)


def publish_crossover(data: dict, results: str, section: str, page: str | None) -> None:
    """Part f of ``data`` (read from ``results``) as the docs section ``section``: its table and what
    machine measured it."""
    from bench.publishing import command_line, publish, table, text

    meta = data["meta"]
    command = command_line("gpu_report")
    blocks = [
        text(
            f"Drawn by `{command}` from `python -m bench.gpu --device {meta['device']} --parts f "
            f"--repeats {meta['repeats']} --out {results}`, measured on "
            f"{meta['device_name'] or meta['device']} ({meta['cpu_count']} CPU cores, torch {meta['torch']}; "
            f"the sparse solver on one core, the dense one on {meta.get('torch_threads', 'all')} torch "
            "threads; "
            f"medians of {meta['repeats']} after a warm-up):",
            "",
        ),
        table(CROSSOVER_HEADER, crossover_rows(data["parts"]["f"])),
    ]
    publish(section, blocks, True, page=page, record={"results": results}, command=command)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("results", help="the JSON file bench/gpu.py wrote")
    ap.add_argument("--section", help="publish part f's table as this docs section instead of printing")
    ap.add_argument("--page", default=None, help="the section's page under docs/ (first publication)")
    args = ap.parse_args(argv)
    data = json.loads(Path(args.results).read_text())
    if args.section:
        publish_crossover(data, args.results, args.section, args.page)
    else:
        print(render(data))


if __name__ == "__main__":
    main()
