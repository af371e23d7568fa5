"""Synthetic controlled-change indoor scenes: layouts, rearrangement, lighting, rendering.

The Python API (``synth.api``, docs/api.md), importable from here without importing Blender or
Open3D until a function needs them::

    import synth
    apt = synth.load_layout("apt_0")                       # or synth.generate_apartment(seed)
    var = synth.rearrange(apt, "my_variant", seed=7)       # a rearranged variant
    tour = synth.render_tour("apt_0", "query", "out/t", frames=300)   # depth + ids, fast renderer
    synth.render_job("quickstart")                         # a whole shipped render job

Layouts: load_layout, save_layout, list_layouts, generate_apartment, rearrange.
Camera paths: plan_path, load_path, save_path. Rendering: render_tour, read_tour, render_job.
The command line (``synth --help``) runs the same code.
"""

from .version import __version__  # noqa: F401
from .api import (  # the API imports nothing heavy until a function is called
    generate_apartment, list_layouts, load_layout, load_path, plan_path, read_tour, rearrange, render_job,
    render_tour, save_layout, save_path,
)

__all__ = ["generate_apartment", "list_layouts", "load_layout", "load_path", "plan_path", "read_tour", "rearrange",
           "render_job", "render_tour", "save_layout", "save_path"]
