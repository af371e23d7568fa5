"""The learned detector's training side (PyTorch, the optional ``[train]`` extra): pack rendered tours
into a training set, train a compact segmentation network, export it to ONNX, evaluate it.

The runtime side, which map building and the front-end use, needs no PyTorch: ``reloc.detection.learned``
runs the exported ONNX model with onnxruntime and turns its output into instances.
"""
