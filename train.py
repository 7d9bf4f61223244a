"""Train the multitask ResGCN surrogate on simulated snapshots (all K folds, or fold=k) and write a report.
See README.md and conf/train.yaml."""

import hydra
from omegaconf import DictConfig

from rheograph.cli.hydra_apps import train_main
from rheograph.errors import one_line_errors, run_hydra_app


@hydra.main(version_base="1.3", config_path="conf", config_name="train")
def main(cfg: DictConfig) -> float:
    with one_line_errors("train.py"):
        return train_main(cfg)


if __name__ == "__main__":
    run_hydra_app(main, "train.py")
