"""rheograph: LF-DEM simulation of dense frictional suspensions and GNN surrogates of their rheology.

import rheograph
rheograph.list_models()                      # the shipped surrogate models
model = rheograph.load_model("N400_phi0.76")
table = model.predict(positions, radii, box, le_offset, stress=10, phi=0.76, mu=0.5, kn_coefficient=2e4,
                      kt_ratio=0.5, delta=1e-3, lub_max_gap=0.5)
snaps = rheograph.read_snapshots("par_run.dat")   # rheograph, bare or LF_DEM sources
rheograph.register_network(MyModule)          # bundles naming this SurrogateModule subclass load as it
rheograph.register_graph_network(MyNet)       # model.net may name this network, and bundles holding it load
"""

__version__ = "0.1.0"
__all__ = ["list_models", "load_model", "read_snapshots", "register_graph_network", "register_network"]


def __dir__():
    return sorted([*globals(), *__all__])


def __getattr__(name):
    # imported on first use: `import rheograph` (and the simulator) stays free of torch
    if name == "load_model":
        from rheograph.learn.predict import load_model

        return load_model
    if name == "list_models":
        from rheograph.learn.registry import list_models

        return list_models
    if name == "register_network":
        from rheograph.learn.networks import register_network

        return register_network
    if name == "register_graph_network":
        from rheograph.learn.nets import register_graph_network

        return register_graph_network
    if name == "read_snapshots":
        from rheograph.io.snapshots import read_snapshots

        return read_snapshots
    raise AttributeError(f"module 'rheograph' has no attribute {name!r}")
