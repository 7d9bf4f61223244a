"""HDF5 storage of trajectories (time series, snapshots, checkpoints)."""
