"""The tour, synth's side: one layout x one lighting x one camera path, rendered to a tour folder
(EXR RGB-D + ground truth), then checked, looked at and exported. ``synth tour render|check|show|export``.

``render``  one tour into a tour folder: what to render, the static files and meta.json, its passes
``check``   ``synth tour check``: every frame, pose and ground-truth file of a tour
``show``    ``synth tour show``: the contact sheet of one frame
``cli``     the ``synth tour`` commands (and their old names ``synth dataset check|show|export``)

The tour's format is the format layer's, because reloc reads tours too and imports nothing of synth:
the reader and the folder's conventions are ``vrformats.tour``, the other methods' formats that
``synth tour export`` writes are ``vrformats.export``. The renderer's pieces that ``render`` drives
(chunks of frames in worker processes, the fast renderer, quality settings) are ``synth.render``;
the Blender side is ``synth.blender``. A render job (``synth.jobs``) renders many tours with
``render``'s preparation and meta.json.
"""
