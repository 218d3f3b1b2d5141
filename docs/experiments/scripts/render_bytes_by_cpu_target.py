"""Does a synthetic dataset's bytes depend on the CPU it is rendered on? Mitsuba's LLVM backend (Dr.Jit) compiles
its kernels for the host's vector unit. This writes one small scene (``synth`` at 64 px, 32 spp) twice: with the
host's own target, and with Dr.Jit's LLVM target forced to AVX2 (``haswell``, 8 lanes) through Dr.Jit-core's C
function ``jit_llvm_set_target`` (not exposed to Python in Dr.Jit 1.5; called through ctypes), and lists the files
whose bytes differ. Run on the 2-core AMD EPYC (``znver4``, AVX-512, 16 lanes) on 2026-12-06: radiance, albedo,
normals, shadows, the photo and ``scene.json`` differ; the environment map and the depth do not.

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/render_bytes_by_cpu_target.py OUT_DIR
"""

from __future__ import annotations

import ctypes
import hashlib
import subprocess
import sys
from pathlib import Path


def digest(root: Path) -> dict[str, str]:
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != "timing.json"}


def write(root: Path, target: str) -> str:
    """Write the scene under ``root`` with the host's target (``"host"``) or AVX2; returns the target used."""
    from synth import writer
    from synth.lighting import _mitsuba

    _mitsuba()
    import drjit as dr

    core = ctypes.CDLL(str(Path(dr.__path__[0]) / "libdrjit-core.so"))
    if target != "host":
        core._Z19jit_llvm_set_targetPKcS0_j.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_uint]
        core._Z19jit_llvm_set_targetPKcS0_j(b"haswell", b"+avx2,+fma,+sse4.2", 8)
    core._Z19jit_llvm_target_cpuv.restype = ctypes.c_char_p
    cfg = writer.SynthConfig(scenes=1, views=2, lights=1, res=64, spp=32, gbuffer_spp=2, shadow_spp=2,
                             env_resolution=16, kinds=("sunsky",))
    writer.write_dataset(root, cfg, progress=False)
    return core._Z19jit_llvm_target_cpuv().decode()


def main(argv: list[str]) -> int:
    if len(argv) == 3 and argv[0] == "--one":  # a child process: one target per process (the JIT keeps its target)
        print(write(Path(argv[1]), argv[2]))
        return 0
    if len(argv) != 1:
        print("usage: render_bytes_by_cpu_target.py OUT_DIR", file=sys.stderr)
        return 2
    out = Path(argv[0])
    roots = {}
    for target in ("host", "avx2"):
        roots[target] = out / target
        used = subprocess.run([sys.executable, __file__, "--one", str(roots[target]), target], check=True,
                              capture_output=True, text=True).stdout.strip().splitlines()[-1]
        print(f"{target}: LLVM target {used}")
    a, b = digest(roots["host"]), digest(roots["avx2"])
    print("files differing:", [k for k in a if a[k] != b.get(k)])
    print("files the same:", [k for k in a if a[k] == b.get(k)])
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
