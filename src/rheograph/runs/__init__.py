"""Running state points and keeping their files: one state point to its target strain (``runner``), the
index of a sweep's trajectory files (``sweep_index``) and coarser snapshot spacing of finished runs
(``respace``)."""
