"""ResGCN / DeepGCN graph regressor (Li et al. 2019/2020) built from PyG's DeepGCNLayer + GENConv."""

from __future__ import annotations

from torch import nn
from torch_geometric.nn import DeepGCNLayer, GENConv, global_add_pool, global_max_pool, global_mean_pool

POOLS = {"mean": global_mean_pool, "add": global_add_pool, "max": global_max_pool}
BLOCKS = ("res", "res+", "dense", "plain")


class ResGCN(nn.Module):
    """Node/edge encoders -> ``num_layers`` DeepGCN layers (GENConv, batch norm, ReLU, dropout, residual)
    -> graph pooling -> linear head with ``out_channels`` outputs.

    Shapes: x (N, node_in), edge_attr (E, edge_in), batch (N,) -> (G, out_channels).
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
    ):
        super().__init__()
        if block not in BLOCKS:
            raise ValueError(f"model.block={block!r} is invalid: allowed {BLOCKS}")
        if pool not in POOLS:
            raise ValueError(f"model.pool={pool!r} is invalid: allowed {sorted(POOLS)}")
        if num_layers < 1 or hidden < 1:
            raise ValueError("model.num_layers and model.hidden must be >= 1")
        self.block = block
        self.node_encoder = nn.Linear(node_in, hidden)
        self.edge_encoder = nn.Linear(edge_in, hidden)
        self.layers = nn.ModuleList()
        for _ in range(num_layers):
            conv = GENConv(
                hidden,
                hidden,
                aggr=aggr,
                t=1.0,
                learn_t=aggr == "softmax",
                num_layers=mlp_layers,
                norm="batch",
                edge_dim=hidden,
            )
            self.layers.append(
                DeepGCNLayer(
                    conv,
                    nn.BatchNorm1d(hidden),
                    nn.ReLU(inplace=True),
                    block=block,
                    dropout=dropout,
                    ckpt_grad=False,
                )
            )
        self.dropout = dropout
        self.pool = POOLS[pool]
        self.head = nn.Linear(hidden, out_channels)

    def forward(self, x, edge_index, edge_attr, batch):
        x = self.node_encoder(x)
        e = self.edge_encoder(edge_attr)
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
        return self.head(self.pool(x, batch))


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters() if p.requires_grad)
