#!/usr/bin/env bash
# Training smoke on a device: a few hundred inverse-network steps (default 300 at 200 px, bf16, CUDA);
# checks the loss falls (mean of the last 20 logged < 0.8 x the first 20), nothing is NaN, a run stopped
# at step K and resumed continues the uninterrupted run (bit-identical on the CPU; on CUDA with
# deterministic algorithms, or within the tolerance scripts/gpu_smoke.py states), and prints steps/s.
#
#   bash scripts/gpu_smoke.sh --data .smoke/data [--steps N] [--res PX] [--device cuda|cpu|mps|auto]
#                             [--precision bf16|fp32|fp16] [--resume-at K] [--json PATH] [--bench]
#
# Exit 0: all checks pass; 1: a check failed (named on stderr); 2: bad input (one line on stderr).
set -euo pipefail
cd "$(dirname "$0")/.."
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}"
export CUBLAS_WORKSPACE_CONFIG="${CUBLAS_WORKSPACE_CONFIG:-:4096:8}"
exec "${PYTHON:-python}" scripts/gpu_smoke.py "$@"
