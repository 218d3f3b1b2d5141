"""Specification of ``physrelight lighting PHOTO -o lighting.json`` (learned/lighting_cli.py) and of the
``lighting.json`` that ``relight --layers`` writes: the schema of docs/sun-from-sky.md; the sun of a Hosek-Wilkie sky
rendered by Mitsuba's own ``sunsky`` through a known camera comes back within the tolerance of
tests/physrelight/test_sun_from_sky.py (5 deg in view); a photo without sky, an overcast sky and a night sky fall back
to the library's estimate with no sun and a reason; bad input is one line on stderr, exit 2, nothing written."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from physrelight import envmap, io, sh
from physrelight.cli import main
from physrelight.colour import LUMINANCE, linear_to_srgb
from physrelight.panorama import camera_rays, level_camera, view_intrinsics
from physrelight.sky_model import overcast_sky
from ..cli_refusal import refused

H, W, FOV, PITCH = 120, 160, 60.0, 12.0
SUN_ELEV, SUN_AZIM, TURBIDITY = 25.0, 10.0, 3.0  # in view: 10 deg right of straight ahead, 25 deg up
KEYS = {"schema_version", "source", "reason", "sun", "sun_spread", "sun_probability", "sky_kind", "level", "turbidity",
        "overcast_mix", "exponent", "camera", "sky_pixels", "sh_camera", "image_size"}


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def _rays() -> np.ndarray:
    """``(H, W, 3)`` world rays of ``relight``'s camera (level, looking along -Z) at PITCH, FOV."""
    return camera_rays(view_intrinsics(FOV, W, H), level_camera(0.0, PITCH)[:3, :3], H, W).numpy()[:, :, 0]


def _ground(rng: np.random.Generator) -> np.ndarray:
    """``(H, W, 3)`` a textured brownish-grey ground (display values)."""
    return np.clip(np.array([0.35, 0.3, 0.25]) + rng.normal(0.0, 0.05, (H, W, 1)), 0.0, 1.0)


def _photo(tmp_path: Path, sky_display: np.ndarray, sky: np.ndarray, name: str = "photo") -> tuple[Path, Path]:
    """The sky's display values over a textured ground, as PNG, and its sky mask PNG."""
    img = np.where(sky[..., None], sky_display, _ground(np.random.default_rng(0)))
    photo, mask = tmp_path / f"{name}.png", tmp_path / f"{name}_sky.png"
    io.write_png(photo, img)
    io.write_png(mask, sky.astype(np.float32))
    return photo, mask


@pytest.fixture(scope="module")
def clear_sky() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mitsuba's ``sunsky`` (sky and sun, turbidity 3) along the camera's rays, exposed one stop over the sky's
    median and sRGB-encoded, clipped at 1; the sky mask (rays above the horizon); the true sun ``(3,)``."""
    pytest.importorskip("mitsuba", reason="Mitsuba 3 renders the reference sky (pip install mitsuba)")
    from synth.lighting import _mitsuba, _sunsky_dict, eval_emitter

    mi = _mitsuba()
    s = envmap.direction_from_angles(SUN_ELEV, SUN_AZIM)
    emitter = mi.load_dict(_sunsky_dict(mi, s, TURBIDITY, 0.2, sky_scale=1.0, sun_scale=1.0))
    rays = _rays()
    lin = np.clip(eval_emitter(mi, emitter, rays.reshape(-1, 3)).reshape(H, W, 3), 0.0, None)
    sky = rays[..., 1] > 0
    lin = lin * (0.36 / np.median(lin[sky] @ np.array(LUMINANCE)))
    return np.clip(np.asarray(linear_to_srgb(lin)), 0.0, 1.0), sky, s


def _run(args: list[str], capsys) -> dict:
    rc = main(["lighting", *args, "--threads", "1"])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return json.loads(Path(args[args.index("-o") + 1]).read_text())


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return math.degrees(math.acos(float(np.clip(a @ b / np.linalg.norm(a) / np.linalg.norm(b), -1.0, 1.0))))


def test_01_a_clear_sky_through_a_known_camera_gives_the_sun_within_5_degrees(tmp_path: Path, clear_sky,
                                                                               capsys) -> None:
    """The schema (every key, types), the sun in ``relight --sun``'s convention within 5 deg of Mitsuba's (test 01
    of test_sun_from_sky), ``source`` "sky", the camera as given, ``sh_camera`` = the posterior's SH turned into the
    camera (``D(R)``), the same bytes on a second run, and the preview (256 x 128) with the red ring where the sun
    is."""
    from physrelight.sun_from_sky import estimate_sun_from_sky

    display, sky, s = clear_sky
    photo, mask = _photo(tmp_path, display, sky)
    out = tmp_path / "lighting.json"
    rec = _run([str(photo), "--fov", str(FOV), "--pitch", str(PITCH), "--mask", str(mask), "-o", str(out)], capsys)
    assert set(rec) == KEYS and rec["schema_version"] == 2
    assert rec["source"] == "sky" and rec["reason"] == "" and rec["sky_kind"] in ("clear", "hazy")
    assert rec["camera"] == {"fov_deg": FOV, "fov_source": "given", "pitch_deg": PITCH, "pitch_source": "given"}
    sun = rec["sun"]
    assert set(sun) == {"azimuth_deg", "elevation_deg"}
    assert _angle(envmap.direction_from_angles(sun["elevation_deg"], sun["azimuth_deg"]), s) < 5.0, sun
    spread = rec["sun_spread"]
    assert set(spread) == {"azimuth_std_deg", "elevation_std_deg", "credible_area_sr", "credible_level"}
    assert 0 < spread["credible_area_sr"] < 0.5 and spread["credible_level"] == 0.9
    assert 2.0 <= rec["turbidity"] <= 6.0 and len(rec["level"]) == 3 and min(rec["level"]) > 0
    assert rec["sky_pixels"] == int(sky.sum()) and rec["image_size"] == [W, H]
    c = np.array(rec["sh_camera"])
    assert c.shape == (9, 3) and np.all(np.isfinite(c))
    post = estimate_sun_from_sky(io.read_photo(photo).image, sky, pitch_deg=PITCH, fov_deg=FOV)
    R = level_camera(0.0, PITCH)[:3, :3]
    from learned.sky_lighting import sky_sun_sh

    # the MAP sky and sun over a ground that reflects them (what the relighter divides by), turned into the camera
    assert np.allclose(c, np.asarray(sh.rotation(R)) @ sky_sun_sh(post)[0], rtol=1e-5, atol=1e-8)
    first = out.read_bytes(), (tmp_path / "lighting_preview.png").read_bytes()
    _run([str(photo), "--fov", str(FOV), "--pitch", str(PITCH), "--mask", str(mask), "-o", str(out)], capsys)
    assert (out.read_bytes(), (tmp_path / "lighting_preview.png").read_bytes()) == first
    from PIL import Image

    prev = np.asarray(Image.open(tmp_path / "lighting_preview.png"))
    assert prev.shape == (128, 256, 3)
    red = (prev[..., 0] > 200) & (prev[..., 1] < 80) & (prev[..., 2] < 80)
    rows, cols = np.nonzero(red)
    # straight ahead is the middle column; azimuth grows to the right, 256 columns per turn, 127 rows per 180 deg
    assert abs(cols.mean() - (128 + sun["azimuth_deg"] / 360 * 256 - 0.5)) < 2.0
    assert abs(rows.mean() - (90 - sun["elevation_deg"]) / 180 * 127) < 2.0


def test_02_without_pitch_and_fov_the_horizon_and_the_default_are_used(tmp_path: Path, clear_sky, capsys) -> None:
    """No ``--pitch``: it comes from where the sky comes down to (within 1 deg of the true 12 here, the mask's edge
    is the horizon), said as "horizon"; no ``--fov`` and no EXIF: the default 60, said as "default"; the sun still
    within 5 deg."""
    display, sky, s = clear_sky
    photo, mask = _photo(tmp_path, display, sky)
    rec = _run([str(photo), "--mask", str(mask), "-o", str(tmp_path / "l.json")], capsys)
    cam = rec["camera"]
    assert cam["fov_source"] == "default" and cam["fov_deg"] == 60.0 and cam["pitch_source"] == "horizon"
    assert abs(cam["pitch_deg"] - PITCH) < 1.0
    assert _angle(envmap.direction_from_angles(rec["sun"]["elevation_deg"], rec["sun"]["azimuth_deg"]), s) < 5.0
    assert (tmp_path / "l_preview.png").is_file()


def _fallback_sh(photo: Path, mask: np.ndarray) -> np.ndarray:
    """The library's own estimate for ``photo``: the decomposition's lighting at the working resolution."""
    from learned.relighter import Relighter
    from physrelight.full_resolution import working_resolution
    from physrelight.image_input import as_image

    rel = Relighter.load()
    lin, _ = as_image(io.read_photo(photo).image)
    small, small_sky = working_resolution(lin, torch.from_numpy(mask)[None, None], rel.res)
    return rel.decompose_linear(small, small_sky)["lighting"][0].double().numpy()


def test_03_a_photo_without_sky_falls_back_with_no_sun_and_a_reason(tmp_path: Path, capsys) -> None:
    """A mask with no sky: ``source`` "fallback", ``sun`` null, ``sky_kind`` "none", the reason says why, and
    ``sh_camera`` is the decomposition's lighting (what ``relight`` relights from)."""
    sky = np.zeros((H, W), bool)
    photo, mask = _photo(tmp_path, np.zeros((H, W, 3)), sky)
    rec = _run([str(photo), "--fov", "60", "--pitch", "0", "--mask", str(mask), "-o", str(tmp_path / "l.json")], capsys)
    assert set(rec) == KEYS
    assert rec["source"] == "fallback" and rec["sun"] is None and rec["sky_kind"] == "none"
    assert "too few sky pixels" in rec["reason"]
    assert rec["level"] is None and rec["turbidity"] is None
    assert np.allclose(rec["sh_camera"], _fallback_sh(photo, sky), rtol=1e-6, atol=1e-9)


def test_04_an_overcast_sky_has_no_sun(tmp_path: Path, capsys) -> None:
    """The CIE overcast sky (slightly blue) through the camera: no sun, ``sky_kind`` "overcast", the fallback SH."""
    rays = _rays()
    sky = rays[..., 1] > 0
    lin = overcast_sky(rays)[..., None] * np.array([0.9, 1.0, 1.1]) * 0.4
    photo, mask = _photo(tmp_path, np.clip(np.asarray(linear_to_srgb(lin)), 0, 1), sky)
    rec = _run([str(photo), "--fov", str(FOV), "--pitch", str(PITCH), "--mask", str(mask),
                "-o", str(tmp_path / "l.json")], capsys)
    assert rec["source"] == "fallback" and rec["sun"] is None and rec["sky_kind"] == "overcast"
    assert "overcast" in rec["reason"]
    assert np.allclose(rec["sh_camera"], _fallback_sh(photo, sky), rtol=1e-6, atol=1e-9)


def test_05_a_night_photo_has_no_sun(tmp_path: Path, clear_sky, capsys) -> None:
    """The clear sky of test 01 darkened to night (display values a fiftieth): no sun, ``sky_kind`` "night"."""
    display, sky, _ = clear_sky
    photo, mask = _photo(tmp_path, display * 0.02, sky)
    rec = _run([str(photo), "--fov", str(FOV), "--pitch", str(PITCH), "--mask", str(mask),
                "-o", str(tmp_path / "l.json")], capsys)
    assert rec["source"] == "fallback" and rec["sun"] is None and rec["sky_kind"] == "night"
    assert "too dark" in rec["reason"]


def _refused(capsys, args: list[str], match: str, folder: Path) -> None:
    before = sorted(p.name for p in folder.iterdir())
    refused(capsys, ["lighting", *args], match)
    assert sorted(p.name for p in folder.iterdir()) == before  # nothing written, no debris


def test_06_bad_input_is_one_line_exit_2_and_nothing_written(tmp_path: Path, capsys) -> None:
    """An unreadable photo, a mask of the wrong size, ``-o`` a folder, ``-o`` not a .json, and a photo that is all
    sky (the mask's word) where the sky tells no sun: there is no scene to fall back on."""
    rays = _rays()
    photo, mask = _photo(tmp_path, np.full((H, W, 3), 0.6), rays[..., 1] > 0)
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    _refused(capsys, [str(bad), "-o", str(tmp_path / "a.json")], "cannot read", tmp_path)
    small = tmp_path / "small_sky.png"
    io.write_png(small, np.ones((10, 12)))
    _refused(capsys, [str(photo), "--mask", str(small), "-o", str(tmp_path / "a.json")], "is 12x10, the photo 160x120",
             tmp_path)
    (tmp_path / "folder.json").mkdir()
    _refused(capsys, [str(photo), "-o", str(tmp_path / "folder.json")], "is a folder", tmp_path)
    _refused(capsys, [str(photo), "-o", str(tmp_path / "a.txt")], "must be a .json", tmp_path)
    overcast = np.clip(np.asarray(linear_to_srgb(overcast_sky(rays)[..., None] * np.array([0.36, 0.4, 0.44]))), 0, 1)
    grey, _ = _photo(tmp_path, overcast, np.ones((H, W), bool), "overcast")
    _refused(capsys, [str(grey), "--pitch", str(PITCH), "--mask", str(tmp_path / "overcast_sky.png"),
                      "-o", str(tmp_path / "a.json")], "the whole photo is sky and it tells no sun", tmp_path)


def test_07_relight_layers_writes_the_same_lighting_json(tmp_path: Path, clear_sky, capsys) -> None:
    """``relight --layers DIR`` with the same mask, field of view and pitch writes DIR/lighting.json and its preview,
    byte for byte what ``physrelight lighting`` writes."""
    display, sky, _ = clear_sky
    photo, mask = _photo(tmp_path, display, sky)
    cam = ["--fov", str(FOV), "--pitch", str(PITCH), "--mask", str(mask)]
    rc = main(["relight", str(photo), "--sun", "30", "90", *cam, "--layers", str(tmp_path / "layers"), "--quiet",
               "--threads", "1", "-o", str(tmp_path / "relit.png")])
    assert rc == 0, capsys.readouterr().err
    _run([str(photo), *cam, "-o", str(tmp_path / "lighting.json")], capsys)
    assert (tmp_path / "layers" / "lighting.json").read_bytes() == (tmp_path / "lighting.json").read_bytes()
    assert ((tmp_path / "layers" / "lighting_preview.png").read_bytes()
            == (tmp_path / "lighting_preview.png").read_bytes())


def test_08_the_field_of_view_comes_from_exif_unless_given(tmp_path: Path, capsys) -> None:
    """A JPEG with ``FocalLengthIn35mmFilm`` 28: ``camera.fov_deg`` is the EXIF's (``io.read_photo``), said as
    "exif"; ``--fov 35`` wins, said as "given"."""
    from PIL import Image

    rays = _rays()
    photo, mask = _photo(tmp_path, np.full((H, W, 3), 0.6), rays[..., 1] > 0)
    im = Image.open(photo)
    exif = im.getexif()
    exif.get_ifd(0x8769)[0xA405] = 28  # FocalLengthIn35mmFilm
    jpg = tmp_path / "exif.jpg"
    im.save(jpg, format="JPEG", quality=95, exif=exif)
    fov = io.read_photo(jpg).fov_deg
    assert fov is not None and abs(fov - 60.0) > 1.0
    rec = _run([str(jpg), "--mask", str(mask), "--pitch", "0", "-o", str(tmp_path / "a.json")], capsys)
    assert rec["camera"]["fov_source"] == "exif" and rec["camera"]["fov_deg"] == pytest.approx(fov, abs=1e-4)
    rec = _run([str(jpg), "--fov", "35", "--mask", str(mask), "-o", str(tmp_path / "b.json")], capsys)
    assert rec["camera"]["fov_source"] == "given" and rec["camera"]["fov_deg"] == 35.0


def test_09_the_dusk_example_photo_reads_no_sun(tmp_path: Path, capsys) -> None:
    """``rocket.jpg`` (the shipped example: a launch pad at dusk, the sun below the horizon) read as a user reads it
    (the segmenter's sky, the horizon's pitch, the default field of view): its blue-hour glow fits a sun 17 deg up
    in the frame, on open sky where no pixel is bright, so it is a stated fallback ("unseen"), not the confident
    wrong sun it was (docs/sun-from-sky.md)."""
    from physrelight.data import example_photo

    rec = _run([str(example_photo()), "-o", str(tmp_path / "rocket.json")], capsys)
    assert rec["source"] == "fallback" and rec["sun"] is None and rec["sky_kind"] == "unseen", rec["reason"]
    assert "shows none" in rec["reason"]
