"""The scene model: layouts, stages, objects, light fixtures, lighting presets and class table.

The bottom layer of ``synth``: everything else reads and writes these types, and nothing here
imports another ``synth`` subpackage (only ``synth.resources`` and ``vrformats``).

``model``      Layout / Stage / ObjectInstance / LightFixture, YAML I/O, layout lookup
``geometry``   oriented boxes, quaternions, polygon helpers (Z-up world, metres)
``classes``    the semantic class table (``scenes/classes.yaml``)
``lighting``   lighting presets (day / evening / night), their validation and jitter
``fixtures``   the light fixtures a layout's objects and windows imply
``openings``   the volumes doors and windows keep free
``stats``      change statistics of a variant against its reference (the paper's ranges)
``preview``    top-down previews of a layout
"""
