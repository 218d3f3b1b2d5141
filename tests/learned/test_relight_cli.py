"""``physrelight relight``: targets, full-resolution output, layers, sequences, one-line errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from physrelight import envmap, io, sh
from physrelight.cli import main


FOREST = Path(__file__).resolve().parents[2] / "physrelight" / "data" / "hdri" / "forest.exr"


@pytest.fixture(scope="module")
def photo(tmp_path_factory) -> Path:
    """A 52 x 76 RGB photo with per-pixel detail and a bright band of sky on top."""
    rng = np.random.default_rng(0)
    img = rng.uniform(0.15, 0.8, (52, 76, 3))
    img[:12] = [0.55, 0.7, 0.95]
    path = tmp_path_factory.mktemp("photo") / "photo.png"
    io.write_png(path, img)
    return path


def test_01_sun_direction_and_azimuth_follow_the_documented_frame() -> None:
    from learned.relight_cli import sun_direction
    from physrelight.target_lighting import rotate_azimuth, sun_lighting

    np.testing.assert_allclose(sun_direction(0, 0), [0, 0, -1], atol=1e-12)  # ahead of the camera
    np.testing.assert_allclose(sun_direction(0, 90), [1, 0, 0], atol=1e-12)  # to its right
    np.testing.assert_allclose(sun_direction(90, 33), [0, 1, 0], atol=1e-12)
    # One convention (docs/conventions.md): a turn by t is clockwise seen from above, as --sun's azimuth counts, so
    # a sun at azimuth a turned by t is the sun at a + t (ahead turned by 90 goes to the right).
    np.testing.assert_allclose(rotate_azimuth(sun_direction(30, 0), 90), sun_direction(30, 90), atol=1e-12)
    np.testing.assert_allclose(rotate_azimuth(sun_direction(30, 40), 20), sun_direction(30, 60), atol=1e-12)
    np.testing.assert_allclose(rotate_azimuth(sun_direction(30, 40), -130), sun_direction(30, -90), atol=1e-12)
    # On SH the turn is the exact SH rotation: same as lighting the turned sun.
    d = sun_direction(30, 0)
    np.testing.assert_allclose(rotate_azimuth(sun_lighting(d), 90), sun_lighting(sun_direction(30, 90)), atol=1e-9)
    # An env map turned by whole columns: its column j moves to j + 8 (u = azimuth / 360 grows), built by hand.
    env = envmap.read(FOREST)
    h, w = env.shape[:2]
    np.testing.assert_allclose(rotate_azimuth(env, 360.0 * 8 / w), sh.project_envmap(np.roll(env, 8, axis=1), order=2),
                               rtol=1e-5, atol=1e-6)


def test_02_relight_writes_full_resolution_output_and_layers(photo: Path, tmp_path: Path) -> None:
    out = tmp_path / "relit.png"
    assert main(["relight", str(photo), "--env", str(FOREST), "--azimuth", "45", "--layers", str(tmp_path / "L"),
                 "-o", str(out), "--threads", "1"]) == 0
    relit = io.read_image(out)
    assert relit.shape == (52, 76, 3)
    names = {p.stem for p in (tmp_path / "L").glob("*.png")}
    assert {"relit", "albedo", "normals", "shadow", "target_shadow", "shading", "sky_mask"} <= names
    # A user mask keeps those pixels exactly (the photo's sky is not relit) at the camera's own
    # settings (--exposure keep: with auto the kept sky would follow the foreground's exposure).
    mask = np.zeros((52, 76), bool)
    mask[:12] = True
    io.write_png(tmp_path / "mask.png", mask.astype(np.float32))
    assert main(["relight", str(photo), "--sun", "20", "120", "--mask", str(tmp_path / "mask.png"), "--keep-sky",
                 "--method", "lambertian_sh", "--exposure", "keep", "-o", str(out), "--threads", "1"]) == 0
    kept = io.read_image(out)
    np.testing.assert_array_equal(kept[:12], io.read_image(photo)[:12])
    # A new sky (the sun's own, rendered) changes the sky only: the foreground is the same.
    assert main(["relight", str(photo), "--sun", "20", "120", "--mask", str(tmp_path / "mask.png"),
                 "--method", "lambertian_sh", "--exposure", "keep", "-o", str(out), "--threads", "1"]) == 0
    painted = io.read_image(out)
    np.testing.assert_array_equal(painted[12:], kept[12:])
    from learned.lighting import WEIGHTS_DIR

    if (WEIGHTS_DIR / "sky_gan.safetensors").is_file():
        assert np.abs(painted[:12] - kept[:12]).mean() > 1e-3


def test_03_sequence_writes_an_animated_gif_that_changes(photo: Path, tmp_path: Path) -> None:
    from PIL import Image

    out = tmp_path / "seq.gif"
    assert main(["relight", str(photo), "--sun", "15", "0", "--sequence", "3", "-o", str(out), "--quiet",
                 "--method", "shadownet_lambertian", "--threads", "1"]) == 0
    with Image.open(out) as im:
        assert im.n_frames == 3
        frames = []
        for k in range(3):
            im.seek(k)
            frames.append(np.asarray(im.convert("RGB"), dtype=np.float64))
    assert frames[0].shape == (52, 76, 3)
    assert np.abs(frames[0] - frames[1]).mean() > 1.0  # the sun moved: the image changed


@pytest.mark.parametrize("make, args, match", [
    ("palette", ["--sun", "20", "0"], "RGB colour photo"),  # a grey-scale photo is read (test_relight_real 08b)
    ("corrupt", ["--sun", "20", "0"], "cannot read"),
    ("missing", ["--sun", "20", "0"], "does not exist"),
    ("ok", ["--env", "nowhere.exr"], "environment map 'nowhere.exr' does not exist"),
    ("ok", ["--env", "PHOTO"], "must be an .exr or .hdr"),
    ("ok", ["--sh", "nowhere.npy"], "does not exist"),
    ("ok", ["--sh", "TMPDIR"], "is not a regular file"),
    ("ok", ["--env", "TMPDIR"], "is not a regular file"),
    ("ok", ["--sun", "120", "0"], "elevation"),
    ("ok", ["--sun", "-5", "0"], "above the horizon"),
    ("ok", ["--sun", "0", "90", "--sky", "clear"], "above the horizon"),
    ("ok", ["--sun", "20", "0", "--mask", "SMALLMASK"], "mask"),
    ("ok", ["--sun", "20", "0", "--sequence", "2"], r"\.gif"),
    ("ok", ["--sun", "20", "0", "--sequence", "2", "--layers", "TMPDIR"], "does not go with --sequence"),
])
def test_04_bad_input_is_one_line_and_non_zero(photo: Path, tmp_path: Path, capsys, make: str, args: list[str],
                                               match: str) -> None:
    from PIL import Image

    src = {"ok": photo, "missing": tmp_path / "missing.png"}.get(make, tmp_path / f"{make}.png")
    if make == "palette":
        Image.open(photo).convert("P").save(src)
    elif make == "corrupt":
        src.write_bytes(b"\x89PNG\r\n\x1a\n truncated")
    small = tmp_path / "small.png"
    io.write_png(small, np.ones((4, 4)))
    args = [str(photo) if a == "PHOTO" else str(small) if a == "SMALLMASK" else str(tmp_path) if a == "TMPDIR" else a
            for a in args]
    rc = main(["relight", str(src), *args, "-o", str(tmp_path / "o.png")])
    err = capsys.readouterr().err
    assert rc == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert err.startswith("physrelight: error:")
    import re

    assert re.search(match, err), err


def test_05_denoise_is_the_relighters_option(photo: Path, tmp_path: Path) -> None:
    """``--denoise`` is ``RelightOptions(denoise=DENOISE)`` (off by default, study 37). On the fixture photo its flat
    sky shows no noise, so the noise floor is 0 and the option changes nothing, however busy the foreground's
    per-pixel texture; on the same photo with sensor noise added, the command line's output equals the API's with
    the option on and differs from the default's."""
    from learned import Relighter
    from learned.relight_cli import sun_direction
    from learned.relight_options import DENOISE, RelightOptions

    kw = dict(method="quotient", exposure="keep", new_sky=False, fov_deg=60.0)
    args = ["--sun", "20", "120", "--method", "quotient", "--exposure", "keep", "--keep-sky", "--fov", "60",
            "--threads", "1"]

    def run(src: Path, name: str, *extra: str) -> np.ndarray:
        assert main(["relight", str(src), *args, *extra, "-o", str(tmp_path / name)]) == 0
        return io.read_image(tmp_path / name)

    np.testing.assert_array_equal(run(photo, "clean_on.png", "--denoise"), run(photo, "clean_off.png"))
    rng = np.random.default_rng(1)
    noisy = tmp_path / "noisy.png"
    io.write_png(noisy, np.clip(io.read_image(photo) + rng.normal(0.0, 0.03, (52, 76, 3)), 0.0, 1.0))
    on, off = run(noisy, "on.png", "--denoise"), run(noisy, "off.png")
    r = Relighter.load(options=RelightOptions(denoise=DENOISE))
    want = r.relight((io.read_image(noisy) * 255).round().astype(np.uint8), sun_direction(20.0, 120.0), **kw)
    assert np.abs(on - want).max() <= 1.0 / 255 + 1e-6
    assert np.abs(off - on).mean() > 1e-3


def test_06_a_large_photo_shows_its_stages_and_quiet_shows_nothing(photo: Path, tmp_path: Path, capsys,
                                                                  monkeypatch) -> None:
    """A single relighting of a photo of ``PROGRESS_PIXELS`` or more shows a bar on stderr that steps through
    ``RELIGHT_STAGES`` to the end (lowered here to this small photo's size; without ``--layers`` the last stage,
    ``"layers"``, is not run and not counted); ``--quiet`` shows none, and neither does a smaller photo. The picture
    is the same either way, and the relighter's stage hook is taken off afterwards."""
    from learned import relight_cli
    from learned.relighter import RELIGHT_STAGES, Relighter

    base = ["relight", str(photo), "--env", str(FOREST), "--threads", "1"]
    assert main(base + ["-o", str(tmp_path / "small.png")]) == 0
    assert "stage" not in capsys.readouterr().err  # 52 x 76 is under a megapixel
    monkeypatch.setattr(relight_cli, "PROGRESS_PIXELS", 52 * 76)
    seen: list[Relighter] = []
    load = Relighter.load
    monkeypatch.setattr(Relighter, "load", classmethod(lambda cls, *a, **k: seen.append(load(*a, **k)) or seen[-1]))
    assert main(base + ["-o", str(tmp_path / "big.png")]) == 0
    err = capsys.readouterr().err
    n = len(RELIGHT_STAGES) - 1
    assert f"{n}/{n}" in err and RELIGHT_STAGES[-2] in err and RELIGHT_STAGES[-1] not in err
    assert seen[-1].on_stage is None
    assert main(base + ["-o", str(tmp_path / "layered.png"), "--layers", str(tmp_path / "layers")]) == 0
    err = capsys.readouterr().err
    assert f"{len(RELIGHT_STAGES)}/{len(RELIGHT_STAGES)}" in err and RELIGHT_STAGES[-1] in err
    assert seen[-1].on_stage is None
    assert np.array_equal(io.read_image(tmp_path / "layered.png"), io.read_image(tmp_path / "big.png"))
    assert main(base + ["-o", str(tmp_path / "quiet.png"), "--quiet"]) == 0
    assert capsys.readouterr().err == ""
    assert np.array_equal(io.read_image(tmp_path / "big.png"), io.read_image(tmp_path / "small.png"))


def test_07_an_exr_output_is_the_relit_linear_radiance(photo: Path, tmp_path: Path, capsys) -> None:
    """``-o relit.exr`` writes the relit radiance before the display curve: its display values are the PNG's (to
    8-bit rounding), and relit to its own lighting on the known track (the quotient, the sky kept, the camera's
    exposure) it is the photo's own linear radiance, exactly. Any other suffix is refused in one line."""
    import torch

    from physrelight import colour

    exr, png = tmp_path / "relit.exr", tmp_path / "relit.png"
    for out in (exr, png):
        assert main(["relight", str(photo), "--env", str(FOREST), "--exposure", "keep", "--quiet", "--threads", "1",
                     "-o", str(out)]) == 0
    linear = envmap.read(exr)
    assert linear.shape == (52, 76, 3) and linear.dtype == np.float32
    shown = colour.to_ldr(torch.from_numpy(linear)).numpy()
    assert np.abs(shown - io.read_image(png)).max() <= 0.5 / 255 + 1e-6
    assert float(linear.max()) > 0.0
    same = tmp_path / "same.exr"
    assert main(["relight", str(photo), "--env", str(FOREST), "--source-env", str(FOREST), "--method", "quotient",
                 "--keep-sky", "--exposure", "keep", "--quiet", "--threads", "1", "-o", str(same)]) == 0
    photo_linear = colour.from_ldr(torch.from_numpy(io.read_image(photo))).numpy()
    np.testing.assert_allclose(envmap.read(same), photo_linear, rtol=1e-5, atol=1e-7)
    capsys.readouterr()
    assert main(["relight", str(photo), "--env", str(FOREST), "-o", str(tmp_path / "relit.jpg")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and ".png (display) or .exr (linear radiance)" in err
    assert not (tmp_path / "relit.jpg").exists()


def test_07b_the_apis_linear_relit_photo_is_the_display_one_before_its_curve(photo: Path) -> None:
    """``Relighter.relight(..., linear=True)`` is the display result before :func:`physrelight.colour.to_ldr`,
    exactly, with the automatic exposure too."""
    import torch

    from learned import Relighter
    from physrelight import colour

    relighter = Relighter.load()
    image = io.read_image(photo)
    for exposure in ("keep", "auto"):
        shown = relighter.relight(image, str(FOREST), exposure=exposure)
        linear = relighter.relight(image, str(FOREST), exposure=exposure, linear=True)
        assert float(linear.min()) >= 0.0
        np.testing.assert_array_equal(colour.to_ldr(torch.from_numpy(linear)).numpy(), shown)


def test_08_a_radiance_photo_is_relit_in_its_own_units(photo: Path, tmp_path: Path, capsys) -> None:
    """A photo given as linear radiance (``radiance=True``; ``.exr`` / ``.hdr`` on the command line): a display
    photo's own linear values relight as the display photo does (to float rounding); an HDR one is relit at a display-like
    level, so scaling it by 10 scales the linear result by 10 (to rounding); relit to its own lighting on the known
    track it comes back exactly, in its own units. The command line reads, writes and refuses EXR photos."""
    import torch

    from learned import Relighter
    from physrelight import colour

    relighter = Relighter.load()
    display = io.read_image(photo)
    linear = colour.from_ldr(torch.from_numpy(display)).numpy()
    # to float rounding (the two decodings run on differently laid-out arrays)
    np.testing.assert_allclose(relighter.relight(linear, str(FOREST), radiance=True, exposure="keep"),
                               relighter.relight(display, str(FOREST), exposure="keep"), atol=1e-5)
    hdr = linear * 40.0  # its 99.9th-percentile luminance well above 1
    one = relighter.relight(hdr, str(FOREST), radiance=True, linear=True, exposure="keep")
    ten = relighter.relight(hdr * 10.0, str(FOREST), radiance=True, linear=True, exposure="keep")
    np.testing.assert_allclose(ten, 10.0 * one, rtol=1e-4, atol=1e-6)
    same = relighter.relight(hdr, str(FOREST), source=str(FOREST), method="quotient", new_sky=False,
                             exposure="keep", radiance=True, linear=True)
    np.testing.assert_allclose(same, hdr, rtol=1e-5)
    # the command line: .exr in, .exr and .png out
    src = tmp_path / "render.exr"
    envmap.write(src, hdr)
    for out in (tmp_path / "relit.exr", tmp_path / "relit.png"):
        assert main(["relight", str(src), "--env", str(FOREST), "--quiet", "--threads", "1", "-o", str(out)]) == 0
    assert "linear radiance" in capsys.readouterr().err  # the note
    assert envmap.read(tmp_path / "relit.exr").shape == (52, 76, 3)
    assert io.read_image(tmp_path / "relit.png").shape == (52, 76, 3)
    bad = hdr.copy()
    bad[3, 4, 0] = np.nan
    import OpenEXR  # write the NaN as it is: envmap.write refuses it

    with OpenEXR.File({"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage},
                      {"RGB": bad.astype(np.float32)}) as f:
        f.write(str(tmp_path / "nan.exr"))
    assert main(["relight", str(tmp_path / "nan.exr"), "--env", str(FOREST), "-o", str(tmp_path / "n.png")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "non-finite" in err and not (tmp_path / "n.png").exists()
    with pytest.raises(ValueError, match="non-negative"):
        relighter.relight(-hdr, str(FOREST), radiance=True)
    with pytest.raises(ValueError, match="floats"):
        relighter.relight(display.astype(np.uint8), str(FOREST), radiance=True)


def test_09_surface_layers_are_transparent_on_the_sky_and_keep_their_values(photo: Path, tmp_path: Path) -> None:
    """``--layers``: albedo, normals, shadows and shading describe surfaces, so they are written transparent on the
    sky (alpha 0 there, 1 elsewhere) with their values unchanged; ``relit`` and ``sky_mask`` have no alpha. A
    layer of a photo without sky is written as it is, and a layer or mask of the wrong shape is refused."""
    from PIL import Image

    from learned.relight_cli import DECOMPOSITION_LAYERS, layer_with_alpha

    rng = np.random.default_rng(1)
    layer, shadow = rng.uniform(0, 1, (5, 7, 3)), rng.uniform(0, 1, (5, 7, 1))
    sky = np.zeros((5, 7), bool)
    sky[:2, 3:] = True
    rgba, la = layer_with_alpha(layer, sky), layer_with_alpha(shadow, sky)
    assert rgba.shape == (5, 7, 4) and la.shape == (5, 7, 2)
    np.testing.assert_array_equal(rgba[..., :3], layer)
    np.testing.assert_array_equal(la[..., :1], shadow)
    np.testing.assert_array_equal(rgba[..., 3], (~sky).astype(float))
    assert layer_with_alpha(layer, np.zeros((5, 7), bool)) is layer
    with pytest.raises(ValueError, match=r"\(H, W, 1\) or \(H, W, 3\)"):
        layer_with_alpha(rng.uniform(0, 1, (5, 7, 2)), sky)
    with pytest.raises(ValueError, match="sky must have shape"):
        layer_with_alpha(layer, sky[:, :6])
    # the command line, with a user's mask of the top rows
    mask = np.zeros((52, 76), bool)
    mask[:12] = True
    io.write_png(tmp_path / "mask.png", mask.astype(np.float32))
    ldir = tmp_path / "L"
    assert main(["relight", str(photo), "--sun", "20", "120", "--mask", str(tmp_path / "mask.png"), "--layers",
                 str(ldir), "--quiet", "--threads", "1", "-o", str(tmp_path / "r.png")]) == 0
    modes = {}
    for p in ldir.glob("*.png"):
        with Image.open(p) as im:
            modes[p.stem] = im.mode
            a = np.asarray(im)
        if p.stem in DECOMPOSITION_LAYERS:
            np.testing.assert_array_equal(a[..., -1], np.where(mask, 0, 255))
    # and the sun and sky read from the photo (physrelight lighting): its JSON and an RGB preview
    assert modes == {"relit": "RGB", "sky_mask": "L", "albedo": "RGBA", "normals": "RGBA", "shading": "RGBA",
                     "shadow": "LA", "target_shadow": "LA", "lighting_preview": "RGB"}
    assert (ldir / "lighting.json").is_file()


# The known-source track with the photo's sky kept and the camera's exposure: what the camera settings and
# the source lighting do shows in the relit radiance (an .exr output), compared with the API's to float noise.
_EXACT = ["--method", "quotient", "--exposure", "keep", "--quiet", "--threads", "1"]
_EXACT_KW = dict(method="quotient", exposure="keep", linear=True)


def _relit_exr(src: Path, out: Path, *args: str) -> np.ndarray:
    assert main(["relight", str(src), *args, *_EXACT, "-o", str(out)]) == 0
    return envmap.read(out)


def test_10_pitch_reaches_the_relighter(photo: Path, tmp_path: Path) -> None:
    """``--pitch 15`` is ``pitch_deg=15``: the command line's relit radiance is the API's with it, and not the
    API's with the pitch estimated from the horizon (the default), which is another picture."""
    from learned import Relighter

    r, image = Relighter.load(), io.read_image(photo)
    got = _relit_exr(photo, tmp_path / "p.exr", "--env", str(FOREST), "--pitch", "15")
    want = r.relight_layers(image, str(FOREST), pitch_deg=15.0, **_EXACT_KW)["relit"]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
    estimated = r.relight_layers(image, str(FOREST), **_EXACT_KW)["relit"]
    assert np.abs(got - estimated).mean() > 0.01


def test_11_fov_overrides_the_exif_focal_length_and_exif_overrides_the_default(photo: Path, tmp_path: Path) -> None:
    """A JPEG whose EXIF says 28 mm (equivalent: 65.0 degrees across this 76 x 52 frame): without ``--fov`` it is
    relit at the EXIF's field of view; ``--fov 35`` (the user's word) wins over the EXIF. Each is the API's with
    that ``fov_deg`` and not the other's."""
    from PIL import Image

    from learned import Relighter

    img = (io.read_image(photo) * 255).round().astype(np.uint8)
    jpg = tmp_path / "exif.jpg"
    im = Image.fromarray(img)
    exif = im.getexif()
    exif.get_ifd(0x8769)[0xA405] = 28  # FocalLengthIn35mmFilm
    im.save(jpg, format="JPEG", quality=95, exif=exif)
    exif_photo = io.read_photo(jpg)
    half = math.atan(math.hypot(36, 24) / 56)
    exif_fov = math.degrees(2 * math.atan(math.tan(half) * 76 / math.hypot(76, 52)))
    assert exif_photo.fov_deg == pytest.approx(exif_fov, rel=1e-9)
    r = Relighter.load()
    at = {fov: r.relight_layers(exif_photo.image, str(FOREST), fov_deg=fov, **_EXACT_KW)["relit"]
          for fov in (exif_fov, 35.0)}
    assert np.abs(at[35.0] - at[exif_fov]).mean() > 0.01
    np.testing.assert_allclose(_relit_exr(jpg, tmp_path / "exif.exr", "--env", str(FOREST)), at[exif_fov],
                               rtol=1e-5, atol=1e-7)
    np.testing.assert_allclose(_relit_exr(jpg, tmp_path / "fov.exr", "--env", str(FOREST), "--fov", "35"), at[35.0],
                               rtol=1e-5, atol=1e-7)


def test_12_source_env_is_the_source_and_env_the_target(photo: Path, tmp_path: Path) -> None:
    """``--source-env A --env B`` relights from A to B: with the quotient, the photo's sky kept and the camera's
    exposure, relighting to its own lighting gives the photo back exactly (test 07), so passing B as the source
    would give the photo; A = forest.exr and B = it turned by 90 degrees give the API's ``relight(B, source=A)``,
    far from the photo."""
    import torch

    from learned import Relighter
    from physrelight import colour, rotations

    turned = tmp_path / "turned.exr"
    envmap.write(turned, envmap.rotate(envmap.read(FOREST), rotations.about_y(90.0)))
    got = _relit_exr(photo, tmp_path / "ab.exr", "--source-env", str(FOREST), "--env", str(turned), "--keep-sky")
    image = io.read_image(photo)
    want = Relighter.load().relight_layers(image, str(turned), source=str(FOREST), new_sky=False, **_EXACT_KW)["relit"]
    np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-7)
    photo_linear = colour.from_ldr(torch.from_numpy(image)).numpy()
    assert np.abs(got - photo_linear).mean() > 0.01


def test_14_azimuth_turns_the_target_the_way_suns_azimuth_counts(photo: Path, tmp_path: Path) -> None:
    """One convention on the command line: ``--sun 30 40 --azimuth 20`` is ``--sun 30 60`` (clockwise seen from
    above; issue 41), not ``--sun 30 20`` (the counter-clockwise turn ``--azimuth`` made before), sky included."""
    def run(name: str, *args: str) -> np.ndarray:
        out = tmp_path / f"{name}.png"
        assert main(["relight", str(photo), *args, "--quiet", "--threads", "1", "-o", str(out)]) == 0
        return io.read_image(out)

    turned = run("turned", "--sun", "30", "40", "--azimuth", "20")
    assert np.abs(turned - run("at60", "--sun", "30", "60")).max() <= 1.0 / 255 + 1e-6
    assert np.abs(turned - run("at20", "--sun", "30", "20")).mean() > 5e-3


def test_13_the_apis_defaults_are_the_command_lines(photo: Path, tmp_path: Path) -> None:
    """The same call gives the same picture: ``Relighter.relight(photo, target)`` at its defaults is what
    ``physrelight relight photo --env MAP`` writes at its own (the automatic exposure included; issue 41), to 8-bit
    rounding, and the camera's own settings (``exposure="keep"``) give another picture."""
    from learned import Relighter

    out = tmp_path / "relit.png"
    assert main(["relight", str(photo), "--env", str(FOREST), "--quiet", "--threads", "1", "-o", str(out)]) == 0
    relighter = Relighter.load()
    api = relighter.relight(io.read_image(photo), str(FOREST))
    assert np.abs(io.read_image(out) - api).max() <= 0.5 / 255 + 1e-4
    keep = relighter.relight(io.read_image(photo), str(FOREST), exposure="keep")
    assert np.abs(keep - api).mean() > 0.01
