#!/usr/bin/env bash
# Sets up everything physrelight needs on a fresh Debian 12 machine with Python 3.11:
# the system LLVM that Mitsuba's llvm_ad_rgb variant loads, a virtual environment
# with the CPU build of torch, and the package with all its extras.
# Idempotent: a stamp keyed on pyproject.toml skips the pip step when nothing changed.
# PHYSRELIGHT_COLMAP=1 also installs Debian's colmap (3.8; SIFT, matching and mapper on the CPU) for the
# tests marked `colmap` (tests/synth/test_colmap_tool.py), which are skipped without it.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${PHYSRELIGHT_VENV:-.venv}
PY=${PYTHON:-python3.11}
command -v "$PY" >/dev/null 2>&1 || PY=python3

have_llvm() {
    local v
    for v in 21 20 19 18 17 16; do
        for d in /usr/lib/x86_64-linux-gnu /usr/lib/aarch64-linux-gnu /usr/lib/llvm-$v/lib /usr/lib64 /usr/local/lib; do
            [ -e "$d/libLLVM-$v.so" ] || [ -e "$d/libLLVM.so.$v.1" ] || [ -e "$d/libLLVM-$v.so.1" ] && return 0
        done
    done
    return 1
}

if ! have_llvm; then
    echo "[setup] installing libllvm19 (Mitsuba's llvm_ad_rgb needs LLVM >= 16)"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libllvm19 >/dev/null
fi

if [ "${PHYSRELIGHT_COLMAP:-0}" = "1" ] && ! command -v colmap >/dev/null 2>&1; then
    echo "[setup] installing colmap (PHYSRELIGHT_COLMAP=1)"
    SUDO=""
    [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq colmap >/dev/null
fi

if [ ! -x "$VENV/bin/python" ]; then
    echo "[setup] creating virtual environment $VENV"
    if ! "$PY" -m venv "$VENV" 2>/dev/null; then
        # Debian's system Python ships venv separately.
        rm -rf "$VENV"
        SUDO=""
        [ "$(id -u)" -eq 0 ] || SUDO="sudo"
        $SUDO apt-get update -qq
        DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq python3-venv >/dev/null
        "$PY" -m venv "$VENV"
    fi
fi

stamp="$VENV/.physrelight-setup"
# The editable install records the top-level packages it found: re-run when they change.
want=$( (cat pyproject.toml; ls -d -- */__init__.py 2>/dev/null) | sha256sum | cut -d' ' -f1)
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    echo "[setup] installing torch==2.13.0 (CPU build) and physrelight[all]"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" -m pip install -q "torch==2.13.0"
    "$VENV/bin/python" -m pip install -q -e ".[all]"
    echo "$want" > "$stamp"
fi
