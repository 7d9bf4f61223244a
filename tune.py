"""Optuna hyperparameter search over train.py's configuration (see conf/tune.yaml, README)."""

import hydra
from omegaconf import DictConfig

from rheograph.cli.hydra_apps import tune_main
from rheograph.errors import one_line_errors, run_hydra_app


@hydra.main(version_base="1.3", config_path="conf", config_name="tune")
def main(cfg: DictConfig) -> None:
    with one_line_errors("tune.py"):
        tune_main(cfg)


if __name__ == "__main__":
    run_hydra_app(main, "tune.py")
