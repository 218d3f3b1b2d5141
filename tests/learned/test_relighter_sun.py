"""Specification of the estimated track's source lighting read from the photo's sky
(``RelightOptions(source_estimate="sky")``, :mod:`learned.sky_lighting`): where the sky speaks, the relighter divides
by the sky's sun and sky (the quotient's source points at the sun, and the photo relit to its own sun changes less);
where it does not (no sky), it falls back to today's estimate and the output is byte-equal to today's."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from physrelight import envmap
from physrelight.colour import LUMINANCE, linear_to_srgb
from physrelight.panorama import camera_rays, level_camera, view_intrinsics
from physrelight.target_lighting import Sun
from validation.bench.real_metrics import dominant_direction

H, W, FOV, PITCH = 120, 160, 60.0, 12.0
SUN_ELEV, SUN_AZIM = 25.0, 10.0  # in view: 10 deg right of straight ahead


pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.fixture(scope="module")
def relighter():
    from learned import Relighter

    return Relighter.load()


@pytest.fixture(scope="module")
def sky_photo() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mitsuba's ``sunsky`` (turbidity 3, sun 25 deg up, 10 deg right of ahead) through relight's camera (60 deg,
    pitch 12), one stop over the sky's median, sRGB, over a textured ground; the sky mask; the sun in the camera
    frame."""
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the reference sky (pip install mitsuba)")
    from synth.lighting import _mitsuba, _sunsky_dict, eval_emitter

    mi = _mitsuba()
    s = envmap.direction_from_angles(SUN_ELEV, SUN_AZIM)
    emitter = mi.load_dict(_sunsky_dict(mi, s, 3.0, 0.2, sky_scale=1.0, sun_scale=1.0))
    R = level_camera(0.0, PITCH)[:3, :3]
    rays = camera_rays(view_intrinsics(FOV, W, H), R, H, W).numpy()[:, :, 0]
    lin = np.clip(eval_emitter(mi, emitter, rays.reshape(-1, 3)).reshape(H, W, 3), 0.0, None)
    sky = rays[..., 1] > 0
    lin = lin * (0.36 / np.median(lin[sky] @ np.array(LUMINANCE)))
    display = np.clip(np.asarray(linear_to_srgb(lin)), 0.0, 1.0)
    ground = np.clip(np.array([0.35, 0.3, 0.25]) + np.random.default_rng(0).normal(0.0, 0.05, (H, W, 1)), 0.0, 1.0)
    return np.where(sky[..., None], display, ground), sky, R @ s


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def _relit(relighter, option: str, image: np.ndarray, sky: np.ndarray | None, target=Sun(SUN_ELEV, SUN_AZIM)):
    return relighter.with_options(source_estimate=option).relight_layers(
        image, target, sky_mask=sky, fov_deg=FOV, pitch_deg=PITCH, method="quotient", exposure="keep")


def test_01_where_the_sky_speaks_the_quotient_divides_by_its_sun(relighter, sky_photo) -> None:
    """The sky's reading puts the sun within 5 deg; the source lighting the relighting divides by then has its
    dominant direction within 5 deg of the true sun (measured 0.3 deg), where today's estimate is more than 45 deg
    off (measured 82 deg: it leans on the prior's overhead light). Relit to its own sun, the foreground changes by at
    most 0.6 of what today's estimate changes it by (measured 0.026 against 0.056 mean |relit - photo|): the
    photo's own sun is divided out."""
    image, sky, sun_cam = sky_photo
    today = _relit(relighter, "decomposition", image, sky)
    read = _relit(relighter, "sky", image, sky)
    assert today.sky_lighting is None
    assert read.sky_lighting.source == "sky" and read.sky_lighting.reason == ""
    p = read.sky_lighting.posterior
    assert abs(p.elevation_deg - SUN_ELEV) < 5.0 and abs(p.azimuth_deg - SUN_AZIM) < 5.0
    np.testing.assert_array_equal(read.decomposition_lighting, today.decomposition_lighting)
    np.testing.assert_array_equal(today.source_lighting, today.decomposition_lighting)
    assert _angle(dominant_direction(read.source_lighting), sun_cam) < 5.0
    assert _angle(dominant_direction(today.source_lighting), sun_cam) > 45.0
    # at the decomposition's level: only the shape is the sky's
    lum = np.array(LUMINANCE)
    assert read.source_lighting[0] @ lum == pytest.approx(today.decomposition_lighting[0] @ lum, rel=1e-5)
    fg = ~sky
    change_read = np.abs(read["relit"][fg] - image[fg]).mean()
    change_today = np.abs(today["relit"][fg] - image[fg]).mean()
    assert change_read < 0.6 * change_today


def test_02_without_sky_it_falls_back_and_the_output_is_todays_to_the_byte(relighter, sky_photo, caplog) -> None:
    """A photo with no sky pixels (the mask all False): the reading falls back with the reason (and a log line says
    so), nothing is read, and every layer is byte-equal to the decomposition's track."""
    import logging

    image, sky, _ = sky_photo
    no_sky = np.zeros_like(sky)
    ground = np.where(sky[..., None], image[::-1], image)  # the ground mirrored over the sky: no sky in the photo
    today = _relit(relighter, "decomposition", ground, no_sky)
    with caplog.at_level(logging.INFO, logger="learned.relighter"):
        fallback = _relit(relighter, "sky", ground, no_sky)
    assert fallback.sky_lighting.source == "fallback"
    assert "too few sky pixels" in fallback.sky_lighting.reason
    assert any("the decomposition's estimate (fallback: too few sky pixels" in r.getMessage() for r in caplog.records)
    assert set(fallback) == set(today)
    for k in today:
        np.testing.assert_array_equal(fallback[k], today[k], err_msg=k)
    np.testing.assert_array_equal(fallback.source_lighting, today.source_lighting)


def test_03_relight_and_sequences_read_the_sky_once_and_agree_with_layers(relighter, sky_photo) -> None:
    """``relight`` and ``relight_layers`` give the same relit photo with the sky read; a sequence of one azimuth is
    that photo too (the reading is made once per photo and reused)."""
    image, sky, _ = sky_photo
    r = relighter.with_options(source_estimate="sky")
    kw = dict(sky_mask=sky, fov_deg=FOV, pitch_deg=PITCH, method="quotient", exposure="keep")
    layers = r.relight_layers(image, Sun(40.0, -60.0), **kw)
    alone = r.relight(image, Sun(40.0, -60.0), **kw)
    seq = r.relight_sequence(image, Sun(40.0, -60.0), [0.0, 90.0], **kw)
    np.testing.assert_array_equal(alone, layers["relit"])
    np.testing.assert_array_equal(seq[0], layers["relit"])


def test_04_the_option_is_checked_at_the_door() -> None:
    from learned.relight_options import SOURCE_ESTIMATES, RelightOptions

    assert SOURCE_ESTIMATES == ("decomposition", "sky")
    with pytest.raises(ValueError, match="source_estimate must be one of"):
        RelightOptions(source_estimate="sun")


def test_04b_the_reading_refuses_bad_input_by_name() -> None:
    """``read_sky_lighting``: a photo that is not ``(1, 3, H, W)``, a mask of another size or not boolean; and a
    fallback has no lighting to turn into a camera."""
    from learned.sky_lighting import read_sky_lighting

    K, R = view_intrinsics(FOV, 16, 12), level_camera(0.0, PITCH)[:3, :3]
    lin = torch.full((1, 3, 12, 16), 0.2)
    with pytest.raises(ValueError, match="lin must have shape"):
        read_sky_lighting(lin[0], torch.ones(12, 16, dtype=torch.bool), K, R)
    with pytest.raises(ValueError, match="boolean mask of the photo's size"):
        read_sky_lighting(lin, torch.ones(12, 15, dtype=torch.bool), K, R)
    with pytest.raises(ValueError, match="boolean mask of the photo's size"):
        read_sky_lighting(lin, np.ones((12, 16)), K, R)
    reading = read_sky_lighting(lin, np.zeros((12, 16), bool), K, R)
    assert reading.source == "fallback" and reading.sh_world is None
    with pytest.raises(ValueError, match="the sky was not read"):
        reading.camera(R)


def test_05_the_ground_under_the_sky_is_a_lambertian_reflector_of_it(relighter, sky_photo) -> None:
    """``sky_sun_sh``: with a black ground it is the posterior's own ``.sh()`` exactly; the ground at albedo 0.2 adds
    a uniform lower hemisphere of radiance ``c = 0.2 E_up / pi``, ``E_up`` the brute-force irradiance of the MAP sky
    plus the sun on a surface facing up. Its order-2 projection, by hand: ``L00 = 2 pi Y00 c``,
    ``L1-1 = -pi 0.488603 c`` (y is up), every other coefficient 0 (the hemisphere's symmetry); within 2 % (the
    64 x 128 map's quadrature)."""
    from learned.sky_lighting import read_sky_lighting, sky_sun_sh
    from physrelight.image_input import as_image

    image, sky, _ = sky_photo
    lin, _ = as_image(image)
    K, R = view_intrinsics(FOV, W, H), level_camera(0.0, PITCH)[:3, :3]
    reading = read_sky_lighting(lin, torch.from_numpy(sky), K, R)
    post = reading.posterior
    black, sun = sky_sun_sh(post, 0.0)
    np.testing.assert_array_equal(black, post.sh())
    grey, sun2 = sky_sun_sh(post, 0.2)
    np.testing.assert_array_equal(sun, sun2)
    np.testing.assert_array_equal(reading.sh_world, grey)  # the reading's ground is GROUND_ALBEDO = 0.2
    e_up = envmap.irradiance_reference(post.envmap(256).astype(np.float64), np.array([[0.0, 1.0, 0.0]]))[0]
    e_up = e_up + post.sun_irradiance() * post.sun_direction[1]
    c = 0.2 * e_up / math.pi
    diff = grey - black
    np.testing.assert_allclose(diff[0], 2 * math.pi * 0.282095 * c, rtol=0.02)
    np.testing.assert_allclose(diff[1], -math.pi * 0.488603 * c, rtol=0.02)
    assert np.abs(diff[2:]).max() < 0.02 * np.abs(diff[0]).max()
    with pytest.raises(ValueError, match="ground_albedo"):
        sky_sun_sh(post, 1.5)


def test_06_relight_on_the_command_line_says_where_the_photos_lighting_came_from(sky_photo, tmp_path, capsys) -> None:
    """``relight --source-estimate sky`` prints one note naming the sun read from the sky; the default
    (``decomposition``) prints none."""
    from physrelight import io
    from physrelight.cli import main

    image, sky, _ = sky_photo
    photo, mask = tmp_path / "photo.png", tmp_path / "sky.png"
    io.write_png(photo, image)
    io.write_png(mask, sky.astype(np.float32))
    args = [str(photo), "--mask", str(mask), "--fov", str(FOV), "--pitch", str(PITCH), "--sun", "40", "-60",
            "--threads", "1", "--quiet"]
    assert main(["relight", *args, "--source-estimate", "sky", "-o", str(tmp_path / "a.png")]) == 0
    err = capsys.readouterr().err
    assert "physrelight: note: the photo's lighting: read from its sky (sun 2" in err, err
    assert main(["relight", *args, "-o", str(tmp_path / "b.png")]) == 0
    assert "the photo's lighting" not in capsys.readouterr().err


def test_07_relight_layers_decomposes_once_when_the_sky_falls_back(sky_photo, tmp_path, capsys, monkeypatch) -> None:
    """``relight --layers`` with a sky too small to read (100 pixels < ``MIN_SKY_PIXELS``): ``lighting.json`` falls
    back to the decomposition's lighting, the one the relighting made: ``decompose_linear`` runs once, not twice."""
    import json

    from learned.relighter import Relighter
    from physrelight import io
    from physrelight.cli import main

    image, _, _ = sky_photo
    small_sky = np.zeros((H, W), bool)
    small_sky[:10, :10] = True
    photo, mask = tmp_path / "photo.png", tmp_path / "small_sky_mask.png"
    io.write_png(photo, image)
    io.write_png(mask, small_sky.astype(np.float32))
    calls = []
    original = Relighter.decompose_linear

    def counted(self, *a, **k):
        calls.append(1)
        return original(self, *a, **k)

    monkeypatch.setattr(Relighter, "decompose_linear", counted)
    for option in ("decomposition", "sky"):
        calls.clear()
        d = tmp_path / option
        assert main(["relight", str(photo), "--mask", str(mask), "--fov", str(FOV), "--pitch", str(PITCH), "--sun",
                     "40", "-60", "--layers", str(d), "--source-estimate", option, "--threads", "1", "--quiet",
                     "-o", str(tmp_path / f"{option}.png")]) == 0
        rec = json.loads((d / "lighting.json").read_text())
        assert rec["source"] == "fallback" and "too few sky pixels" in rec["reason"]
        assert len(calls) == 1, option
    capsys.readouterr()
    assert (tmp_path / "decomposition" / "lighting.json").read_bytes() == (tmp_path / "sky" / "lighting.json").read_bytes()
