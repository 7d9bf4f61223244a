"""ResGCN / DeepGCN graph regressor (Li et al. 2019/2020) built from PyG's DeepGCNLayer + GENConv."""

from __future__ import annotations

import torch
from torch import nn
from torch_geometric.nn import DeepGCNLayer, GENConv, global_add_pool, global_max_pool, global_mean_pool
from torch_geometric.utils import to_dense_batch

from rheograph.errors import InputError


def _area_pool(x, batch, area):
    """Sum over the particles of a graph divided by its box area: an intensive, stress-like readout
    (the stress is a sum over pairs per area), comparable across system sizes."""
    return global_add_pool(x, batch) / area.view(-1, 1)


POOLS = {"mean": global_mean_pool, "add": global_add_pool, "max": global_max_pool, "area": _area_pool}
BLOCKS = ("res", "res+", "plain")  # DeepGCN's "dense" widens every layer: not supported
AGGRS = ("softmax", "mean", "add", "max", "powermean")
NORMS = {"batch": nn.BatchNorm1d, "layer": nn.LayerNorm}  # per-feature over the batch | per node
GLOBAL_MIXING = ("none", "virtual_node", "attention")


class VirtualNode(nn.Module):
    """Global context: the mean node embedding of each graph through a two-layer MLP, broadcast back to
    its nodes.  x (N, hidden), batch (N,) -> (N, hidden)."""

    def __init__(self, hidden: int):
        super().__init__()
        self.mlp = nn.Sequential(nn.Linear(hidden, hidden), nn.ReLU(), nn.Linear(hidden, hidden))

    def forward(self, x, batch):
        return self.mlp(global_mean_pool(x, batch))[batch]


class GraphAttention(nn.Module):
    """Multi-head self-attention among all particles of a graph (pre-layer-norm; padded per graph and
    masked): every particle reads every other, whatever the graph distance.
    x (N, hidden), batch (N,) -> (N, hidden)."""

    HEADS = 4

    def __init__(self, hidden: int):
        super().__init__()
        self.norm = nn.LayerNorm(hidden)
        self.attn = nn.MultiheadAttention(hidden, self.HEADS, batch_first=True)

    def forward(self, x, batch):
        dense, mask = to_dense_batch(self.norm(x), batch)
        out, _ = self.attn(dense, dense, dense, key_padding_mask=~mask, need_weights=False)
        return out[mask]


class ResGCN(nn.Module):
    """Node/edge encoders -> ``num_layers`` DeepGCN layers (GENConv, ``norm`` normalisation — batch, the
    seed paper's, or layer, DeeperGCN's — ReLU, dropout, residual)
    -> graph pooling -> head (``head_layers`` linear layers) with ``out_channels`` outputs.

    With ``global_mixing`` every layer's output also receives a non-local update (added residually): a
    virtual node (the graph's mean embedding through an MLP) or self-attention among all particles.  Why:
    the shear rate at imposed stress comes from a global solve of the lubrication network, which two
    rounds of local messages can only approximate.  Measured at N = 400: no gain on held-out trajectories
    (the score is limited by the number of training trajectories; docs/validation/surrogate_accuracy.md),
    so off by default.

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
        global_mixing: str = "none",
    ):
        super().__init__()
        if block not in BLOCKS:
            raise InputError(f"model.net.block={block!r} is invalid: allowed {BLOCKS}")
        if pool not in POOLS:
            raise InputError(f"model.net.pool={pool!r} is invalid: allowed {sorted(POOLS)}")
        if aggr not in AGGRS:
            raise InputError(f"model.net.aggr={aggr!r} is invalid: allowed {AGGRS}")
        if norm not in NORMS:
            raise InputError(f"model.net.norm={norm!r} is invalid: allowed {tuple(NORMS)}")
        if global_mixing not in GLOBAL_MIXING:
            raise InputError(f"model.net.global_mixing={global_mixing!r} is invalid: allowed {GLOBAL_MIXING}")
        if num_layers < 1 or hidden < 1 or head_layers < 1:
            raise InputError("model.net.num_layers, model.net.hidden and model.net.head_layers must be >= 1")
        if not 0.0 <= dropout < 1.0:
            raise InputError(f"model.net.dropout={dropout} is invalid: allowed 0 <= dropout < 1")
        if global_mixing == "attention" and hidden % GraphAttention.HEADS:
            raise InputError(
                f"model.net.hidden={hidden} is invalid with model.net.global_mixing=attention: a multiple of "
                f"{GraphAttention.HEADS} (the attention heads)"
            )
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
        mixer = {"none": None, "virtual_node": VirtualNode, "attention": GraphAttention}[global_mixing]
        self.mixers = nn.ModuleList(mixer(hidden) for _ in range(num_layers)) if mixer else None
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
        for k, layer in enumerate(self.layers):
            # res+ is a pre-activation residual: the first conv has no norm/act before it
            x = layer.conv(x, edge_index, e) if k == 0 and self.block == "res+" else layer(x, edge_index, e)
            if self.mixers is not None:
                x = x + self.mixers[k](x, batch)
        if self.block == "res+":  # final norm + act of the pre-activation stack
            x = self.layers[0].act(self.layers[0].norm(x))
            x = nn.functional.dropout(x, p=self.dropout, training=self.training)
        pooled = self.pool(x, batch, area) if self.pool_name == "area" else self.pool(x, batch)
        if self.edge_readout is not None:
            graphs = int(batch.max()) + 1 if batch.numel() else 0
            sums = global_add_pool(scaled, batch[edge_index[0]], size=graphs) / area.view(-1, 1)
            norm = self.edge_readout
            if self.training and graphs == 1:
                # a training batch of one graph (the last of an epoch, a DDP shard's) has no batch
                # statistics: normalised with the running ones, as in evaluation
                readout = nn.functional.batch_norm(
                    sums, norm.running_mean, norm.running_var, norm.weight, norm.bias, False, 0.0, norm.eps
                )
            else:
                readout = norm(sums)
            pooled = torch.cat([pooled, readout], dim=1)
        if self.global_in:
            pooled = torch.cat([pooled, u], dim=1)
        return self.head(pooled)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
