"""The benchmarks behind the validation pages: each a module run as ``python -m bench.<name>`` from the
repository root, writing its numbers as JSON records under docs/results/bench/ (``bench.publishing``);
``python -m bench.render`` draws every published table from those records."""
