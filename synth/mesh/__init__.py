"""The mesh layer: reading standard mesh formats and doing geometry on meshes, for any scene source.

``gltf`` (GLB meshes and their PBR materials), ``urdf`` (URDF models: links, joints, visual meshes at
a joint state), ``roots`` (the dataset folder a file belongs to), ``mesh_assets`` (the mesh an
``ObjectInstance.asset`` names, in its local Z-up frame), ``collision`` (mesh collision tests),
``surfaces`` (support surfaces of mesh objects) and ``stage_structure`` (walls, floors, openings and
rooms recovered from a stage mesh). No Blender here, and no dataset's own configs: those are the
scene sources' (``synth.sources``).

Sits above ``scene`` and ``assets``; below ``paths``, ``layout``, the sources and the renderers.
"""
