"""The training settings of the learned detector, without PyTorch: ``reloc detector train``'s options
take their defaults from here (``reloc.detector.train`` trains with them)."""

from __future__ import annotations

from dataclasses import dataclass, field


@dataclass
class TrainConfig:
    epochs: int = 40
    batch: int = 32
    lr: float = 2e-3
    weight_decay: float = 1e-4
    width: int = 16
    boundary_pos_weight: float = 3.0
    boundary_loss_weight: float = 1.0
    exposure_log2: float = 0.7
    seed: int = 0
    val_layouts: list[str] = field(default_factory=list)  # default: the last layout of the set
