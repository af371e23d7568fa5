"""Rendering without bpy: how a tour's frames are split and rendered, and the renderers' shared inputs.

``meshes``       triangle meshes of a layout, as both renderers read them
``chunks``       a tour split into chunks of frames, each a Blender process
``chunk_worker`` chunks that need no Blender (depth, instance, semantic with the fast renderer)
``fast_render``  the fast geometry renderer (Open3D ray casting)
``settings``     render quality presets and their defaults
``bench``        the render benchmark

The Blender side (the only bpy code) is ``synth.blender``, one layer up. What a tour is and how one is
rendered, checked and exported is ``synth.tour``, above both.
"""
