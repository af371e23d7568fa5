"""Experiments over rendered designs: evaluation, the unit experiment, the paper's tables, plots,
the report, robustness checks and benchmarks."""
