"""VideoReloc: video relocalization against a kilobyte-scale map of class-labelled boxes.

The Python API (``reloc.api``, docs/api.md), importable from here without importing Open3D or
onnxruntime until a function needs them::

    import reloc
    bmap = reloc.build_map("out/t/mapping", detector="oracle")          # or "learned"
    summary = reloc.relocalize("out/t/query", bmap, "out/t/run")         # causal + closure poses
    rep = reloc.evaluate("out/t/run", "out/t/query")                     # rep["closure"]["recall_1m_10deg"]
    results = reloc.run_experiment("quickstart_experiment", tours="out/quickstart")
    rows = reloc.check("quickstart_checks", "out/quickstart/experiment")

Tours and maps: read_tour, ground_truth_map, build_map, load_map. Relocalization: relocalize,
evaluate. Experiments: run_experiment, check. The command line (``reloc --help``) runs the same code.
"""

from .version import __version__  # noqa: F401
from .api import build_map, check, evaluate, ground_truth_map, load_map, read_tour, relocalize, run_experiment

__all__ = ["build_map", "check", "evaluate", "ground_truth_map", "load_map", "read_tour", "relocalize",
           "run_experiment"]
