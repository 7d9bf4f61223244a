"""Surrogate speed: training and inference throughput (graphs/s) on N = 2000 particle graphs, batch 8 and
32, peak memory, 2 CPU threads; compared in the same run with a plain PyG DeeperGCN (DeepGCNLayer +
GENConv as in PyG's ogbn-proteins example) of the same width and depth.  Also: graph-building time per
snapshot, and the surrogate speed-up over the simulator (one prediction vs producing one decorrelated
snapshot).

    OMP_WAIT_POLICY=PASSIVE python bench/train_speed.py [--graphs 64] [--sim-strain-per-snapshot 0.5]

Graphs are relaxed random configurations at phi = 0.76 (same particle and edge counts as sheared
snapshots: the throughput depends on sizes, not on the physics).  Results replace the marked section of
docs/benchmarks.md.
"""

from __future__ import annotations

import argparse
import os
import resource
import time
from pathlib import Path

os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402
from torch import nn  # noqa: E402
from torch_geometric.data import Data  # noqa: E402
from torch_geometric.loader import DataLoader  # noqa: E402
from torch_geometric.nn import DeepGCNLayer, GENConv, global_mean_pool  # noqa: E402

from rheograph.graphs.features import node_features, snapshot_edges  # noqa: E402
from rheograph.learn.model import ResGCN, count_parameters  # noqa: E402
from rheograph.sim.init_config import random_configuration  # noqa: E402
from rheograph.sim.params import SimParams  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


class PlainDeeperGCN(nn.Module):
    """The reference: PyG's ogbn-proteins DeeperGCN pattern, unchanged apart from graph pooling."""

    def __init__(self, node_in, edge_in, hidden, num_layers):
        super().__init__()
        self.node_encoder = nn.Linear(node_in, hidden)
        self.edge_encoder = nn.Linear(edge_in, hidden)
        self.layers = nn.ModuleList()
        for _ in range(num_layers):
            conv = GENConv(hidden, hidden, aggr="softmax", t=1.0, learn_t=True, num_layers=2, norm="layer")
            norm = nn.LayerNorm(hidden, elementwise_affine=True)
            self.layers.append(DeepGCNLayer(conv, norm, nn.ReLU(inplace=True), block="res+", dropout=0.1))
        self.lin = nn.Linear(hidden, 3)

    def forward(self, x, edge_index, edge_attr, batch):
        x = self.node_encoder(x)
        e = self.edge_encoder(edge_attr)
        x = self.layers[0].conv(x, edge_index, e)
        for layer in self.layers[1:]:
            x = layer(x, edge_index, e)
        x = self.layers[0].act(self.layers[0].norm(x))
        return self.lin(global_mean_pool(x, batch))


def build_graphs(n_graphs, n_particles, cutoff):
    params = SimParams(n_particles=n_particles, phi=0.76)
    box = params.box_length()
    graphs, times = [], []
    configs = [random_configuration(*params.species_counts(), 1.4, box, seed) for seed in range(4)]
    for k in range(n_graphs):
        pos, radii = configs[k % len(configs)]
        t0 = time.perf_counter()
        edge_index, feats, _ = snapshot_edges(pos, radii, box, box, 0.37 * k, cutoff, params.to_dict())
        edge_attr = np.stack([feats[f] for f in ("gap", "distance", "dx", "dy", "sin", "cos")], axis=1)
        times.append(time.perf_counter() - t0)
        graphs.append(
            Data(
                x=torch.from_numpy(node_features(radii, 1.4)),
                edge_index=torch.from_numpy(edge_index),
                edge_attr=torch.from_numpy(edge_attr).float(),
                y=torch.randn(1, 3),
            )
        )
    return graphs, float(np.median(times[1:]))


def throughput(model, graphs, batch_size, repeats):
    loader = DataLoader(graphs, batch_size=batch_size, shuffle=False)
    opt = torch.optim.Adam(model.parameters(), lr=1e-3)
    model.train()
    for batch in loader:  # warm-up
        loss = nn.functional.smooth_l1_loss(
            model(batch.x, batch.edge_index, batch.edge_attr, batch.batch), batch.y
        )
        opt.zero_grad()
        loss.backward()
        opt.step()
        break
    train_rates, infer_rates = [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        for batch in loader:
            out = model(batch.x, batch.edge_index, batch.edge_attr, batch.batch)
            loss = nn.functional.smooth_l1_loss(out, batch.y)
            opt.zero_grad()
            loss.backward()
            opt.step()
        train_rates.append(len(graphs) / (time.perf_counter() - t0))
        model.eval()
        t0 = time.perf_counter()
        with torch.no_grad():
            for batch in loader:
                model(batch.x, batch.edge_index, batch.edge_attr, batch.batch)
        infer_rates.append(len(graphs) / (time.perf_counter() - t0))
        model.train()
    return float(np.median(train_rates)), float(np.median(infer_rates))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--graphs", type=int, default=64)
    ap.add_argument("--n-particles", type=int, default=2000)
    ap.add_argument("--hidden", type=int, default=64)
    ap.add_argument("--layers", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument(
        "--sim-seconds-per-strain",
        type=float,
        default=None,
        help="simulator wall s/strain at this N (default: measured value from docs)",
    )
    ap.add_argument(
        "--sim-strain-per-snapshot", type=float, default=0.5, help="strain between decorrelated snapshots"
    )
    ap.add_argument("--no-write", action="store_true")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    graphs, build_time = build_graphs(args.graphs, args.n_particles, 0.5)
    edges = np.mean([g.edge_index.shape[1] for g in graphs])
    rows = []
    for name, model in (
        ("rheograph ResGCN (batch norm)", ResGCN(2, 6, args.hidden, args.layers)),
        ("plain PyG DeeperGCN (layer norm)", PlainDeeperGCN(2, 6, args.hidden, args.layers)),
    ):
        for bs in (8, 32):
            rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            train, infer = throughput(model, graphs, bs, args.repeats)
            rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
            rows.append((name, count_parameters(model), bs, train, infer, rss1 / 1024, (rss1 - rss0) / 1024))
            print(rows[-1], flush=True)
    model = ResGCN(2, 6, args.hidden, args.layers).eval()
    g = graphs[0]
    batch = torch.zeros(g.num_nodes, dtype=torch.long)
    with torch.no_grad():
        times = []
        for _ in range(20):
            t0 = time.perf_counter()
            model(g.x, g.edge_index, g.edge_attr, batch)
            times.append(time.perf_counter() - t0)
    predict_one = float(np.median(times)) + build_time
    lines = (
        [
            f"{args.graphs} graphs of N = {args.n_particles} particles (mean {edges:.0f} directed edges, "
            "gap cut-off 0.5a), "
            f"{args.threads} torch threads, OMP_WAIT_POLICY=PASSIVE, medians of {args.repeats} passes.",
            "",
            "| model | parameters | batch | train graphs/s | inference graphs/s | peak RSS MiB "
            "| RSS growth MiB |",
            "|---|---|---|---|---|---|---|",
        ]
        + [f"| {r[0]} | {r[1]} | {r[2]} | {r[3]:.1f} | {r[4]:.1f} | {r[5]:.0f} | {r[6]:.0f} |" for r in rows]
        + [
            "",
            "Graph building (numba cell list with Lees–Edwards images + features): "
            f"{1e3 * build_time:.2f} ms per "
            f"N = {args.n_particles} snapshot (median).",
            f"Predicting one snapshot (graph build + forward pass, batch 1): {1e3 * predict_one:.1f} ms.",
        ]
    )
    if args.sim_seconds_per_strain:
        produce = args.sim_seconds_per_strain * args.sim_strain_per_snapshot
        lines.append(
            f"Simulator: {args.sim_seconds_per_strain:.0f} s/strain at this N → one decorrelated snapshot "
            f"every {args.sim_strain_per_snapshot} strain costs {produce:.0f} s: speed-up "
            f"{produce / predict_one:.0f}× for the surrogate."
        )
    lines += [
        "",
        "Command: `python bench/train_speed.py "
        + " ".join(
            f"--{k.replace('_', '-')} {v}" for k, v in vars(args).items() if k != "no_write" and v is not None
        )
        + "`",
    ]
    print("\n".join(lines))
    if not args.no_write:
        from simulate_speed import write_section

        write_section(ROOT / "docs" / "benchmarks.md", "train_speed", "\n".join(lines))


if __name__ == "__main__":
    main()
