"""The learned detector's training side (PyTorch, the optional ``[train]`` extra): pack rendered tours
into a training set, train a compact segmentation network, export it to ONNX, evaluate it.

The runtime side, which the front-end uses, needs no PyTorch: ``reloc.frontend.detection_learned``
runs the exported ONNX model with onnxruntime and turns its output into instances.
"""
