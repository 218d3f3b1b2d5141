"""``physrelight.data``: the shipped maps by name, and the package data that carries them."""

from __future__ import annotations

from pathlib import Path

import pytest

from physrelight import data, envmap


def test_01_hdri_gives_the_path_of_a_shipped_map_by_name() -> None:
    assert data.hdri_names() == ("city", "courtyard", "forest", "studio")
    assert data.hdri_names(heldout=True) == ("sunrise",)
    p = data.hdri("forest")
    assert p == Path(data.__file__).resolve().parent / "hdri" / "forest.exr" and p.is_file()
    env = envmap.read(p)
    assert env.ndim == 3 and env.shape[1] == 2 * env.shape[0]
    assert data.hdri("sunrise", heldout=True).is_file()


@pytest.mark.parametrize("name", ["moon", "sunrise", "forest.exr", "", None])
def test_02_an_unknown_name_lists_the_known_ones(name) -> None:
    with pytest.raises(ValueError, match=r"unknown HDRI .*; the shipped ones are city, courtyard, forest, studio"):
        data.hdri(name)


def test_03_the_maps_are_package_data() -> None:
    """pyproject ships every file under physrelight/data (the maps and their sky masks)."""
    import tomllib

    root = Path(__file__).resolve().parents[2]
    cfg = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]
    globs = cfg["package-data"]["physrelight"]
    shipped = {p for g in globs for p in (root / "physrelight").glob(g) if p.is_file()}
    for name in data.hdri_names():
        assert data.hdri(name) in shipped and (data.HDRI_DIR / f"{name}_sky.png") in shipped
    assert any(i in ("physrelight*", "physrelight.data") for i in cfg["packages"]["find"]["include"])
