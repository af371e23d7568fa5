"""ReplicaCAD (habitat-sim) scenes from disk: the readers of its formats and the import into the scene model.

Readers: ``habitat_format`` (typed fields of the JSON configs), ``gltf`` (GLB meshes and PBR
materials), ``urdf`` (articulated objects), ``receptacles`` (declared support boxes), ``navmesh``
(habitat's navmesh), ``stage_structure`` (walls, floors and rooms recovered from a stage mesh),
``habitat_lighting`` (lighting configs), ``mesh_assets`` (an asset's mesh, cached), ``collision``
(mesh collision tests) and ``surfaces`` (support surfaces of mesh objects). ``importer`` turns a
scene instance into a ``Layout``; ``job`` is the ``replicacad:`` section of a render spec.

Sits above ``scene``, ``assets`` and ``paths``; below ``layout`` and ``render``.
"""
