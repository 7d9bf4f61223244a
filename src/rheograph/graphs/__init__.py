"""Snapshot -> graph conversion and the PyG dataset of snapshot graphs."""
