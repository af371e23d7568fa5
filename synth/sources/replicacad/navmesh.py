"""habitat-sim navigation meshes (``.navmesh``): the walkable polygons, levels and floor footprints.

No Blender here; numpy and scipy only.

File layout (little-endian; habitat-sim ``PathFinder::saveNavMesh`` writing Recast/Detour data,
verified byte for byte on ReplicaCAD's ``navmeshes/*.navmesh``)::

    int32  magic 'MSET' (bytes b"TESM"), int32 version (2), int32 numTiles
    dtNavMeshParams   float orig[3], tileWidth, tileHeight; int32 maxTiles, maxPolys      28 bytes
    NavMeshSettings   13 float32: cellSize, cellHeight, agentHeight, agentRadius,
                      agentMaxClimb, agentMaxSlope, regionMinSize, regionMergeSize,
                      edgeMaxLen, edgeMaxError, vertsPerPoly, detailSampleDist,
                      detailSampleMaxError; then 3 bools (filterLowHangingObstacles,
                      filterLedgeSpans, filterWalkableLowHeightSpans) + 1 pad byte       56 bytes
    numTiles x { uint32 tileRef, int32 dataSize, dataSize bytes of Detour tile data }

Detour tile data (``dtCreateNavMeshData``, DT_NAVMESH_VERSION 7), every section 4-byte aligned::

    dtMeshHeader   int32 magic 'DNAV', version, x, y, layer, userId, polyCount, vertCount,
                   maxLinkCount, detailMeshCount, detailVertCount, detailTriCount, bvNodeCount,
                   offMeshConCount, offMeshBase; float walkableHeight, walkableRadius,
                   walkableClimb, bmin[3], bmax[3], bvQuantFactor                        100 bytes
    verts          float32[3 * vertCount]                                  (habitat frame, Y up)
    polys          dtPoly[polyCount], 32 bytes: uint32 firstLink, uint16 verts[6], uint16 neis[6],
                   uint16 flags, uint8 vertCount, uint8 areaAndType (area: low 6 bits, type: high 2)
    links          12 bytes x maxLinkCount; detail meshes 12 x detailMeshCount; detail verts
                   12 x detailVertCount; detail tris 4 x detailTriCount; BV nodes 16 x bvNodeCount;
                   off-mesh connections 36 x offMeshConCount

so ``dataSize`` must equal the sum of those sections exactly; a file that does not (truncated, a
Git LFS pointer, another Detour version) is a one-line ``SceneFormatError`` naming the file.

What is returned: the ground polygons (``type`` 0; off-mesh connection polygons are skipped) with
their vertices in OUR frame (``Y_UP_TO_Z_UP``: habitat ``(x, y, z)`` -> ``(x, -z, y)``), and the
agent the navmesh was built for (radius, height, max climb). Polygon vertex heights are Recast's
voxel heights: quantised to ``cellHeight`` (0.2 m in ReplicaCAD) above the tile's ``bmin`` and
lying up to one cell above the true surface; plan positions are within ``edgeMaxError`` cells
(1.3 x 0.05 m) of the walkable boundary.

Levels, walkable grid and footprint
    ``levels()`` groups polygons by their mean height (gaps over ``LEVEL_GAP`` split levels), so a
    stage with stairs and raised areas gives the main floor, the steps and the upper areas as
    separate levels, the largest first. ``Level.grid()`` rasterises a level on a grid of the
    navmesh's own cell size (``Grid``: a bool mask with a known origin; cell (i, j) covers
    ``origin + [i, i+1) x [j, j+1)`` cells, i along our x). The navmesh is the floor eroded by the
    agent radius (Recast keeps the agent's centre ``agentRadius`` away from walls), so the *floor
    footprint* is the walkable grid dilated by that radius (``footprint``; a square structuring
    element, so that axis-aligned wall corners stay square) with holes smaller than the agent
    filled.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from vrformats.lfs import LFS_HINT, is_lfs_pointer
from scipy import ndimage

from .habitat_format import Y_UP_TO_Z_UP, fail, inside_root, mapping, read_json

__all__ = ["NavMesh", "NavSettings", "NavPolygon", "Level", "Grid", "read_navmesh", "navmesh_for_scene", "footprint_of",
           "StandinSpec", "Standin", "standin_stage", "write_standin_glb",
           "polygon_area"]

MSET_MAGIC = 0x4D534554  # 'MSET'
MSET_VERSION = 2
DT_MAGIC = 0x444E4156  # 'DNAV'
DT_VERSION = 7
DT_VERTS_PER_POLYGON = 6
DT_POLYTYPE_GROUND = 0
HEADER = struct.Struct("<iii")
PARAMS = struct.Struct("<5f2i")
SETTINGS = struct.Struct("<13f3?x")
TILE = struct.Struct("<Ii")
MESH_HEADER = struct.Struct("<15i10f")
POLY = struct.Struct("<I6H6HHBB")
SETTINGS_NAMES = ("cell_size", "cell_height", "agent_height", "agent_radius", "agent_max_climb", "agent_max_slope",
                  "region_min_size", "region_merge_size", "edge_max_len", "edge_max_error", "verts_per_poly",
                  "detail_sample_dist", "detail_sample_max_error")
LEVEL_GAP = 0.1  # m: polygons whose mean heights differ by more than this (after sorting) are different levels
_C = Y_UP_TO_Z_UP


@dataclass(frozen=True)
class NavSettings:
    """habitat-sim's NavMeshSettings as stored in the file (metres, degrees, cells)."""

    cell_size: float
    cell_height: float
    agent_height: float
    agent_radius: float
    agent_max_climb: float
    agent_max_slope: float
    region_min_size: float
    region_merge_size: float
    edge_max_len: float
    edge_max_error: float
    verts_per_poly: float
    detail_sample_dist: float
    detail_sample_max_error: float
    filter_low_hanging_obstacles: bool
    filter_ledge_spans: bool
    filter_walkable_low_height_spans: bool


@dataclass
class NavPolygon:
    vertices: np.ndarray  # (k, 3), our frame (Z up), counter-clockwise seen from above
    area_id: int  # Detour area (low 6 bits of areaAndType)
    flags: int
    tile: int

    @property
    def z(self) -> float:
        return float(self.vertices[:, 2].mean())

    @property
    def area(self) -> float:
        return polygon_area(self.vertices[:, :2])


@dataclass
class Grid:
    """A bool raster in our XY plane: ``mask[i, j]`` covers x in ``origin[0] + [i, i+1) * cell``,
    y in ``origin[1] + [j, j+1) * cell``."""

    mask: np.ndarray
    origin: np.ndarray  # (2,) world x, y of cell (0, 0)'s lower corner
    cell: float

    @property
    def area(self) -> float:
        return float(self.mask.sum()) * self.cell * self.cell

    def centres(self) -> np.ndarray:
        """(n, 2) world XY of the set cells' centres."""
        ii, jj = np.nonzero(self.mask)
        return self.origin + (np.stack([ii, jj], axis=1) + 0.5) * self.cell

    def contains(self, xy) -> np.ndarray:
        p = np.atleast_2d(np.asarray(xy, float))
        ij = np.floor((p - self.origin) / self.cell).astype(np.int64)
        W, H = self.mask.shape
        ok = (ij[:, 0] >= 0) & (ij[:, 0] < W) & (ij[:, 1] >= 0) & (ij[:, 1] < H)
        out = np.zeros(len(p), bool)
        out[ok] = self.mask[ij[ok, 0], ij[ok, 1]]
        return out

    def bounds(self) -> tuple[float, float, float, float]:
        """(xmin, ymin, xmax, ymax) of the set cells."""
        ii, jj = np.nonzero(self.mask)
        if len(ii) == 0:
            return (0.0, 0.0, 0.0, 0.0)
        o, c = self.origin, self.cell
        return (float(o[0] + ii.min() * c), float(o[1] + jj.min() * c), float(o[0] + (ii.max() + 1) * c),
                float(o[1] + (jj.max() + 1) * c))


@dataclass
class Level:
    """Polygons at one height. ``z``: the area-weighted mean of their mean heights (our frame)."""

    z: float
    polygons: list[NavPolygon]
    cell: float  # the navmesh's cell size

    @property
    def area(self) -> float:
        return float(sum(p.area for p in self.polygons))

    @property
    def z_range(self) -> tuple[float, float]:
        zs = np.concatenate([p.vertices[:, 2] for p in self.polygons])
        return float(zs.min()), float(zs.max())

    def grid(self, lo=None, shape=None, cell: float | None = None) -> Grid:
        """The level's polygons rasterised (a cell is set when its centre lies in a polygon). By
        default the grid spans the polygons plus a margin of one metre, snapped to the cell size."""
        cell = float(cell or self.cell)
        pts = np.concatenate([p.vertices[:, :2] for p in self.polygons])
        if lo is None:
            lo = np.floor((pts.min(axis=0) - 1.0) / cell) * cell
        lo = np.asarray(lo, float)
        if shape is None:
            hi = pts.max(axis=0) + 1.0
            shape = tuple(int(v) for v in np.ceil((hi - lo) / cell))
        from ...mesh.stage_structure import rasterise

        tris = []
        for p in self.polygons:
            v = p.vertices[:, :2]
            for k in range(1, len(v) - 1):
                tris.append([v[0], v[k], v[k + 1]])
        tri = (np.asarray(tris, float).reshape(-1, 3, 2) - lo) / cell
        return Grid(rasterise(tri, tuple(shape)), lo, cell)


@dataclass
class NavMesh:
    path: str
    version: int
    origin: np.ndarray  # dtNavMeshParams.orig, habitat frame
    tile_width: float
    tile_height: float
    max_tiles: int
    max_polys: int
    settings: NavSettings
    tiles: list[dict]  # per tile: ref, x, y, layer, poly/vert counts, walkable_height/radius/climb, bmin/bmax (habitat frame)
    polygons: list[NavPolygon] = field(default_factory=list)

    @property
    def agent_radius(self) -> float:
        return self.settings.agent_radius

    @property
    def agent_height(self) -> float:
        return self.settings.agent_height

    @property
    def cell_size(self) -> float:
        return self.settings.cell_size

    def levels(self, gap: float = LEVEL_GAP) -> list[Level]:
        """Polygons grouped by height (mean heights sorted; a jump over ``gap`` starts a new level),
        largest area first (the main floor)."""
        if not self.polygons:
            return []
        zs = np.array([p.z for p in self.polygons])
        order = np.argsort(zs, kind="stable")
        cuts = np.flatnonzero(np.diff(zs[order]) > gap) + 1
        out = []
        for g in np.split(order, cuts):
            polys = [self.polygons[i] for i in g]
            a = np.array([p.area for p in polys])
            z = float((zs[g] * a).sum() / a.sum()) if a.sum() > 0 else float(zs[g].mean())
            out.append(Level(z, polys, self.cell_size))
        out.sort(key=lambda lv: (-round(lv.area, 6), lv.z))
        return out

    def main_level(self) -> Level:
        lv = self.levels()
        if not lv:
            fail(self.path, None, "navmesh has no ground polygons")
        return lv[0]

    def walkable(self, level: Level | None = None, lo=None, shape=None) -> Grid:
        return (level or self.main_level()).grid(lo, shape)

    def footprint(self, level: Level | None = None, lo=None, shape=None, radius: float | None = None) -> Grid:
        """The floor a level stands for: its walkable grid dilated by the agent radius (a square
        element: axis-aligned corners stay square), holes smaller than the agent's disc filled."""
        g = self.walkable(level, lo, shape)
        return footprint_of(g, self.agent_radius if radius is None else radius)


def footprint_of(g: Grid, radius: float) -> Grid:
    k = int(round(radius / g.cell))
    m = g.mask
    if k > 0:
        m = ndimage.binary_dilation(m, structure=np.ones((2 * k + 1, 2 * k + 1), bool))
    lab, n = ndimage.label(~m)
    if n:
        sizes = np.bincount(lab.ravel(), minlength=n + 1)
        border = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
        small = sizes * g.cell * g.cell < math.pi * radius * radius
        small[0] = False
        small[border] = False
        m = m | small[lab]
    return Grid(m, g.origin.copy(), g.cell)


def polygon_area(xy: np.ndarray) -> float:
    x, y = np.asarray(xy, float)[:, 0], np.asarray(xy, float)[:, 1]
    return float(0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1))))


def _align4(n: int) -> int:
    return (n + 3) & ~3


def read_navmesh(path) -> NavMesh:
    """Parse a habitat-sim ``.navmesh`` (see the module docstring). Errors: ``SceneFormatError``
    naming the file (missing, truncated, wrong magic or version, sizes that do not add up)."""
    path = Path(path)
    if not path.is_file():
        fail(path, None, "navmesh file not found")
    try:
        b = path.read_bytes()
    except OSError as e:
        fail(path, None, f"cannot read: {e}")
    if is_lfs_pointer(b):
        fail(path, None, LFS_HINT)
    need = HEADER.size + PARAMS.size + SETTINGS.size
    if len(b) < need:
        fail(path, None, f"truncated navmesh: {len(b)} bytes, the header alone is {need}")
    magic, version, ntiles = HEADER.unpack_from(b, 0)
    if magic != MSET_MAGIC:
        fail(path, None, f"not a habitat-sim navmesh: magic {b[:4]!r}, expected b'TESM' ('MSET')")
    if version != MSET_VERSION:
        fail(path, None, f"navmesh version {version} is not supported (expected {MSET_VERSION})")
    if ntiles < 0 or ntiles > 1 << 20:
        fail(path, None, f"implausible tile count {ntiles}")
    p = PARAMS.unpack_from(b, HEADER.size)
    s = SETTINGS.unpack_from(b, HEADER.size + PARAMS.size)
    settings = NavSettings(*[float(v) for v in s[:13]], *[bool(v) for v in s[13:]])
    if not (settings.cell_size > 0 and settings.cell_height > 0 and settings.agent_radius >= 0 and settings.agent_height > 0):
        fail(path, None, f"implausible navmesh settings {settings}")
    for k, (lo, hi) in SETTING_RANGES.items():  # a hostile header must not ask for a grid larger than memory
        v = getattr(settings, k)
        if not (math.isfinite(v) and lo <= v <= hi):
            fail(path, f"settings.{k}", f"{v:g} m is outside the range a navmesh can have ({lo:g} to {hi:g} m)")
    nav = NavMesh(str(path), version, np.array(p[:3], float), float(p[3]), float(p[4]), int(p[5]), int(p[6]), settings, [])
    o = need
    for t in range(ntiles):
        if o + TILE.size > len(b):
            fail(path, None, f"truncated navmesh: tile {t} of {ntiles} starts at byte {o}, the file has {len(b)}")
        ref, size = TILE.unpack_from(b, o)
        o += TILE.size
        if ref == 0 or size <= 0:
            break  # habitat stops writing at an empty tile
        if o + size > len(b):
            fail(path, None, f"truncated navmesh: tile {t} needs {size} bytes at byte {o}, the file has {len(b)}")
        _tile(nav, path, t, ref, memoryview(b)[o:o + size])
        o += size
    if o != len(b):
        fail(path, None, f"{len(b) - o} trailing bytes after {len(nav.tiles)} tile(s)")
    return nav


def _tile(nav: NavMesh, path: Path, t: int, ref: int, d) -> None:
    if len(d) < MESH_HEADER.size:
        fail(path, None, f"tile {t}: {len(d)} bytes, less than the {MESH_HEADER.size}-byte Detour header")
    h = MESH_HEADER.unpack_from(d, 0)
    magic, version, tx, ty, layer, _user, pc, vc, mlc, dmc, dvc, dtc, bvc, omc, _omb = h[:15]
    wh, wr, wc = h[15:18]
    bmin, bmax = np.array(h[18:21]), np.array(h[21:24])
    if magic != DT_MAGIC:
        fail(path, None, f"tile {t}: Detour magic {bytes(d[:4])!r}, expected b'VAND' ('DNAV')")
    if version != DT_VERSION:
        fail(path, None, f"tile {t}: Detour version {version} is not supported (expected {DT_VERSION})")
    counts = (pc, vc, mlc, dmc, dvc, dtc, bvc, omc)
    if min(counts) < 0:
        fail(path, None, f"tile {t}: negative counts {counts}")
    sections = [12 * vc, POLY.size * pc, 12 * mlc, 12 * dmc, 12 * dvc, 4 * dtc, 16 * bvc, 36 * omc]
    expect = MESH_HEADER.size + sum(_align4(x) for x in sections)
    if expect != len(d):
        fail(path, None, f"tile {t}: {len(d)} bytes of tile data, but its header's counts need {expect}")
    off = MESH_HEADER.size
    V = np.frombuffer(d, dtype="<f4", count=3 * vc, offset=off).astype(np.float64).reshape(-1, 3)
    off += _align4(12 * vc)
    if not np.isfinite(V).all():
        fail(path, None, f"tile {t}: non-finite vertices")
    Vz = V @ _C.T
    npoly = 0
    for k in range(pc):
        f = POLY.unpack_from(d, off + k * POLY.size)
        verts, flags, n, at = f[1:7], f[13], f[14], f[15]
        if n < 3 or n > DT_VERTS_PER_POLYGON or max(verts[:n]) >= vc:
            fail(path, None, f"tile {t}: polygon {k} has {n} vertices / indices {verts[:n]} (tile has {vc} vertices)")
        if at >> 6 != DT_POLYTYPE_GROUND:
            continue  # off-mesh connection
        nav.polygons.append(NavPolygon(Vz[list(verts[:n])].copy(), at & 0x3F, flags, t))
        npoly += 1
    nav.tiles.append({"ref": ref, "x": tx, "y": ty, "layer": layer, "polygons": pc, "ground_polygons": npoly,
                      "vertices": vc, "detail_meshes": dmc, "detail_vertices": dvc, "detail_triangles": dtc,
                      "bv_nodes": bvc, "off_mesh_connections": omc, "walkable_height": wh, "walkable_radius": wr,
                      "walkable_climb": wc, "bmin": bmin, "bmax": bmax, "verts_habitat": V})


def navmesh_for_scene(root, scene_doc: dict, scene_path=None) -> Path | None:
    """The navmesh file a scene instance names, resolved as habitat-sim does: the scene's
    ``navmesh_instance`` handle is looked up in the scene dataset config's ``navmesh_instances``
    (ReplicaCAD's apartments name "empty_stage_navmesh" while the config's key is "empty_stage": a
    key that the handle starts with followed by "_navmesh" matches too); a handle that is a path
    (relative to the root) to an existing file is taken as is. None when the scene names no navmesh.
    Errors (``SceneFormatError``): a handle that matches nothing, a listed file that is missing."""
    root = Path(root)
    where = scene_path or "<scene instance>"
    name = mapping(where, scene_doc, None).get("navmesh_instance")
    if name in (None, ""):
        return None
    if not isinstance(name, str):
        fail(where, "navmesh_instance", f"expected a string, got {name!r}")
    configs = sorted(root.glob("*.scene_dataset_config.json"))
    table = {}
    for cfg in configs:
        doc = mapping(cfg, read_json(cfg), None)
        nm = doc.get("navmesh_instances", {})
        table.update({k: (cfg, v) for k, v in mapping(cfg, nm, "navmesh_instances").items()})
    cands = [name]
    if name.endswith("_navmesh"):
        cands.append(name[: -len("_navmesh")])
    for c in cands:
        if c in table:
            cfg, rel = table[c]
            if not isinstance(rel, str):
                fail(cfg, f"navmesh_instances.{c}", f"expected a path, got {rel!r}")
            f = inside_root(cfg, f"navmesh_instances.{c}", cfg.parent / rel, root)
            if not f.is_file():
                fail(cfg, f"navmesh_instances.{c}", f"navmesh file not found: {f}")
            return f
    direct = inside_root(where, "navmesh_instance", root / name, root)
    if direct.is_file():
        return direct
    fail(where, "navmesh_instance", f"no navmesh '{name}' in the scene dataset config's navmesh_instances "
                                    f"({', '.join(str(c) for c in configs) or 'no *.scene_dataset_config.json in ' + str(root)})")


# --------------------------------------------------------------------------------------------
# a stand-in stage from a navmesh (for datasets whose stage GLB is missing: tools/replicacad_standin.py)

STANDIN_WALL_CELLS = 2  # wall thickness in navmesh cells (0.1 m at ReplicaCAD's 0.05 m)
STANDIN_SLAB = 0.1  # floor and ceiling slab thickness, m
STANDIN_CEILING = 2.8  # m above the floor (see StandinSpec)
STANDIN_STEP = 0.18  # m: ramps (stairs in the navmesh) become steps of at most this rise
STANDIN_SLAB_STEP = 0.15  # m: thickness of a stair flight's slab above a walkable space
STANDIN_STAIR_HEADROOM = 2.5  # m above the highest raised level: the ceiling over the stairs
WINDOW_SILL, WINDOW_HEAD = 0.9, 2.1  # m above the floor
WINDOW_WIDTH = 1.2  # m
WINDOW_SPACING = 2.5  # m of exterior wall per window
WINDOW_MIN_WALL = 0.8  # m: shorter (free) exterior wall stretches get none
WINDOW_END_MARGIN = 0.1  # m of solid wall at either end of a wall with windows
WINDOW_CLEAR = 0.2  # m: no window where an object stands this close to the wall
STANDIN_KEEP_MARGIN = 0.02  # m: the floor holds every object's footprint with this much to spare
STANDIN_KEEP_MAX = 1.2  # m: footprints farther out of the navmesh footprint are not held (reported)
STANDIN_KEEP_STAND = 0.1  # m: an object whose bottom is this close to a level it touches stands on it (else: hangs)
STANDIN_COLOURS = {"floor": (0.55, 0.45, 0.35, 1.0), "walls": (0.85, 0.84, 0.80, 1.0), "ceiling": (0.95, 0.95, 0.95, 1.0),
                   "steps": (0.50, 0.42, 0.34, 1.0), "trim": (0.92, 0.91, 0.88, 1.0)}
BASEBOARD_HEIGHT = 0.08  # m: a baseboard (StandinSpec.baseboards) is a band this high, one cell deep, along the walls
FRAME_WIDTH = 0.05  # m: a window frame's (StandinSpec.window_frames) sill and head bands are this high; jambs one cell wide


@dataclass
class StandinSpec:
    """Choices of the stand-in stage (all in metres, our frame; see ``standin_stage``).

    ``floor_z``: the main floor's true height. The navmesh only brackets it (Recast heights lie up to
    one ``cell_height`` above the surface); None: ``main level z - cell_height / 2``.
    ``ceiling``: the ceiling height above the floor. ``windows``: cut window openings in exterior walls.
    ``keep``: footprints (XY quads, our frame) of objects that stand in the stage (on its floor or on
    its walls): the floor is extended to hold each of them with ``keep_margin`` to spare (the walls
    move out around them; with ``keep_bottoms``, one whose bottom is more than ``STANDIN_KEEP_STAND``
    from every level it touches hangs on a wall: held to the cell, without margin, so that the wall
    stays right behind it), unless one lies more than ``keep_max`` outside the navmesh footprint
    or does not overlap it (an object outside the building, or in a recess of the building wider than
    that: reported, not held); no window is cut where one of them whose top (``keep_tops``) is above
    the sill stands within ``window_clear`` of the wall (a rug or a low table does not hide a window).
    ``keep_bottoms``: their bottoms (z, our frame). A floor cell added to hold an object goes to the
    level, among those whose footprint the object's touches, whose height there is nearest the
    object's bottom (a bike beside the stairs stays on the floor, a plant on the landing is raised
    to it); a cell held by several objects, to the one with the lowest bottom (what stands on the
    floor, not what stands on it). Empty: to the level whose walkable cells are nearest.
    ``baseboards``: a band ``BASEBOARD_HEIGHT`` high and one cell deep on the floor along the inside
    of every wall (not on the steps). ``window_frames``: around each window opening, on both sides of
    the wall, a frame protruding one cell: a sill and a head band ``FRAME_WIDTH`` high and a jamb one
    cell wide at either end. Both are the part ``trim``. ``window_jog``: an exterior wall run that
    jogs sideways by at most this many cells (and is broken by at most as many) is still one straight
    run for the windows (``_wall_runs``): a stage built on a grid rotated off its walls."""

    floor_z: float | None = None
    ceiling: float = STANDIN_CEILING
    wall_cells: int = STANDIN_WALL_CELLS
    windows: bool = True
    keep: list = field(default_factory=list)  # (4, 2) XY footprints of objects the floor must hold
    keep_tops: list = field(default_factory=list)  # their tops (z, our frame); empty: all reach above the sills
    keep_bottoms: list = field(default_factory=list)  # their bottoms (z, our frame); empty: cells to the nearest level
    keep_margin: float = STANDIN_KEEP_MARGIN
    keep_max: float = STANDIN_KEEP_MAX
    window_clear: float = WINDOW_CLEAR
    baseboards: bool = False
    window_frames: bool = False
    window_jog: int = 0  # cells: a straight wall run may jog sideways this much (a grid rotated off the walls)


@dataclass
class Standin:
    """The stand-in's meshes (our frame, Z up) by part, and its figures."""

    parts: dict  # name -> trimesh.Trimesh (floor, walls, ceiling, steps, trim)
    floor_z: float
    ceiling_z: float
    stair_ceiling_z: float | None
    footprint: Grid  # the union of every level's footprint (the floor inside the walls)
    main_footprint: Grid
    walls: Grid  # wall cells
    windows: list[dict]  # {"axis": "x"|"y", "at": wall line coordinate, "from", "to", "bottom", "top"}
    levels: list[dict]  # per level: z (navmesh), z_true, kind, walkable/footprint area
    report: dict = field(default_factory=dict)


def _rects(mask: np.ndarray) -> list[tuple[int, int, int, int]]:
    """A cover of the set cells of a 2-D bool array by disjoint rectangles [i0, i1) x [j0, j1):
    runs along j in each column i, merged over consecutive columns with the same run."""
    out = []
    open_: dict[tuple[int, int], int] = {}
    m = np.asarray(mask, bool)
    d = np.diff(np.pad(m.astype(np.int8), ((0, 0), (1, 1))), axis=1)
    si, sj = np.nonzero(d == 1)  # run starts and ends, column by column (row-major: in order within a column)
    _, ej = np.nonzero(d == -1)
    by_col: dict[int, set] = {}
    for i, a, b in zip(si.tolist(), sj.tolist(), ej.tolist()):
        by_col.setdefault(i, set()).add((a, b))
    # only columns with runs, and the one after each, can open or close a rectangle
    for i in sorted(set(by_col) | {c + 1 for c in by_col}):
        runs = by_col.get(i, set())
        for r in list(open_):
            if r not in runs:
                out.append((open_.pop(r), i, r[0], r[1]))
        for r in runs:
            if r not in open_:
                open_[r] = i
    out.sort()
    return out


def _wall_runs(ext: np.ndarray, thick: int, jog: int = 0) -> list[tuple[int, int, int, int]]:
    """Straight runs of the exterior wall cells ``ext``: its rectangles (``_rects``) at most
    ``thick`` cells thick. With ``jog`` > 0, runs that continue one another along their length
    (overlapping by at most ``jog`` cells, or after a gap of at most ``thick`` where the band turns)
    shifted sideways by at most ``jog`` cells (the staircase of a wall that runs off the grid's
    axes) are one run: their bounding rectangle."""
    rects = [r for r in _rects(ext) if min(r[1] - r[0], r[3] - r[2]) <= thick]
    if jog <= 0:
        return rects
    out = [r for r in rects if r[1] - r[0] == r[3] - r[2]]
    for along in (0, 1):
        lng = sorted((r for r in rects if (r[1] - r[0] > r[3] - r[2]) == (along == 0) and r[1] - r[0] != r[3] - r[2]),
                     key=lambda r: (r[2 * along], r[2 * (1 - along)]))
        chains: list[list] = []
        for r in lng:
            a0, a1, c0, c1 = (r[0], r[1], r[2], r[3]) if along == 0 else (r[2], r[3], r[0], r[1])
            for ch in chains:
                b0, b1, d0, d1 = ch[-1]
                if -jog <= a0 - b1 <= thick and abs(c0 - d0) <= jog and abs(c1 - d1) <= jog:
                    ch.append((a0, a1, c0, c1))
                    break
            else:
                chains.append([(a0, a1, c0, c1)])
        for ch in chains:
            a0, a1 = ch[0][0], ch[-1][1]
            c0, c1 = min(x[2] for x in ch), max(x[3] for x in ch)
            out.append((a0, a1, c0, c1) if along == 0 else (c0, c1, a0, a1))
    out.sort()
    return out


def _box(lo, hi):
    import trimesh

    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    b = trimesh.creation.box(extents=hi - lo)
    b.apply_translation((lo + hi) / 2.0)
    return b


def _boxes(g: Grid, mask: np.ndarray, z0: float, z1: float) -> list:
    o, c = g.origin, g.cell
    return [_box((o[0] + i0 * c, o[1] + j0 * c, z0), (o[0] + i1 * c, o[1] + j1 * c, z1)) for i0, i1, j0, j1 in _rects(mask)]


PARTS = ("floor", "steps", "walls", "ceiling", "trim")


def _solid_surface(g: Grid, solids) -> tuple[dict, dict]:
    """The outer surface of a union of prisms (``(part, 2-D mask, z0, z1)``, later ones win where
    they overlap) on ``g``'s cells: a closed surface with outward normals and no faces between
    touching prisms (so that a mesh reader sees only visible faces). Faces are merged into
    rectangles and belong to the part of the solid cell they bound."""
    import trimesh

    zs = np.unique(np.round(np.array([z for _, _, a, b in solids for z in (a, b)]), 6))
    W, H = g.mask.shape
    S = np.zeros((W + 2, H + 2, len(zs) + 1), np.int8)  # padded; layer k spans zs[k-1]..zs[k]
    for name, m, z0, z1 in solids:
        k0, k1 = int(np.searchsorted(zs, round(z0, 6))), int(np.searchsorted(zs, round(z1, 6)))
        if k1 <= k0 or not m.any():
            continue
        lab = PARTS.index(name) + 1
        sub = S[1:-1, 1:-1, k0 + 1:k1 + 1]
        sub[m] = lab
    xs = g.origin[0] + np.arange(W + 1) * g.cell
    ys = g.origin[1] + np.arange(H + 1) * g.cell
    verts: dict[str, list] = {p: [] for p in PARTS}
    normals: dict[str, list] = {p: [] for p in PARTS}
    coords = (xs, ys, zs)
    for ax in range(3):
        Sm = np.moveaxis(S, ax, 0)
        A, B = Sm[:-1], Sm[1:]  # boundary b lies between cells b-1 and b (unpadded index)
        for b in range(A.shape[0]):
            a_, b_ = A[b], B[b]
            for sgn, own, other in ((1.0, a_, b_), (-1.0, b_, a_)):
                face = (own > 0) & (other == 0)
                if not face.any():
                    continue
                for lab in np.unique(own[face]):
                    m = (face & (own == lab))[1:-1, 1:-1]  # drop the padding of the two in-plane axes
                    ua, va = [a for a in range(3) if a != ax]
                    u, v = coords[ua], coords[va]
                    part = PARTS[int(lab) - 1]
                    nrm = np.zeros(3)
                    nrm[ax] = sgn
                    for r0, r1, s0, s1 in _rects(m):
                        q = np.zeros((4, 3))
                        q[:, ax] = coords[ax][b]
                        q[:, ua] = [u[r0], u[r1], u[r1], u[r0]]
                        q[:, va] = [v[s0], v[s0], v[s1], v[s1]]
                        verts[part].append(q)
                        normals[part].append(nrm)
    parts, counts = {}, {}
    for p in PARTS:
        if not verts[p]:
            continue
        Q = np.asarray(verts[p])
        N = np.asarray(normals[p])
        tri = np.concatenate([Q[:, [0, 1, 2]], Q[:, [0, 2, 3]]])
        nn = np.concatenate([N, N])
        cr = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        flip = (cr * nn).sum(axis=1) < 0
        tri[flip] = tri[flip][:, ::-1]
        mesh = trimesh.Trimesh(tri.reshape(-1, 3), np.arange(3 * len(tri)).reshape(-1, 3), process=False)
        mesh.merge_vertices()
        parts[p] = mesh
        counts[p] = len(Q)
    return parts, counts


SETTING_RANGES = {"cell_size": (1e-3, 10.0), "cell_height": (1e-3, 10.0), "agent_radius": (0.0, 10.0),
                  "agent_height": (1e-3, 20.0)}  # metres; habitat's defaults: 0.05, 0.2, 0.1, 1.5
MAX_STANDIN_CELLS = 50_000_000  # the stand-in's floor grid (ReplicaCAD's apartment: ~0.1 M cells)


def standin_stage(nav: NavMesh, spec: StandinSpec | None = None) -> Standin:
    """A stage that matches the navmesh: what an agent of the navmesh's radius could walk on is
    floor, and walls stand where it could not (see the module docstring of
    ``tools/replicacad_standin.py`` for the choices). Our frame; ``write_standin_glb`` writes it."""

    spec = spec or StandinSpec()
    levels = nav.levels()
    if not levels:
        fail(nav.path, None, "navmesh has no ground polygons: no stand-in stage can be built from it")
    main = levels[0]
    ch, cell = nav.settings.cell_height, nav.cell_size
    floor_z = float(main.z - ch / 2.0) if spec.floor_z is None else float(spec.floor_z)
    shift = floor_z - main.z  # navmesh height -> true height (the same offset on every level)
    pts = np.concatenate([p.vertices[:, :2] for p in nav.polygons])
    margin = 1.0
    if spec.keep:  # room for a held footprint keep_max out of the navmesh footprint, its walls and the outside
        margin = max(margin, nav.agent_radius + spec.keep_max + spec.keep_margin + (max(1, int(spec.wall_cells)) + 3) * cell)
    lo = np.floor((pts.min(axis=0) - margin) / cell) * cell
    shape = tuple(int(v) for v in np.ceil((pts.max(axis=0) + margin - lo) / cell))
    if not np.isfinite(pts).all() or shape[0] * shape[1] > MAX_STANDIN_CELLS:
        fail(nav.path, "settings.cell_size", f"the navmesh's extent at a {cell:g} m cell size needs a {shape[0]} x {shape[1]} "
                                             f"grid; at most {MAX_STANDIN_CELLS:,} cells are built")
    walk = [lv.grid(lo, shape) for lv in levels]
    feet = [footprint_of(w, nav.agent_radius) for w in walk]
    U = np.zeros(shape, bool)
    for f in feet:
        U |= f.mask
    nav_fp = U.copy()
    xc = lo[0] + (np.arange(shape[0]) + 0.5) * cell
    yc = lo[1] + (np.arange(shape[1]) + 0.5) * cell
    X, Y = np.meshgrid(xc, yc, indexing="ij")
    kinds, planes = [], []  # per level: main / flat / ramp; a ramp's (plane coefficients, base, rise)
    for k, lv in enumerate(levels):
        z0, z1 = lv.z_range
        kinds.append("main" if k == 0 else ("ramp" if z1 - z0 > nav.settings.agent_max_climb + 1e-6 else "flat"))
        if kinds[-1] == "ramp":  # the plane through its vertices, cut into steps
            V = np.concatenate([p.vertices for p in lv.polygons])
            A = np.c_[V[:, 0], V[:, 1], np.ones(len(V))]
            n = max(1, int(math.ceil((z1 - z0) / STANDIN_STEP)))
            planes.append((np.linalg.lstsq(A, V[:, 2], rcond=None)[0], z0 + shift, (z1 - z0) / n))
        else:
            planes.append(None)

    def level_height(k: int, sel: np.ndarray) -> np.ndarray:
        """True height of level ``k`` at the cells ``sel`` (a ramp's: its step there)."""
        if k == 0:
            return np.full(int(sel.sum()), floor_z)
        if planes[k] is None:
            return np.full(int(sel.sum()), levels[k].z + shift)
        (a, b, c), base_, rise_ = planes[k]
        z0, z1 = levels[k].z_range
        h = np.clip(a * X[sel] + b * Y[sel] + c, z0, z1) + shift
        return base_ + np.ceil((h - base_) / rise_ - 1e-6) * rise_

    add_owner = np.full(shape, -1)  # a cell added to hold an object: the level it goes to (keep_bottoms)
    add_bottom = np.full(shape, np.inf)  # ... and the bottom of the object that chose it
    objects = np.zeros(shape, bool)  # cells any kept footprint reaching above the window sills touches
    keep_info = {"objects": len(spec.keep), "held": 0, "hung": 0, "not_held": [], "added_m2": 0.0}
    if spec.keep:
        from ...mesh.stage_structure import rasterise

        out_dist = ndimage.distance_transform_edt(~nav_fp) * cell  # distance of a cell centre from the footprint
        grow = spec.keep_margin + cell / 2.0  # a cell whose square meets the footprint + margin
        if spec.keep_bottoms and len(spec.keep_bottoms) != len(spec.keep):
            raise ValueError(f"StandinSpec: {len(spec.keep_bottoms)} keep_bottoms for {len(spec.keep)} keep footprints")
        touch = [ndimage.binary_dilation(f.mask, iterations=2) for f in feet]  # a held object touches these levels
        z_rng = [(lv.z_range[0] + shift, lv.z_range[1] + shift) for lv in levels]

        def box_cells(q: np.ndarray, g: float) -> np.ndarray:
            # each side moved out by g along the box's own axes (corners out along the diagonals
            # would move a long box's ends by up to g * sqrt(2) and its long sides by less than g)
            c = q.mean(axis=0)
            u, v = q[1] - q[0], q[3] - q[0]
            u, v = u / max(float(np.linalg.norm(u)), 1e-9), v / max(float(np.linalg.norm(v)), 1e-9)
            qq = q + g * (np.sign((q - c) @ u)[:, None] * u + np.sign((q - c) @ v)[:, None] * v)
            return rasterise((np.array([[qq[0], qq[1], qq[2]], [qq[0], qq[2], qq[3]]]) - lo) / cell, shape)

        for k, q in enumerate(spec.keep):
            q = np.asarray(q, float).reshape(-1, 2)
            m = box_cells(q, grow)  # whether it is held, and where no window goes, are decided with the margin
            if not m.any():  # wholly off the grid: farther out than keep_max
                fc = lo + (np.argwhere(nav_fp) + 0.5) * cell
                far = max(float(np.min(np.hypot(*(fc - v).T))) for v in q)
                keep_info["not_held"].append({"index": k, "outside_m": round(far, 3)})
                continue
            if not spec.keep_tops or spec.keep_tops[k] > floor_z + WINDOW_SILL:
                objects |= m
            if float(out_dist[m].max()) > spec.keep_max + grow or float(out_dist[m].min()) > cell:
                keep_info["not_held"].append({"index": k, "outside_m": round(float(out_dist[m].max()), 3)})
                continue
            keep_info["held"] += 1
            cand = [j for j in range(len(levels)) if (touch[j] & m).any()]
            if spec.keep_bottoms and cand:
                zb = float(spec.keep_bottoms[k])
                if not any(z_rng[j][0] - STANDIN_KEEP_STAND <= zb <= z_rng[j][1] + STANDIN_KEEP_STAND for j in cand):
                    keep_info["hung"] += 1  # on a wall (or on furniture): no margin, so that the wall stays behind it
                    m = box_cells(q, cell / 2.0)
            U |= m
            if spec.keep_bottoms:
                zb = float(spec.keep_bottoms[k])
                new = m & ~nav_fp & (zb < add_bottom)
                if new.any():
                    cand = cand or list(range(len(levels)))
                    d = np.abs(np.stack([level_height(j, new) for j in cand]) - zb)
                    add_owner[new] = np.asarray(cand)[np.argmin(d, axis=0)]  # ties: the lower level index (main first)
                    add_bottom[new] = zb
        keep_info["added_m2"] = round(float((U & ~nav_fp).sum()) * cell * cell, 3)
    # each footprint cell belongs to the level whose walkable cells are nearest (the main level on ties)
    dist = np.stack([ndimage.distance_transform_edt(~w.mask) if w.mask.any() else np.full(shape, np.inf) for w in walk])
    added = U & ~nav_fp
    for k, f in enumerate(feet):
        dist[k][~f.mask & ~added] = np.inf
    owner = np.argmin(dist, axis=0)
    owner[added & (add_owner >= 0)] = add_owner[added & (add_owner >= 0)]
    owner[~U] = -1
    height = np.full(shape, floor_z)
    over_h = np.full(shape, -np.inf)
    info = []
    top = floor_z
    for k, lv in enumerate(levels):
        z0, z1 = lv.z_range
        kind = kinds[k]
        sel = owner == k
        if k > 0 and sel.any():
            height[sel] = np.maximum(level_height(k, sel), floor_z)
            top = max(top, float(height[sel].max()))
        if k > 0:
            # walkable both here and on the main floor (a flight of stairs above a walkable space):
            # a floating slab at this level's height, the space under it left free
            ov = walk[k].mask & (owner == 0)
            if ov.any():
                hv = level_height(k, ov)
                over_h[ov] = np.maximum(over_h[ov], hv)
                top = max(top, float(hv.max()))
        info.append({"z_navmesh": round(lv.z, 3), "z_range_navmesh": [round(z0, 3), round(z1, 3)], "kind": kind,
                     "polygons": len(lv.polygons), "navmesh_area_m2": round(lv.area, 3),
                     "walkable_m2": round(walk[k].area, 3), "footprint_m2": round(feet[k].area, 3),
                     "owned_m2": round(float(sel.sum()) * cell * cell, 3),
                     "over_main_m2": round(float((walk[k].mask & (owner == 0)).sum()) * cell * cell, 3) if k else 0.0})
    raised = U & (height > floor_z + 0.01)
    floating = U & np.isfinite(over_h) & ~raised
    # walls: a band of wall cells around the footprint (outside it; gaps between rooms too)
    t = max(1, int(spec.wall_cells))
    wall = ndimage.binary_dilation(U, structure=np.ones((2 * t + 1, 2 * t + 1), bool)) & ~U
    lab, _ = ndimage.label(~U)
    outer_labels = np.unique(np.concatenate([lab[0], lab[-1], lab[:, 0], lab[:, -1]]))
    outer = np.isin(lab, outer_labels[outer_labels > 0]) & ~wall
    ceil_z = floor_z + float(spec.ceiling)
    stair_z = None
    stairwell = np.zeros(shape, bool)
    if (raised.any() or floating.any()) and top + nav.agent_height > ceil_z - 1e-6:
        stair_z = top + STANDIN_STAIR_HEADROOM
        r = int(math.ceil(nav.agent_radius / cell))
        stairwell = ndimage.binary_dilation(raised | floating, structure=np.ones((2 * r + 1, 2 * r + 1), bool)) & U
    near_stair = ndimage.binary_dilation(stairwell, structure=np.ones((2 * t + 3, 2 * t + 3), bool)) & wall
    shell = U | wall
    g = Grid(U, lo, cell)
    solids = [("floor", shell, floor_z - STANDIN_SLAB, floor_z)]
    for hv in np.unique(height[raised]):
        solids.append(("steps", raised & np.isclose(height, hv), floor_z, float(hv)))
    for hv in np.unique(over_h[floating]):
        solids.append(("steps", floating & np.isclose(over_h, hv), float(hv) - STANDIN_SLAB_STEP, float(hv)))
    # windows: holes in straight exterior wall runs away from the stairs
    windows = []
    solid = wall.copy()
    win_cells = np.zeros(shape, bool)
    busy = np.zeros(shape, bool)
    frames = []  # (along axis, along cells [a0, a1), across cells [c0, c1)) of each window hole, for its frame
    if spec.windows:
        ext = wall & ndimage.binary_dilation(outer, structure=np.ones((3, 3), bool)) & ~near_stair
        if (U != nav_fp).any():  # straight runs from the navmesh's own walls (not broken by the moves around objects)
            wall0 = ndimage.binary_dilation(nav_fp, structure=np.ones((2 * t + 1, 2 * t + 1), bool)) & ~nav_fp
            lab0, _ = ndimage.label(~nav_fp)
            ol = np.unique(np.concatenate([lab0[0], lab0[-1], lab0[:, 0], lab0[:, -1]]))
            outer0 = np.isin(lab0, ol[ol > 0]) & ~wall0
            ext = wall0 & ndimage.binary_dilation(outer0, structure=np.ones((3, 3), bool)) & ~near_stair
        if objects.any():  # no window behind furniture: wall cells within window_clear (+ the band) of an object
            r = int(math.ceil((spec.window_clear + t * cell) / cell))
            yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
            busy = ndimage.binary_dilation(objects, structure=(xx * xx + yy * yy) <= r * r)
        ext &= ~busy
        x = t + int(math.ceil(STANDIN_KEEP_MAX / 4 / cell)) if (U != nav_fp).any() else t  # a hole reaches a moved wall too
        for i0, i1, j0, j1 in _wall_runs(ext, 2 * t, spec.window_jog):
            wi, wj = i1 - i0, j1 - j0
            along = 0 if wi > wj else 1
            n_cells = wi if along == 0 else wj
            L = n_cells * cell
            if L < WINDOW_MIN_WALL:
                continue
            n = max(1, int(L // WINDOW_SPACING))
            width = min(WINDOW_WIDTH, L / n - 2 * WINDOW_END_MARGIN)
            for q in range(n):
                cen = (q + 0.5) * L / n
                a = int(round((cen - width / 2) / cell))
                b = int(round((cen + width / 2) / cell))
                if along == 0:
                    sl = (slice(i0 + a, i0 + b), slice(max(j0 - x, 0), j1 + x))  # the band's whole thickness
                    at = (lo[1] + j0 * cell, lo[1] + j1 * cell)
                    span = (lo[0] + (i0 + a) * cell, lo[0] + (i0 + b) * cell)
                else:
                    sl = (slice(max(i0 - x, 0), i1 + x), slice(j0 + a, j0 + b))
                    at = (lo[0] + i0 * cell, lo[0] + i1 * cell)
                    span = (lo[1] + (j0 + a) * cell, lo[1] + (j0 + b) * cell)
                hole = wall[sl] & ~near_stair[sl] & ~busy[sl]
                win_cells[sl] |= hole
                across = np.flatnonzero(hole.any(axis=along))  # cells across the wall band
                if len(across):
                    base_ = (j0 if along == 0 else i0) - (min(j0, x) if along == 0 else min(i0, x))
                    at = (lo[1 - along] + (base_ + across[0]) * cell, lo[1 - along] + (base_ + across[-1] + 1) * cell)
                    if spec.window_frames:
                        ins = np.flatnonzero(hole.any(axis=1 - along))  # cells along the wall
                        a0_, a1_ = (sl[along].start + ins[0], sl[along].start + ins[-1] + 1)
                        c0_, c1_ = base_ + across[0], base_ + across[-1] + 1
                        frames.append((along, a0_, a1_, c0_, c1_))
                windows.append({"axis": "xy"[along], "wall_line": [round(float(v), 3) for v in at],
                                "from": round(float(span[0]), 3), "to": round(float(span[1]), 3),
                                "bottom": WINDOW_SILL, "top": WINDOW_HEAD})
        solid &= ~win_cells
    solids.append(("walls", solid & ~near_stair, floor_z, ceil_z))
    if stair_z is not None:
        solids.append(("walls", near_stair, floor_z, stair_z))
    solids.append(("walls", win_cells, floor_z, floor_z + WINDOW_SILL))
    solids.append(("walls", win_cells, floor_z + WINDOW_HEAD, ceil_z))
    if spec.baseboards:  # along the inside of every wall, on the main floor (not on the steps)
        board = U & ~raised & ndimage.binary_dilation(wall, structure=np.ones((3, 3), bool))
        solids.append(("trim", board, floor_z, floor_z + BASEBOARD_HEIGHT))
    else:
        board = np.zeros(shape, bool)
    if frames:
        band, jamb = np.zeros(shape, bool), np.zeros(shape, bool)
        for along, a0_, a1_, c0_, c1_ in frames:
            for c in (c0_ - 1, c1_):  # one cell in front of either face of the wall
                if not 0 <= c < shape[1 - along]:
                    continue
                a_lo, a_hi = max(a0_ - 1, 0), min(a1_ + 1, shape[along])
                sl_b = (slice(a_lo, a_hi), c) if along == 0 else (c, slice(a_lo, a_hi))
                band[sl_b] = True
                for a in (a0_ - 1, a1_):
                    if 0 <= a < shape[along]:
                        jamb[(a, c) if along == 0 else (c, a)] = True
        band &= ~wall
        jamb &= ~wall
        solids.append(("trim", band, floor_z + WINDOW_SILL - FRAME_WIDTH, floor_z + WINDOW_SILL))
        solids.append(("trim", band, floor_z + WINDOW_HEAD, floor_z + WINDOW_HEAD + FRAME_WIDTH))
        solids.append(("trim", jamb, floor_z + WINDOW_SILL - FRAME_WIDTH, floor_z + WINDOW_HEAD + FRAME_WIDTH))
    if stair_z is None:
        solids.append(("ceiling", shell, ceil_z, ceil_z + STANDIN_SLAB))
    else:
        solids.append(("ceiling", shell & ~stairwell & ~near_stair, ceil_z, stair_z + STANDIN_SLAB))
        solids.append(("ceiling", stairwell | near_stair, stair_z, stair_z + STANDIN_SLAB))
    parts, nfaces = _solid_surface(g, solids)
    main_fp = Grid(feet[0].mask.copy(), lo, cell)
    report = {"navmesh": nav.path, "cell_m": cell, "floor_z": round(floor_z, 3), "ceiling_z": round(ceil_z, 3),
              "stair_ceiling_z": None if stair_z is None else round(stair_z, 3),
              "footprint_m2": round(g.area, 3), "main_footprint_m2": round(main_fp.area, 3),
              "wall_cells_m2": round(float(wall.sum()) * cell * cell, 3), "windows": len(windows),
              "raised_m2": round(float(raised.sum()) * cell * cell, 3),
              "floating_m2": round(float(floating.sum()) * cell * cell, 3), "levels": info, "keep": keep_info,
              "quads": nfaces}
    if spec.baseboards or spec.window_frames:  # (absent otherwise: the default stand-in's report is unchanged)
        report["baseboards_m2"] = round(float(board.sum()) * cell * cell, 3)
        report["window_frames"] = len(frames)
    return Standin(parts, floor_z, ceil_z, stair_z, g, main_fp, Grid(wall, lo, cell), windows, info, report)


def write_standin_glb(standin: Standin, path, visuals: dict | None = None) -> Path:
    """Write the stand-in's parts as a GLB in habitat's Y-up glTF frame (vertices ``C^T v``), one
    node and one PBR material per part: plain (base colour factor ``STANDIN_COLOURS``), or the
    part's entry in ``visuals`` (a ``trimesh.visual.TextureVisuals`` matching the part's vertices:
    UVs and a material with a base colour texture, ``synth.sources.replicacad.stages``)."""
    import trimesh
    from trimesh.visual import TextureVisuals
    from trimesh.visual.material import PBRMaterial

    from vrformats.atomic import write_bytes_atomic

    path = Path(path)
    scene = trimesh.Scene()
    T = np.eye(4)
    T[:3, :3] = _C.T
    for name, mesh in standin.parts.items():
        m = mesh.copy()
        m.apply_transform(T)
        if visuals and name in visuals:
            m.visual = visuals[name]
        else:
            m.visual = TextureVisuals(material=PBRMaterial(name=f"standin_{name}", baseColorFactor=list(STANDIN_COLOURS[name]),
                                                           metallicFactor=0.0, roughnessFactor=0.9))
        scene.add_geometry(m, node_name=name, geom_name=name)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, trimesh.exchange.gltf.export_glb(scene))
    return path
