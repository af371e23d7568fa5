"""Detection (paper Sec. III-C): turning frames into per-frame object detections, class-labelled masks.

The layer below both map building (``reloc.map``) and the front-end (``reloc.frontend``), which
both run a detector on a tour's frames; it imports neither of them.

* ``base``: what every detector takes and gives (``FrameData``, ``Detection``, the ``Detector``
  protocol) and the RGB schedule a detector that sees pixels needs;
* ``oracle``: the ground-truth detector, from the rendered instance and semantic images, with a
  seeded corruption model;
* ``learned``: the toolkit's own segmentation model (trained by ``reloc.detector``), run with
  onnxruntime;
* ``onnx_yolo``: a user's YOLO-style ONNX instance-segmentation model (and the onnxruntime
  session both ONNX detectors open);
* ``factory``: how commands and experiments name a detector (``DetectorSpec``, the command-line
  options), build it and record it.
"""
