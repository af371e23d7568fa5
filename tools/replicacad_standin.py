"""Complete a ReplicaCAD folder that lacks its stage GLBs (and a few object GLBs) with stand-ins.

    python tools/replicacad_standin.py SRC OUT [--no-windows] [--ceiling 2.8] [--force]

The public SAPIEN copy of ReplicaCAD (github angli66/SAPIEN-ReplicaCAD, ``replica_cad/``) has every
config, URDF, navmesh and 89 of the 92 object GLBs, but no ``stages/*.glb``. This script copies SRC
to OUT (files are copied, not linked: OUT may be edited without touching SRC) and writes:

* for every ``configs/stages/*.stage_config.json`` whose ``render_asset`` is missing, a **stand-in
  stage** built from the stage's navmeshes (``synth.sources.replicacad.navmesh.standin_stage``): the navmeshes of every
  scene instance that uses the stage, walkable areas united (``frl_apartment_stage``: its scenes all
  name ``empty_stage_navmesh``, i.e. ``navmeshes/empty_stage.navmesh``, built without furniture;
  ``Stage_v3_scK_staging``: the 21 ``v3_scK_staging_NN`` navmeshes, each built with its furniture, so
  their union recovers the floor under it). Floor = the main level's walkable area dilated by the
  agent radius (0.3 m) + the other levels' (stairs, landings); a 0.1 m floor slab under it; walls 0.1
  m thick around it (outside it, so the footprint is the free floor; gaps between rooms become
  interior walls); a ceiling slab; raised levels as boxes (flat levels at their height; a sloped
  navmesh polygon, i.e. a flight of stairs, as steps of at most 0.18 m rise; a flight above a
  walkable space as a floating 0.15 m slab); window openings in straight exterior walls (see
  ``--no-windows``). Written in habitat's Y-up glTF frame, in the stage's own frame (the scenes
  place the stages at the identity; any other stage pose is refused).
* for every object config whose ``render_asset`` is missing, a grey box GLB with the bounds (in the
  GLB's own frame) of its ``collision_asset`` (bike_01, bike_02: their convex decompositions), else
  of a numbered sibling's render asset (clothes_hanger_01, which has no collision asset:
  clothes_hanger_02.glb).

Choices (stand-in, not measurements)
    floor height: the navmesh only brackets the floor (Recast heights lie up to one cell height,
    0.2 m, above the surface); the stand-in takes the median bottom of the rigid objects of the
    stage's scenes that rest within that bracket, minus the stage config's collision ``margin``
    (0.01), rounded to 1 cm (frl_apartment_stage: 0.00); without such objects, the level height
    minus half a cell height.
    ceiling: 2.8 m above the floor (``--ceiling``): the lighting configs hang their interior lights
    at 2.3 and 2.6 m (habitat y; the two at 3.3 m stand outside the navmesh, beyond the east facade),
    so 2.8 m keeps them 0.2 m under the ceiling. The real FRL apartment's living area is higher and
    its ceiling is not flat; over the stairs the stand-in's ceiling is raised to the top of the
    stairs + 2.5 m, and the walls around the stairwell go up to it.
    windows: in every straight exterior wall run (a wall band touching the outside, away from the
    stairwell) at least 1.6 m long, one 1.2 m wide opening per 2.5 m of wall, centred in equal
    shares, sill 0.9 m, head 2.1 m above the floor. The real stage's windows are elsewhere.

Prints one table row per file built. See /work/rcad_real/STANDIN.md (written by ``--notes``) for
what the stand-in cannot show.
"""

from __future__ import annotations

import argparse
import json
import math
import shutil
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from vrformats.atomic import write_bytes_atomic, write_text_atomic  # noqa: E402
from vrformats.errors import UserError  # noqa: E402
from synth.sources.replicacad.habitat_format import hab_matrix, mapping, read_json  # noqa: E402
from synth.sources.replicacad.navmesh import (  # noqa: E402
    NavMesh, StandinSpec, navmesh_for_scene, read_navmesh, standin_stage, write_standin_glb,
)

STAGE_SUFFIX = ".stage_config.json"
OBJECT_SUFFIX = ".object_config.json"
SCENE_SUFFIX = ".scene_instance.json"
BOX_COLOUR = (0.6, 0.6, 0.6, 1.0)


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
    from synth.mesh.gltf import glb_geometry
    from synth.sources.replicacad.habitat_format import Y_UP_TO_Z_UP as C

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
    """The objects of a scene as the importer reads them (``synth.sources.replicacad.importer``: rigid objects at their
    configs' bounds, articulated ones from their URDFs, doors opened) without reading its stage,
    which is what is being built."""
    from synth.sources.replicacad.importer import scene_objects as read_scene_objects

    return read_scene_objects(root, scene_path, doc)


def object_footprints(root: Path, scenes: list[tuple[Path, dict]], floor_z: float, ceiling: float) -> tuple[list, list, list, list]:
    """XY footprints (4, 2) of the boxes of every object of the scenes that stands in the storey (its
    box's bottom between 0.1 m below the floor and the ceiling: on the floor, on furniture, on a
    wall), their tops and bottoms (z), and (scene, object id, class) of each, in the same order."""
    from synth.scene.model import object_box

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
    import re

    m = re.fullmatch(r"(.*_)(\d+)", glb.stem)
    if not m:
        return None
    for cand in sorted(glb.parent.glob(f"{m.group(1)}*.glb")):
        if re.fullmatch(re.escape(m.group(1)) + r"\d+", cand.stem) and cand != glb:
            return cand
    return None


def glb_bounds_habitat(path: Path) -> np.ndarray:
    """Bounds of a GLB in its own (Y-up) frame, through the importer's reading (node transforms)."""
    from synth.mesh.gltf import glb_geometry
    from synth.sources.replicacad.habitat_format import Y_UP_TO_Z_UP as C

    v = glb_geometry(path).vertices @ C
    return np.stack([v.min(0), v.max(0)])


def _refuse_outside_links(src: Path) -> None:
    """A link in SRC that leads outside it would copy another file of the user's into OUT: refused."""
    import os

    for d, dirs, files in os.walk(src):
        for n in dirs + files:
            p = Path(d) / n
            if p.is_symlink() and not p.resolve().is_relative_to(src):
                raise UserError(f"{p}: a link to {p.resolve()}, outside {src}; copy the file itself into the dataset")


def build(src: Path, final: Path, spec: StandinSpec, force: bool = False, hold: bool = True) -> list[dict]:
    """Copy ``src`` to ``final`` with stand-ins (built in a temporary sibling folder, then swapped in,
    so that readers of ``final`` never see a half-built dataset)."""
    src, final = src.resolve(), final.resolve()
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
        rows = _fill(out, spec, hold)
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


def _fill(out: Path, spec: StandinSpec, hold: bool = True) -> list[dict]:
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
        if not files:
            rows.append({"file": str(glb.relative_to(out)), "kind": "stage", "built": "NO: no navmesh names this stage"})
            continue
        nav = merged([read_navmesh(f) for f in files])
        floor, why = floor_height(nav, object_bottoms(out, users), float(cfg.get("margin", 0.0)))
        keep, tops, bottoms, who = object_footprints(out, users, floor, spec.ceiling) if hold else ([], [], [], [])
        s = standin_stage(nav, StandinSpec(floor_z=floor, ceiling=spec.ceiling, wall_cells=spec.wall_cells, windows=spec.windows,
                                           keep=keep, keep_tops=tops, keep_bottoms=bottoms, keep_margin=spec.keep_margin, window_clear=spec.window_clear))
        write_standin_glb(s, glb)
        r = s.report
        rows.append({"file": str(glb.relative_to(out)), "kind": "stage",
                     "navmeshes": [str(f.relative_to(out)) for f in files], "floor_z": floor, "floor_from": why,
                     "ceiling_z": r["ceiling_z"], "stair_ceiling_z": r["stair_ceiling_z"],
                     "footprint_m2": r["footprint_m2"], "main_footprint_m2": r["main_footprint_m2"],
                     "raised_m2": r["raised_m2"], "windows": r["windows"], "quads": r["quads"],
                     "levels": r["levels"], "window_list": s.windows,
                     "objects_held": r["keep"]["held"], "objects_hung": r["keep"]["hung"], "objects_considered": r["keep"]["objects"],
                     "floor_added_m2": r["keep"]["added_m2"],
                     "objects_not_held": [dict(x, scene=who[x["index"]][0], id=who[x["index"]][1], cls=who[x["index"]][2])
                                          for x in r["keep"]["not_held"]],
                     "seconds": round(time.time() - t0, 2)})
    return rows


def print_table(rows: list[dict]) -> None:
    print(f"{'built':<46} {'kind':<7} details")
    for r in rows:
        if r["kind"] == "stage" and "footprint_m2" in r:
            lv = ", ".join(f"{x['kind']} {x['z_navmesh']:.2f}: {x['owned_m2']:.1f} m2" for x in r["levels"])
            sc = "" if r["stair_ceiling_z"] is None else f" / stairs {r['stair_ceiling_z']:.2f}"
            d = (f"floor z {r['floor_z']:.2f} ({r['floor_from']}), ceiling {r['ceiling_z']:.2f}{sc}, "
                 f"holds {r['objects_held']} of {r['objects_considered']} object footprints ({r['objects_hung']} hung, +{r['floor_added_m2']:.2f} m2), "
                 f"footprint {r['footprint_m2']:.1f} m2 (main {r['main_footprint_m2']:.1f}), windows {r['windows']}, "
                 f"{len(r['navmeshes'])} navmesh(es); levels: {lv}")
        elif "bounds_min" in r:
            d = f"box {r['bounds_min']} .. {r['bounds_max']} from {r['from']}"
        else:
            d = r.get("built", "")
        print(f"{r['file']:<46} {r['kind']:<7} {d}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("src", type=Path, help="ReplicaCAD folder (replica_cad/ of the SAPIEN copy)")
    ap.add_argument("out", type=Path, help="output folder (a complete dataset root)")
    ap.add_argument("--ceiling", type=float, default=StandinSpec.ceiling, help="ceiling height above the floor, m")
    ap.add_argument("--no-windows", action="store_true", help="no window openings")
    ap.add_argument("--no-hold-objects", action="store_true",
                    help="walls from the navmesh alone (not moved out around the scenes' objects)")
    ap.add_argument("--force", action="store_true", help="replace OUT if it exists")
    ap.add_argument("--report", type=Path, help="write the rows as JSON here")
    a = ap.parse_args(argv)
    try:
        if not (math.isfinite(a.ceiling) and 1.5 <= a.ceiling <= 10.0):
            raise UserError(f"--ceiling: expected a height from 1.5 to 10 m, got {a.ceiling:g}")
        rows = build(a.src, a.out, StandinSpec(ceiling=a.ceiling, windows=not a.no_windows), a.force,
                     hold=not a.no_hold_objects)
    except UserError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print_table(rows)
    if a.report:
        write_text_atomic(a.report, json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
