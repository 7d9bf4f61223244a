"""ResGCN / DeepGCN graph regressor (Li et al. 2019/2020) built from PyG's DeepGCNLayer + GENConv."""

from __future__ import annotations

import torch
from torch import nn
from torch_geometric.nn import DeepGCNLayer, GENConv, global_add_pool, global_max_pool, global_mean_pool

from rheograph.errors import InputError


def _area_pool(x, batch, area):
    """Sum over the particles of a graph divided by its box area: an intensive, stress-like readout
    (the stress is a sum over pairs per area), comparable across system sizes."""
    return global_add_pool(x, batch) / area.view(-1, 1)


POOLS = {"mean": global_mean_pool, "add": global_add_pool, "max": global_max_pool, "area": _area_pool}
BLOCKS = ("res", "res+", "dense", "plain")
AGGRS = ("softmax", "mean", "add", "max", "powermean")
NORMS = {"batch": nn.BatchNorm1d, "layer": nn.LayerNorm}  # per-feature over the batch | per node


class ResGCN(nn.Module):
    """Node/edge encoders -> ``num_layers`` DeepGCN layers (GENConv, ``norm`` normalisation — batch, the
    seed paper's, or layer, DeeperGCN's — ReLU, dropout, residual)
    -> graph pooling -> head (``head_layers`` linear layers) with ``out_channels`` outputs.

    Graph-level inputs u (G, global_in) — the imposed log stress, phi — are encoded and added to every node
    embedding before message passing, and concatenated to the pooled embedding before the head.
    Edge features are standardised inside the model with buffers fitted on the training folds
    (``set_edge_scaling``), so a saved model maps raw features to predictions.

    With ``edge_readout`` the head also sees the sum over pairs of each standardised edge feature per
    box area (batch normalised): the targets are such sums (stresses over pairs per area, Z_mu a count).

    Shapes: x (N, node_in), edge_attr (E, edge_in), batch (N,), u (G, global_in), area (G,)
    -> (G, out_channels).
    """

    def __init__(
        self,
        node_in: int,
        edge_in: int,
        hidden: int = 64,
        num_layers: int = 2,
        aggr: str = "softmax",
        block: str = "res+",
        dropout: float = 0.1,
        pool: str = "mean",
        out_channels: int = 3,
        mlp_layers: int = 2,
        global_in: int = 0,
        head_layers: int = 1,
        edge_readout: bool = False,
        norm: str = "batch",
    ):
        super().__init__()
        if block not in BLOCKS:
            raise InputError(f"model.block={block!r} is invalid: allowed {BLOCKS}")
        if pool not in POOLS:
            raise InputError(f"model.pool={pool!r} is invalid: allowed {sorted(POOLS)}")
        if aggr not in AGGRS:
            raise InputError(f"model.aggr={aggr!r} is invalid: allowed {AGGRS}")
        if norm not in NORMS:
            raise InputError(f"model.norm={norm!r} is invalid: allowed {tuple(NORMS)}")
        if num_layers < 1 or hidden < 1 or head_layers < 1:
            raise InputError("model.num_layers, model.hidden and model.head_layers must be >= 1")
        self.block, self.pool_name, self.global_in = block, pool, global_in
        # edge readout: the sums over pairs of every (standardised) edge feature per box area, batch
        # normalised, next to the pooled node embedding: the stresses and Z_mu are such sums, which the
        # head then reads directly instead of through message passing
        self.edge_readout = nn.BatchNorm1d(edge_in) if edge_readout else None
        self.node_encoder = nn.Linear(node_in, hidden)
        self.edge_encoder = nn.Linear(edge_in, hidden)
        self.register_buffer("edge_mean", torch.zeros(edge_in))
        self.register_buffer("edge_std", torch.ones(edge_in))
        self.global_encoder = nn.Linear(global_in, hidden) if global_in else None
        self.layers = nn.ModuleList()
        for _ in range(num_layers):
            conv = GENConv(
                hidden,
                hidden,
                aggr=aggr,
                t=1.0,
                learn_t=aggr == "softmax",
                num_layers=mlp_layers,
                norm=norm,
                edge_dim=hidden,
            )
            self.layers.append(
                DeepGCNLayer(
                    conv,
                    NORMS[norm](hidden),
                    nn.ReLU(inplace=True),
                    block=block,
                    dropout=dropout,
                    ckpt_grad=False,
                )
            )
        self.dropout = dropout
        self.pool = POOLS[pool]
        head, width = [], hidden + global_in + (edge_in if edge_readout else 0)
        for _ in range(head_layers - 1):
            head += [nn.Linear(width, hidden), nn.ReLU()]
            width = hidden
        self.head = nn.Sequential(*head, nn.Linear(width, out_channels))

    def set_edge_scaling(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        self.edge_mean.copy_(mean)
        self.edge_std.copy_(std)

    def forward(self, x, edge_index, edge_attr, batch, u=None, area=None):
        x = self.node_encoder(x)
        scaled = (edge_attr - self.edge_mean) / self.edge_std
        e = self.edge_encoder(scaled)
        if self.global_encoder is not None:
            x = x + self.global_encoder(u)[batch]
        if self.block == "res+":
            # pre-activation residual: the first conv has no norm/act before it; a final norm+act after
            x = self.layers[0].conv(x, edge_index, e)
            for layer in self.layers[1:]:
                x = layer(x, edge_index, e)
            x = self.layers[0].act(self.layers[0].norm(x))
            x = nn.functional.dropout(x, p=self.dropout, training=self.training)
        else:
            for layer in self.layers:
                x = layer(x, edge_index, e)
        pooled = self.pool(x, batch, area) if self.pool_name == "area" else self.pool(x, batch)
        if self.edge_readout is not None:
            graphs = int(batch.max()) + 1 if batch.numel() else 0
            sums = global_add_pool(scaled, batch[edge_index[0]], size=graphs) / area.view(-1, 1)
            pooled = torch.cat([pooled, self.edge_readout(sums)], dim=1)
        if self.global_in:
            pooled = torch.cat([pooled, u], dim=1)
        return self.head(pooled)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
