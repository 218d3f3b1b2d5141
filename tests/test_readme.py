"""The README's Python example runs as written (issue 41): its ``python`` block under "## Python API" is taken out
of README.md and run in an empty folder, and what the README says of it holds: the shapes, the value range, the
files it writes, that the relit photo is what ``physrelight relight`` writes at its defaults, and that the turned
sun is the sun at the summed azimuth."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def python_api_block(text: str) -> str:
    """The first fenced ``python`` block of the README's "## Python API" section (up to the next "## " heading)."""
    section = re.search(r"^## Python API\n(.*?)(?=^## )", text, flags=re.S | re.M)
    assert section is not None, "README.md has no '## Python API' section"
    block = re.search(r"^```python\n(.*?)^```", section.group(1), flags=re.S | re.M)
    assert block is not None, "the README's Python API section has no ```python block"
    return block.group(1)


def test_01_the_block_is_found_and_names_only_what_it_imports() -> None:
    code = python_api_block(README.read_text())
    assert "from learned import Relighter" in code and "Relighter.load()" in code
    # Nothing relative to the repository: the inputs come from the package (a user's folder is not the repo's).
    assert "physrelight/data" not in code and '"photo.jpg"' not in code
    compile(code, "README.md", "exec")


@pytest.fixture(scope="module")
def ran(tmp_path_factory) -> tuple[dict, Path]:
    """The block run in an empty folder (as a user would paste it), its namespace and the folder."""
    import os

    import torch

    torch.set_num_threads(1)
    folder = tmp_path_factory.mktemp("readme")
    code = python_api_block(README.read_text())
    here = os.getcwd()
    os.chdir(folder)
    try:
        namespace: dict = {"__name__": "__readme__"}
        exec(compile(code, "README.md", "exec"), namespace)
    finally:
        os.chdir(here)
    return namespace, folder


def test_02_the_photo_and_the_relit_photos_are_display_values_of_the_photos_size(ran) -> None:
    ns, _ = ran
    photo = ns["photo"]
    assert photo.shape == (427, 640, 3) and photo.dtype == np.float32
    assert 0.0 <= photo.min() and photo.max() <= 1.0
    for name in ("relit", "low_sun", "turned"):
        img = ns[name]
        assert isinstance(img, np.ndarray) and img.shape == (427, 640, 3), name
        assert np.isfinite(img).all() and 0.0 <= img.min() and img.max() <= 1.0, name
    # the targets differ, so do the pictures (far beyond rounding)
    assert np.abs(ns["relit"] - ns["low_sun"]).mean() > 0.01
    assert np.abs(ns["low_sun"] - ns["turned"]).mean() > 0.002


def test_03_it_writes_the_pngs_it_names(ran) -> None:
    from physrelight import io

    ns, folder = ran
    written = sorted(p.name for p in folder.iterdir())
    assert written == ["relit_forest.png", "relit_low_sun.png"], written  # nothing else left behind
    for name, key in (("relit_forest.png", "relit"), ("relit_low_sun.png", "low_sun")):
        back = io.read_image(folder / name)
        assert back.shape == (427, 640, 3)
        assert np.abs(back - ns[key]).max() <= 0.5 / 255 + 1e-4  # 8-bit rounding only


def test_04_the_layers_are_the_decomposition_at_full_size(ran) -> None:
    ns, _ = ran
    layers = ns["layers"]
    assert set(layers) == {"albedo", "normals", "shadow", "lighting", "sky_mask"}
    assert layers["albedo"].shape == layers["normals"].shape == (427, 640, 3)
    assert layers["shadow"].shape == layers["sky_mask"].shape == (427, 640, 1)
    assert layers["lighting"].shape == (9, 3) and np.isfinite(layers["lighting"]).all()
    n = np.linalg.norm(layers["normals"], axis=-1)
    assert np.abs(n[~layers["sky_mask"][..., 0].astype(bool)] - 1.0).max() < 1e-3  # unit camera-frame normals
    assert layers["sky_mask"].astype(bool).any()  # the rocket's clear sky is found


def test_05_relit_is_what_the_command_line_writes_at_its_defaults(ran, tmp_path) -> None:
    from physrelight import io
    from physrelight.cli import main
    from physrelight.data import example_photo, hdri

    ns, _ = ran
    out = tmp_path / "cli.png"
    assert main(["relight", str(example_photo()), "--env", str(hdri("forest")), "--quiet", "--threads", "1",
                 "-o", str(out)]) == 0
    assert np.abs(io.read_image(out) - ns["relit"]).max() <= 0.5 / 255 + 1e-4


def test_06_the_turned_sun_is_the_sun_at_the_summed_azimuth(ran) -> None:
    from physrelight.target_lighting import Sun

    ns, _ = ran
    again = ns["relighter"].relight(ns["photo"], Sun(10, 90))  # the README: Sun(10, 60) turned by 30 = Sun(10, 90)
    assert np.abs(again - ns["turned"]).max() < 1e-5
