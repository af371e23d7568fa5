"""Every threshold of VideoReloc in one place, with the paper's values as defaults.

Section references are to the paper, *VideoReloc: Long-Term Indoor Video Relocalization against a
Kilobyte-Scale Semantic Scene Graph* (https://videoreloc.github.io; CITATION.cff): Sec. III-B map,
III-C per-clip graph construction, III-D candidates and verification, III-E orientation cues and
refinement, IV-A implementation details. Values the paper does not state are marked "ours" with
the reason for the choice.

A config is a frozen dataclass tree; ``Config().replace("registration.center_match_m", 0.4)``
returns a modified copy, and ``Config.from_dict`` / ``to_dict`` round-trip it through YAML/JSON
for experiment specs.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any


from vrformats import fields
from vrformats.errors import UserError
from vrformats.yamlfile import read_yaml





@dataclass(frozen=True)
class MapConfig:
    """The ``map`` section of :class:`Config`: how a loaded box map indexes its objects for
    registration (the center-distance edges and class-keyed triangles of ``reloc.map.boxmap.BoxMap``).

    Not how a map is built from a mapping tour: those knobs are
    :class:`reloc.map.settings.MapBuildSettings` (``reloc map build``), which is no part of Config."""

    # Sec. III-B: "nearby object pairs form center-distance edges, and non-degenerate triples form
    # an index keyed by vertex classes and edge lengths". Edge range from Sec. IV-A (0.2-8 m).
    triangle_edge_min_m: float = 0.2
    triangle_edge_max_m: float = 8.0
    # ours: a triangle whose smallest angle is below this is degenerate (collinear centers fix
    # no rotation about their line)
    triangle_min_angle_deg: float = 10.0


@dataclass(frozen=True)
class OdometryConfig:
    # Sec. III-C: Open3D geometry-based RGB-D odometry chains consecutive frames. Resolution,
    # stride, iterations and min_information are ours, chosen by the benchmark
    # `reloc bench odometry TOUR` (speed/drift trade-off on the 640x480 apt_0 query
    # tour, 300-frame windows): 160 px / stride 2 costs ~3-4 ms per frame on 2 shared cores with
    # 0.75 % median translation drift and 0.08 deg/m (whole tour: median 0.25 %, worst window
    # 4 % in a weakly constrained stretch); 80 px drifts ~2x more, 320 px costs ~3x more and
    # 640 px ~20x more for no gain at clip lengths.
    method: str = "point_to_plane"  # point_to_plane (depth only) | hybrid (Open3D, needs RGB)
    width: int = 160  # odometry image width; height keeps the aspect ratio (chosen by the benchmark)
    stride: int = 2  # run odometry every `stride` frames, interpolate the poses in between (benchmark)
    depth_max_m: float = 6.0
    depth_diff_max_m: float = 0.07  # projective association: larger depth / plane gaps are outliers
    depth_huber_delta_m: float = 0.05  # ours: Huber delta of the point-to-plane loss (Open3D's default)
    # Gauss-Newton iterations per pyramid level, coarse to fine (finest last); one level, chosen
    # by the benchmark: coarse levels of depth-only odometry slide along weakly constrained
    # directions and drifted more (6,6,6: 1.1 % vs 0.7 %); the constant-velocity seed replaces them
    iterations: tuple[int, ...] = (20,)
    # ours: gates that end a clip (Open3D's own success flag is True even without overlap)
    min_fitness: float = 0.5  # fraction of valid pixels with a correspondence
    max_inlier_rmse_m: float = 0.05
    max_step_translation_m: float = 0.5  # per odometry step: larger means a capture gap
    max_step_rotation_deg: float = 30.0
    min_valid_depth_fraction: float = 0.05
    # ours: a frame with less valid depth than min_valid_depth_fraction (or, where the detector needs
    # it, no RGB) is degenerate; reloc run counts them, and a tour with a larger share than this fails
    # (a broken render or capture, not a relocalization result)
    max_degenerate_fraction: float = 0.25
    # ours: directions whose point-to-plane information (normalised, per inlier; rotations scaled
    # by the median depth) is below this are degenerate (e.g. sliding along one wall); the
    # constant-velocity prediction replaces the estimate along them
    min_information: float = 0.005  # chosen by the benchmark (0.003-0.005 best; 0.03 drifts 5 %)


@dataclass(frozen=True)
class DetectionConfig:
    # Sec. IV-A: a mask-box pair requires 2D IoU > 0.4 and center-depth difference <= 0.4 z + 0.5 m
    mask_box_iou: float = 0.4
    depth_check_scale: float = 0.4
    depth_check_offset_m: float = 0.5
    # ours: smaller masks carry too few depth pixels to place anything (observe() drops them; the
    # oracle detector reports no smaller instance)
    min_mask_pixels: int = 20


@dataclass(frozen=True)
class ObservationConfig:
    # Sec. IV-A: object observations use every fifth frame and the final frame of a clip
    stride: int = 5
    # Sec. III-C: farthest-point sampling retains up to twelve visible-surface samples
    surface_samples: int = 12
    # ours: "depth-consistent" mask pixels lie within this band of the mask's median depth
    depth_band_scale: float = 0.15
    depth_band_offset_m: float = 0.3
    # ours: same-class observations closer than this (centers, clip frame) join one fused node
    fusion_radius_m: float = 0.5
    max_node_samples: int = 96  # ours: per node, farthest-point subsampled when exceeded
    # ours: structure fuses by plane (walls: normals within 20 degrees, plane offsets within
    # 0.2 m, centers within 4 m) or by a wider radius (floors, ceilings)
    wall_fusion_normal_deg: float = 20.0
    wall_fusion_offset_m: float = 0.2
    wall_fusion_radius_m: float = 4.0
    floor_fusion_radius_m: float = 2.0
    # ours: bounded work per mask: at most this many pixels are back-projected (grid-subsampled
    # beyond that), and farthest-point sampling runs over about this many of them
    max_points_per_mask: int = 4000
    fps_pool: int = 400


@dataclass(frozen=True)
class ClipConfig:
    # Sec. IV-A: clips begin at 100 frames, grow by 50 to at most 600, and close once
    # |K_c| >= 20 and the camera path reaches 2 m
    start_frames: int = 100
    grow_frames: int = 50
    max_frames: int = 600
    min_nodes: int = 20
    min_path_m: float = 2.0
    adaptive: bool = True  # False: fixed clips of `start_frames` (the paper's Table III ablation)


@dataclass(frozen=True)
class RegistrationConfig:
    # Sec. IV-A: at most 48 local instances form the query triplets
    max_local_instances: int = 48
    # compatible map triangles have 0.2-8 m edges within 0.3 m of the query
    triangle_edge_tol_m: float = 0.3
    max_indexed_matches: int = 500
    random_draws: int = 2000
    # Sec. III-D: same-class pairs within 0.5 m
    center_match_m: float = 0.5
    # anchor route runs when S_g is absent, has fewer than 6 center matches, or fewer than 60 %
    # of instances pass the 0.5 m box-surface test
    min_graph_matches: int = 6
    min_graph_surface_fraction: float = 0.6
    # per-frame RANSAC: poses ranked by 0.3 m box-surface inliers (object instances)
    anchor_inlier_m: float = 0.3
    anchor_ransac_iterations: int = 200  # ours
    anchor_refits: int = 2  # ours: the winner is refitted on its inliers' box centers this often
    anchor_min_inliers: int = 6
    anchor_max_rmse_m: float = 0.5
    max_anchors: int = 25
    anchor_consensus: float = 0.6  # translation (m) + rotation (rad)
    anchor_min_support: int = 3
    # anchors reject S_g beyond a median disagreement of 1.5 m or 40 degrees
    veto_translation_m: float = 1.5
    veto_rotation_deg: float = 40.0
    # Eq. 2: box-surface consistency with tau = 0.5 m
    kappa_tau_m: float = 0.5
    # orientation fallback: four yaw candidates; inliers within 0.5 m; 45 degrees of the
    # odometry prediction
    fallback_inlier_m: float = 0.5
    fallback_yaw_window_deg: float = 45.0


@dataclass(frozen=True)
class RefinementConfig:
    # Sec. III-E gravity gate: 30 degrees, 60 for the camera-up fallback
    gravity_gate_deg: float = 30.0
    gravity_gate_camera_up_deg: float = 60.0
    # Manhattan yaw: at least five normals, circular MAD <= 12 degrees
    manhattan_min_normals: int = 5
    manhattan_max_mad_deg: float = 12.0
    # Eq. 3 scales (ours; the paper names them without values)
    sigma_f_m: float = 0.1
    sigma_g_deg: float = 2.0
    prior_translation_m: float = 1.0
    prior_rotation_deg: float = 10.0
    iterations: int = 8  # outer iterations: assignments, closest points, one Gauss-Newton step
    orientation_aware: bool = True  # False: point-to-point refinement (Table III ablation)
    # ours: plane fitting for the gravity/wall cues
    plane_min_points: int = 30
    plane_max_rms_m: float = 0.03
    # ours: wall normals give a vertical (their common orthogonal direction) only when they span
    # two clearly different directions (second singular value at least this fraction of the first)
    gravity_wall_spread: float = 0.3
    # ours: a structure-derived vertical further than this from the camera-up direction is
    # implausible; the camera-up fallback is used instead
    gravity_max_from_camera_up_deg: float = 60.0
    # ours: a wall normal gives a yaw only when its horizontal part is at least this long (it is
    # within about 45 degrees of horizontal)
    wall_min_horizontal: float = 0.7


@dataclass(frozen=True)
class BackendConfig:
    # Sec. III-F tracking: the boundary odometry's prediction is accepted when the new clip's
    # surface support (kappa, Eq. 2) reaches this (ours: the same 60 % the anchor route uses to
    # call a graph placement weak)
    tracking: bool = True
    track_min_kappa: float = 0.6
    # run-level decision: placement-consistent sub-runs agree within 0.5 m and 10 degrees;
    # replacements are box-refined under a 0.5 m / 5 degree prior
    run_level: bool = True
    subrun_translation_m: float = 0.5
    subrun_rotation_deg: float = 10.0
    revision_prior_translation_m: float = 0.5
    revision_prior_rotation_deg: float = 5.0
    # clip-rigid pose graph: object-graph (absolute) constraints weigh 20, demoted to 1 when
    # inconsistent; Gauss-Seidel relaxation with chordal rotation averaging and Geman-McClure
    absolute_weight: float = 20.0
    demoted_weight: float = 1.0
    relative_weight: float = 20.0  # ours: boundary odometry is as trusted as a consistent placement
    gm_scale: float = 0.5  # ours: Geman-McClure scale of the residual (m + rad)
    graph_iterations: int = 30  # ours
    # causal evaluation: "at run starts, it uses per-frame localization when available"
    frame_localization: bool = True


@dataclass(frozen=True)
class ClipRigidConfig:
    # ours: the clip-rigid controls of the per-frame baselines (Table I dagger rows): a candidate
    # S_i = T_i V_i^-1 supports a frame when it predicts its position within pos_tol_m and its
    # orientation within rot_tol_deg; a consensus needs min_support frames (its own included)
    pos_tol_m: float = 0.25
    rot_tol_deg: float = 5.0
    min_support: int = 2


@dataclass(frozen=True)
class Config:
    map: MapConfig = field(default_factory=MapConfig)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    detection: DetectionConfig = field(default_factory=DetectionConfig)
    observation: ObservationConfig = field(default_factory=ObservationConfig)
    clips: ClipConfig = field(default_factory=ClipConfig)
    registration: RegistrationConfig = field(default_factory=RegistrationConfig)
    refinement: RefinementConfig = field(default_factory=RefinementConfig)
    backend: BackendConfig = field(default_factory=BackendConfig)
    clip_rigid: ClipRigidConfig = field(default_factory=ClipRigidConfig)

    def replace(self, dotted: str, value: Any) -> "Config":
        section, _, name = dotted.partition(".")
        if not name or section not in {f.name for f in dataclasses.fields(self)}:
            raise KeyError(f"unknown config key {dotted!r} (expected SECTION.NAME)")
        sub = getattr(self, section)
        if name not in {f.name for f in dataclasses.fields(sub)}:
            raise KeyError(f"unknown config key {dotted!r}")
        return dataclasses.replace(self, **{section: dataclasses.replace(sub, **{name: value})})

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @staticmethod
    def from_dict(d: dict | None, source: str = "<config>", under: str = "") -> "Config":
        """Overrides on top of the defaults; unknown sections or keys and values of the wrong type are
        a SceneFormatError naming ``source`` and the key (``under``: where the overrides sit in the
        file, e.g. ``config`` in an experiment spec, prefixed to the key), checked by vrformats.fields."""
        cfg = Config()
        at = f"{under}." if under else ""
        sections = {f.name for f in dataclasses.fields(Config)}
        for section, values in (d or {}).items():
            if section not in sections:
                fields.fail(source, f"{at}{section}", f"unknown section; known: {', '.join(sorted(sections))}")
            fields.mapping(source, values, f"{at}{section}", what="a mapping")
            names = {f.name for f in dataclasses.fields(getattr(cfg, section))}
            for name, v in values.items():
                key = f"{at}{section}.{name}"
                if name not in names:
                    fields.fail(source, key, "unknown setting")
                cur = getattr(getattr(cfg, section), name)
                if isinstance(cur, tuple):
                    if not isinstance(v, (list, tuple)):
                        fields.fail(source, key, f"expected a list of integers, got {fields.shown(v)}")
                    v = tuple(fields.integer(source, x, f"{key}[{i}]") for i, x in enumerate(v))
                elif isinstance(cur, bool):
                    v = fields.boolean(source, v, key)
                elif isinstance(cur, str):
                    if not isinstance(v, str):
                        fields.fail(source, key, f"expected a name, got {fields.shown(v)}")
                elif isinstance(cur, int):
                    v = fields.whole_number(source, v, key)
                else:
                    v = fields.number(source, v, key)
                cfg = cfg.replace(f"{section}.{name}", v)
        return cfg


def load_config(path) -> Config:
    """A YAML/JSON file of overrides (``registration: {center_match_m: 0.4}``) on the paper's defaults."""
    p = Path(path)
    if not p.is_file():
        raise UserError(f"{p}: config file not found")
    d = read_yaml(p)
    if d is not None and not isinstance(d, dict):
        raise UserError(f"{p}: expected a mapping of sections (map, odometry, clips, registration, ...)")
    return Config.from_dict(d, source=str(p))
