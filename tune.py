"""Optuna hyperparameter search over train.py's configuration (see conf/tune.yaml, README)."""

import hydra
from omegaconf import DictConfig

from rheograph.cli import tune_main


@hydra.main(version_base="1.3", config_path="conf", config_name="tune")
def main(cfg: DictConfig) -> None:
    tune_main(cfg)


if __name__ == "__main__":
    main()
