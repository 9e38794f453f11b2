"""Drake systems and numpy cores, one sub-package per world. Lowest first: ``common`` (checks,
topology, spatial algebra, contact results), ``dynamics`` (the floating-base model), then
``simulation`` (sensors, noise, pushes, cable, PD), ``locomotion`` (walking), ``residuals``
(Flacco et al. 2016), ``observer`` (Hawley et al. 2019), ``estimation`` (the floating-base
state estimator, Hartley et al. 2020) and ``io`` (recorded logs: CSV, Parquet, MCAP, ROS
bags). Systems never simulate and never import ``diagrams`` or ``apps`` (tests/test_import_layers.py)."""
