#!/usr/bin/env bash
# The detector trainings of issue 28 as they ran on the device machine (one NVIDIA H200, its image's
# python3 with PyTorch; nothing of the toolkit installed: the checkout is on PYTHONPATH).
# Usage: tools/train_detector_gpu.sh PACK.npz OUT EPOCHS [DEVICE]
# Trains two candidates side by side on the one GPU, fastseg at widths 32 and 40 with the camera
# augmentation, and writes for each OUT/<run>.onnx, OUT/<run>.pt (the weights and training log,
# without the optimiser: `reloc detector export` reads it) and OUT/<run>.json (the training log);
# OUT/train.log holds both runs' output.
set -u
data=$1; out=$2; epochs=$3; device=${4:-cuda}
export PYTHONPATH=$PWD PYTHONUNBUFFERED=1
mkdir -p "$out"
{ nvidia-smi -L; python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"; } 2>&1 | tee "$out/train.log"
run() {  # name arch width
    python3 - "$data" "/tmp/work_$1" "$2" "$3" "$epochs" "$device" "$out/$1" <<'PY' > "/tmp/$1.log" 2>&1
import json, shutil, sys, torch
from reloc.detector.settings import TrainConfig
from reloc.detector.train import export_onnx, load_checkpoint, train
data, work, arch, width, epochs, device, dest = sys.argv[1:]
cfg = TrainConfig(epochs=int(epochs), batch=32, lr=2e-3, width=int(width), arch=arch, augment="camera", seed=0)
log = train(data, work, cfg, device=device, resume=True)
state = load_checkpoint(f"{work}/checkpoint.pt")
torch.save({"model": state["model"], "log": state["log"]}, dest + ".pt")
shutil.copy(f"{work}/train_log.json", dest + ".json")
export_onnx(dest + ".pt", dest + ".onnx")
print("done", log["wall_time_s"], json.dumps(log["epochs"][-1]))
PY
}
run fastseg32 fastseg 32 & run fastseg40 fastseg 40 &
wait
for r in fastseg32 fastseg40; do echo "== $r"; cat "/tmp/$r.log"; done >> "$out/train.log"
tail -n 4 "$out/train.log"
