#!/usr/bin/env bash
# The detector trainings of issue 28 as they ran on the device machine (one NVIDIA H200, its image's
# python3 with PyTorch; nothing of the toolkit installed: the checkout is on PYTHONPATH).
# Usage: tools/train_detector_gpu.sh PACK.npz OUT EPOCHS
# Trains three candidates side by side on the one GPU (fastseg at widths 32 and 40 with the camera
# augmentation, and the first model's segnet-24 on the same data and augmentation as a control),
# each exported to OUT/<run>.onnx with OUT/<run>.json (its training log).
set -u
data=$1; out=$2; epochs=$3
export PYTHONPATH=$PWD PYTHONUNBUFFERED=1
nvidia-smi -L || true
python3 -c "import torch; print('torch', torch.__version__, 'cuda', torch.cuda.is_available())"
run() {  # name arch width
    python3 - "$data" "$out/work_$1" "$2" "$3" "$epochs" <<'PY' > "$out/$1.log" 2>&1
import sys
from reloc.detector.settings import TrainConfig
from reloc.detector.train import export_onnx, train
data, work, arch, width, epochs = sys.argv[1:]
cfg = TrainConfig(epochs=int(epochs), batch=32, lr=2e-3, width=int(width), arch=arch, augment="camera", seed=0)
log = train(data, work, cfg, device="cuda", resume=True)
export_onnx(f"{work}/checkpoint.pt", f"{work}/model.onnx")
print("done", log["wall_time_s"], log["epochs"][-1])
PY
    cp "$out/work_$1/model.onnx" "$out/$1.onnx"; cp "$out/work_$1/train_log.json" "$out/$1.json"
}
mkdir -p "$out"
run fastseg32 fastseg 32 & run fastseg40 fastseg 40 & run segnet24 segnet 24 &
wait
tail -n 3 "$out"/*.log
rm -rf "$out"/work_*
