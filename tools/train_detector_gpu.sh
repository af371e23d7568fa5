#!/usr/bin/env bash
# The detector trainings of issue 28 as they ran on the device machine (one NVIDIA H200, its image's
# python3 with PyTorch; nothing of the toolkit installed: the checkout is on PYTHONPATH).
# Usage: tools/train_detector_gpu.sh PACK.npz OUT EPOCHS [DEVICE] [SECONDS]
# Trains two candidates side by side on the one GPU, fastseg at widths 32 and 40 with the camera
# augmentation, each stopped after SECONDS at the latest (default 430; then the last finished
# epoch's checkpoint is what comes back, and its log says how many epochs ran). For each run:
# OUT/<run>.onnx, OUT/<run>.pt (the weights and training log without the optimiser: `reloc detector
# export` reads it) and OUT/<run>.json (the training log); OUT/train.log holds both runs' output.
set -u
data=$1; out=$2; epochs=$3; device=${4:-cuda}; limit=${5:-430}
export PYTHONPATH=$PWD PYTHONUNBUFFERED=1
mkdir -p "$out"
{ nvidia-smi -L; python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"; } 2>&1 | tee "$out/train.log"
run() {  # name arch width
    timeout "$limit" python3 - "$data" "/tmp/work_$1" "$2" "$3" "$epochs" "$device" <<'PY' > "/tmp/$1.log" 2>&1
import sys
from reloc.detector.settings import TrainConfig
from reloc.detector.train import train
data, work, arch, width, epochs, device = sys.argv[1:]
cfg = TrainConfig(epochs=int(epochs), batch=32, lr=2e-3, width=int(width), arch=arch, augment="camera", seed=0)
log = train(data, work, cfg, device=device, resume=True)
print("trained", log["wall_time_s"])
PY
    echo "training exit $?" >> "/tmp/$1.log"
    python3 - "/tmp/work_$1" "$out/$1" <<'PY' >> "/tmp/$1.log" 2>&1
import json, sys, torch
from reloc.detector.train import export_onnx, load_checkpoint
work, dest = sys.argv[1:]
state = load_checkpoint(f"{work}/checkpoint.pt")
torch.save({"model": state["model"], "log": state["log"]}, dest + ".pt")
json.dump(state["log"], open(dest + ".json", "w"), indent=1)
export_onnx(dest + ".pt", dest + ".onnx")
print("exported after", len(state["log"]["epochs"]), "epochs:", json.dumps(state["log"]["epochs"][-1]))
PY
}
run fastseg32 fastseg 32 & run fastseg40 fastseg 40 &
wait
for r in fastseg32 fastseg40; do echo "== $r"; cat "/tmp/$r.log"; done >> "$out/train.log"
tail -n 12 "$out/train.log"
