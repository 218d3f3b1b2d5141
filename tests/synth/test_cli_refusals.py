"""``physrelight synth`` checks sizes and input maps before it makes anything, and a run that fails leaves
nothing of itself behind, its error on a line of its own (issue 41, item 4: each case failed on 4ce9156)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from physrelight.cli import main
from ..cli_refusal import refused


def _refused_last(capsys, args: list[str], match: str) -> str:
    return refused(capsys, args, match, last_line=True)


pytest.importorskip("mitsuba")

TINY = ["--scenes", "1", "--views", "1", "--lights", "1", "--res", "24", "--spp", "2", "--gbuffer-spp", "1",
        "--shadow-spp", "1", "--env-res", "16", "--kinds", "sunsky"]


def test_01_a_scene_that_cannot_fit_in_memory_is_refused_with_the_numbers(tmp_path: Path, capsys) -> None:
    """``--res 100000`` used to end in a 74.5 GiB ArrayMemoryError traceback with a manifest and a .partial
    folder left behind. The estimate (synth.writer.scene_bytes: a measured 600 bytes per pixel plus the process)
    is refused against half the available memory, before the folder is made."""
    from synth import writer

    need = writer.scene_bytes(writer.SynthConfig(res=100_000))
    assert need > 100_000**2 * 500
    last = _refused_last(capsys, ["synth", str(tmp_path / "ds"), "--res", "100000", "--quiet"],
                    "rendering one 100000 x 100000 scene needs about")
    assert f"{need / 2**30:.1f} GiB" in last and "available" in last
    assert list(tmp_path.iterdir()) == []


def _maps(tmp_path: Path, bad: str) -> Path:
    d = tmp_path / "maps"
    d.mkdir()
    good = Path(__file__).resolve().parents[2] / "physrelight" / "data" / "hdri" / "city.exr"
    shutil.copy(good, d / "city.exr")
    if bad == "truncated":
        (d / "broken.exr").write_bytes(good.read_bytes()[: 4000])
    elif bad == "text":
        (d / "broken.exr").write_text("not an image")
    else:  # a readable map that is no lat-long map: 3:1
        from physrelight import io

        io.write_exr(d / "broken.exr", np.ones((8, 24, 3), np.float32))
    return d


@pytest.mark.parametrize("bad", ["truncated", "text", "shape"])
def test_02_every_input_map_is_read_and_checked_first(tmp_path: Path, capsys, bad: str) -> None:
    maps = _maps(tmp_path, bad)
    _refused_last(capsys, ["synth", str(tmp_path / "ds"), *TINY[:-1], "hdri", "--hdri-dir", str(maps)], "broken.exr")
    assert not (tmp_path / "ds").exists()


def test_03_a_run_that_fails_leaves_nothing_and_prints_its_error_on_its_own_line(tmp_path: Path, capsys,
                                                                                   monkeypatch) -> None:
    from synth import render

    real = render.render_lit

    def fail(*a, **k):
        real(*a, **k)
        raise ValueError("the renderer gave up")

    monkeypatch.setattr(render, "render_lit", fail)
    _refused_last(capsys, ["synth", str(tmp_path / "ds"), *TINY], "the renderer gave up")  # progress bar on
    assert list(tmp_path.iterdir()) == []
    (tmp_path / "kept").mkdir()
    _refused_last(capsys, ["synth", str(tmp_path / "kept"), *TINY, "--quiet"], "the renderer gave up")
    assert [p.name for p in tmp_path.iterdir()] == ["kept"] and list((tmp_path / "kept").iterdir()) == []


def test_04_a_failed_run_keeps_what_earlier_runs_finished(tmp_path: Path, capsys, monkeypatch) -> None:
    from synth import render

    ds = tmp_path / "ds"
    assert main(["synth", str(ds), *TINY, "--quiet"]) == 0
    before = sorted(p.name for p in ds.iterdir())
    assert before == ["manifest.json", "scene_0000"]
    monkeypatch.setattr(render, "render_lit", lambda *a, **k: (_ for _ in ()).throw(ValueError("gave up")))
    _refused_last(capsys, ["synth", str(ds), *TINY, "--scenes", "2", "--quiet"], "gave up")
    assert sorted(p.name for p in ds.iterdir()) == before  # no .scene_0001.partial; the manifest stays
