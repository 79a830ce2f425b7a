"""Campaigns (docs/architecture.md §9): a grid of trials run on Ray, stored as one parquet row per trial, summarised per
scenario x vehicle x policy and written up as a report with plots.

``spec`` reads the TOML grid, ``trial`` runs one trial (pure: inputs in, row out), ``executors`` decides where
trials run (in this process, or on Ray: the only module that imports it), ``store`` keeps rows, resumes and
summarises, ``report`` draws. ``sweep`` wires them for ``returnlink sim sweep``.
"""
