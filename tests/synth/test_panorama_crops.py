"""Specification of :mod:`synth.panorama_crops`: real photos with known camera and lighting cut from
real HDR panoramas (the ground truth of ``bench --real``), and the refusals of bad panoramas."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from physrelight import envmap, panorama, sh
from synth import panorama_crops as pc


@pytest.fixture(scope="module")
def sunrise() -> pc.Panorama:
    return pc.load_panorama(pc.HELDOUT_DIR / "sunrise.exr", "heldout")


def test_01_shipped_panoramas_are_grouped_with_their_reviewed_masks() -> None:
    panos = {p.name: p for p in pc.shipped_panoramas()}
    assert {n: p.group for n, p in panos.items()} == {"city": "training", "courtyard": "training",
                                                        "forest": "training", "studio": "indoor",
                                                        "sunrise": "heldout"}
    assert all(p.mask_source == "reviewed" for p in panos.values())
    assert not panos["studio"].sky.any() and panos["sunrise"].sky.mean() > 0.3


def test_02_cameras_spread_round_the_circle_within_their_ranges() -> None:
    cams = pc.crop_cameras(8, seed=5)
    yaws = np.sort([c[0] for c in cams])
    np.testing.assert_allclose(np.diff(yaws), 45.0, atol=1e-9)
    assert all(-5.0 <= p <= 20.0 and 45.0 <= f <= 75.0 for _, p, f in cams)
    assert cams == pc.crop_cameras(8, seed=5) and cams != pc.crop_cameras(8, seed=6)
    with pytest.raises(ValueError, match=r"179"):
        pc.crop_cameras(2, 0, fov_range=(60.0, 180.0))


def test_03_a_crop_is_its_panorama_seen_through_its_recorded_camera(sunrise) -> None:
    crop = pc.make_crops(sunrise, 2, seed=1)[1]
    h, w = crop.size
    np.testing.assert_allclose(crop.K, panorama.view_intrinsics(crop.fov_deg, w, h))
    np.testing.assert_allclose(crop.world_to_camera, panorama.level_camera(crop.yaw_deg, crop.pitch_deg))
    again = panorama.view(sunrise.env, crop.K, crop.world_to_camera, h, w, samples=4)
    np.testing.assert_allclose(crop.radiance, again, rtol=1e-5, atol=1e-6)
    cover = panorama.view_mask(sunrise.sky.astype(np.float32), crop.K, crop.world_to_camera, h, w, samples=4)
    np.testing.assert_array_equal(crop.sky, cover > 0.5)
    # never wider than native, the photo made from the view with an sRGB curve
    assert w == panorama.native_width(crop.fov_deg, pc.ASPECT, sunrise.env.shape[1])
    assert crop.photo.dtype == np.uint8 and crop.params.curve == "srgb"


def test_04_the_crops_camera_frame_lighting_is_the_panorama_turned_into_the_camera(sunrise) -> None:
    crop = pc.make_crops(sunrise, 1, seed=2)[0]
    for order in (2, 4):
        np.testing.assert_allclose(crop.lighting_sh(order),
                                   np.asarray(sh.rotation(crop.rotation, order)) @ sh.project_envmap(
                                       sunrise.env.astype(np.float64), order), rtol=1e-10, atol=1e-10)
    # The camera-frame map looked up along the camera's axis (-z) is what the crop's centre pixel sees.
    cam_map = crop.lighting_map()
    centre = envmap.sample(cam_map, np.array([0.0, 0.0, -1.0]))
    h, w = crop.size
    np.testing.assert_allclose(centre, crop.radiance[h // 2 - 1: h // 2 + 1, w // 2 - 1: w // 2 + 1].mean((0, 1)),
                               rtol=0.15)


def test_05_same_seed_same_bytes_and_the_photo_is_metered(sunrise) -> None:
    a = pc.make_crops(sunrise, 2, seed=3)
    b = pc.make_crops(sunrise, 2, seed=3)
    for x, y in zip(a, b):
        assert x.photo.tobytes() == y.photo.tobytes() and x.params == y.params
    assert a[0].photo.tobytes() != pc.make_crops(sunrise, 2, seed=4)[0].photo.tobytes()
    lum = (a[0].radiance * a[0].gain) @ np.array([0.2126, 0.7152, 0.0722])
    key = float(np.exp(np.mean(np.log(np.maximum(lum, 1e-6)))))
    assert 0.18 * 2**-0.31 < key < 0.18 * 2**0.31  # metered to 0.18, +- 0.3 EV


def test_06_other_maps_through_the_same_rays(sunrise) -> None:
    crop = pc.make_crops(sunrise, 1, seed=0)[0]
    np.testing.assert_allclose(crop.view_of(sunrise.env), crop.radiance, rtol=1e-6)
    const = np.full((16, 32, 3), 2.5, np.float32)
    np.testing.assert_allclose(crop.view_of(const), 2.5, rtol=1e-6)


def _write_map(path, env: np.ndarray) -> None:
    """Write an EXR as a broken camera or tool might: no checks (io.write_exr refuses NaN)."""
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(env, dtype=np.float32)}) as f:
        f.write(str(path))


@pytest.mark.parametrize("case,match", [("not_2_1", r"2:1"), ("nan", r"NaN|finite"), ("negative", r"negative")])
def test_07_bad_panoramas_are_refused_in_one_line(tmp_path, case, match) -> None:
    env = np.ones((16, 32, 3), np.float32)
    if case == "not_2_1":
        env = np.ones((16, 16, 3), np.float32)
    elif case == "nan":
        env[3, 4, 1] = np.nan
    else:
        env[3, 4, 1] = -5.0
    _write_map(tmp_path / "bad.exr", env)
    with pytest.raises(ValueError, match=match) as err:
        pc.load_panorama(tmp_path / "bad.exr")
    assert "\n" not in str(err.value) and "bad.exr" in str(err.value)


def test_08_an_empty_or_missing_folder_is_refused(tmp_path) -> None:
    with pytest.raises(ValueError, match=r"no \.exr or \.hdr"):
        pc.folder_panoramas(tmp_path)
    with pytest.raises(ValueError, match=r"does not exist"):
        pc.folder_panoramas(tmp_path / "nowhere")


def test_09_a_crop_is_never_upsampled_past_the_panorama(sunrise) -> None:
    native = panorama.native_width(60.0, pc.ASPECT, sunrise.env.shape[1])
    with pytest.raises(ValueError, match=r"upsample"):
        pc.make_crop(sunrise, 0, 0.0, 0.0, 60.0, np.random.default_rng(0), width=native + 1)
    assert torch.is_tensor(pc.make_crop(sunrise, 0, 0.0, 0.0, 60.0, np.random.default_rng(0), width=native // 2).rays)
