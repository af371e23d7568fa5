"""Experiments over rendered designs.

``reloc experiment``: the spec file (``spec``), the run (``runner``), the maps and runs it
schedules (``tasks``), the keys that make it resumable (``fingerprint``) and other people's
relocalizers (``external``); the metrics (``evaluation``) and ``reloc eval`` (``cli``); the
localization-unit experiment (``localization_units``, ``reloc units``); the paper's tables
(``tables``), plots, the report, robustness checks (``checks``) and benchmarks (``bench``)."""
