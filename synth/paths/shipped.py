"""The shipped paths (``SHIPPED``, written to scenes/paths by ``generate_shipped``), planning by kind
(``plan_path``) and replanning a saved path from the inputs it records (``replan``).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from vrformats.errors import UserError

from ..scene.model import Layout
from ..resources import generated_dir
from .files import save_path
from .mapping import plan_mapping_path
from .model import DEFAULTS, CameraPath
from .query import plan_query_path

__all__ = ["SHIPPED", "plan_path", "replan", "generate_shipped"]

# The paths under scenes/paths/ (``synth path generate`` rewrites them), planned with the planners'
# defaults: both keep 0.3 m from every object of their layouts (scenes/paths/query.yaml records a
# minimum of 0.32 m over apt_0..apt_5).
SHIPPED: dict[str, dict[str, Any]] = {
    "query": {"kind": "query", "layouts": [f"apt_{i}" for i in range(6)], "frames": DEFAULTS.query_frames,
              "seed": DEFAULTS.seed, "clearance": DEFAULTS.clearance},
    "mapping": {"kind": "mapping", "layouts": ["apt_0"], "frames": DEFAULTS.mapping_frames, "seed": DEFAULTS.seed,
                "clearance": DEFAULTS.clearance},
}


def plan_path(kind: str, layouts: list[Layout], frames: int, seed: int = DEFAULTS.seed, fps: float = DEFAULTS.fps,
              speed: float = DEFAULTS.speed, clearance: float = DEFAULTS.clearance, obstacles: str = DEFAULTS.obstacles,
              name: str | None = None) -> CameraPath:
    """``plan_query_path`` or ``plan_mapping_path`` by kind."""
    if kind == "query":
        return plan_query_path(layouts, frames, seed, fps, speed, clearance, obstacles, name or "query")
    if kind == "mapping":
        if len(layouts) != 1:
            raise UserError(f"a mapping path is planned on one layout, got {len(layouts)}")
        return plan_mapping_path(layouts[0], frames, seed, fps, speed, clearance, obstacles, name or "mapping")
    raise UserError(f"unknown path kind {kind!r}; use query or mapping")


def replan(path: CameraPath) -> CameraPath:
    """Plan a saved path again from the inputs its metadata records (to check for drift)."""
    from ..scene.model import load_layout

    m = path.meta
    pl = m.get("planner") or {}
    try:
        lays = [load_layout(n) for n in m["layouts"]]
        return plan_path(m["kind"], lays, int(pl["frames"]), int(m["seed"]), float(pl["fps"]), float(pl["speed_mps"]),
                         float(pl["clearance_m"]), str(pl.get("obstacles", DEFAULTS.obstacles)), path.name)
    except KeyError as e:
        raise UserError(f"camera path '{path.name}' does not record its planner input {e}") from None


def generate_shipped(out_dir=None, names=None) -> list[Path]:
    """(Re)write the shipped paths (``SHIPPED``) into ``out_dir`` (default ``resources.generated_dir("paths")``)."""
    from ..scene.model import load_layout

    out_dir = Path(out_dir) if out_dir else generated_dir("paths")
    written = []
    for name, spec in SHIPPED.items():
        if names and name not in names:
            continue
        lays = [load_layout(n) for n in spec["layouts"]]
        path = plan_path(spec["kind"], lays, spec["frames"], spec["seed"], clearance=spec["clearance"], name=name)
        written.append(save_path(path, out_dir / f"{name}.txt"))
    return written
