"""``physrelight validate`` and ``bench`` check their outputs and options before any work: one line on stderr,
exit 2, nothing written (issue 41, item 4: each case failed on 4ce9156, some after minutes of work)."""

from __future__ import annotations

from pathlib import Path

import pytest

from physrelight.cli import main
from ..cli_refusal import refused


@pytest.fixture()
def spy(monkeypatch):
    """Record any call that would start the work (validate's checks, each bench): none may happen."""
    calls: list[str] = []
    from validation import report
    from validation.bench import full_resolution, real, run

    monkeypatch.setattr(report, "run_checks", lambda *a, **k: calls.append("validate"))
    monkeypatch.setattr(run, "run_bench", lambda *a, **k: calls.append("bench") or
                        {"seconds": 0.0, "verdicts": {"finite": {"passed": True}}})
    monkeypatch.setattr(real, "run_real_bench", lambda *a, **k: calls.append("real"))
    monkeypatch.setattr(full_resolution, "run_full_resolution", lambda *a, **k: calls.append("full"))
    return calls


@pytest.mark.parametrize("command", [["validate"], ["bench"], ["bench", "--real"], ["bench", "--full-resolution"]])
@pytest.mark.parametrize("where, match", [
    ("FILE", "is a file, not a folder"),
    ("FILE/sub", "'FILE' is a file, not a folder"),
    ("/proc/nope/rep", "'/proc' does not take new files"),
])
def test_01_an_output_folder_that_cannot_be_made_is_refused_first(tmp_path: Path, capsys, monkeypatch, spy,
                                                                  command: list[str], where: str, match: str) -> None:
    monkeypatch.chdir(tmp_path)
    Path("FILE").write_text("x")
    refused(capsys, [*command, "-o", where], match)
    assert spy == [] and sorted(p.name for p in tmp_path.iterdir()) == ["FILE"]


@pytest.mark.parametrize("args, match", [
    (["--fov", "30", "60"], "--fov goes with --real"),
    (["--seed", "3"], "--seed goes with --real"),
    (["--hdri-dir", "x"], "--hdri-dir goes with --real"),
    (["--native-data", "x"], "--native-data goes with --full-resolution"),
    (["--real", "--no-abs"], "--no-abs goes with the synthetic bench"),
    (["--real", "--runs", "r"], "--runs goes with the synthetic bench"),
    (["--real", "--data", "d"], "--data goes with the synthetic bench (no --real) or --full-resolution"),
    (["--full-resolution", "--fov", "30", "60"], "--fov goes with --real"),
    (["--full-resolution", "--quick"], "--quick goes with"),
    (["--full-resolution", "--no-abs"], "--no-abs goes with the synthetic bench"),
    (["--real", "--full-resolution"], "two different benches"),
])
def test_02_an_option_the_chosen_bench_would_ignore_is_refused(tmp_path: Path, capsys, spy, args: list[str],
                                                               match: str) -> None:
    refused(capsys, ["bench", *args, "-o", str(tmp_path / "out")], match)
    assert spy == [] and list(tmp_path.iterdir()) == []


def test_03_the_options_each_bench_reads_still_reach_it(tmp_path: Path, capsys, spy, monkeypatch) -> None:
    """The refusals refuse only ignored options: each mode's own options run (the work itself is spied on)."""
    from synth import panorama_crops

    monkeypatch.setattr(panorama_crops, "folder_panoramas", lambda d: None)
    seen = {}
    from validation.bench import real

    def fake_real(level, hdri_dir, out, command, **kw):
        seen.update(kw, command=command)
        return {"seconds": 0.0, "crops": []}

    monkeypatch.setattr(real, "run_real_bench", fake_real)
    assert main(["bench", "--real", "--fov", "40", "70", "--seed", "3", "--hdri-dir", str(tmp_path),
                 "-o", str(tmp_path / "o")]) == 0
    assert seen["fov_range"] == (40.0, 70.0) and seen["seed"] == 3 and "--fov 40 70" in seen["command"]
    assert main(["bench", "--real", "-o", str(tmp_path / "o")]) == 0
    assert seen["fov_range"] == (45.0, 75.0) and seen["seed"] == 0


def test_04_a_bench_without_llvm_names_the_real_setup_command(tmp_path: Path, capsys, spy, monkeypatch) -> None:
    """Without an LLVM >= 16 library the analysis-by-synthesis baseline cannot run: one line naming
    ``bash scripts/setup.sh`` (the hint used to name a ``make setup`` that does not exist) and --no-abs."""
    from synth import backend

    monkeypatch.setattr(backend, "find_llvm", lambda: None)
    err = refused(capsys, ["bench", "-o", str(tmp_path / "out")], "bash scripts/setup.sh")
    assert "--no-abs" in err and "make setup" not in err
    assert spy == [] and list(tmp_path.iterdir()) == []
    assert "make setup" not in backend._INSTALL_HINT and "bash scripts/setup.sh" in backend._INSTALL_HINT
    assert main(["bench", "--no-abs", "-o", str(tmp_path / "out")]) == 0 and spy == ["bench"]  # not needed then


def test_05_no_file_of_the_project_names_a_make_setup_that_does_not_exist() -> None:
    root = Path(__file__).resolve().parents[2]
    assert not (root / "Makefile").exists()
    hits = [str(p.relative_to(root)) for p in root.rglob("*") if p.is_file() and p.suffix in (".py", ".md", ".sh",
                                                                                               ".toml", ".txt")
            and ".git" not in p.parts and ".venv" not in p.parts and p.name != Path(__file__).name
            and "make setup" in p.read_text(errors="ignore")]
    assert hits == []
