#!/usr/bin/env bash
# The detector trainings of issue 28 as they ran on the device machine (one NVIDIA H200, its image's
# python3 with PyTorch; nothing of the toolkit installed: the checkout is on PYTHONPATH).
# Usage: tools/train_detector_gpu.sh PACK.npz OUT EPOCHS [DEVICE] [SECONDS]
# Trains three runs side by side on the one GPU: the candidates, fastseg at widths 32 and 40 with
# the camera augmentation, and an ablation, fastseg 32 with the first model's exposure jitter only
# (what the camera augmentation buys under sensor noise); RUNS="fastseg40" trains a subset (the
# shipped model was fastseg40 alone). Each run first times two epochs (the second one warm), then
# trains for as many epochs as fit in SECONDS (default 430; at most EPOCHS), so that the one-cycle learning-rate
# schedule runs to its end rather than being cut off; `timeout SECONDS` stays as a guard (then the
# last finished epoch's checkpoint is what comes back, and its log says how many epochs ran). For
# each run: OUT/<run>.onnx, OUT/<run>.pt (the weights and training log without the optimiser:
# `reloc detector export` reads it; `python -c` can print its "log"); OUT/train.log holds every
# run's output. Three runs x two files and the log stay within the device tool's 8 files.
set -u
data=$1; out=$2; epochs=$3; device=${4:-cuda}; limit=${5:-430}
export PYTHONPATH=$PWD PYTHONUNBUFFERED=1
mkdir -p "$out"
{ nvidia-smi -L; python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"; } 2>&1 | tee "$out/train.log"
run() {  # name arch width augment
    timeout "$limit" python3 - "$data" "/tmp/work_$1" "$2" "$3" "$epochs" "$device" "$limit" "$4" <<'PY' > "/tmp/$1.log" 2>&1
import sys, time
t0 = time.perf_counter()
from reloc.detector.settings import TrainConfig
from reloc.detector.train import train
data, work, arch, width, epochs, device, limit, augment = sys.argv[1:]
def cfg(n):
    return TrainConfig(epochs=n, batch=32, lr=2e-3, width=int(width), arch=arch, augment=augment, seed=0)
sec = train(data, work + "_timing", cfg(2), device=device)["epochs"][-1]["seconds"]
left = float(limit) - (time.perf_counter() - t0) - 60  # the export and a margin
n = max(1, min(int(epochs), int(left / (1.1 * sec))))
print(f"timing: {sec} s per epoch, {left:.0f} s left: training {n} epochs", flush=True)
log = train(data, work, cfg(n), device=device, resume=True)
print("trained", log["wall_time_s"])
PY
    echo "training exit $?" >> "/tmp/$1.log"
    python3 - "/tmp/work_$1" "$out/$1" <<'PY' >> "/tmp/$1.log" 2>&1
import json, sys, torch
from reloc.detector.train import export_onnx, load_checkpoint
work, dest = sys.argv[1:]
state = load_checkpoint(f"{work}/checkpoint.pt")
torch.save({"model": state["model"], "log": state["log"]}, dest + ".pt")
export_onnx(dest + ".pt", dest + ".onnx")
print("exported after", len(state["log"]["epochs"]), "epochs:", json.dumps(state["log"]["epochs"][-1]))
PY
}
runs=${RUNS:-fastseg32 fastseg40 fastseg32_exposure}
for r in $runs; do
    case $r in
        fastseg32) run fastseg32 fastseg 32 camera & ;;
        fastseg40) run fastseg40 fastseg 40 camera & ;;
        fastseg32_exposure) run fastseg32_exposure fastseg 32 exposure & ;;
        *) echo "RUNS: unknown run $r (fastseg32, fastseg40, fastseg32_exposure)" >&2; exit 2 ;;
    esac
done
wait
for r in $runs; do echo "== $r"; cat "/tmp/$r.log"; done >> "$out/train.log"
tail -n 12 "$out/train.log"
