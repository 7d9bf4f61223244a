"""The command line: the Hydra applications behind ``simulate.py``, ``train.py`` and ``tune.py``
(``hydra_apps``) and the ``rheograph`` command that reaches every entry point (``console``)."""
