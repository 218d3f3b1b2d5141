"""Specification of scripts/clean_hdri_more.py and of the folder it writes, physrelight/data/hdri_more."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest

from physrelight import envmap, io, panorama_repair

ROOT = Path(__file__).resolve().parents[2]
PACKAGED = ROOT / "physrelight" / "data" / "hdri_more"


def _script():
    spec = importlib.util.spec_from_file_location("clean_hdri_more", ROOT / "scripts" / "clean_hdri_more.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def script():
    return _script()


@pytest.fixture(scope="module")
def source(script) -> Path:
    if not (script.SOURCE / "pm_sky.exr").is_file():
        pytest.skip(f"the shared panoramas are not at {script.SOURCE}")
    return script.SOURCE


def test_01_the_folder_holds_every_map_its_kind_and_licence(script) -> None:
    kinds = json.loads((PACKAGED / "kinds.json").read_text())
    assert kinds == script.KINDS and len(kinds) == 15
    assert sorted(n for n, k in kinds.items() if k == "outdoor") == [
        "pm_city", "pm_dawn", "pm_forest", "pm_night", "pm_sky", "pm_venice"]
    assert set(kinds.values()) == {"outdoor", "indoor", "walkway"}
    for name in kinds:
        env = envmap.read(PACKAGED / f"{name}.exr")  # the library's reader: no negatives, finite
        assert env.shape == (256, 512, 3) and env.min() >= 0
    assert "CC0" in (PACKAGED / "LICENSE").read_text()
    assert set(json.loads((PACKAGED / "cleaning.json").read_text())) == set(kinds)
    # Small: the fifteen maps together stay under 8 MB (measured 6.1 MB).
    assert sum((PACKAGED / f"{n}.exr").stat().st_size for n in kinds) < 8e6


def test_02_the_stored_maps_are_the_script_output_and_it_is_deterministic(script, source: Path,
                                                                           tmp_path: Path) -> None:
    first, second = tmp_path / "a", tmp_path / "b"
    assert script.main(["--src", str(source), "--dst", str(first), "--only", "pm_sky"]) == 0
    assert script.main(["--src", str(source), "--dst", str(second), "--only", "pm_sky"]) == 0
    data = (first / "pm_sky.exr").read_bytes()
    assert data == (second / "pm_sky.exr").read_bytes()
    assert data == (PACKAGED / "pm_sky.exr").read_bytes()
    assert sorted(p.name for p in first.iterdir()) == ["pm_sky.exr"]  # no debris


def test_03_a_stored_map_is_the_repair_rounded_to_half(source: Path) -> None:
    decoded = io.read_exr(source / "pm_sky.exr")
    assert decoded.min() < -1000  # the sun's wrecked block, before cleaning
    expected = panorama_repair.repair_panorama(decoded).env.astype(np.float16).astype(np.float32)
    np.testing.assert_array_equal(io.read_exr(PACKAGED / "pm_sky.exr"), expected)


def test_04_the_readme_table_is_the_cleaning_report() -> None:
    report = json.loads((PACKAGED / "cleaning.json").read_text())
    readme = (PACKAGED / "README.md").read_text()
    for name, r in report.items():
        assert f"| {name} |" in readme
        assert abs(r["luminance_change_repair"]) < 1e-4  # the repair keeps energy; the clamp adds it
    assert report["pm_sky"]["windows"] >= 1 and report["pm_sky"]["luminance_change"] > 0.1


def test_05_bad_input_exits_2_with_one_line(script, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    assert script.main(["--src", str(tmp_path / "nowhere"), "--dst", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "is not a folder" in err
    assert script.main(["--src", str(tmp_path), "--dst", str(tmp_path / "out"), "--only", "pm_sky"]) == 2
    assert "lacks pm_sky.exr" in capsys.readouterr().err
    assert script.main(["--src", str(tmp_path), "--dst", str(tmp_path / "out"), "--only", "pm_moon"]) == 2
    assert "unknown map" in capsys.readouterr().err
    assert not (tmp_path / "out").exists()


def test_06_the_readme_says_which_maps_have_a_sky_mask() -> None:
    # The README's sentence is the generator's text; the folder is what scripts/hdri_more_sky_masks.py wrote.
    kinds = json.loads((PACKAGED / "kinds.json").read_text())
    masked = {n for n in kinds if (PACKAGED / f"{n}_sky.png").is_file()}
    readme = (PACKAGED / "README.md").read_text()
    assert "Not here: sky masks" not in readme
    assert {n for n in masked if kinds[n] == "outdoor"} == {"pm_city", "pm_dawn", "pm_night", "pm_sky", "pm_venice"}
    assert "outdoor maps city, dawn, night, sky, venice" in " ".join(readme.split())
    assert {n for n, k in kinds.items() if k == "indoor"} <= masked and "the eight rooms' are empty" in readme
    assert not {"pm_forest", "pm_bridge"} & masked and "pm_forest" in readme and "pm_bridge." in readme
