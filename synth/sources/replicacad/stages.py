"""Stand-in stages for a ReplicaCAD folder without its stage GLBs, built under stated, seeded rules.

The public SAPIEN copy of ReplicaCAD (github angli66/SAPIEN-ReplicaCAD, ``replica_cad/``) has every
config, URDF, navmesh and 89 of the 92 object GLBs, but no ``stages/*.glb``. :func:`build` copies a
ReplicaCAD folder SRC to OUT (files are copied, not linked) and writes

* for every ``configs/stages/*.stage_config.json`` whose ``render_asset`` is missing, a **stand-in
  stage** built from the stage's navmeshes (``synth.sources.replicacad.navmesh.standin_stage``) under
  a :class:`StageRules`, with a **stage card** beside it (``stages/<stem>.stage_card.json``: the
  variant, its rules and seed, the toolkit version, what was built, and what the importer's
  structure detection finds in it), and ``OUT/STANDIN.md`` (the variant, and what a stand-in cannot
  show);
* for every object config whose ``render_asset`` is missing, a grey box GLB with the bounds (in the
  GLB's own frame) of its ``collision_asset`` (bike_01, bike_02: their convex decompositions), else
  of a numbered sibling's render asset (clothes_hanger_01, which has no collision asset:
  clothes_hanger_02.glb).

``tools/replicacad_standin.py`` is its command line.

The stage from the navmeshes
    The navmeshes of every scene instance that uses the stage, walkable areas united
    (``frl_apartment_stage``: its scenes all name ``empty_stage_navmesh``, i.e.
    ``navmeshes/empty_stage.navmesh``, built without furniture; ``Stage_v3_scK_staging``: the 21
    ``v3_scK_staging_NN`` navmeshes, each built with its furniture, so their union recovers the floor
    under it). Floor = the main level's walkable area dilated by the agent radius (0.3 m) + the other
    levels' (stairs, landings); a 0.1 m floor slab under it; walls 0.1 m thick around it (outside it,
    so the footprint is the free floor; gaps between rooms become interior walls); a ceiling slab;
    raised levels as boxes (flat levels at their height; a sloped navmesh polygon, i.e. a flight of
    stairs, as steps of at most 0.18 m rise; a flight above a walkable space as a floating 0.15 m
    slab); window openings in straight exterior walls. Written in habitat's Y-up glTF frame, in the
    stage's own frame (the scenes place the stages at the identity; any other stage pose is refused).

    floor height: the navmesh only brackets the floor (Recast heights lie up to one cell height,
    0.2 m, above the surface); the stand-in takes the median bottom of the rigid objects of the
    stage's scenes that rest within that bracket, minus the stage config's collision ``margin``
    (0.01), rounded to 1 cm (frl_apartment_stage: 0.00); without such objects, the level height
    minus half a cell height.
    ceiling: 2.8 m above the floor in the ``standin`` variant: the lighting configs hang their
    interior lights at 2.3 and 2.6 m (habitat y; the two at 3.3 m stand outside the navmesh, beyond
    the east facade), so 2.8 m keeps them 0.2 m under the ceiling. The real FRL apartment's living
    area is higher and its ceiling is not flat; over the stairs the stand-in's ceiling is raised to
    the top of the stairs + 2.5 m, and the walls around the stairwell go up to it.
    windows: in every straight exterior wall run (a wall band touching the outside, away from the
    stairwell) at least 1.6 m long, one 1.2 m wide opening per 2.5 m of wall, centred in equal
    shares, sill 0.9 m, head 2.1 m above the floor. The real stage's windows are elsewhere.

The rules (:class:`StageRules`; named variants are YAML files in ``scenes/stages/``, read by
:func:`load_stage_variant`)
    ``footprint``: ``objects`` (the navmesh footprint, walls moved out to hold the box of every object
    of the stage's scenes that stands in the storey, see ``StandinSpec.keep``) or ``navmesh`` (the
    navmesh footprint alone, walls just outside it) or ``furnished`` (the union of the walkable areas of
    the navmeshes each scene has of its own, built with its furniture (``navmeshes/<scene>.navmesh``;
    scenes without one add nothing; the stage's navmesh when no scene has one), walls just outside it: the floor under furniture that
    stands in every scene is not floor, so walls cut into it and narrow passages split rooms). ``ceiling``: m above the floor. ``stairs``:
    False builds the main level only (no steps, no raised level; where the stairs were is floor only
    where it is the main level's footprint, and objects standing on the other levels are not held).
    ``windows``, ``window_frames`` (a frame protruding one cell around each opening, both sides),
    ``baseboards`` (a 0.08 m band one cell deep along the inside of every wall). ``skew_deg``: the
    stage is built on a grid rotated by this angle about the centre of the navmesh's bounds, then
    rotated back: its walls run off the world axes and follow the navmesh footprint within a cell.
    ``noise_m``: seeded Gaussian noise of this sigma (per axis, clipped at 3 sigma and at 0.45 of a
    cell so that no face turns over) moves every wall vertex horizontally; coincident vertices of
    every part move together, and T-junctions are split first, so the surface stays closed (the
    displacement is a function of a vertex's XY position: vertical edges stay vertical).
    ``materials`` (walls, floor, ceiling; the steps take the floor's, the trim stays plain):
    ``plain`` (the stand-in's base colour factors), ``painted`` (a seeded colour of
    ``PALETTE``), ``tiled`` (a generated grid of tiles of a seeded size in ``TILE_SIZE``, 4 x 4
    tiles a texture), ``textured`` (a generated seeded plaster on walls and ceiling, planks of wood
    on the floor). Textures are PNG base colour textures of glTF PBR materials with planar UVs
    (each face projected along its axis, in the grid's frame), read by ``synth.mesh.gltf`` and the
    Blender importer as an object GLB's. ``seed``: every random choice (noise, paint, tiles,
    textures) follows from it and the stage's name.

What the importer finds (:func:`structure_counts`)
    The stage card holds what ``synth scene import-replicacad`` derives from the stage built
    (``synth.mesh.stage_structure`` through the importer's stage reading, and the renderers'
    ``face_ids``): walls, rooms, doors, windows, the floor and ceiling instances the triangles get,
    rooms whose rect the floor fills less than ``FILL_WARN`` of (a warning at import).
"""

from __future__ import annotations

import json
import math
import os
import re
import shutil
import time
import zlib
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from vrformats.atomic import write_bytes_atomic, write_json_atomic, write_text_atomic
from vrformats.errors import UserError
from vrformats.fields import boolean, fail, is_integer, is_number, name_text, shown, text

from .habitat_format import hab_matrix, mapping, read_json
from .navmesh import (STANDIN_CEILING, STANDIN_COLOURS, NavMesh, NavPolygon, Standin, StandinSpec, footprint_of,
                      navmesh_for_scene, read_navmesh, standin_stage, write_standin_glb)

__all__ = ["StageRules", "StageVariant", "load_stage_variant", "load_stage_rules", "rules_from_dict", "stage_variants",
           "build", "fill", "make_stage", "structure_counts", "print_table", "CARD_SUFFIX"]

STAGE_SUFFIX = ".stage_config.json"
OBJECT_SUFFIX = ".object_config.json"
SCENE_SUFFIX = ".scene_instance.json"
CARD_SUFFIX = ".stage_card.json"
NOTES = "STANDIN.md"
BOX_COLOUR = (0.6, 0.6, 0.6, 1.0)
DEFAULT_VARIANT = "standin"  # the stand-in as the tool always built it
FOOTPRINTS = ("objects", "navmesh", "furnished")
MATERIALS = ("plain", "painted", "tiled", "textured")
SURFACES = ("walls", "floor", "ceiling")
CEILING_RANGE = (1.5, 10.0)  # m: StageRules.ceiling (and the command line's --ceiling)
VARIANT_CEILING_RANGE = (2.4, 3.0)  # m: a variant file's ceiling (a storey people live in)
MAX_NOISE_M = 0.02  # m: the largest noise_m
NOISE_CLIP_SIGMA = 3.0  # a displacement component is clipped at this many sigma ...
NOISE_CLIP_CELLS = 0.45  # ... and at this fraction of a cell (neighbours one cell apart never swap)
MAX_SKEW_DEG = 45.0
MAX_SEED = 2**32 - 1
TILE_SIZE = (0.3, 0.6)  # m: the side of a tile (seeded, rounded to 5 mm)
TILES_PER_TEXTURE = 4  # a tiled texture holds 4 x 4 tiles
PLASTER_PATCH_M = 1.0  # m of wall or ceiling one plaster texture covers
PLANK_WIDTH = (0.12, 0.2)  # m: the width of a floor plank (seeded)
PLANKS_PER_TEXTURE = 6
TEXTURE_PX = 256
# paints (linear base colour factors): a seeded one per surface
PALETTE = {"walls": ((0.80, 0.74, 0.62), (0.62, 0.70, 0.72), (0.74, 0.62, 0.58), (0.66, 0.72, 0.60), (0.88, 0.86, 0.78),
                     (0.56, 0.58, 0.66)),
           "floor": ((0.42, 0.30, 0.20), (0.58, 0.50, 0.40), (0.30, 0.30, 0.32), (0.62, 0.58, 0.52), (0.36, 0.24, 0.16)),
           "ceiling": ((0.95, 0.95, 0.95), (0.92, 0.90, 0.84), (0.88, 0.90, 0.92))}
RULE_KEYS = ("footprint", "ceiling", "stairs", "windows", "window_frames", "baseboards", "skew_deg", "noise_m",
             "materials", "seed")
CANNOT_SHOW = (
    "the real windows (a stand-in's are invented: straight exterior walls, away from the stairs and the furniture)",
    "textures and materials of the real stage (a variant's are generated)",
    "the real ceiling (the FRL apartment's living area is higher and not flat; a stand-in's is flat)",
    "door frames and lintels (openings between rooms reach the ceiling)",
    "walls better than about +-7 cm (a navmesh cell, its edge error and the agent radius)",
)


# --------------------------------------------------------------------------------------------
# the rules


def _default_materials() -> dict:
    return {s: "plain" for s in SURFACES}


@dataclass
class StageRules:
    """How a stand-in stage is built (see the module docstring). Checked when made: a bad value is a
    one-line ``SceneFormatError`` naming the field (``StageRules: ceiling: ...``)."""

    footprint: str = "objects"
    ceiling: float = STANDIN_CEILING
    stairs: bool = True
    windows: bool = True
    window_frames: bool = False
    baseboards: bool = False
    skew_deg: float = 0.0
    noise_m: float = 0.0
    materials: dict = field(default_factory=_default_materials)
    seed: int = 0

    def __post_init__(self):
        d = asdict(self)
        d["materials"] = dict(self.materials)
        checked = _check_rules("StageRules", d, "", CEILING_RANGE, complete=True)
        for k, v in checked.items():
            object.__setattr__(self, k, v)

    def to_dict(self) -> dict:
        d = asdict(self)
        d["materials"] = {s: self.materials[s] for s in SURFACES}
        return d

    @property
    def meshes_as_built(self) -> bool:
        """The builder's meshes are written as they are (no skew, noise or generated material)."""
        return self.skew_deg == 0 and self.noise_m == 0 and all(m == "plain" for m in self.materials.values())


def _check_rules(file, d, prefix: str, ceiling_range, complete: bool = False) -> dict:
    """The rule values of mapping ``d`` checked (``prefix`` + key names the field); missing keys take
    StageRules' defaults unless ``complete``."""
    if not isinstance(d, dict):
        fail(file, prefix.rstrip(".") or None, f"expected a mapping of rules, got {shown(d)}")
    for k in d:
        if k not in RULE_KEYS:
            fail(file, f"{prefix}{k}", f"unknown rule; the rules are: {', '.join(RULE_KEYS)}")
    out: dict = {}
    if "footprint" in d:
        v = d["footprint"]
        if v not in FOOTPRINTS:
            fail(file, f"{prefix}footprint", f"expected one of {', '.join(FOOTPRINTS)}, got {shown(v)}")
        out["footprint"] = v
    if "ceiling" in d:
        v = d["ceiling"]
        lo, hi = ceiling_range
        if not is_number(v):
            fail(file, f"{prefix}ceiling", f"expected a height in m, got {shown(v)}")
        if not lo <= v <= hi:
            fail(file, f"{prefix}ceiling", f"expected a height from {lo:g} to {hi:g} m above the floor, got {v:g}")
        out["ceiling"] = float(v)
    for k in ("stairs", "windows", "window_frames", "baseboards"):
        if k in d:
            out[k] = boolean(file, d[k], f"{prefix}{k}")
    if "skew_deg" in d:
        v = d["skew_deg"]
        if not is_number(v):
            fail(file, f"{prefix}skew_deg", f"expected an angle in degrees, got {shown(v)}")
        if abs(v) > MAX_SKEW_DEG:
            fail(file, f"{prefix}skew_deg", f"expected an angle from -{MAX_SKEW_DEG:g} to {MAX_SKEW_DEG:g} deg, got {v:g}")
        out["skew_deg"] = float(v)
    if "noise_m" in d:
        v = d["noise_m"]
        if not is_number(v):
            fail(file, f"{prefix}noise_m", f"expected a sigma in m, got {shown(v)}")
        if not 0 <= v <= MAX_NOISE_M:
            fail(file, f"{prefix}noise_m", f"expected a sigma from 0 to {MAX_NOISE_M:g} m, got {v:g}")
        out["noise_m"] = float(v)
    if "materials" in d:
        m = d["materials"]
        if not isinstance(m, dict):
            fail(file, f"{prefix}materials", f"expected a mapping of {', '.join(SURFACES)} to a material, got {shown(m)}")
        mats = _default_materials()
        for s, v in m.items():
            if s not in SURFACES:
                fail(file, f"{prefix}materials.{s}", f"unknown surface; the surfaces are: {', '.join(SURFACES)}")
            if v not in MATERIALS:
                fail(file, f"{prefix}materials.{s}", f"unknown material {shown(v)}; the materials are: {', '.join(MATERIALS)}")
            mats[s] = v
        out["materials"] = mats
    if "seed" in d:
        v = d["seed"]
        if not is_integer(v) or not 0 <= v <= MAX_SEED:
            fail(file, f"{prefix}seed", f"expected an integer from 0 to {MAX_SEED}, got {shown(v)}")
        out["seed"] = int(v)
    if complete:
        missing = [k for k in RULE_KEYS if k not in d]
        if missing:
            fail(file, prefix.rstrip(".") or None, f"missing rule(s) {', '.join(missing)}")
    return out


def rules_from_dict(d, file, field_prefix: str = "rules", ceiling_range=VARIANT_CEILING_RANGE) -> StageRules:
    """A :class:`StageRules` from a mapping of rules (missing rules: the defaults); errors name
    ``file`` and ``field_prefix.<rule>``."""
    return StageRules(**_check_rules(file, d, f"{field_prefix}." if field_prefix else "", ceiling_range))


@dataclass
class StageVariant:
    """A named variant: ``name``, ``description``, ``rules``, and the ``file`` it was read from."""

    name: str
    description: str
    rules: StageRules
    file: str | None = None

    def card(self) -> dict:
        return {"name": self.name, "description": self.description, "file": self.file}


def stages_dir() -> Path:
    """The shipped stage variants: ``scenes/stages/`` of the scenes folder (``SYNTH_SCENES_DIR``),
    or the package's own when that folder has none (a user's scenes need not copy them)."""
    from ...resources import DATA_DIR, scenes_dir

    d = scenes_dir() / "stages"
    return d if d.is_dir() else DATA_DIR / "stages"


def stage_variants() -> list[str]:
    """The names of the shipped stage variants."""
    return sorted(p.stem for p in stages_dir().glob("*.yaml"))


def load_stage_variant(name_or_path) -> StageVariant:
    """A stage variant file: a path that exists wins; a bare name (no folder, no suffix) is the
    shipped ``scenes/stages/NAME.yaml``. Every field is checked: one line naming the file and the
    field (``.../plain.yaml: rules.ceiling: ...``); an unknown name lists the shipped ones."""
    from vrformats.shipped import resolve_spec
    from vrformats.yamlfile import read_yaml

    path = resolve_spec(str(name_or_path), stages_dir(), "stage variant")
    doc = read_yaml(path)
    doc = mapping(path, doc, None, allowed=("name", "description", "rules"), required=("name", "rules"),
                  what="a mapping (name, description, rules)")
    name = name_text(path, doc["name"], "name")
    if not re.fullmatch(r"[A-Za-z0-9][A-Za-z0-9_.-]*", name):
        fail(path, "name", f"expected letters, digits, '_', '-' or '.', got {shown(name)}")
    desc = text(path, doc.get("description", ""), "description")
    return StageVariant(name, desc.strip(), rules_from_dict(doc["rules"], path, "rules"), str(path))


def load_stage_rules(name_or_path) -> StageRules:
    """The rules of a stage variant (:func:`load_stage_variant`)."""
    return load_stage_variant(name_or_path).rules


# --------------------------------------------------------------------------------------------
# reading the dataset


def _base(name: str) -> str:
    return name.replace("\\", "/").rstrip("/").rsplit("/", 1)[-1]


def merged(navs: list[NavMesh]) -> NavMesh:
    """One navmesh whose polygons are those of all ``navs`` (the first one's header and settings)."""
    first = navs[0]
    out = NavMesh(first.path if len(navs) == 1 else f"{first.path} (+{len(navs) - 1} more)", first.version, first.origin,
                  first.tile_width, first.tile_height, first.max_tiles, first.max_polys, first.settings,
                  [t for n in navs for t in n.tiles], [p for n in navs for p in n.polygons])
    return out


def stage_scenes(root: Path) -> dict[str, list[tuple[Path, dict]]]:
    """Stage base name -> [(scene file, scene doc)] of the scenes that use it."""
    out: dict[str, list] = {}
    for p in sorted((root / "configs" / "scenes").glob("*" + SCENE_SUFFIX)):
        doc = mapping(p, read_json(p), None)
        st = doc.get("stage_instance") or {}
        name = st.get("template_name")
        if not isinstance(name, str):
            continue
        t = np.asarray(st.get("translation", [0, 0, 0]), float)
        q = np.asarray(st.get("rotation", [1, 0, 0, 0]), float)
        if not (np.allclose(t, 0) and np.allclose(np.abs(q), [1, 0, 0, 0])):
            raise UserError(f"{p}: stage_instance: the stand-in needs the stage at the identity pose, got "
                            f"translation {t.tolist()} rotation {q.tolist()}")
        out.setdefault(_base(name), []).append((p, doc))
    return out


def object_bottoms(root: Path, scenes: list[tuple[Path, dict]]) -> list[float]:
    """World heights (habitat y) of the lowest vertex of every rigid object with a GLB in the scenes."""
    from ...mesh.gltf import glb_geometry
    from .habitat_format import Y_UP_TO_Z_UP as C

    cache: dict[str, tuple[np.ndarray, np.ndarray | None] | None] = {}
    out = []
    for _, doc in scenes:
        origin_all = str(doc.get("translation_origin", "")).lower()
        for inst in doc.get("object_instances", []) or []:
            name = _base(str(inst.get("template_name", "")))
            if name not in cache:
                cfg_p = root / "configs" / "objects" / f"{name}{OBJECT_SUFFIX}"
                cache[name] = None
                if cfg_p.is_file():
                    cfg = json.loads(cfg_p.read_text())
                    glb = (cfg_p.parent / str(cfg.get("render_asset", ""))).resolve()
                    if glb.is_file():
                        v = glb_geometry(glb).vertices @ C  # back to the GLB's own (habitat) frame
                        cache[name] = (v, np.asarray(cfg["COM"], float) if "COM" in cfg else None)
            if cache[name] is None:
                continue
            v, com = cache[name]
            s = np.ones(3) * float(inst.get("uniform_scale", 1.0)) * np.asarray(inst.get("non_uniform_scale", [1, 1, 1]), float)
            org = str(inst.get("translation_origin", origin_all)).lower()
            c = np.zeros(3) if org == "asset_local" else (com if com is not None else (v.min(0) + v.max(0)) / 2)
            R = hab_matrix(np.asarray(inst.get("rotation", [1, 0, 0, 0]), float))
            w = ((v - c) * s) @ R.T + np.asarray(inst.get("translation", [0, 0, 0]), float)
            out.append(float(w[:, 1].min()))
    return out


def scene_objects(root: Path, scene_path: Path, doc: dict) -> list:
    """The objects of a scene as the importer reads them (``synth.sources.replicacad.importer``: rigid
    objects at their configs' bounds, articulated ones from their URDFs, doors opened) without
    reading its stage, which is what is being built."""
    from .importer import scene_objects as read_scene_objects

    return read_scene_objects(root, scene_path, doc)


def object_footprints(root: Path, scenes: list[tuple[Path, dict]], floor_z: float, ceiling: float) -> tuple[list, list, list, list]:
    """XY footprints (4, 2) of the boxes of every object of the scenes that stands in the storey (its
    box's bottom between 0.1 m below the floor and the ceiling: on the floor, on furniture, on a
    wall), their tops and bottoms (z), and (scene, object id, class) of each, in the same order."""
    from ...scene.model import object_box

    quads, tops, bottoms, who = [], [], [], []
    for p, doc in scenes:
        for o in scene_objects(root, p, doc):
            b = object_box(o)
            if floor_z - 0.1 <= b.zmin < floor_z + ceiling:
                quads.append(b.corners_2d())
                tops.append(float(b.zmax))
                bottoms.append(float(b.zmin))
                who.append((p.name[: -len(SCENE_SUFFIX)], o.id, o.cls))
    return quads, tops, bottoms, who


def floor_height(nav: NavMesh, bottoms: list[float], margin: float) -> tuple[float, str]:
    z = nav.main_level().z
    ch = nav.settings.cell_height
    inside = [b for b in bottoms if z - ch - 0.02 <= b <= z]
    if len(inside) >= 3:
        return round(float(np.median(inside)) - margin, 2), f"median bottom of {len(inside)} objects - margin {margin:g}"
    return round(z - ch / 2.0, 3), "navmesh level - cell_height/2"


def box_glb(bounds: np.ndarray, path: Path, colour=BOX_COLOUR, name: str = "box") -> None:
    """A box GLB with the given bounds (GLB frame: the vertices are written as given)."""
    import trimesh
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial

    lo, hi = np.asarray(bounds[0], float), np.asarray(bounds[1], float)
    b = trimesh.creation.box(extents=np.maximum(hi - lo, 1e-4))
    b.apply_translation((lo + hi) / 2.0)
    b.visual = TextureVisuals(material=PBRMaterial(name=name, baseColorFactor=list(colour), metallicFactor=0.0,
                                                   roughnessFactor=0.9))
    scene = trimesh.Scene()
    scene.add_geometry(b, node_name=name, geom_name=name)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, trimesh.exchange.gltf.export_glb(scene))


def sibling_glb(glb: Path) -> Path | None:
    """``<stem>_NN.glb`` missing: an existing ``<stem>_MM.glb`` next to it (the same object's variant)."""
    m = re.fullmatch(r"(.*_)(\d+)", glb.stem)
    if not m:
        return None
    for cand in sorted(glb.parent.glob(f"{m.group(1)}*.glb")):
        if re.fullmatch(re.escape(m.group(1)) + r"\d+", cand.stem) and cand != glb:
            return cand
    return None


def glb_bounds_habitat(path: Path) -> np.ndarray:
    """Bounds of a GLB in its own (Y-up) frame, through the importer's reading (node transforms)."""
    from ...mesh.gltf import glb_geometry
    from .habitat_format import Y_UP_TO_Z_UP as C

    v = glb_geometry(path).vertices @ C
    return np.stack([v.min(0), v.max(0)])


def _refuse_outside_links(src: Path) -> None:
    """A link in SRC that leads outside it would copy another file of the user's into OUT: refused."""
    for d, dirs, files in os.walk(src):
        for n in dirs + files:
            p = Path(d) / n
            if p.is_symlink() and not p.resolve().is_relative_to(src):
                raise UserError(f"{p}: a link to {p.resolve()}, outside {src}; copy the file itself into the dataset")


# --------------------------------------------------------------------------------------------
# one stage under the rules


def _rot(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])


def _rotated_nav(nav: NavMesh, deg: float, centre: np.ndarray) -> NavMesh:
    """The navmesh with its polygons rotated by ``deg`` about ``centre`` (XY)."""
    R = _rot(deg)
    polys = []
    for p in nav.polygons:
        v = p.vertices.copy()
        v[:, :2] = (v[:, :2] - centre) @ R.T + centre
        polys.append(NavPolygon(v, p.area_id, p.flags, p.tile))
    return replace(nav, polygons=polys)


def _level_footprints(nav: NavMesh, levels) -> tuple[np.ndarray, np.ndarray, list]:
    """Every level's footprint on one grid: (origin, cell) and the masks, the main level's first."""
    cell = nav.cell_size
    pts = np.concatenate([p.vertices[:, :2] for p in nav.polygons])
    lo = np.floor((pts.min(axis=0) - 1.0) / cell) * cell
    shape = tuple(int(v) for v in np.ceil((pts.max(axis=0) + 1.0 - lo) / cell))
    return lo, cell, [footprint_of(lv.grid(lo, shape), nav.agent_radius).mask for lv in levels]


def make_stage(nav: NavMesh, floor_z: float, rules: StageRules, name: str, keep=(), tops=(),
               bottoms=()) -> tuple[Standin, dict, dict]:
    """The stand-in of ``nav`` under ``rules``: (the stand-in with its final meshes, the visuals of
    its parts for ``write_standin_glb``, what the rules did). ``keep``/``tops``/``bottoms``: the
    object footprints the floor holds (``StandinSpec.keep``; used only with ``footprint:
    objects``). ``name`` (the stage's) seeds the noise together with ``rules.seed``."""
    keep, tops, bottoms = list(keep), list(tops), list(bottoms)
    index = list(range(len(keep)))  # keep[k] is the caller's keep[index[k]]
    applied: dict = {"footprint": rules.footprint}
    if rules.footprint in ("navmesh", "furnished"):
        keep, tops, bottoms, index = [], [], [], []
    levels = nav.levels()
    if not rules.stairs and len(levels) > 1:
        lo, cell, feet = _level_footprints(nav, levels)
        other = np.zeros_like(feet[0])
        for f in feet[1:]:
            other |= f
        drop = set()
        for k, q in enumerate(keep):  # an object standing on the stairs or a landing: not held
            c = np.asarray(q, float).reshape(-1, 2).mean(axis=0)
            i, j = np.floor((c - lo) / cell).astype(int)
            inside = 0 <= i < feet[0].shape[0] and 0 <= j < feet[0].shape[1]
            if inside and other[i, j] and not feet[0][i, j]:
                drop.add(k)
        keep = [q for k, q in enumerate(keep) if k not in drop]
        tops = [t for k, t in enumerate(tops) if k not in drop] if tops else tops
        bottoms = [b for k, b in enumerate(bottoms) if k not in drop] if bottoms else bottoms
        applied["objects_dropped_with_stairs"] = [index[k] for k in sorted(drop)]
        index = [x for k, x in enumerate(index) if k not in drop]
        nav = replace(nav, polygons=list(levels[0].polygons))
        applied["levels_left_out"] = len(levels) - 1
    centre = None
    if rules.skew_deg:
        pts = np.concatenate([p.vertices[:, :2] for p in nav.polygons])
        centre = np.round((pts.min(axis=0) + pts.max(axis=0)) / 2.0, 3)
        nav = _rotated_nav(nav, -rules.skew_deg, centre)
        R = _rot(-rules.skew_deg)
        keep = [(np.asarray(q, float).reshape(-1, 2) - centre) @ R.T + centre for q in keep]
        applied["skew"] = {"deg": rules.skew_deg, "centre_xy": [float(v) for v in centre],
                           "note": "the report's grid, windows and footprints are in the rotated grid's frame"}
    spec = StandinSpec(floor_z=floor_z, ceiling=rules.ceiling, windows=rules.windows, keep=keep, keep_tops=tops,
                       keep_bottoms=bottoms, window_frames=rules.windows and rules.window_frames, baseboards=rules.baseboards,
                       window_jog=1 if rules.skew_deg else 0)
    s = standin_stage(nav, spec)
    for x in s.report["keep"]["not_held"]:  # back to the caller's indices
        x["index"] = index[x["index"]]
    visuals: dict = {}
    if not rules.meshes_as_built:
        cell = float(s.footprint.cell)
        parts, visuals, info = _finish(s.parts, rules, name, cell, centre)
        s.parts = parts
        applied.update(info)
    applied["materials"] = dict(rules.materials)
    return s, visuals, applied


# --------------------------------------------------------------------------------------------
# meshes: T-junctions, noise, UVs, rotation back


def _global(parts: dict) -> tuple[np.ndarray, dict]:
    """All parts' vertices as one table of distinct positions (1 um) and each part's faces into it."""
    names = list(parts)
    V = np.concatenate([np.asarray(parts[n].vertices, float) for n in names])
    key = np.round(V * 1e6).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    P = V[first]
    faces, off = {}, 0
    for n in names:
        nv = len(parts[n].vertices)
        faces[n] = inv[off: off + nv][np.asarray(parts[n].faces, np.int64)]
        off += nv
    return P, faces


def _split_t_junctions(P: np.ndarray, faces: dict) -> tuple[np.ndarray, dict, int]:
    """Split every triangle that has a vertex of another one inside one of its axis-aligned edges
    (a T-junction: the stand-in's rectangles meet that way), so that moving a vertex cannot open a
    crack. A triangle with such vertices on one edge is fanned from the opposite corner, one with
    them on several edges from a new vertex at its centroid. Returns (vertices, faces, splits)."""
    key = np.round(P * 1e6).astype(np.int64)
    inner: dict[tuple[int, int], list[int]] = {}  # (a, b) edge of vertex ids -> vertex ids strictly inside, a to b
    allf = np.concatenate(list(faces.values())) if faces else np.zeros((0, 3), np.int64)
    E = np.concatenate([allf[:, [0, 1]], allf[:, [1, 2]], allf[:, [2, 0]]])
    E = np.unique(np.sort(E, axis=1), axis=0)
    d = key[E[:, 1]] != key[E[:, 0]]
    for ax in range(3):
        sel = E[d[:, ax] & (d.sum(axis=1) == 1)]  # edges along axis ax
        if not len(sel):
            continue
        oth = [a for a in range(3) if a != ax]
        grp_keys = np.concatenate([key[:, oth], key[sel[:, 0]][:, oth]])
        _, g = np.unique(grp_keys, axis=0, return_inverse=True)
        g = g.reshape(-1)
        gv, ge = g[: len(P)], g[len(P):]
        span = float(key[:, ax].max() - key[:, ax].min()) + 2.0
        vk = gv * span + (key[:, ax] - key[:, ax].min())
        order = np.argsort(vk, kind="stable")
        vs = vk[order]
        a_, b_ = key[sel[:, 0], ax], key[sel[:, 1], ax]
        lo_k = ge * span + (np.minimum(a_, b_) - key[:, ax].min())
        hi_k = ge * span + (np.maximum(a_, b_) - key[:, ax].min())
        i0 = np.searchsorted(vs, lo_k, side="right")
        i1 = np.searchsorted(vs, hi_k, side="left")
        for e in np.flatnonzero(i1 > i0):
            ids = order[i0[e]:i1[e]]
            a, b = int(sel[e, 0]), int(sel[e, 1])
            ids = ids[np.argsort(key[ids, ax] * (1 if key[b, ax] > key[a, ax] else -1), kind="stable")]
            inner[(a, b)] = [int(i) for i in ids]
            inner[(b, a)] = [int(i) for i in ids[::-1]]
    if not inner:
        return P, faces, 0
    extra: list[np.ndarray] = []
    out, split = {}, 0
    for n, F in faces.items():
        tris = []
        for t in F:
            ins = [inner.get((int(t[k]), int(t[(k + 1) % 3])), []) for k in range(3)]
            if not any(ins):
                tris.append(t)
                continue
            split += 1
            loop = []
            for k in range(3):
                loop += [int(t[k])] + ins[k]
            if sum(bool(x) for x in ins) == 1:  # fan from the corner opposite the edge
                k = next(k for k in range(3) if ins[k])
                apex = int(t[(k + 2) % 3])
                chain = [int(t[k])] + ins[k] + [int(t[(k + 1) % 3])]
                tris += [np.array([chain[j], chain[j + 1], apex]) for j in range(len(chain) - 1)]
            else:  # fan from the centroid
                c = len(P) + len(extra)
                extra.append(P[list(t)].mean(axis=0))
                tris += [np.array([loop[j], loop[(j + 1) % len(loop)], c]) for j in range(len(loop))]
        out[n] = np.asarray(tris, np.int64).reshape(-1, 3)
    if extra:
        P = np.concatenate([P, np.asarray(extra)])
    return P, out, split


def _noise(P: np.ndarray, faces: dict, sigma: float, cell: float, rng) -> tuple[np.ndarray, dict]:
    """Horizontal displacement of every vertex whose XY position is a wall vertex's: one Gaussian
    draw (sigma per axis, clipped) per distinct XY, so coincident vertices and vertical edges move
    together."""
    walls = np.unique(faces.get("walls", np.zeros((0, 3), np.int64)))
    xy = np.round(P[:, :2] * 1e6).astype(np.int64)
    wall_xy = np.unique(xy[walls], axis=0)
    clip = min(NOISE_CLIP_SIGMA * sigma, NOISE_CLIP_CELLS * cell)
    D = np.clip(rng.normal(0.0, sigma, size=(len(wall_xy), 2)), -clip, clip)
    # match every vertex's XY against the wall XYs (sorted rows)
    allk = np.concatenate([wall_xy, xy])
    _, g = np.unique(allk, axis=0, return_inverse=True)
    g = g.reshape(-1)
    table = np.full(g.max() + 1, -1)
    table[g[: len(wall_xy)]] = np.arange(len(wall_xy))
    which = table[g[len(wall_xy):]]
    out = P.copy()
    moved = which >= 0
    out[moved, :2] += D[which[moved]]
    d = np.abs(D)
    return out, {"sigma_m": sigma, "clip_m": round(clip, 4), "positions": int(len(wall_xy)),
                 "vertices_moved": int(moved.sum()), "max_m": round(float(d.max()) if len(d) else 0.0, 4),
                 "rms_m": round(float(np.sqrt((D ** 2).mean())) if len(D) else 0.0, 4)}


def _uv_mesh(P_uv: np.ndarray, P: np.ndarray, F: np.ndarray, patch: float):
    """Vertices split per face axis, planar UVs (positions ``P_uv`` projected along each face's axis,
    over ``patch`` m), and the faces: (vertices, uv, faces)."""
    tri = P_uv[F]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ax = np.argmax(np.abs(n), axis=1)
    pairs = np.stack([F.reshape(-1), np.repeat(ax, 3)], axis=1)
    uniq, inv = np.unique(pairs, axis=0, return_inverse=True)
    keep = np.array([[1, 2], [0, 2], [0, 1]])[uniq[:, 1]]
    src = P_uv[uniq[:, 0]]
    uv = np.take_along_axis(src, keep, axis=1) / patch
    return P[uniq[:, 0]], uv, inv.reshape(-1, 3)


def _finish(parts: dict, rules: StageRules, name: str, cell: float, centre) -> tuple[dict, dict, dict]:
    """The parts after the rules' noise, materials and rotation back; their visuals; what was done."""
    import trimesh
    from trimesh.visual import TextureVisuals

    info: dict = {}
    P, faces = _global(parts)
    if rules.noise_m > 0:
        P, faces, split = _split_t_junctions(P, faces)
        info["t_junction_triangles_split"] = split
    P_uv = P.copy()  # UVs from the positions before noise and rotation: textures follow the walls
    if rules.noise_m > 0:
        rng = np.random.default_rng([rules.seed, zlib.crc32(name.encode())])
        P, info["noise"] = _noise(P, faces, rules.noise_m, cell, rng)
    if centre is not None:
        R = _rot(rules.skew_deg)
        P = P.copy()
        P[:, :2] = (P[:, :2] - centre) @ R.T + centre
    mats = {s: _material(s, rules.materials[s], rules.seed) for s in SURFACES}
    mats["steps"] = mats["floor"]
    out, visuals, used = {}, {}, {}
    for n, F in faces.items():
        m = mats.get(n)
        if m is not None and m["patch_m"]:
            V, uv, FF = _uv_mesh(P_uv, P, F, m["patch_m"])
            out[n] = trimesh.Trimesh(V, FF, process=False)
            visuals[n] = TextureVisuals(uv=uv, material=m["material"])
        else:
            ids, FF = np.unique(F, return_inverse=True)
            out[n] = trimesh.Trimesh(P[ids], FF.reshape(-1, 3), process=False)
            if m is not None and m["material"] is not None:
                visuals[n] = TextureVisuals(material=m["material"])
        if m is not None and n in SURFACES:
            used[n] = m["info"]
    info["material_details"] = used
    return out, visuals, info


# --------------------------------------------------------------------------------------------
# materials


def _srgb8(lin: np.ndarray) -> np.ndarray:
    lin = np.clip(lin, 0.0, 1.0)
    s = np.where(lin <= 0.0031308, 12.92 * lin, 1.055 * np.power(lin, 1 / 2.4) - 0.055)
    return np.clip(np.round(s * 255.0), 0, 255).astype(np.uint8)


def _periodic_noise(rng, n: int, scale_px: float) -> np.ndarray:
    """Smooth noise on an n x n image that tiles seamlessly (white noise low-passed in Fourier
    space), zero mean, unit standard deviation."""
    w = rng.standard_normal((n, n))
    f = np.fft.fftfreq(n) * n
    k = np.hypot(f[:, None], f[None, :])
    out = np.real(np.fft.ifft2(np.fft.fft2(w) * np.exp(-(k * scale_px / n) ** 2)))
    return (out - out.mean()) / max(float(out.std()), 1e-12)


def _tiles_image(rng, base: np.ndarray) -> np.ndarray:
    n, t = TEXTURE_PX, TILES_PER_TEXTURE
    step = n // t
    img = np.zeros((n, n, 3))
    jitter = 1.0 + rng.normal(0.0, 0.04, size=(t, t, 1))
    for i in range(t):
        for j in range(t):
            img[i * step:(i + 1) * step, j * step:(j + 1) * step] = base * jitter[i, j]
    img *= 1.0 + 0.02 * _periodic_noise(rng, n, 24.0)[:, :, None]
    grout = max(2, n // 128)
    yy, xx = np.mgrid[0:n, 0:n]
    line = ((yy % step) < grout) | ((xx % step) < grout)
    img[line] = base * 0.3
    return img


def _plaster_image(rng, base: np.ndarray) -> np.ndarray:
    n = TEXTURE_PX
    v = 0.05 * _periodic_noise(rng, n, 40.0) + 0.025 * _periodic_noise(rng, n, 8.0) + 0.012 * _periodic_noise(rng, n, 2.0)
    return base[None, None, :] * (1.0 + v[:, :, None])


def _wood_image(rng, base: np.ndarray) -> np.ndarray:
    n, p = TEXTURE_PX, PLANKS_PER_TEXTURE
    rows = np.arange(n)
    plank = rows * p // n  # planks run along u (image columns), one per n/p rows
    tone = 1.0 + rng.normal(0.0, 0.08, size=p)
    warp = _periodic_noise(rng, n, 6.0)
    phase = rng.uniform(0, 2 * np.pi, size=p)
    grain = np.sin(2 * np.pi * 24 * (rows[:, None] / n) + 3.0 * warp + phase[plank][:, None]) * 0.5 + 0.5
    img = base[None, None, :] * (tone[plank][:, None, None] * (0.88 + 0.18 * grain[:, :, None]))
    seam = (rows % (n // p)) < max(1, n // 256)
    img[seam] *= 0.55
    cut = rng.integers(0, n, size=p)  # one butt joint per plank
    for k in range(p):
        r = (plank == k) & ~seam
        img[r, cut[k]] *= 0.6
    return img


def _material(surface: str, kind: str, seed: int) -> dict:
    """{"material": PBRMaterial or None (plain), "patch_m": metres one texture spans or None, "info"}."""
    from PIL import Image
    from trimesh.visual.material import PBRMaterial

    if kind == "plain":
        return {"material": None, "patch_m": None, "info": {"kind": "plain"}}
    rng = np.random.default_rng([seed, SURFACES.index(surface), MATERIALS.index(kind)])
    if kind == "painted":
        pal = PALETTE[surface]
        c = pal[int(rng.integers(len(pal)))]
        mat = PBRMaterial(name=f"stage_{surface}_painted", baseColorFactor=[*c, 1.0], metallicFactor=0.0, roughnessFactor=0.9)
        return {"material": mat, "patch_m": None, "info": {"kind": kind, "colour": list(c)}}
    base = np.asarray(STANDIN_COLOURS[surface][:3], float)
    if kind == "tiled":
        tile = round(float(rng.uniform(*TILE_SIZE)) / 0.005) * 0.005
        img, patch = _tiles_image(rng, base), tile * TILES_PER_TEXTURE
        info = {"kind": kind, "tile_m": round(tile, 3)}
    elif surface == "floor":
        width = round(float(rng.uniform(*PLANK_WIDTH)) / 0.005) * 0.005
        img, patch = _wood_image(rng, base), width * PLANKS_PER_TEXTURE
        info = {"kind": kind, "pattern": "wood", "plank_m": round(width, 3)}
    else:
        img, patch = _plaster_image(rng, base), PLASTER_PATCH_M
        info = {"kind": kind, "pattern": "plaster"}
    info["texture_m"] = round(patch, 3)
    info["texture_px"] = TEXTURE_PX
    pil = Image.fromarray(_srgb8(img), "RGB")
    mat = PBRMaterial(name=f"stage_{surface}_{kind}", baseColorTexture=pil, baseColorFactor=[1.0, 1.0, 1.0, 1.0],
                      metallicFactor=0.0, roughnessFactor=0.9)
    return {"material": mat, "patch_m": patch, "info": info}


# --------------------------------------------------------------------------------------------
# what the importer finds


def structure_counts(root: Path, scene: tuple[Path, dict], glb: Path) -> dict:
    """What ``synth scene import-replicacad`` derives from the stage ``glb`` of ``scene`` (its file and doc):
    the importer's own stage reading (``synth.mesh.stage_structure``) and the renderers' triangle
    labels (``face_ids``). A stage the importer refuses gives ``{"error": <its message>}``."""
    from vrformats.boxes import CEILING_ID_BASE, FLOOR_ID_BASE, WALL_ID_BASE

    from ...mesh.gltf import glb_geometry
    from ...mesh.stage_structure import FILL_WARN, face_ids
    from .importer import _load_stage

    p, doc = scene
    t0 = time.time()
    try:
        stage, rep = _load_stage(root, p, doc, structure=True)
    except UserError as e:
        return {"scene": p.name[: -len(SCENE_SUFFIX)], "error": str(e)}
    m = glb_geometry(glb)  # the scenes place the stage at the identity (stage_scenes)
    tri = np.asarray(m.triangles)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    ids = face_ids(stage, tri.mean(axis=1), n)
    fill = (rep.get("rooms") or {}).get("fill_ratio", {})
    kinds = [o.kind for o in stage.openings]
    return {"scene": p.name[: -len(SCENE_SUFFIX)], "floor_z": stage.floor_z, "ceiling_height": stage.ceiling_height,
            "walls": len(stage.walls), "rooms": len(stage.rooms), "doors": kinds.count("door"),
            "windows": kinds.count("window"), "openings": len(kinds),
            "floors": int(len(np.unique(ids[(ids >= FLOOR_ID_BASE) & (ids < FLOOR_ID_BASE + 1000)]))),
            "ceilings": int(len(np.unique(ids[(ids >= CEILING_ID_BASE) & (ids < CEILING_ID_BASE + 1000)]))),
            "wall_instances_on_triangles": int(len(np.unique(ids[(ids >= WALL_ID_BASE) & (ids < WALL_ID_BASE + 1000)]))),
            "triangles": int(len(ids)), "unlabelled_triangles": int((ids == 0).sum()),
            "wall_directions_deg": rep.get("wall_directions", []),
            "fill_ratio": fill, "fill_ratio_warnings": sorted(r for r, v in fill.items() if v < FILL_WARN),
            "seconds": round(time.time() - t0, 2)}


# --------------------------------------------------------------------------------------------
# the dataset


def build(src: Path, final: Path, variant: StageVariant | StageRules | None = None, force: bool = False,
          structure_report: bool = True, overrides: dict | None = None) -> list[dict]:
    """Copy ``src`` to ``final`` with stand-ins built under ``variant`` (default: the shipped
    ``standin``), stage cards and ``STANDIN.md`` (built in a temporary sibling folder, then swapped
    in, so that readers of ``final`` never see a half-built dataset, and a failed build leaves
    nothing)."""
    variant = _variant(variant)
    src, final = Path(src).resolve(), Path(final).resolve()
    if not (src / "configs").is_dir():
        raise UserError(f"{src}: not a ReplicaCAD folder (no configs/)")
    if final.exists() and not force:
        raise UserError(f"{final}: exists (pass --force to replace it)")
    out = final.with_name(final.name + ".building")
    _refuse_outside_links(src)
    if out.exists():
        shutil.rmtree(out)
    try:
        shutil.copytree(src, out, symlinks=False)
        rows = fill(out, variant, structure_report=structure_report, overrides=overrides)
        write_notes(out, variant, rows, src, overrides)
    except BaseException:  # a failed build leaves nothing behind (OUT.building is a full copy of SRC)
        shutil.rmtree(out, ignore_errors=True)
        raise
    if final.exists():
        old = final.with_name(final.name + ".old")
        if old.exists():
            shutil.rmtree(old)
        final.rename(old)
        out.rename(final)
        shutil.rmtree(old)
    else:
        out.rename(final)
    return rows


def _variant(v) -> StageVariant:
    if v is None:
        return load_stage_variant(DEFAULT_VARIANT)
    if isinstance(v, StageRules):
        return StageVariant("custom", "rules given in code", v, None)
    return v


def fill(out: Path, variant: StageVariant | StageRules | None = None, structure_report: bool = True,
         overrides: dict | None = None) -> list[dict]:
    """Build, inside the dataset root ``out``, every missing object GLB (a box) and every missing stage
    GLB (a stand-in under the variant's rules, with its stage card). One row per file built."""
    from ...version import __version__

    variant = _variant(variant)
    rules = variant.rules
    out = Path(out)
    rows = []
    scenes = stage_scenes(out)
    # object stand-ins first: the stages are built around the scenes' objects, which need their GLBs
    for cfg_p in sorted((out / "configs" / "objects").rglob("*" + OBJECT_SUFFIX)):
        cfg = mapping(cfg_p, read_json(cfg_p), None)
        glb = (cfg_p.parent / str(cfg.get("render_asset", ""))).resolve()
        if glb.is_file():
            continue
        col = cfg.get("collision_asset")
        colp = (cfg_p.parent / str(col)).resolve() if isinstance(col, str) else None
        if colp is None or not colp.is_file():
            colp = sibling_glb(glb)  # clothes_hanger_01 has no collision asset: clothes_hanger_02's GLB
        if colp is None:
            rows.append({"file": str(glb.relative_to(out)), "kind": "object", "built": "NO: no collision asset, no sibling"})
            continue
        bounds = glb_bounds_habitat(colp)
        box_glb(bounds, glb, name=glb.stem)
        rows.append({"file": str(glb.relative_to(out)), "kind": "object", "from": str(colp.relative_to(out)),
                     "bounds_min": [round(float(v), 4) for v in bounds[0]], "bounds_max": [round(float(v), 4) for v in bounds[1]]})
    for cfg_p in sorted((out / "configs" / "stages").glob("*" + STAGE_SUFFIX)):
        t0 = time.time()
        cfg = mapping(cfg_p, read_json(cfg_p), None)
        glb = (cfg_p.parent / str(cfg.get("render_asset", ""))).resolve()
        if glb.is_file():
            continue
        name = cfg_p.name[: -len(STAGE_SUFFIX)]
        users = scenes.get(name, [])
        files = []
        for p, doc in users:
            f = navmesh_for_scene(out, doc, p)
            if f is not None and f not in files:
                files.append(f)
        if rules.footprint == "furnished":  # the scenes' own navmeshes, built with their furniture, where they have them
            own = [out / "navmeshes" / (p.name[: -len(SCENE_SUFFIX)] + ".navmesh") for p, doc in users
                   if doc.get("object_instances")]  # a scene without furniture (empty_stage) adds the empty floor
            files = [f for f in own if f.is_file()] or files
        if not files:
            rows.append({"file": str(glb.relative_to(out)), "kind": "stage", "built": "NO: no navmesh names this stage"})
            continue
        nav = merged([read_navmesh(f) for f in files])
        floor, why = floor_height(nav, object_bottoms(out, users), float(cfg.get("margin", 0.0)))
        hold = rules.footprint == "objects"
        keep, tops, bottoms, who = object_footprints(out, users, floor, rules.ceiling) if hold else ([], [], [], [])
        s, visuals, applied = make_stage(nav, floor, rules, name, keep, tops, bottoms)
        write_standin_glb(s, glb, visuals)
        r = s.report
        row = {"file": str(glb.relative_to(out)), "kind": "stage", "variant": variant.name,
               "navmeshes": [str(f.relative_to(out)) for f in files], "floor_z": floor, "floor_from": why,
               "ceiling_z": r["ceiling_z"], "stair_ceiling_z": r["stair_ceiling_z"],
               "footprint_m2": r["footprint_m2"], "main_footprint_m2": r["main_footprint_m2"],
               "raised_m2": r["raised_m2"], "windows": r["windows"], "quads": r["quads"],
               "levels": r["levels"], "window_list": s.windows,
               "objects_held": r["keep"]["held"], "objects_hung": r["keep"]["hung"], "objects_considered": r["keep"]["objects"],
               "floor_added_m2": r["keep"]["added_m2"],
               "objects_not_held": [dict(x, scene=who[x["index"]][0], id=who[x["index"]][1], cls=who[x["index"]][2])
                                    for x in r["keep"]["not_held"]]}
        for k in ("baseboards_m2", "window_frames"):
            if k in r:
                row[k] = r[k]
        row["parts"] = {n: int(len(m.faces)) for n, m in s.parts.items()}
        dropped = applied.pop("objects_dropped_with_stairs", None)
        if dropped is not None:
            applied["objects_dropped_with_stairs"] = [{"scene": who[k][0], "id": who[k][1], "cls": who[k][2]} for k in dropped]
        row["applied"] = applied
        if structure_report and users:
            row["structure"] = structure_counts(out, users[0], glb)
        row["seconds"] = round(time.time() - t0, 2)
        rows.append(row)
        st = row.get("structure")
        card = {"card": "stage", "format": 1, "stage": name, "glb": row["file"], "variant": variant.card(),
                "rules": rules.to_dict(), "seed": rules.seed, "overrides": overrides or {},
                "toolkit_version": __version__,
                "built": {k: v for k, v in row.items() if k not in ("structure", "seconds")},
                "structure": None if st is None else {k: v for k, v in st.items() if k != "seconds"}}
        write_json_atomic(glb.with_name(glb.stem + CARD_SUFFIX), card, indent=1)
    return rows


def _stage_line(r: dict) -> str:
    lv = ", ".join(f"{x['kind']} {x['z_navmesh']:.2f}: {x['owned_m2']:.1f} m2" for x in r["levels"])
    sc = "" if r["stair_ceiling_z"] is None else f" / stairs {r['stair_ceiling_z']:.2f}"
    d = (f"floor z {r['floor_z']:.2f} ({r['floor_from']}), ceiling {r['ceiling_z']:.2f}{sc}, "
         f"holds {r['objects_held']} of {r['objects_considered']} object footprints ({r['objects_hung']} hung, +{r['floor_added_m2']:.2f} m2), "
         f"footprint {r['footprint_m2']:.1f} m2 (main {r['main_footprint_m2']:.1f}), windows {r['windows']}, "
         f"{len(r['navmeshes'])} navmesh(es); levels: {lv}")
    st = r.get("structure")
    if st and "error" not in st:
        d += (f"; importer finds {st['walls']} walls, {st['rooms']} rooms, {st['doors']} doors, {st['windows']} windows"
              + (f", fill ratio under 0.85: {', '.join(st['fill_ratio_warnings'])}" if st["fill_ratio_warnings"] else ""))
    elif st:
        d += f"; importer refuses it: {st['error']}"
    return d


def _row_detail(r: dict, box_bounds: bool) -> str:
    """One built file's details: a stage's line, an object box (with its bounds or not), or why nothing was built."""
    if r["kind"] == "stage" and "footprint_m2" in r:
        return _stage_line(r)
    if "bounds_min" in r:
        return f"box {r['bounds_min']} .. {r['bounds_max']} from {r['from']}" if box_bounds else f"box from {r['from']}"
    return r.get("built", "")


def print_table(rows: list[dict]) -> None:
    print(f"{'built':<46} {'kind':<7} details")
    for r in rows:
        print(f"{r['file']:<46} {r['kind']:<7} {_row_detail(r, True)}")


def write_notes(out: Path, variant: StageVariant, rows: list[dict], src: Path, overrides: dict | None = None) -> Path:
    """``OUT/STANDIN.md``: what was built, under which variant, and what a stand-in cannot show."""
    from ...version import __version__

    rules = variant.rules
    lines = ["# Stand-in stages", "",
             f"This folder is a copy of `{src}` completed by `tools/replicacad_standin.py` (toolkit {__version__}):",
             "its stage GLBs (and any missing object GLB) are stand-ins, not the dataset's.", "",
             f"Stage variant: **{variant.name}**" + (f" ({variant.file})" if variant.file else "")
             + (f": {variant.description}" if variant.description else ""), "",
             "Rules: " + ", ".join(f"{k} {json.dumps(v)}" for k, v in rules.to_dict().items())
             + (f"; overridden on the command line: {json.dumps(overrides)}" if overrides else ""), "",
             "Each stage's card (rules, seed, what was built, what the importer finds in it) lies beside its GLB: "
             f"`stages/<stem>{CARD_SUFFIX}`.", "", "| file | built |", "|---|---|"]
    for r in rows:
        lines.append(f"| `{r['file']}` | {_row_detail(r, False).replace('|', '/')} |")
    lines += ["", "## What a stand-in cannot show", ""] + [f"- {x}" for x in CANNOT_SHOW] + [""]
    return write_text_atomic(Path(out) / NOTES, "\n".join(lines))
