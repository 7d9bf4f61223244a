"""rheograph: LF-DEM simulation of dense frictional suspensions and GNN surrogates of their rheology."""

__version__ = "0.1.0"
