"""Camera-realistic augmentation at training time (PyTorch, batched, on the training device).

Each training frame is stored as the 8-bit sRGB the camera pipeline made of its linear render
(``vrformats.tour.tonemap``: auto exposure, sRGB, 8 bits) together with that exposure's scale, so
the linear scene radiance is recovered as ``srgb_decode(x) / scale`` (up to the 8-bit steps and the
~3 % of highlights the tonemap clipped). On it, per image and with random strengths
(``reloc.detector.settings.AugmentConfig``), in the order a camera applies them:

1. scene brightness ``x 2^U(-a, b)`` (a darker room, a brighter one), raised where needed so that
   the 97th luminance percentile stays at or above ``min_p97`` (the camera must see something),
   and a white-balance error (red and blue gains ``2^U(-w, w)``);
2. motion blur from a random camera motion during the exposure: the frame averaged over
   ``blur_samples`` affine warps (a shift of up to ``blur_px`` pixels along a random direction and a
   roll of up to ``blur_roll_deg``), rotation-only flow as ``vrformats.sensors.motion_blur`` draws it
   for distant points;
3. the colour camera of ``vrformats.sensors.ColorModel``, with its parameters drawn around a preset's
   (``sensor``: structured_light's, shared by tof): auto exposure on the 97th luminance
   percentile, analog gain at the longest exposure, shot and read noise in electrons, full-well
   clip, with ``electrons_per_ms`` and ``read_noise_e`` scaled at random (``sensor_prob`` of the
   frames; the others keep the renderer's noise only);
4. the display transform of inference (``vrformats.tour.tonemap``: the 97th luminance percentile to
   0.9, sRGB, clip) and 8-bit quantisation;
5. JPEG-like compression (``jpeg_prob`` of the frames): 8x8 DCT blocks quantised with the JPEG
   luminance table at a random quality in ``jpeg_quality``.

``tests/reloc/detector/test_detector_augment.py`` checks steps 3 and 4 against ``vrformats.sensors`` and
``vrformats.tour.tonemap`` on the same frames.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

from vrformats import color

LUMA = (0.2126, 0.7152, 0.0722)
# the JPEG standard's luminance quantisation table (ITU-T T.81, Annex K.1)
JPEG_LUMA = (
    (16, 11, 10, 16, 24, 40, 51, 61), (12, 12, 14, 19, 26, 58, 60, 55), (14, 13, 16, 24, 40, 57, 69, 56),
    (14, 17, 22, 29, 51, 87, 80, 62), (18, 22, 37, 56, 68, 109, 103, 77), (24, 35, 55, 64, 81, 104, 113, 92),
    (49, 64, 78, 87, 103, 121, 120, 101), (72, 92, 95, 98, 112, 100, 103, 99),
)


def srgb_decode(x: torch.Tensor) -> torch.Tensor:
    """``vrformats.color.srgb_decode`` on tensors (their dtype kept)."""
    return torch.where(x <= color.DECODE_KNEE, x / color.SLOPE, ((x + color.OFFSET) / (1.0 + color.OFFSET)) ** color.GAMMA)


def srgb_encode(x: torch.Tensor) -> torch.Tensor:
    """``vrformats.color.srgb_encode`` on tensors (clipped to [0, 1] first; the power's input kept
    above 1e-8, where the linear segment is taken anyway, so that its gradient stays finite)."""
    x = x.clamp(0.0, 1.0)
    return torch.where(x <= color.ENCODE_KNEE, x * color.SLOPE,
                       (1.0 + color.OFFSET) * x.clamp_min(1e-8) ** (1.0 / color.GAMMA) - color.OFFSET)


def luminance(lin: torch.Tensor) -> torch.Tensor:
    """(B, H, W) Rec. 709 luminance of (B, 3, H, W) linear RGB."""
    w = torch.tensor(LUMA, device=lin.device, dtype=lin.dtype).view(1, 3, 1, 1)
    return (lin * w).sum(1)


def percentile(lum: torch.Tensor, q: float) -> torch.Tensor:
    """(B,) the q-th percentile of each image's values, interpolated linearly as numpy does."""
    flat = lum.reshape(len(lum), -1)
    return torch.quantile(flat, q / 100.0, dim=1)


def tonemap(lin: torch.Tensor) -> torch.Tensor:
    """``vrformats.tour.tonemap`` on a batch: each image's 97th luminance percentile to 0.9, sRGB."""
    p = percentile(luminance(lin), 97.0)
    scale = torch.where(p > 1e-8, 0.9 / p.clamp_min(1e-12), torch.ones_like(p)).view(-1, 1, 1, 1)
    return srgb_encode(lin * scale)


def exposure(lin: torch.Tensor, electrons_per_ms: torch.Tensor, full_well_e: float, percentile_q: float,
             target: float, min_ms: float, max_ms: float, max_gain: float) -> tuple[torch.Tensor, torch.Tensor]:
    """``vrformats.sensors.exposure`` on a batch: (exposure ms, analog gain), each (B,)."""
    p = percentile(luminance(lin), percentile_q)
    want = target * full_well_e / (electrons_per_ms * p.clamp_min(1e-30))
    t = want.clamp(min_ms, max_ms)
    gain = torch.where(want > max_ms, (want / t).clamp(1.0, max_gain), torch.ones_like(want))
    dark = ~(p > 0)
    t = torch.where(dark, torch.full_like(t, max_ms), t)
    gain = torch.where(dark, torch.full_like(gain, max_gain), gain)
    return t, gain


def sensor_noise(lin: torch.Tensor, electrons_per_ms: torch.Tensor, read_noise_e: torch.Tensor, full_well_e: float,
                 percentile_q: float, target: float, min_ms: float, max_ms: float, max_gain: float,
                 generator: torch.Generator | None = None) -> torch.Tensor:
    """``vrformats.sensors`` colour camera (without motion blur) on a batch; per-image
    ``electrons_per_ms`` and ``read_noise_e`` (B,). Returns linear scene-referred values."""
    t, gain = exposure(lin, electrons_per_ms, full_well_e, percentile_q, target, min_ms, max_ms, max_gain)
    k = (electrons_per_ms * t).view(-1, 1, 1, 1)
    g = gain.view(-1, 1, 1, 1)
    rn = read_noise_e.view(-1, 1, 1, 1)
    e = (lin.clamp_min(0.0) * k)
    e = e + torch.sqrt(e + rn**2) * torch.randn(e.shape, generator=generator, device=e.device, dtype=e.dtype)
    e = e.clamp(0.0, full_well_e)
    e = torch.minimum(e * g, torch.tensor(full_well_e, device=e.device, dtype=e.dtype)) / g
    return e / k


def motion_blur(lin: torch.Tensor, shift_px: torch.Tensor, angle: torch.Tensor, roll_rad: torch.Tensor,
                samples: int) -> torch.Tensor:
    """The batch averaged over ``samples`` affine warps spread over the exposure: a shift of
    ``shift_px`` (B,) along ``angle`` (B,) and a roll of ``roll_rad`` (B,) about the centre, centred
    on the frame's time (rotation-only flow: the same for every depth)."""
    B, _, H, W = lin.shape
    acc = torch.zeros_like(lin)
    for k in range(samples):
        tau = (k + 0.5) / samples - 0.5
        r = roll_rad * tau
        cos, sin = torch.cos(r), torch.sin(r)
        # affine_grid works in normalised coordinates ([-1, 1] over each axis)
        tx = shift_px * tau * torch.cos(angle) * 2.0 / W
        ty = shift_px * tau * torch.sin(angle) * 2.0 / H
        theta = torch.stack([torch.stack([cos, -sin * H / W, tx], 1), torch.stack([sin * W / H, cos, ty], 1)], 1)
        grid = F.affine_grid(theta, list(lin.shape), align_corners=False)
        acc += F.grid_sample(lin, grid, mode="bilinear", padding_mode="border", align_corners=False)
    return acc / samples


def _dct_matrix(device, dtype) -> torch.Tensor:
    n = torch.arange(8, device=device, dtype=dtype)
    k = n.view(-1, 1)
    m = torch.cos(math.pi * (2 * n + 1) * k / 16) * math.sqrt(2 / 8)
    m[0] = m[0] / math.sqrt(2)
    return m  # orthonormal: m @ m.T = I


def jpeg_like(x8: torch.Tensor, quality: torch.Tensor) -> torch.Tensor:
    """8-bit images (B, 3, H, W, values 0..255; H and W multiples of 8) through 8x8 DCT
    quantisation with the JPEG luminance table scaled for ``quality`` (B,) as libjpeg scales it;
    returns values rounded to 0..255."""
    B, C, H, W = x8.shape
    D = _dct_matrix(x8.device, x8.dtype)
    q = quality.clamp(1, 100)
    s = torch.where(q < 50, 5000.0 / q, 200.0 - 2.0 * q).view(-1, 1, 1, 1, 1, 1)
    table = ((torch.tensor(JPEG_LUMA, device=x8.device, dtype=x8.dtype) * s + 50) / 100).floor().clamp(1, 255)
    blocks = (x8 - 128.0).reshape(B, C, H // 8, 8, W // 8, 8).permute(0, 1, 2, 4, 3, 5)
    coef = D @ blocks @ D.T
    coef = torch.round(coef / table) * table
    back = (D.T @ coef @ D).permute(0, 1, 2, 4, 3, 5).reshape(B, C, H, W) + 128.0
    return back.round().clamp(0, 255)


def uniform(n: int, lo: float, hi: float, g: torch.Generator, device) -> torch.Tensor:
    return lo + (hi - lo) * torch.rand(n, generator=g, device=device)


def camera_augment(x8: torch.Tensor, scale: torch.Tensor, cfg, g: torch.Generator) -> torch.Tensor:
    """(B, 3, H, W) uint8 sRGB frames and (B,) their tonemap scales -> the augmented network input
    (float in [0, 1], 8-bit steps). ``cfg``: ``AugmentConfig``; ``g``: a generator on x8's device."""
    dev = x8.device
    B = x8.shape[0]
    lin = srgb_decode(x8.float() / 255.0) / scale.view(-1, 1, 1, 1).clamp_min(1e-12)
    bright = 2.0 ** uniform(B, -cfg.brightness_log2[0], cfg.brightness_log2[1], g, dev)
    wb = 2.0 ** uniform(B * 2, -cfg.white_balance_log2, cfg.white_balance_log2, g, dev).view(B, 2)
    p97 = percentile(luminance(lin), 97.0).clamp_min(1e-12)
    bright = torch.maximum(bright, cfg.min_p97 / p97)
    gains = torch.stack([wb[:, 0], torch.ones(B, device=dev), wb[:, 1]], 1) * bright.view(-1, 1)
    lin = lin * gains.view(B, 3, 1, 1)
    blur = torch.rand(B, generator=g, device=dev) < cfg.blur_prob
    if blur.any() and cfg.blur_px > 0:
        shift = uniform(B, 0.0, cfg.blur_px, g, dev) * blur
        ang = uniform(B, 0.0, 2 * math.pi, g, dev)
        roll = uniform(B, -1.0, 1.0, g, dev) * math.radians(cfg.blur_roll_deg) * blur
        lin = torch.where(blur.view(-1, 1, 1, 1), motion_blur(lin, shift, ang, roll, cfg.blur_samples), lin)
    noisy = torch.rand(B, generator=g, device=dev) < cfg.sensor_prob
    if noisy.any():
        epm = cfg.electrons_per_ms * 2.0 ** uniform(B, -cfg.electrons_log2, cfg.electrons_log2, g, dev)
        rn = cfg.read_noise_e * 2.0 ** uniform(B, -1.0, 1.0, g, dev)
        n = sensor_noise(lin, epm, rn, cfg.full_well_e, cfg.exposure_percentile, cfg.exposure_target,
                         cfg.exposure_min_ms, cfg.exposure_max_ms, cfg.max_gain, generator=g)
        lin = torch.where(noisy.view(-1, 1, 1, 1), n, lin)
    x = torch.round(tonemap(lin) * 255.0)
    jp = torch.rand(B, generator=g, device=dev) < cfg.jpeg_prob
    H, W = x.shape[-2:]
    if jp.any() and H % 8 == 0 and W % 8 == 0:
        q = uniform(B, cfg.jpeg_quality[0], cfg.jpeg_quality[1], g, dev)
        x = torch.where(jp.view(-1, 1, 1, 1), jpeg_like(x, q), x)
    return x / 255.0
