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


def test_04_the_example_photo_is_scikit_images_public_domain_rocket_and_package_data() -> None:
    """``example_photo()`` is a real outdoor photo with a sky, shipped byte for byte as its licence note says
    (scikit-image's ``rocket.jpg``, sha256 in ``photos/LICENSE.txt``), readable by the photo reader, and carried
    by the package data."""
    import hashlib
    import tomllib

    from physrelight import io

    p = data.example_photo()
    assert p == data.PHOTO_DIR / "rocket.jpg" and p.is_file()
    note = (data.PHOTO_DIR / "LICENSE.txt").read_text()
    assert "public domain" in note and hashlib.sha256(p.read_bytes()).hexdigest() in note
    photo = io.read_photo(p)
    assert photo.image.shape == (427, 640, 3) and not photo.radiance and not photo.notes
    assert photo.image[:40].mean(axis=(0, 1))[2] > photo.image[:40].mean(axis=(0, 1))[0] + 0.1  # a blue sky on top
    skimage = pytest.importorskip("skimage")
    assert p.read_bytes() == (Path(skimage.__file__).parent / "data" / "rocket.jpg").read_bytes()
    root = Path(__file__).resolve().parents[2]
    globs = tomllib.loads((root / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["physrelight"]
    shipped = {q for g in globs for q in (root / "physrelight").glob(g) if q.is_file()}
    assert p in shipped and data.PHOTO_DIR / "LICENSE.txt" in shipped
