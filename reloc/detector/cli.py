"""``reloc detector pack|train|export|eval``: the learned detector's commands.

``pack`` and ``eval`` need no PyTorch; ``train`` and ``export`` need the ``[train]`` extra
(``pip install '.[train]'``) and say so in one line when it is missing.
"""

from __future__ import annotations

import json
from pathlib import Path

from vrformats.design import list_tours
from vrformats.errors import UserError, check_output_file, check_output_folder

from .settings import INPUT_HEIGHT, INPUT_WIDTH, TrainConfig
from vrformats.cli import add_json, add_quiet, positive_int


def _tours(args_tours) -> list[Path]:
    """Tour folders from the arguments: a tour (has meta.json) or a design folder (its tours)."""
    out = []
    for t in args_tours:
        p = Path(t)
        if (p / "meta.json").is_file():
            out.append(p)
        elif p.is_dir():
            found = list_tours(p)
            if not found:
                raise UserError(f"{p}: neither a tour nor a folder of tours")
            out += [p / n for n in found]
        else:
            raise UserError(f"{p}: tour not found")
    return out


def _torch():
    try:
        import torch  # noqa: F401
    except ImportError:
        raise UserError("training needs PyTorch: pip install '.[train]'") from None


def cmd_pack(args) -> int:
    from .data import pack, tour_classes

    check_output_file(args.out)
    tours = _tours(args.tours)
    s = pack(tours, args.out, tour_classes(tours), every=args.every, progress=not args.quiet)
    print(f"packed {s['frames']} frames of {len(tours)} tours, {s['classes']} classes, "
          f"{s['bytes'] / 1e6:.1f} MB -> {args.out}")
    return 0


def cmd_train(args) -> int:
    from .data import open_pack

    check_output_folder(args.out)
    if not Path(args.data).is_file():
        raise UserError(f"{args.data}: training set not found (make one with reloc detector pack)")
    open_pack(args.data)  # another file is one line now, before PyTorch loads and the output folder is made
    _torch()
    from .train import export_onnx, train
    arch, width = args.arch, args.width
    if args.init:  # the network is the model's own
        from .train import onnx_init

        ini = onnx_init(args.init)
        arch, width = ini["arch"], ini["width"]
    cfg = TrainConfig(epochs=args.epochs, batch=args.batch, lr=args.lr, width=width, seed=args.seed,
                      arch=arch, augment=args.augment, val_layouts=args.val_layouts)
    log = train(args.data, args.out, cfg, device=args.device, resume=args.resume, progress=not args.quiet,
                init=args.init)
    onnx_path = export_onnx(Path(args.out) / "checkpoint.pt", Path(args.out) / "model.onnx")
    last = log["epochs"][-1]
    print(f"trained {len(log['epochs'])} epochs in {log['wall_time_s']} s; validation mIoU {last['val_miou']}, "
          f"pixel accuracy {last['val_pixel_acc']}; wrote {onnx_path}")
    return 0


def cmd_export(args) -> int:
    _torch()
    from .train import export_onnx

    check_output_file(args.out)
    print(export_onnx(args.checkpoint, args.out, height=args.height, width=args.width))
    return 0


def cmd_eval(args) -> int:
    from .evaluate import evaluate, format_report

    rep = evaluate(args.model, _tours(args.tours), every=args.every, progress=not args.quiet, sensor=args.sensor)
    print(json.dumps(rep, indent=1) if args.json else format_report(rep))
    return 0


def register_cli(subparsers) -> None:
    g = subparsers.add_parser("detector", help="the learned detector: pack renders, train, export, evaluate")
    ds = g.add_subparsers(dest="cmd", required=True)
    a = ds.add_parser("pack", help="pack rendered tours into a training set (.npz)")
    a.add_argument("tours", nargs="+", help="tour folders, or design folders holding tours")
    a.add_argument("--out", required=True, help="training set file (.npz)")
    a.add_argument("--every", type=positive_int, default=1, help="every N-th frame (default 1)")
    add_quiet(a)
    a.set_defaults(fn=cmd_pack)
    a = ds.add_parser("train", help="train the segmentation model, then export it (needs PyTorch)")
    a.add_argument("data", help="training set (.npz) from reloc detector pack")
    a.add_argument("--out", required=True, help="folder: checkpoint.pt, train_log.json, model.onnx")
    d = TrainConfig()
    a.add_argument("--epochs", type=positive_int, default=d.epochs, help=f"default {d.epochs}")
    a.add_argument("--batch", type=positive_int, default=d.batch, help=f"frames per step (default {d.batch})")
    a.add_argument("--lr", type=float, default=d.lr, help=f"Adam's learning rate (default {d.lr:g})")
    a.add_argument("--width", type=int, default=d.width, help=f"channels of the first stage (default {d.width})")
    a.add_argument("--seed", type=int, default=d.seed, help=f"default {d.seed}")
    a.add_argument("--arch", default=d.arch, choices=["segnet", "fastseg"],
                   help=f"network (reloc.detector.model; default {d.arch})")
    a.add_argument("--augment", default=d.augment, choices=["exposure", "camera"],
                   help=f"exposure: flips and exposure only; camera: the camera pipeline (reloc.detector.augment); default {d.augment}")
    a.add_argument("--val-layouts", nargs="*", default=[], help="layouts held out for validation (default: the last)")
    a.add_argument("--device", default="cpu", help="cpu or cuda")
    a.add_argument("--resume", action="store_true", help="continue from the folder's checkpoint")
    a.add_argument("--init", metavar="MODEL.onnx", help="fine-tune: start from an exported model's weights (its "
                   "architecture and width; classes matched by name, new ones added); e.g. reloc/models/detector_v2_160x120.onnx")
    add_quiet(a)
    a.set_defaults(fn=cmd_train)
    a = ds.add_parser("export", help="a checkpoint as ONNX (needs PyTorch)")
    a.add_argument("checkpoint")
    a.add_argument("--out", required=True, help="model file (.onnx)")
    a.add_argument("--height", type=int, default=INPUT_HEIGHT, help=f"input height in pixels (default {INPUT_HEIGHT})")
    a.add_argument("--width", type=int, default=INPUT_WIDTH, help=f"input width in pixels (default {INPUT_WIDTH})")
    a.set_defaults(fn=cmd_export)
    a = ds.add_parser("eval", help="per-lighting class IoU, instance recall/precision, confusions, ms/frame")
    a.add_argument("tours", nargs="+", help="tour folders, or design folders holding tours")
    a.add_argument("--model", required=True, help="ONNX model (reloc detector export)")
    a.add_argument("--every", type=positive_int, default=1)
    a.add_argument("--sensor", help="read the frames through a sensor preset or file (vrformats/sensor_presets: "
                                    "structured_light, tof; default: the renders as they are)")
    add_json(a, "the report")
    add_quiet(a)
    a.set_defaults(fn=cmd_eval)
