"""Procedural object assets: meshes generated from a class, a size and a few parameters.

``procedural`` holds the generators, their parameter samplers, the registry that maps a class to
them and the support surfaces of each family (what a table or a shelf can hold). Imports only
``synth.scene``.
"""
