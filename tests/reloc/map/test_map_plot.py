"""reloc map show --plot [--gt]: the map top-down, its boxes coloured by how they match the ground
truth and counted in the legend (a map made from apt_0's own ground truth with one object removed,
one moved 3 m and one added, so every count is known)."""

from __future__ import annotations

import copy
import json

import numpy as np
from PIL import Image

from reloc.cli import main as reloc_main
from tests.cli_errors import one_line_error
from tests.conftest import make_tour
from vrformats.camera import Intrinsics


def test_the_map_against_its_ground_truth(tmp_path, capsys, monkeypatch):
    import reloc.figures
    from synth.scene.model import boxes_document, load_layout

    gt = boxes_document(load_layout("apt_0"))
    tour = make_tour(tmp_path / "apt_0__day__mapping", [np.eye(4)], {0: dict(depth=np.ones((24, 32), np.float32))},
                     intrinsics=Intrinsics.from_fov(32, 24, 75.0), objects=gt, layout="apt_0", lighting="day",
                     path="mapping")
    built = copy.deepcopy(gt)
    objects = [b for b in built["boxes"] if b.get("kind", "object") == "object"]
    removed, moved = objects[0], objects[1]
    built["boxes"].remove(removed)
    moved["center"] = [moved["center"][0] + 3.0, moved["center"][1], moved["center"][2]]  # 3 m off: no match
    extra = dict(copy.deepcopy(objects[2]), id=999999)
    extra["center"] = [extra["center"][0], extra["center"][1] + 4.0, extra["center"][2]]
    built["boxes"].append(extra)
    (tmp_path / "map.json").write_text(json.dumps(built))
    legends = []
    real = reloc.figures.save_figure

    def spy(fig, out, dpi):
        legends.extend(t.get_text() for ax in fig.axes if ax.get_legend() for t in ax.get_legend().get_texts())
        return real(fig, out, dpi)

    monkeypatch.setattr(reloc.figures, "save_figure", spy)
    out = tmp_path / "map.png"
    assert reloc_main(["map", "show", str(tmp_path / "map.json"), "--plot", str(out), "--gt", str(tour)]) == 0
    drawn_gt = sum(1 for b in gt["boxes"] if b.get("kind", "object") in ("object", "wall"))
    assert f"ground truth ({drawn_gt})" in legends and "missed (2)" in legends, legends  # removed + moved away
    assert "extra (2)" in legends and f"matched ({drawn_gt - 2})" in legends, legends  # moved + added
    assert Image.open(out).size[0] > 600
    capsys.readouterr()
    assert reloc_main(["map", "show", str(tmp_path / "map.json"), "--gt", str(tour)]) == 2
    one_line_error(capsys, "--gt", "--plot")
