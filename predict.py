"""Ensemble prediction of eta_r, Pi, Z_mu for every snapshot of a trajectory file (see --help)."""

from rheograph.errors import one_line_errors
from rheograph.learn.predict import main

if __name__ == "__main__":
    with one_line_errors("predict.py"):
        main()
