"""A compact encoder-decoder for per-pixel classes and instance boundaries (PyTorch).

Input: an 8-bit sRGB image as float in [0, 1], NCHW, height and width divisible by 8. Outputs, at
full resolution: ``semantic`` logits (background + the class table's classes) and ``boundary``
logits (one channel: the pixel lies on the border between two instances, or between an instance
and the background). Instances are cut from these by ``reloc.detection.learned``, which
also splits them at depth discontinuities.

Two architectures (``ARCHS``; the exported model's metadata names its ``stride``, which the input's
height and width must divide):

* ``segnet`` (the first shipped model): three stride-2 stages (24, 48, 96 channels, a 128-channel
  bottleneck at 1/8) with skip connections and full-resolution decoding; stride 8.
* ``fastseg`` (issue 28): the same U shape started at half resolution (a stride-2 stem), one
  stage deeper (a bottleneck at 1/16 for more context), decoder stages that first reduce the
  concatenated channels with a 1x1 convolution, and heads at 1/2 upsampled bilinearly to full
  resolution; about a sixth of segnet's arithmetic at the same width; stride 16.

Only ONNX-friendly operations (convolutions, batch norm, ReLU, nearest and bilinear upsampling,
concatenation).
"""

from __future__ import annotations

import torch
from torch import nn


def _block(cin: int, cout: int, stride: int = 1) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 3, stride=stride, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
    )


def _unet(m: nn.Module, x: torch.Tensor) -> torch.Tensor:
    """The encoder-decoder both networks share (stages e1..e4, d3..d1, skip connections): the last
    decoder stage's features."""
    x1 = m.e1(x)
    x2 = m.e2(x1)
    x3 = m.e3(x2)
    x4 = m.e4(x3)
    y = m.d3(torch.cat([m.up(x4), x3], 1))
    y = m.d2(torch.cat([m.up(y), x2], 1))
    return m.d1(torch.cat([m.up(y), x1], 1))


class SegNet(nn.Module):
    def __init__(self, n_classes: int, width: int = 24):
        super().__init__()
        w1, w2, w3, w4 = width, 2 * width, 4 * width, 128 * width // 24
        self.n_classes = int(n_classes)
        self.width = int(width)
        self.e1 = _block(3, w1)
        self.e2 = _block(w1, w2, 2)
        self.e3 = _block(w2, w3, 2)
        self.e4 = _block(w3, w4, 2)
        self.up = nn.Upsample(scale_factor=2, mode="nearest")
        self.d3 = _block(w4 + w3, w3)
        self.d2 = _block(w3 + w2, w2)
        self.d1 = _block(w2 + w1, w1)
        self.semantic = nn.Conv2d(w1, n_classes, 1)
        self.boundary = nn.Conv2d(w1, 1, 1)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        y = _unet(self, x)
        return self.semantic(y), self.boundary(y)


def _reduce(cin: int, cout: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(cin, cout, 1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
        nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
    )


class FastSeg(nn.Module):
    stride = 16

    def __init__(self, n_classes: int, width: int = 24):
        super().__init__()
        w1, w2, w3, w4 = width, 2 * width, 4 * width, 6 * width
        self.n_classes = int(n_classes)
        self.width = int(width)
        self.e1 = _block(3, w1, 2)  # 1/2
        self.e2 = _block(w1, w2, 2)  # 1/4
        self.e3 = _block(w2, w3, 2)  # 1/8
        self.e4 = _block(w3, w4, 2)  # 1/16
        self.up = nn.Upsample(scale_factor=2, mode="nearest")
        self.d3 = _reduce(w4 + w3, w3)
        self.d2 = _reduce(w3 + w2, w2)
        self.d1 = _reduce(w2 + w1, w1)
        self.semantic = nn.Conv2d(w1, n_classes, 1)
        self.boundary = nn.Conv2d(w1, 1, 1)
        self.full = nn.Upsample(scale_factor=2, mode="bilinear", align_corners=False)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        y = _unet(self, x)
        return self.full(self.semantic(y)), self.full(self.boundary(y))


SegNet.stride = 8
ARCHS = {"segnet": SegNet, "fastseg": FastSeg}


def build(arch: str, n_classes: int, width: int) -> nn.Module:
    """The named architecture (``ARCHS``) for ``n_classes`` classes at ``width``."""
    if arch not in ARCHS:
        raise ValueError(f"unknown architecture {arch!r}; known: {', '.join(ARCHS)}")
    return ARCHS[arch](n_classes, width)


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
