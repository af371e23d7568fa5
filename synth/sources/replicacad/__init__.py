"""ReplicaCAD (habitat-sim) scenes from disk: a scene source (``synth.sources``), registered as ``replicacad``.

Readers of habitat's own files: ``habitat_format`` (typed fields of the JSON configs, the frame
conversion, config lookup), ``articulated`` (articulated-object instances and their URDFs/ao_configs),
``receptacles`` (declared support boxes), ``navmesh`` (habitat's navmesh), ``habitat_lighting``
(lighting configs). ``importer`` turns a scene instance into a ``Layout``; ``job`` is the
``replicacad:`` section of a render spec; ``commands`` is ``synth scene import-replicacad``;
``source`` is the object the registry holds. The formats every dataset shares (GLB, URDF) and the
geometry on meshes (collision, support surfaces, stage structure) are the mesh layer's (``synth.mesh``).

Sits above ``scene``, ``assets``, ``mesh``, ``paths`` and ``layout``; below ``render``.
"""
