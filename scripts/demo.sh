#!/usr/bin/env bash
# The main job: set up everything (system LLVM, venv, CPU torch, the package), then run the demo.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
exec .venv/bin/physrelight demo -o "${1:-out/demo}"
