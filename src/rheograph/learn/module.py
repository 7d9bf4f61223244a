"""LightningModule: multitask Huber regression of (transformed eta_r, transformed Pi, Z_mu)."""

from __future__ import annotations

import lightning as L
import numpy as np
import torch
from torch import nn

from rheograph.graphs.features import inverse_transform
from rheograph.learn.model import ResGCN

TARGET_NAMES = ("eta", "pressure", "z_mu")


def physical_targets(y_transformed: np.ndarray, viscosity_scale: float, pressure_scale: float) -> np.ndarray:
    """Invert the target transforms: (G, 3) transformed -> (G, 3) [eta_r, Pi, Z_mu] in physical units."""
    y = np.asarray(y_transformed, dtype=np.float64)
    return np.stack(
        [inverse_transform(y[:, 0], viscosity_scale), inverse_transform(y[:, 1], pressure_scale), y[:, 2]],
        axis=1,
    )


def regression_metrics(pred: np.ndarray, true: np.ndarray) -> dict:
    """R^2, MAE and MAPE per target (physical units); MAPE skips |true| < 1e-8 (e.g. Z_mu = 0)."""
    out = {}
    for k, name in enumerate(TARGET_NAMES):
        p, t = pred[:, k], true[:, k]
        ss_res = float(np.sum((t - p) ** 2))
        ss_tot = float(np.sum((t - t.mean()) ** 2))
        out[f"r2_{name}"] = 1.0 - ss_res / ss_tot if ss_tot > 0 else float("nan")
        out[f"mae_{name}"] = float(np.mean(np.abs(t - p)))
        nz = np.abs(t) > 1e-8
        out[f"mape_{name}"] = float(np.mean(np.abs((t[nz] - p[nz]) / t[nz]))) if nz.any() else float("nan")
    return out


class SurrogateModule(L.LightningModule):
    """ResGCN + summed SmoothL1 (beta = 1) over standardised targets, Adam.

    ``target_mean``/``target_std`` (fitted on the training fold) and the transform scales are buffers /
    hyperparameters, so a checkpoint alone maps graphs to physical eta_r, Pi, Z_mu.
    """

    def __init__(
        self,
        node_in: int = 2,
        edge_in: int = 6,
        hidden: int = 64,
        num_layers: int = 2,
        aggr: str = "softmax",
        block: str = "res+",
        dropout: float = 0.1,
        pool: str = "mean",
        lr: float = 5e-3,
        weight_decay: float = 0.0,
        loss_weights=(1.0, 1.0, 1.0),
        huber_beta: float = 1.0,
        viscosity_scale: float = 1.0,
        pressure_scale: float = 0.1,
    ):
        super().__init__()
        self.save_hyperparameters()
        if lr <= 0:
            raise ValueError(f"model.lr={lr} is invalid: allowed > 0")
        if len(loss_weights) != 3 or min(loss_weights) < 0:
            raise ValueError(f"model.loss_weights={list(loss_weights)}: three weights >= 0")
        self.net = ResGCN(node_in, edge_in, hidden, num_layers, aggr, block, dropout, pool, 3)
        self.register_buffer("target_mean", torch.zeros(3))
        self.register_buffer("target_std", torch.ones(3))
        self.register_buffer("loss_weights", torch.tensor(list(loss_weights), dtype=torch.float32))
        self.huber = nn.SmoothL1Loss(beta=huber_beta, reduction="none")
        self._outputs = {"train": [], "val": [], "test": []}

    def set_target_scaling(self, mean: torch.Tensor, std: torch.Tensor) -> None:
        self.target_mean.copy_(mean)
        self.target_std.copy_(std)

    def forward(self, batch) -> torch.Tensor:
        """Predicted transformed targets (G, 3) (not standardised)."""
        z = self.net(batch.x, batch.edge_index, batch.edge_attr, batch.batch)
        return z * self.target_std + self.target_mean

    def _step(self, batch, stage: str):
        z = self.net(batch.x, batch.edge_index, batch.edge_attr, batch.batch)
        target = (batch.y - self.target_mean) / self.target_std
        per_target = self.huber(z, target).mean(dim=0)
        loss = (per_target * self.loss_weights).sum()
        size = batch.num_graphs
        self.log(
            f"{stage}/loss", loss, batch_size=size, on_epoch=True, on_step=False, prog_bar=stage == "val"
        )
        for k, name in enumerate(TARGET_NAMES):
            self.log(f"{stage}/loss_{name}", per_target[k], batch_size=size, on_epoch=True, on_step=False)
        pred = (z * self.target_std + self.target_mean).detach()
        self._outputs[stage].append((pred.cpu().numpy(), batch.y.cpu().numpy()))
        return loss

    def training_step(self, batch, batch_idx):
        return self._step(batch, "train")

    def validation_step(self, batch, batch_idx):
        self._step(batch, "val")

    def test_step(self, batch, batch_idx):
        self._step(batch, "test")

    def _epoch_metrics(self, stage: str):
        if not self._outputs[stage]:
            return
        pred = np.concatenate([p for p, _ in self._outputs[stage]])
        true = np.concatenate([t for _, t in self._outputs[stage]])
        self._outputs[stage].clear()
        if self.trainer is not None and self.trainer.world_size > 1:
            # data-parallel: every process holds a shard; gather so that R^2 etc. cover the whole split
            # (the distributed sampler pads shards to equal length with repeated graphs)
            both = torch.from_numpy(np.concatenate([pred, true], axis=1)).to(self.device)
            gathered = self.all_gather(both).reshape(-1, 6).cpu().numpy()
            pred, true = gathered[:, :3], gathered[:, 3:]
        hp = self.hparams
        metrics = regression_metrics(
            physical_targets(pred, hp.viscosity_scale, hp.pressure_scale),
            physical_targets(true, hp.viscosity_scale, hp.pressure_scale),
        )
        self.log_dict({f"{stage}/{k}": v for k, v in metrics.items()}, on_epoch=True)

    def on_train_epoch_end(self):
        self._epoch_metrics("train")

    def on_validation_epoch_end(self):
        self._epoch_metrics("val")

    def on_test_epoch_end(self):
        self._epoch_metrics("test")

    def configure_optimizers(self):
        return torch.optim.Adam(self.parameters(), lr=self.hparams.lr, weight_decay=self.hparams.weight_decay)
