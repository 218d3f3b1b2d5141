#!/usr/bin/env bash
# The GPU check the lead runs on the device machine (one CUDA GPU; Python 3.12, torch with CUDA, no
# Mitsuba, no network). Carry .smoke/data (scripts/make_smoke_data.sh renders it here) and the OpenEXR
# wheel (the dataset's depth maps are EXR). Budget: under 6 minutes wall time (BUDGET=330 s for the parts).
#
#   bash scripts/device_check.sh            (writes $OUT/gpu_smoke.json and $OUT/device_check.log)
#
# 1. nvidia-smi -L and a few-second CUDA warm-up;
# 2. the smoke: 300 inverse-network steps at 200 px in bf16, loss falls, no NaN, resume at 150 continues
#    the run (scripts/gpu_smoke.py states the rules);
# 3. steps/s at 64 and 200 px in fp32 and bf16 (80 steps each, median of 20-step windows after the first);
# 4. a few steps of the other paths on CUDA: ShadowNet in fp16 (loss scaler), the renderer through both
#    phases in bf16, 2 DataLoader workers with pinned memory.
# Each part runs under its own timeout and a failure is recorded, not fatal, so one run gives every figure.
set -uo pipefail
cd "$(dirname "$0")/.."
OUT="${OUT:-out/device_check}"
DATA="${DATA:-.smoke/data}"
PY="${PYTHON:-python}"
mkdir -p "$OUT"
LOG="$OUT/device_check.log"
: > "$LOG"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
export CUBLAS_WORKSPACE_CONFIG=":4096:8"
PARTS="$OUT/parts"
mkdir -p "$PARTS"
STATUS="$PARTS/status.txt"
: > "$STATUS"

BUDGET="${BUDGET:-330}"  # seconds for all parts: a part gets at most what is left, none starts with < 15 s

part() {  # part NAME TIMEOUT_S COMMAND...: run, log, record the exit status (124 = timed out)
    local name="$1" limit="$2"; shift 2
    local t0=$SECONDS left=$((BUDGET - SECONDS))
    if [ "$left" -lt 15 ]; then
        echo "=== $name: skipped, budget spent" | tee -a "$LOG"
        echo "$name skipped 0" >> "$STATUS"
        return
    fi
    [ "$limit" -gt "$left" ] && limit=$left
    echo "=== $name: $*" | tee -a "$LOG"
    timeout "$limit" "$@" >> "$LOG" 2>&1
    local rc=$?
    echo "=== $name: exit $rc after $((SECONDS - t0)) s" | tee -a "$LOG"
    echo "$name $rc $((SECONDS - t0))" >> "$STATUS"
}

part nvidia_smi 20 nvidia-smi -L
part versions 60 "$PY" -c "import sys, torch, numpy, OpenEXR; print(sys.version.split()[0], 'torch', torch.__version__, 'cuda', torch.version.cuda, torch.cuda.is_available(), 'numpy', numpy.__version__, 'OpenEXR', OpenEXR.__version__)"
part warmup 60 "$PY" -c "
import time, torch
t = time.perf_counter(); x = torch.randn(4096, 4096, device='cuda')
for _ in range(50): x = (x @ x).tanh()
torch.cuda.synchronize(); print('warm-up', round(time.perf_counter() - t, 2), 's on', torch.cuda.get_device_name())"
part smoke_200_bf16 150 "$PY" scripts/gpu_smoke.py --data "$DATA" --steps 300 --resume-at 150 --res 200 \
    --device cuda --precision bf16 --json "$PARTS/smoke_200_bf16.json"
for res in 64 200; do
    for prec in fp32 bf16; do
        part "bench_${res}_${prec}" 45 "$PY" scripts/gpu_smoke.py --data "$DATA" --bench --steps 80 --res "$res" \
            --device cuda --precision "$prec" --json "$PARTS/bench_${res}_${prec}.json"
    done
done
RUNS="$(mktemp -d)"
CLI=("$PY" -c "from physrelight.cli import main; raise SystemExit(main())")
part inverse_workers2 40 "${CLI[@]}" train inverse --data "$DATA" --out "$RUNS/inv" --res 64 --steps 12 \
    --val-every 12 --val-images 2 --val-split all --ckpt-every 6 --device cuda --precision bf16 --workers 2 --quiet
part shadow_fp16 40 "${CLI[@]}" train shadow --data "$DATA" --out "$RUNS/sh" --inverse "$RUNS/inv" --res 64 \
    --steps 12 --val-every 12 --val-images 2 --val-split all --ckpt-every 6 --device cuda --precision fp16 --quiet
part renderer_bf16 60 "${CLI[@]}" train renderer --data "$DATA" --out "$RUNS/rn" --res 64 --steps 12 \
    --phase1-steps 6 --val-every 12 --val-images 2 --val-split all --ckpt-every 6 --device cuda --precision bf16 --quiet
rm -rf "$RUNS"

"$PY" - "$PARTS" "$OUT/gpu_smoke.json" <<'PYEOF'
import json, sys
from pathlib import Path
parts, dest = Path(sys.argv[1]), Path(sys.argv[2])
report = {"parts": {}, "figures": {}}
for line in (parts / "status.txt").read_text().split("\n"):
    if line.strip():
        name, rc, secs = line.split()
        report["parts"][name] = {"exit": int(rc) if rc != "skipped" else rc, "seconds": int(secs)}
for f in sorted(parts.glob("*.json")):
    report["figures"][f.stem] = json.loads(f.read_text())
report["steps_per_s"] = {k: v.get("steps_per_s") for k, v in report["figures"].items()}
report["pass"] = all(p["exit"] == 0 for p in report["parts"].values())
tmp = dest.with_name(dest.name + ".tmp")
tmp.write_text(json.dumps(report, indent=1))
tmp.replace(dest)
print(json.dumps({"pass": report["pass"], "steps_per_s": report["steps_per_s"],
                  "parts": {k: v["exit"] for k, v in report["parts"].items()}}, indent=1))
PYEOF
echo "total ${SECONDS} s; figures in $OUT/gpu_smoke.json, log in $LOG" | tee -a "$LOG"
