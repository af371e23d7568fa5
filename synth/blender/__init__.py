"""Blender (bpy) side of the toolkit: the only package allowed to import bpy.

Importing this package itself does not import bpy; its modules (e.g. ``synth.blender.materials``) do.
"""
