"""Hydra configuration of rheograph's entry points (a package so that installed entry points find it)."""
