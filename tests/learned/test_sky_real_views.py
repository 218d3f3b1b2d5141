"""The sky segmenter's real-photo training data and full-resolution mask (issue 25, study 22).

Real views of panoramas (:class:`learned.train_sky.RealCrops`), the wider camera
(``photometric_augment(..., wide=True)``, :func:`learned.sky_segmentation.jpeg_like`) and the
leave-one-panorama-out exclusion, each on small inputs made here.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from learned.sky_segmentation import jpeg_like, photometric_augment


def _panorama(folder: Path, name: str, horizon_row: int = 16) -> None:
    """A 32 x 64 lat-long map: a blue sky over a brown ground, its sky mask beside it."""
    from physrelight import envmap
    from synth.panorama_sky import mask_path, write_sky_mask

    env = np.zeros((32, 64, 3), np.float32)
    env[:horizon_row] = [0.3, 0.5, 1.0]
    env[horizon_row:] = [0.2, 0.12, 0.05]
    path = folder / f"{name}.exr"
    envmap.write(path, env)
    sky = np.zeros((32, 64), bool)
    sky[:horizon_row] = True
    write_sky_mask(mask_path(path), sky)


def test_01_real_views_are_seeded_and_their_sky_is_the_panoramas(tmp_path) -> None:
    from learned.train_sky import RealCrops

    _panorama(tmp_path, "plain")
    a = RealCrops(tmp_path, 16, views=6, seed=3)
    b = RealCrops(tmp_path, 16, views=6, seed=3)
    assert a.image.shape == (6, 3, 16, 16) and a.sky.shape == (6, 1, 16, 16) and a.sky.dtype == torch.bool
    assert torch.equal(a.image, b.image) and torch.equal(a.sky, b.sky)
    assert not torch.equal(a.image, RealCrops(tmp_path, 16, views=6, seed=4).image)
    # the sky is where the view looks at the blue half: blue over red there, brown below
    img = a.image.float()
    ratio = img[:, 2] / img[:, 0].clamp_min(1e-6)
    sky = a.sky[:, 0]
    assert bool(sky.any()) and bool((~sky).any())
    assert float(ratio[sky].median()) > 2.0 and float(ratio[~sky].median()) < 0.5
    im, sk = a.batch(5, seed=0, step=7)
    im2, sk2 = a.batch(5, seed=0, step=7)
    assert im.shape == (5, 3, 16, 16) and torch.equal(im, im2) and torch.equal(sk, sk2)


def test_02_real_views_refuse_the_held_out_panorama_and_an_empty_folder(tmp_path) -> None:
    from learned.train_sky import RealCrops
    from synth.panorama_crops import HELDOUT_DIR

    with pytest.raises(ValueError, match="held-out"):
        RealCrops(HELDOUT_DIR, 16, views=1)
    _panorama(tmp_path, "sunrise")  # a copy under the held-out name is refused too
    with pytest.raises(ValueError, match="held-out"):
        RealCrops(tmp_path, 16, views=1)
    with pytest.raises(ValueError, match="no .exr panorama left"):
        RealCrops(tmp_path, 16, views=1, exclude=("sunrise",))
    with pytest.raises(ValueError, match="does not exist"):
        RealCrops(tmp_path / "nowhere", 16, views=1)


def test_03_jpeg_like_keeps_a_flat_block_and_quantises_detail() -> None:
    flat = torch.full((1, 3, 13, 21), 0.4, dtype=torch.float64)
    # a flat block has only a DC coefficient: 8 * 0.4 = 3.2 is rounded to a multiple of the step
    out = jpeg_like(flat, 0.1)
    assert out.shape == flat.shape and float((out - flat).abs().max()) < 0.1 / 8 + 1e-12
    g = torch.Generator().manual_seed(0)
    noisy = torch.rand(1, 3, 16, 16, generator=g, dtype=torch.float64)
    coarse, fine = jpeg_like(noisy, 0.2), jpeg_like(noisy, 0.01)
    assert float((fine - noisy).abs().mean()) < float((coarse - noisy).abs().mean())
    assert float((jpeg_like(noisy, 1e-9) - noisy).abs().max()) < 1e-8
    with pytest.raises(ValueError, match="step"):
        jpeg_like(noisy, 0.0)


def test_04_the_wide_camera_is_seeded_photographic_and_wider() -> None:
    g = torch.Generator().manual_seed(0)
    image = torch.rand(24, 3, 16, 16, generator=g) * 0.5
    a = photometric_augment(image, torch.Generator().manual_seed(1), wide=True)
    b = photometric_augment(image, torch.Generator().manual_seed(1), wide=True)
    assert torch.equal(a, b) and bool(torch.isfinite(a).all()) and float(a.min()) >= 0 and float(a.max()) <= 1
    narrow = photometric_augment(image, torch.Generator().manual_seed(1))
    # exposure +-2 EV against +-1.5: the spread of mean log brightness is wider
    spread = lambda x: float(torch.log(x.mean((1, 2, 3)) + 1e-4).std())
    assert spread(a) > spread(narrow)
    # the default camera is unchanged by the wide option (same draws, same bytes as before)
    assert torch.equal(narrow, photometric_augment(image, torch.Generator().manual_seed(1), wide=False))


def test_05_leave_one_out_drops_the_photos_lit_by_the_left_out_panorama(tmp_path) -> None:
    import json

    from learned.train_sky import _hdri_name

    scene = tmp_path / "scene_0000" / "lights"
    for k, params in enumerate(({"hdri": "city"}, {"turbidity": 3.0})):
        (scene / f"light_{k:02d}").mkdir(parents=True)
        (scene / f"light_{k:02d}" / "lighting.json").write_text(json.dumps({"kind": "x", "params": params}))
    assert _hdri_name(tmp_path, "scene_0000", 0) == "city"
    assert _hdri_name(tmp_path, "scene_0000", 1) is None
    assert _hdri_name(tmp_path, "scene_0000", 2) is None


def test_06_a_run_with_real_views_is_seeded_and_resumes_bit_identically(tiny_dataset, tmp_path) -> None:
    import csv

    from safetensors.torch import load_file

    from learned.train_sky import SkyTrainConfig, train_sky

    pano = tmp_path / "panoramas"
    pano.mkdir()
    _panorama(pano, "plain")
    _panorama(pano, "low", horizon_row=12)

    def config(out: str, steps: int, **kw) -> SkyTrainConfig:
        base = dict(stage="segmentation", data=str(tiny_dataset), out=str(tmp_path / out), train_split="all",
                    val_split="all", res=24, batch=4, steps=steps, width=4, ckpt_every=3, val_every=1000,
                    val_images=4, log_every=1, threads=1, progress=False, wide_augment=True,
                    real_panoramas=str(pano), real_views=8, real_exclude=("low",))
        base.update(kw)
        return SkyTrainConfig(**base)

    train_sky(config("a", 6))
    train_sky(config("b", 3))
    train_sky(config("b", 6))
    a = load_file(str(tmp_path / "a" / "checkpoints" / "step_0000006.safetensors"))
    b = load_file(str(tmp_path / "b" / "checkpoints" / "step_0000006.safetensors"))
    for k in a:
        assert torch.equal(a[k], b[k]), k
    rows = lambda p: [r[:-1] for r in csv.reader((tmp_path / p / "train.csv").open())]
    assert rows("a") == rows("b")
    with pytest.raises(ValueError, match="another configuration"):
        train_sky(config("b", 8, real_exclude=()))
    with pytest.raises(ValueError, match="real_fraction"):
        config("c", 1, real_fraction=0.0)


def test_02b_real_views_pool_folders_and_take_rooms_as_negatives(tmp_path) -> None:
    """``hdri:hdri_more`` (os.pathsep-joined) pools both folders; a map without a reviewed mask is left out (not
    masked by the procedure); the rooms' empty masks make no-sky views."""
    import os

    from learned.train_sky import RealCrops
    from physrelight import data

    _panorama(tmp_path, "plain")
    crops = RealCrops(f"{tmp_path}{os.pathsep}{data.MORE_DIR}", 16, views=28, seed=0)
    names = [p.name for p in crops.panoramas]
    assert names[0] == "plain" and len(names) == 1 + 13
    assert set(crops.left_out) == {"pm_bridge", "pm_forest"}
    rooms = set(data.hdri_names(collection="more", kind="indoor"))
    for k in range(28):  # the bank draws the panoramas in turn
        if names[k % len(names)] in rooms:
            assert not bool(crops.sky[k].any())
    assert sum(bool(crops.sky[k].any()) for k in range(28) if names[k % len(names)] not in rooms) >= 6
    with pytest.raises(ValueError, match="does not exist"):
        RealCrops([tmp_path, tmp_path / "nowhere"], 16, views=1)
