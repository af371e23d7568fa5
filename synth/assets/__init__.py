"""Procedural object assets: meshes generated from a class, a size and a few parameters.

Modules, bottom up (each imports only those above it, and ``vrformats.errors``):

* ``materials``   the material vocabulary (``MATERIALS``) and the colour palettes;
* ``surfaces``    ``Surface``, a supporting rectangle in an object's local frame;
* ``sampling``    ``ParamSampler``, the random draws the samplers make;
* ``primitives``  the local-frame conventions, ``Part``, ``param``, mesh primitives (boxes, cylinders,
  surfaces of revolution...) and the ``Builder`` that fits the parts to the object's box;
* ``components``  legs, handles and cabinet casework shared by several families;
* the families, each ``generate_<class>`` beside its ``sample_<class>``: ``seating`` (sofa, armchair,
  chair, stool, bench), ``tables`` (dining, coffee and side tables, desk), ``storage`` (nightstand,
  cabinet, tv_stand, bookshelf, wardrobe, shoe_rack), ``kitchen`` (kitchen_counter, fridge, stove),
  ``beds`` (bed), ``bathroom`` (toilet, bathtub, washbasin), ``lighting`` (floor_lamp, table_lamp,
  ceiling_light), ``plants`` (plant, small_plant), ``decor`` (cushion, book, vase, bowl, picture,
  mirror, bin, basket, other), ``electronics`` (laptop, tv);
* ``registry``    ``REGISTRY`` (class -> generator, sampler, whether it holds objects) and the public
  entry points ``known_classes``, ``sample_params``, ``make_parts``, ``make_mesh``,
  ``support_surfaces``, ``NO_SURFACE_CLASSES``, ``UnknownClassError``.

This package imports nothing itself: import the module you need.
"""
