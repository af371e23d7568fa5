"""Layout operations: the built-in apartment, placement, rearrangement and the validity checks.

``apartment``  the procedural reference apartment (``apt_0``), same seed same bytes
``placement``  valid placements of object instances (the engine behind apartment and variants)
``rearrange``  the rearrangement operator that makes layout variants
``validity``   the checks every layout must pass (``synth scene check``)
"""
