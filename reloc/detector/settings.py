"""The training settings of the learned detector, without PyTorch: ``reloc detector train``'s options
take their defaults from here (``reloc.detector.train`` trains with them)."""

from __future__ import annotations

from dataclasses import dataclass, field

# The detector's input size (pixels): the size the training set is rendered at (docs/detector.md),
# what ``reloc detector export`` fixes the ONNX model's example input to by default, and the size in
# the shipped models' names (reloc/models/detector_v2_160x120.onnx).
INPUT_WIDTH, INPUT_HEIGHT = 160, 120


@dataclass
class AugmentConfig:
    """Random strengths of the camera augmentation (``reloc.detector.augment.camera_augment``). The
    colour camera's centre values come from the sensor preset ``sensor`` (``vrformats.sensors``) when
    training starts (``with_sensor``)."""

    brightness_log2: tuple[float, float] = (2.0, 1.0)  # scene radiance x 2^U(-a, b)
    # ... but no darker than this 97th-percentile luminance (linear, Cycles' scale). The demo's night
    # query frames measure 5e-5 / 2.2e-3 / 1.3e-2 at their 5th / 25th / 50th percentiles (108 frames
    # of apt_0, apt_1, apt_3); below ~3e-4 the sensor presets' colour camera delivers noise alone
    # (16x gain at 33.3 ms: ~25 electrons at the brightest pixels), nothing a detector could learn from.
    min_p97: float = 3e-4
    white_balance_log2: float = 0.2  # red and blue gains 2^U(-w, w)
    blur_prob: float = 0.5
    blur_px: float = 6.0  # longest shift over the exposure
    blur_roll_deg: float = 2.0
    blur_samples: int = 8
    sensor_prob: float = 0.7
    sensor: str = "structured_light"
    electrons_log2: float = 1.0  # electrons_per_ms x 2^U(-e, e) around the preset's
    jpeg_prob: float = 0.5
    jpeg_quality: tuple[float, float] = (40.0, 95.0)
    # the preset's colour camera (filled by with_sensor)
    electrons_per_ms: float = 0.0
    read_noise_e: float = 0.0
    full_well_e: float = 0.0
    exposure_percentile: float = 97.0
    exposure_target: float = 0.8
    exposure_min_ms: float = 0.01
    exposure_max_ms: float = 33.3
    max_gain: float = 16.0

    def with_sensor(self) -> "AugmentConfig":
        """A copy with the colour camera of the preset ``sensor``."""
        from dataclasses import replace

        from vrformats.sensors import load_sensor

        c = load_sensor(self.sensor).color
        return replace(self, electrons_per_ms=c.electrons_per_ms, read_noise_e=c.read_noise_e, full_well_e=c.full_well_e,
                       exposure_percentile=c.exposure_percentile, exposure_target=c.exposure_target,
                       exposure_min_ms=c.exposure_min_ms, exposure_max_ms=c.exposure_max_ms, max_gain=c.max_gain)


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
    arch: str = "segnet"  # reloc.detector.model.ARCHS
    augment: str = "exposure"  # exposure (flips and exposure only) | camera (AugmentConfig)
    val_layouts: list[str] = field(default_factory=list)  # default: the last layout of the set
