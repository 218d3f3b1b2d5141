"""``physrelight.data``: the shipped maps by name, and the package data that carries them."""

from __future__ import annotations

from pathlib import Path

import numpy as np
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


def test_04_the_fifteen_more_maps_by_collection_and_kind() -> None:
    """``collection="more"`` gives issue 43's panoramas with the kinds of their ``kinds.json``; the default
    collection is unchanged (test_01)."""
    import json

    kinds = json.loads((data.MORE_DIR / "kinds.json").read_text())
    assert data.hdri_names(collection="more") == tuple(sorted(kinds)) and len(kinds) == 15
    assert data.hdri_names(collection="more", kind="outdoor") == ("pm_city", "pm_dawn", "pm_forest", "pm_night",
                                                                 "pm_sky", "pm_venice")
    assert len(data.hdri_names(collection="more", kind="indoor")) == 8
    assert data.hdri_names(collection="more", kind="walkway") == ("pm_bridge",)
    assert data.hdri_names(kind="outdoor") == ("city", "courtyard", "forest")
    assert data.hdri_names(kind="indoor") == ("studio",)
    assert data.hdri_names(collection="heldout") == data.hdri_names(heldout=True) == ("sunrise",)
    p = data.hdri("pm_sky", collection="more")
    assert p == data.MORE_DIR / "pm_sky.exr" and p.is_file()
    assert data.hdri_kind("pm_lab", collection="more") == "indoor" and data.hdri_kind("studio") == "indoor"
    assert data.hdri_kind("sunrise", heldout=True) == "outdoor"
    assert data.hdri_sky_mask("forest") == data.HDRI_DIR / "forest_sky.png"


@pytest.mark.parametrize("call, match", [
    (lambda: data.hdri("city", collection="more"), r"unknown HDRI of hdri_more 'city'; the shipped ones are pm_apartment"),
    (lambda: data.hdri_names(collection="extra"), r"collection must be one of shipped, heldout, more, got 'extra'"),
    (lambda: data.hdri_names(kind="outside"), r"kind must be one of outdoor, indoor, walkway, got 'outside'"),
    (lambda: data.hdri_names(heldout=True, collection="more"), r"heldout=True .* cannot be combined with 'more'"),
    (lambda: data.hdri_kind("moon", collection="more"), r"unknown HDRI of hdri_more 'moon'"),
])
def test_05_bad_collection_kind_or_name_is_refused_by_name(call, match) -> None:
    with pytest.raises(ValueError, match=match):
        call()


def test_06_every_mask_beside_a_more_map_is_package_data_and_matches_its_map() -> None:
    """A ``pm_NAME_sky.png`` is shipped with its map, has the map's size, and rooms have no sky at all."""
    from synth.panorama_sky import read_sky_mask

    for name in data.hdri_names(collection="more"):
        mask = data.hdri_sky_mask(name, collection="more")
        if mask is None:
            continue
        env = envmap.read(data.hdri(name, collection="more"))
        sky = read_sky_mask(mask, env.shape[:2])
        if data.hdri_kind(name, collection="more") == "indoor":
            assert not sky.any(), name
        else:
            assert 0.05 < sky.mean() < 0.6, name


def test_07_the_more_masks_are_what_their_script_writes() -> None:
    """The PNGs beside the hdri_more maps are scripts/hdri_more_sky_masks.py's reviewed masks, byte for byte in
    content: regenerate them deliberately when a rule changes. pm_forest has none (its sky through the canopy could
    not be made trustworthy at 512 px), nor has pm_bridge (a walkway)."""
    import importlib.util

    from synth.panorama_sky import read_sky_mask

    root = Path(__file__).resolve().parents[2]
    spec = importlib.util.spec_from_file_location("hdri_more_sky_masks", root / "scripts" / "hdri_more_sky_masks.py")
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    assert set(script.LEFT_OUT) == {"pm_forest"}
    for name in data.hdri_names(collection="more"):
        want = script.reviewed_mask(name)
        path = data.hdri_sky_mask(name, collection="more")
        if want is None:
            assert path is None, name
            continue
        np.testing.assert_array_equal(read_sky_mask(path, want.shape), want, err_msg=name)


def test_08_the_example_photo_is_scikit_images_public_domain_rocket_and_package_data() -> None:
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
