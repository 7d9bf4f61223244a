"""The ``rheograph`` command: every entry point from any folder once the package is installed.

    rheograph simulate sim.phi=0.78 sim.stress=50        # = python simulate.py ...
    rheograph train experiment=demo                        # = python train.py ...
    rheograph tune                                         # = python tune.py ...
    rheograph predict --models N400_phi0.76 --input f.npz --out p.csv
    rheograph collect DIR --out index.json | flowcurve DIR --out D | dataset-card ... |
        jamming-points INDEX... | models ship RUN --name NAME

The Hydra commands read the configuration shipped inside the package (``rheograph/conf``), so they run
outside the repository too; their options are the configuration keys (``rheograph simulate --help``).
"""

from __future__ import annotations

import os
import sys

from rheograph.errors import one_line_errors, run_hydra_app

HYDRA_APPS = {"simulate": "simulate", "train": "train", "tune": "tune"}
TOOLS = {
    "predict": "rheograph.learn.predict",
    "collect": "rheograph.runs.sweep_index",
    "flowcurve": "rheograph.analysis.flow_curves",
    "dataset-card": "rheograph.analysis.dataset_card",
    "jamming-points": "rheograph.analysis.jamming_points",
    "models": "rheograph.learn.registry",
}


def _hydra_app(name: str):
    import hydra
    from omegaconf import DictConfig

    from rheograph.cli import hydra_apps

    hydra_apps.register_resolvers()
    run = {
        "simulate": hydra_apps.simulate_main,
        "train": hydra_apps.train_main,
        "tune": hydra_apps.tune_main,
    }[name]

    @hydra.main(version_base="1.3", config_path="../conf", config_name=HYDRA_APPS[name])
    def app(cfg: DictConfig):
        with one_line_errors(f"rheograph {name}"):
            return run(cfg)

    return app


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    commands = [*HYDRA_APPS, *TOOLS]
    if not argv or argv[0] in ("-h", "--help") or argv[0] not in commands:
        print(__doc__.strip())
        if argv and argv[0] not in ("-h", "--help"):
            print(f"\nrheograph: unknown command {argv[0]!r}; one of {', '.join(commands)}", file=sys.stderr)
            sys.exit(2)
        return
    command, rest = argv[0], argv[1:]
    if command == "simulate":
        # one thread per simulation: CHOLMOD's OpenMP reads OMP_THREAD_LIMIT when libgomp loads
        os.environ.setdefault("OMP_THREAD_LIMIT", "1")
        os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    sys.argv = [f"rheograph {command}", *rest]
    if command in HYDRA_APPS:
        run_hydra_app(_hydra_app(command), f"rheograph {command}")
        return
    import importlib

    with one_line_errors(f"rheograph {command}"):
        importlib.import_module(TOOLS[command]).main(rest)


if __name__ == "__main__":
    main()
