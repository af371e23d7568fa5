"""The knobs of map construction (:class:`MapBuildSettings`)."""

from __future__ import annotations

import math
from dataclasses import dataclass

from vrformats.errors import UserError


DEFAULT_STRIDE = 5  # every 5th frame: a 6000-frame 320x240 tour maps in well under a minute


@dataclass(frozen=True)
class MapBuildSettings:
    """Knobs of :func:`~reloc.map.build.build_map` (all "ours": the paper's pipeline has none of these):
    how a box map is built from a mapping tour (``reloc map build --stride --voxel``).

    Not a section of :class:`reloc.config.Config`: ``Config.map`` (:class:`reloc.config.MapConfig`)
    is how a map, once built and loaded, indexes its objects for registration."""

    stride: int = DEFAULT_STRIDE
    voxel: float = 0.05  # m, one centroid per cell
    depth_max_m: float = 10.0
    # a pixel is on a depth discontinuity when a 4-neighbour differs by more than abs + rel * z
    edge_abs_m: float = 0.05
    edge_rel: float = 0.05
    # object masks: keep pixels within scale * median + offset of the mask's median depth
    band_scale: float = 0.25
    band_offset_m: float = 0.5
    min_mask_pixels: int = 10  # depth-consistent pixels a detection needs to count
    # a mask's outer rim_px pixels count only where their depth agrees with the mask's interior
    # nearby (a mask bleeding onto what lies behind or in front of it); 0: no rim test
    rim_px: int = 2
    min_voxels: int = 8  # segments with fewer occupied voxels are dropped
    min_frames: int = 2  # ... and segments seen in fewer frames (one-off spurious detections)
    # a voxel several segments claim stays only with those that put at least this fraction of the
    # best claimant's points in it (per-voxel majority labelling, as semantic mapping does)
    vote_ratio: float = 0.5
    quantile: float = 0.01  # robust extents: quantile .. 1 - quantile
    # minimum box thickness: walls as the thinnest ground-truth wall, objects 2 cm; floors and
    # ceilings as the ground truth's slab (vrformats.boxes.STRUCT_SLAB)
    min_wall_thickness_m: float = 0.1
    min_object_size_m: float = 0.02
    # association of untracked object detections to untracked segments
    assoc_min_overlap: float = 0.2  # fraction of the detection's voxels already in the segment
    assoc_radius_m: float = 0.3  # or centroids this close with touching bounding boxes
    # class-agnostic fusion (no track ids): a segment sharing this fraction of its voxels with a
    # bigger one of any class joins it (one thing under two labels); 0 = off
    cross_class_shared: float = 0.5
    # geometric split of pooled (untracked) structure
    wall_line_tol_m: float = 0.06
    wall_gap_m: float = 0.5
    # an untracked wall piece lower than this is dropped (walls run floor to ceiling; a strip along
    # a ceiling edge or a skirting that a detector calls wall is not one)
    min_wall_height_m: float = 1.0

    def __post_init__(self):
        if int(self.stride) != self.stride or self.stride < 1:
            raise UserError(f"stride must be a positive integer, got {self.stride!r}")
        if not (self.voxel > 0 and math.isfinite(self.voxel)):
            raise UserError(f"voxel must be a positive number of metres, got {self.voxel!r}")
        if not 0.0 <= self.quantile < 0.25:
            raise UserError(f"quantile must be in [0, 0.25), got {self.quantile!r}")
