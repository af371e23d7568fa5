"""Rendering without bpy: what to render, how it is split, and the renderers' shared inputs.

``meshes``       triangle meshes of a layout, as both renderers read them
``render_tour``  one tour (layout x lighting x path) into a tour folder
``chunks``       a tour split into chunks of frames, each a Blender process
``chunk_worker`` chunks that need no Blender (depth, instance, semantic with the fast renderer)
``fast_render``  the fast geometry renderer (Open3D ray casting)
``settings``     render quality presets and their defaults
``bench``        the render benchmark

The Blender side (the only bpy code) is ``synth.blender``, one layer up.
"""
