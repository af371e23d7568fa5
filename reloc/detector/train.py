"""Train the learned detector, and export it to ONNX: the command is ``reloc detector train`` (its
options and defaults are ``reloc.detector.cli``'s, from ``reloc.detector.settings.TrainConfig``).

Loss: class-weighted cross-entropy on the per-pixel classes (weights ``freq ** -0.5``, normalised,
so that small objects count) plus binary cross-entropy on instance boundaries (positive weight
``boundary_pos_weight``). Augmentation: horizontal flips and an exposure change (the stored sRGB
frame decoded to linear, scaled by ``2 ** U(-e, e)``, encoded again), since exposure belongs to the
camera, not to the rendered light. Adam with a cosine schedule; seeded.

Validation frames are whole tours held out by layout (``val_layouts``); the checkpoint after each
epoch is written atomically, and ``--resume`` continues from it. Runs on the CPU or, with
``--device cuda``, on a GPU; it imports nothing of the toolkit but this package and
``vrformats.atomic``, so it runs wherever PyTorch and Pillow are.
"""

from __future__ import annotations

import json
import math
import sys
import time
import warnings
from dataclasses import asdict
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from vrformats.atomic import replacing, write_json_atomic
from vrformats.errors import UserError, one_line

from .augment import camera_augment, srgb_decode, srgb_encode
from .data import boundaries, load
from .settings import INPUT_HEIGHT, INPUT_WIDTH, AugmentConfig, TrainConfig
from .model import build, parameter_count

MODEL_FORMAT = "videoreloc-segnet/1"
NEW_CLASS_BIAS_MARGIN = 2.0  # --init: a class the model did not have starts this far under its lowest bias


def _weights(sem: np.ndarray, n: int) -> torch.Tensor:
    counts = np.bincount(sem.ravel(), minlength=n).astype(np.float64)
    freq = counts / counts.sum()
    w = np.where(counts > 0, (freq + 1e-6) ** -0.5, 0.0)
    w = w / w[counts > 0].mean()
    return torch.tensor(np.minimum(w, 10.0), dtype=torch.float32)


def _augment(x: torch.Tensor, g: torch.Generator, exposure_log2: float) -> torch.Tensor:
    """x: (B, 3, H, W) sRGB in [0, 1]: an exposure change in linear light, per image."""
    gain = 2.0 ** ((torch.rand(x.shape[0], 1, 1, 1, generator=g, device=x.device) * 2 - 1) * exposure_log2)
    return srgb_encode(srgb_decode(x) * gain)


def pad_to(x: torch.Tensor, stride: int) -> torch.Tensor:
    """(B, C, H, W) padded at the bottom and right (edge values) to multiples of ``stride``, as
    ``reloc.detection.learned`` pads a frame for the model."""
    ph, pw = (-x.shape[-2]) % stride, (-x.shape[-1]) % stride
    return F.pad(x, (0, pw, 0, ph), mode="replicate") if ph or pw else x


def forward(model, x: torch.Tensor):
    """The model's (semantic, boundary) logits for a batch of any size (padded, then cropped)."""
    h, w = x.shape[-2:]
    ls, lb = model(pad_to(x, model.stride))
    return ls[..., :h, :w], lb[..., :h, :w]


def onnx_init(path) -> dict:
    """What ``--init MODEL.onnx`` takes from an exported model: its classes, architecture, width and
    the (weight, bias) of each convolution in graph order (batch norm folded in by the export)."""
    import onnx
    from onnx import numpy_helper

    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: model not found")
    try:
        m = onnx.load(str(path))
    except Exception as e:  # noqa: BLE001 - a truncated or foreign file
        raise UserError(f"{path}: not an ONNX model ({one_line(e, limit=120)})") from None
    meta = {p.key: p.value for p in m.metadata_props}
    if meta.get("format") != MODEL_FORMAT:
        raise UserError(f"{path}: not a model of reloc detector export (format {meta.get('format')!r})")
    cfg = json.loads(meta.get("train", "{}")).get("config", {})
    inits = {t.name: numpy_helper.to_array(t) for t in m.graph.initializer}
    convs = []
    for node in m.graph.node:
        if node.op_type == "Conv":
            w = inits.get(node.input[1])
            b = inits.get(node.input[2]) if len(node.input) > 2 else None
            if w is None:
                raise UserError(f"{path}: convolution {node.name} has no stored weights")
            convs.append((np.array(w, np.float32), np.array(b, np.float32) if b is not None else np.zeros(w.shape[0], np.float32)))
    return {"classes": json.loads(meta["classes"]), "arch": cfg.get("arch", "segnet"), "width": cfg.get("width"),
            "convs": convs, "path": str(path)}


@torch.no_grad()
def init_from_onnx(model, init: dict, classes: list[str], calib: torch.Tensor) -> dict:
    """Load an exported model's weights into ``model`` (same architecture and width) to fine-tune it.

    The export folded each batch norm into the convolution before it, so a body convolution gets the
    folded weight and its batch norm is set so that it changes nothing in eval mode, whatever the
    statistics: ``gamma = sigma``, ``beta = mu + b``, running mean ``mu``, running variance
    ``sigma^2 - eps``. ``mu`` and ``sigma`` are the channel's mean and spread on ``calib`` (a batch
    of training frames), so that in training mode, where batch norm uses the batch's own
    statistics, the network starts close to the exported one. The class head keeps the rows of the
    classes both lists share (by name); a new class starts with zero weights and a bias
    ``NEW_CLASS_BIAS_MARGIN`` under the lowest exported one, so that it is rarely predicted until trained. Returns what was carried over."""
    from torch import nn

    convs = [m for m in model.modules() if isinstance(m, nn.Conv2d)]
    if len(convs) != len(init["convs"]) or any(c.weight.shape[1:] != torch.Size(w.shape[1:]) for c, (w, _) in
                                              zip(convs[:-2], init["convs"][:-2])):
        raise UserError(f"{init['path']}: its network ({init['arch']}, width {init['width']}) is not the one being "
                        f"trained; pass --arch {init['arch']} --width {init['width']}")
    bns = [m for m in model.modules() if isinstance(m, nn.BatchNorm2d)]
    body = convs[:-2]
    if len(bns) != len(body):
        raise UserError(f"{init['path']}: expected a batch norm after each of {len(body)} convolutions")
    for conv, bn, (w, b) in zip(body, bns, init["convs"]):
        conv.weight.copy_(torch.from_numpy(w))
        bn.weight.fill_(1.0)
        bn.bias.copy_(torch.from_numpy(b))
        bn.running_mean.zero_()
        bn.running_var.fill_(1.0 - bn.eps)
    # the statistics of each body convolution's output, in eval mode (which the settings above keep exact)
    stats = {}
    hooks = [bn.register_forward_hook(lambda m, i, o, k=k: stats.__setitem__(k, (i[0].mean((0, 2, 3)), i[0].std((0, 2, 3)))))
             for k, bn in enumerate(bns)]
    model.eval()
    model(pad_to(calib, model.stride))
    for h in hooks:
        h.remove()
    for k, bn in enumerate(bns):
        mu, sd = stats[k]
        sd = sd.clamp_min(1e-3)
        b = bn.bias.clone()
        bn.weight.copy_(sd)
        bn.bias.copy_(mu + b)
        bn.running_mean.copy_(mu)
        bn.running_var.copy_(sd * sd - bn.eps)
    old = {c: i for i, c in enumerate(init["classes"])}
    (ws, bs), (wb, bb) = init["convs"][-2], init["convs"][-1]
    sem, bnd = convs[-2], convs[-1]
    sem.weight.zero_()
    sem.bias.fill_(float(bs.min()) - NEW_CLASS_BIAS_MARGIN)
    kept = []
    for i, c in enumerate(classes):
        if c in old:
            sem.weight[i] = torch.from_numpy(ws[old[c]])
            sem.bias[i] = float(bs[old[c]])
            kept.append(c)
    bnd.weight.copy_(torch.from_numpy(wb))
    bnd.bias.copy_(torch.from_numpy(bb))
    return {"model": init["path"], "kept_classes": kept, "new_classes": [c for c in classes if c not in old]}


def train(data_path, out, cfg: TrainConfig, device: str = "cpu", resume: bool = False, progress: bool = True,
          augment: AugmentConfig | None = None, init: str | None = None) -> dict:
    """Train on a packed set; writes ``out/checkpoint.pt``, ``out/train_log.json`` and returns the log."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    torch.manual_seed(cfg.seed)
    if str(device).startswith("cuda"):
        torch.backends.cudnn.benchmark = True  # fixed input sizes: let cuDNN pick its fastest kernels
    ds = load(data_path)
    n_cls = len(ds.classes)
    layouts = sorted(set(ds.layouts))
    if cfg.val_layouts or len(layouts) > 1:
        val_layouts = set(cfg.val_layouts or layouts[-1:])
        val = np.array([lay in val_layouts for lay in ds.layouts])
    else:  # one layout: hold out its last tour
        val_layouts = {f"{layouts[0]} (tour {ds.tours[-1]})"}
        val = np.array([t == ds.tours[-1] for t in ds.tours])
    if val.all() or not val.any():
        raise ValueError(f"validation layouts {sorted(val_layouts)} leave no training or no validation frames")
    if cfg.augment not in ("exposure", "camera"):
        raise UserError(f"augment: expected exposure or camera, got {cfg.augment!r}")
    aug = (augment or AugmentConfig()).with_sensor() if cfg.augment == "camera" else None
    if aug is not None and ds.scales is None:
        raise UserError(f"{data_path}: packed without exposure scales (an older reloc detector pack): "
                        "pack it again for --augment camera")
    bnd = boundaries(ds.instance)
    X = torch.from_numpy(ds.rgb).permute(0, 3, 1, 2).contiguous()  # uint8, moved per batch
    S = torch.from_numpy(ds.semantic.astype(np.int64))
    B = torch.from_numpy(bnd.astype(np.float32))
    SC = torch.from_numpy(ds.scales if ds.scales is not None else np.ones(len(ds), np.float32))
    if device != "cpu":  # the whole set fits on any GPU (6,000 frames at 160x120: 0.5 GB)
        X, S, B, SC = X.to(device), S.to(device), B.to(device), SC.to(device)
    tr_idx, va_idx = np.flatnonzero(~val), np.flatnonzero(val)
    model = build(cfg.arch, n_cls, cfg.width).to(device)
    w = _weights(ds.semantic[~val], n_cls).to(device)
    opt = torch.optim.AdamW(model.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps_per_epoch = math.ceil(len(tr_idx) / cfg.batch)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=cfg.lr, total_steps=cfg.epochs * steps_per_epoch,
                                                pct_start=0.1)
    log = {"format": MODEL_FORMAT, "config": asdict(cfg), "classes": ds.classes, "data": str(data_path),
           "train_frames": int(len(tr_idx)), "val_frames": int(len(va_idx)), "val_layouts": sorted(val_layouts),
           "parameters": parameter_count(model), "device": device, "stride": model.stride,
           "resolution": [int(ds.rgb.shape[2]), int(ds.rgb.shape[1])],
           "augment_config": asdict(aug) if aug is not None else None, "epochs": []}
    start = 0
    ck = out / "checkpoint.pt"
    if init is not None and not (resume and ck.is_file()):
        ini = onnx_init(init)
        calib = X[torch.from_numpy(tr_idx[:: max(1, len(tr_idx) // 64)][:64])].to(device).float() / 255.0
        log["init"] = init_from_onnx(model, ini, ds.classes, calib)
        if progress:
            i = log["init"]
            print(f"initialised from {init}: {len(i['kept_classes'])} classes kept, {len(i['new_classes'])} new "
                  f"({', '.join(i['new_classes'][:12])}{', ...' if len(i['new_classes']) > 12 else ''})", file=sys.stderr)
    if resume and ck.is_file():
        state = load_checkpoint(ck, device)
        was = (state["log"].get("config") or {}).get("epochs")
        if was != cfg.epochs:  # the learning-rate schedule spans the epochs it was started with
            raise UserError(f"{ck}: this run was started for {was} epochs; resume it with --epochs {was}, "
                            "or train into another --out")
        model.load_state_dict(state["model"])
        opt.load_state_dict(state["opt"])
        sched.load_state_dict(state["sched"])
        log = state["log"]
        start = len(log["epochs"])
    g = torch.Generator(device="cpu").manual_seed(cfg.seed)
    gd = torch.Generator(device=device).manual_seed(cfg.seed)
    t_all = time.perf_counter()
    for epoch in range(start, cfg.epochs):
        model.train()
        t0 = time.perf_counter()
        perm = tr_idx[torch.randperm(len(tr_idx), generator=g).numpy()]
        tot = 0.0
        for k in range(steps_per_epoch):
            idx = torch.from_numpy(perm[k * cfg.batch:(k + 1) * cfg.batch]).to(X.device)
            s, b = S[idx].to(device), B[idx].to(device)
            if aug is not None:
                x = camera_augment(X[idx].to(device), SC[idx].to(device), aug, gd)
            else:
                x = _augment(X[idx].to(device).float() / 255.0, gd, cfg.exposure_log2)
            flip = (torch.rand(len(idx), generator=g) < 0.5).to(device)
            x[flip], s[flip], b[flip] = x[flip].flip(-1), s[flip].flip(-1), b[flip].flip(-1)
            ls, lb = forward(model, x)
            loss = F.cross_entropy(ls, s, weight=w) + cfg.boundary_loss_weight * F.binary_cross_entropy_with_logits(
                lb[:, 0], b, pos_weight=torch.tensor(cfg.boundary_pos_weight, device=device))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            tot += loss.item() * len(idx)
        va = torch.from_numpy(va_idx).to(X.device)
        ev = evaluate_pixels(model, X[va], S[va], n_cls, device)
        rec = {"epoch": epoch + 1, "loss": round(tot / len(tr_idx), 5), "val_pixel_acc": ev["pixel_acc"],
               "val_miou": ev["miou"], "seconds": round(time.perf_counter() - t0, 2)}
        log["epochs"].append(rec)
        with replacing(ck) as tmp:
            torch.save({"model": model.state_dict(), "opt": opt.state_dict(), "sched": sched.state_dict(), "log": log}, tmp)
        if progress:
            print(json.dumps(rec), file=sys.stderr, flush=True)
    log["wall_time_s"] = round(time.perf_counter() - t_all, 1)
    write_json_atomic(out / "train_log.json", log, indent=1)
    return log


@torch.no_grad()
def evaluate_pixels(model, X: torch.Tensor, S: torch.Tensor, n_cls: int, device: str, batch: int = 64) -> dict:
    model.eval()
    conf = torch.zeros(n_cls, n_cls, dtype=torch.int64)
    for k in range(0, len(X), batch):
        x = X[k:k + batch].to(device).float() / 255.0
        pred = forward(model, x)[0].argmax(1).cpu()
        s = S[k:k + batch].cpu()
        conf += torch.bincount(s.reshape(-1) * n_cls + pred.reshape(-1), minlength=n_cls * n_cls).reshape(n_cls, n_cls)
    tp = conf.diag().double()
    present = conf.sum(1) > 0
    iou = tp / (conf.sum(0) + conf.sum(1) - conf.diag()).double().clamp_min(1)
    return {"pixel_acc": round(float(tp.sum() / conf.sum().clamp_min(1)), 4),
            "miou": round(float(iou[present].mean()), 4) if present.any() else 0.0}


def load_checkpoint(path, device: str = "cpu") -> dict:
    """A checkpoint of ``reloc detector train``, read with ``weights_only=True``: tensors, numbers,
    strings, lists and dicts only, so a crafted file cannot run code (``torch.load``'s pickle would);
    anything else is one line naming the file."""
    path = Path(path)
    if not path.is_file():
        raise UserError(f"{path}: checkpoint not found")
    try:
        state = torch.load(path, map_location=device, weights_only=True)
    except Exception as e:  # noqa: BLE001 - an unpickling refusal, a truncated or foreign file
        raise UserError(f"{path}: not a checkpoint of reloc detector train ({one_line(e, limit=160)})") from None
    if not isinstance(state, dict) or not {"model", "log"} <= set(state):
        raise UserError(f"{path}: not a checkpoint of reloc detector train (no model and log in it)")
    return state


def export_onnx(checkpoint, out_onnx, height: int = INPUT_HEIGHT, width: int = INPUT_WIDTH) -> Path:
    """The checkpoint's model as ONNX (input ``image``: N x 3 x H x W sRGB in [0, 1], H and W
    multiples of the metadata's ``stride``; outputs ``semantic`` and ``boundary`` logits), with its
    classes, format, stride and training resolution in the metadata."""
    import onnx

    state = load_checkpoint(checkpoint, "cpu")
    log = state["log"]
    model = build(log["config"].get("arch", "segnet"), len(log["classes"]), log["config"]["width"])
    model.load_state_dict(state["model"])
    model.eval()
    out_onnx = Path(out_onnx)
    with replacing(out_onnx) as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # the TorchScript exporter: no onnxscript needed
        stride = model.stride
        h, w = height + (-height) % stride, width + (-width) % stride
        torch.onnx.export(model, torch.zeros(1, 3, h, w), str(tmp), input_names=["image"],
                          output_names=["semantic", "boundary"], opset_version=17, dynamo=False,
                          dynamic_axes={"image": {0: "n", 2: "h", 3: "w"}, "semantic": {0: "n", 2: "h", 3: "w"},
                                        "boundary": {0: "n", 2: "h", 3: "w"}})
        m = onnx.load(str(tmp))
        for k, v in (("format", MODEL_FORMAT), ("classes", json.dumps(log["classes"])),
                     ("input", f"sRGB 8-bit / 255, NCHW, H and W divisible by {stride}"),
                     ("stride", str(stride)),
                     ("resolution", json.dumps(log.get("resolution") or [width, height])),
                     ("train", json.dumps({k: log[k] for k in ("config", "train_frames", "val_frames", "val_layouts",
                                                              "parameters") if k in log}))):
            p = m.metadata_props.add()
            p.key, p.value = k, v
        onnx.save(m, str(tmp))
    return out_onnx
