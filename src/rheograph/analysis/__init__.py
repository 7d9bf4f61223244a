"""What is measured from finished runs: steady-state statistics (``steady``), flow curves
(``flow_curves``), jamming points (``jamming_points``) and dataset cards (``dataset_card``)."""
