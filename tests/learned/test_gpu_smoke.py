"""Specification of scripts/gpu_smoke.sh at tiny scale on the CPU, as the GPU machine would run it.

The GPU machine has torch, numpy, pillow, safetensors, tqdm, h5py, scipy, matplotlib and OpenEXR (carried
by the lead), but no Mitsuba, Dr.Jit, trimesh, colour-science, scikit-image or TensorBoard: every run here
has those modules blocked (``sys.modules[name] = None``), so an import of one of them fails the test.
The full-size smoke (300 steps, 200 px, bf16, CUDA) is scripts/device_check.sh's.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]
# Absent on the GPU machine (OpenEXR is carried: the datasets' depth maps are EXR).
BLOCKED = ("mitsuba", "drjit", "trimesh", "colour", "skimage", "tensorboard", "cv2")


def run_blocked(code: str, *args: str) -> subprocess.CompletedProcess:
    """``python -c`` with the GPU machine's missing modules blocked before ``code`` runs."""
    shim = f"import sys\nfor m in {BLOCKED!r}: sys.modules[m] = None\nsys.argv = ['x', *sys.argv[1:]]\n"
    return subprocess.run([sys.executable, "-c", shim + code, *args], capture_output=True, text=True,
                          timeout=600, cwd=ROOT)


SMOKE = "import runpy; runpy.run_path('scripts/gpu_smoke.py', run_name='__main__')"
CLI = "from physrelight.cli import main; raise SystemExit(main())"


def _bf16_on_cpu() -> bool:
    from learned import runs

    try:
        runs.check_compute(torch.device("cpu"), "bf16")
        return True
    except ValueError:
        return False


@pytest.mark.parametrize("precision", ["fp32", "bf16"])
def test_01_the_smoke_passes_on_the_cpu_at_tiny_scale_without_the_renderer_libraries(
        precision: str, tiny_dataset: Path, tmp_path: Path) -> None:
    if precision == "bf16" and not _bf16_on_cpu():
        pytest.skip("this torch has no bf16 autocast on the CPU")
    out = tmp_path / "smoke.json"
    proc = run_blocked(SMOKE, "--data", str(tiny_dataset), "--steps", "8", "--resume-at", "4", "--res", "32",
                       "--batch", "2", "--device", "cpu", "--precision", precision, "--threads", "1",
                       "--json", str(out))
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-3000:]
    report = json.loads(out.read_text())
    assert report["pass"] and report["checks"] == {"loss_falls": True, "finite": True, "resume": True}
    assert report["loss"]["ratio"] < 0.8 and report["loss"]["window"] == 2
    assert report["resume"]["bit_identical"] and report["resume"]["max_param_abs_diff"] == 0.0  # CPU: bit for bit
    assert report["steps_per_s"] > 0 and report["precision"] == precision and report["device"] == "cpu"


def test_02_the_other_training_commands_run_without_the_renderer_libraries(tiny_dataset: Path, tmp_path: Path,
                                                                          tiny_prior: Path) -> None:
    common = ["--data", str(tiny_dataset), "--prior", str(tiny_prior), "--train-split", "all", "--val-split", "all",
              "--res", "24", "--batch", "1", "--steps", "2", "--ckpt-every", "2", "--val-every", "2",
              "--val-images", "2", "--threads", "1", "--quiet", "--device", "cpu"]
    for argv in (["train", "inverse", "--out", str(tmp_path / "inv"), "--width", "4", "--depth", "2", "--workers", "1"],
                 ["train", "shadow", "--out", str(tmp_path / "sh"), "--inverse", str(tmp_path / "inv"), "--width", "4",
                  "--depth", "2"],
                 ["train", "renderer", "--out", str(tmp_path / "rn"), "--width", "4", "--depth", "2", "--d-width", "4",
                  "--phase1-steps", "1"]):
        proc = run_blocked(CLI, *argv, *common)
        assert proc.returncode == 0, (argv[:2], proc.stderr[-3000:])
        assert (tmp_path / argv[3].rsplit("/", 1)[-1] / "summary.json").is_file()


def test_03_bad_input_is_one_line_on_stderr_and_exit_2(tiny_dataset: Path, tmp_path: Path) -> None:
    def sh(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(["bash", "scripts/gpu_smoke.sh", *args], capture_output=True, text=True, timeout=120,
                              cwd=ROOT, env={"PATH": "/usr/bin:/bin", "PYTHON": sys.executable})

    cases = [("--data", str(tmp_path / "none")),
             ("--data", str(tiny_dataset), "--steps", "4", "--resume-at", "4"),
             ("--data", str(tiny_dataset), "--device", "cpu", "--workers", "-1")]
    if not torch.cuda.is_available():
        cases.append(("--data", str(tiny_dataset)))  # the default device is cuda
    if not (getattr(torch.backends, "mps", None) and torch.backends.mps.is_available()):
        cases.append(("--data", str(tiny_dataset), "--device", "mps"))
    for args in cases:
        proc = sh(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gpu_smoke: error:") and "Traceback" not in proc.stderr, args
    out = tmp_path / "busy"
    (out / "x").mkdir(parents=True)
    proc = sh("--data", str(tiny_dataset), "--device", "cpu", "--out", str(out))
    assert proc.returncode == 2 and "not empty" in proc.stderr


def test_04_the_device_scripts_parse_and_the_smoke_data_is_ignored_by_git() -> None:
    for script in ("gpu_smoke.sh", "device_check.sh", "make_smoke_data.sh"):
        proc = subprocess.run(["bash", "-n", f"scripts/{script}"], capture_output=True, text=True, cwd=ROOT)
        assert proc.returncode == 0, (script, proc.stderr)
    proc = subprocess.run(["git", "check-ignore", "-q", ".smoke/data/manifest.json"], cwd=ROOT)
    assert proc.returncode == 0  # the rendered smoke data never lands in a commit
