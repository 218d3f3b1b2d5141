"""``physrelight relight`` refuses, before any work, what it cannot do well: one line on stderr, exit 2, nothing
written. Each case was a trial's rough edge (issue 41, item 4); they failed on 4ce9156."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from physrelight import io
from physrelight.cli import main
from ..cli_refusal import refused


@pytest.fixture()
def photo(tmp_path: Path) -> Path:
    """A 40 x 56 RGB photo with a sky band on top (PNG)."""
    rng = np.random.default_rng(0)
    img = rng.uniform(0.15, 0.8, (40, 56, 3))
    img[:10] = [0.55, 0.7, 0.95]
    path = tmp_path / "photo.png"
    io.write_png(path, img)
    return path


def _argparse_refused(capsys, args: list[str], match: str) -> str:
    with pytest.raises(SystemExit) as exc:
        main(args)
    err = capsys.readouterr().err
    assert exc.value.code == 2
    assert err.count("\n") == 1 and "Traceback" not in err, err  # one line: no usage block
    assert match in err, err
    return err


def test_01_a_sequence_beyond_the_frame_cap_is_refused_before_any_work(photo: Path, tmp_path: Path,
                                                                      capsys) -> None:
    from learned.relight_cli import MAX_SEQUENCE

    refused(capsys, ["relight", str(photo), "--sun", "20", "0", "--sequence", "100000000",
                      "-o", str(tmp_path / "a.gif")], f"at most {MAX_SEQUENCE} frames")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photo.png"]


def test_02_a_sequence_that_does_not_fit_in_memory_is_refused_with_the_numbers(photo: Path, tmp_path: Path,
                                                                              capsys, monkeypatch) -> None:
    """The rule: frames x H x W x 3 x (4 + 1) bytes (float32 frames and their 8-bit GIF copies) must stay within
    half the available memory. With 1 MiB available, 100 frames of 40 x 56 (3.2 MiB) are refused, 2 are not."""
    from learned.relight_cli import sequence_bytes

    from physrelight import cli_common

    assert sequence_bytes(100, 40, 56) == 100 * 40 * 56 * 15
    monkeypatch.setattr(cli_common, "available_memory", lambda: 1 << 20)
    err = refused(capsys, ["relight", str(photo), "--sun", "20", "0", "--sequence", "100",
                            "-o", str(tmp_path / "a.gif")], "--sequence 100 of a 56x40 photo")
    assert "3.2 MiB" in err and "1.0 MiB available" in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photo.png"]
    with pytest.raises(ValueError, match="needs about"):
        cli_common.check_fits_in_memory(sequence_bytes(100, 40, 56), "x", available=1 << 20)
    cli_common.check_fits_in_memory(sequence_bytes(2, 40, 56), "x", available=1 << 20)  # fits


@pytest.mark.parametrize("spelling", ["same", "dot", "link"])
def test_03_the_output_may_not_be_the_input_photo(photo: Path, tmp_path: Path, capsys, monkeypatch,
                                                  spelling: str) -> None:
    before = photo.read_bytes()
    monkeypatch.chdir(tmp_path)
    out = {"same": str(photo), "dot": "./photo.png", "link": str(tmp_path / "link.png")}[spelling]
    if spelling == "link":
        (tmp_path / "link.png").symlink_to(photo)
    refused(capsys, ["relight", str(photo), "--sun", "20", "0", "-o", out], "is the input photo")
    assert photo.read_bytes() == before


def test_04_layers_beside_the_photo_are_fine_but_not_the_photo_itself(photo: Path, tmp_path: Path, capsys) -> None:
    """``--layers`` into the photo's own folder is allowed (it writes named layers, not the photo); the checks
    let it through to the relighting. A photo named like a layer (``albedo.png``) in that folder is refused."""
    before = photo.read_bytes()
    assert main(["relight", str(photo), "--sun", "20", "0", "--method", "quotient", "--threads", "1", "--quiet",
                 "--layers", str(tmp_path), "-o", str(tmp_path / "out.png")]) == 0
    assert (tmp_path / "albedo.png").is_file() and photo.read_bytes() == before
    named = tmp_path / "sub" / "albedo.png"
    named.parent.mkdir()
    named.write_bytes(before)
    refused(capsys, ["relight", str(named), "--sun", "20", "0", "--layers", str(named.parent),
                      "-o", str(tmp_path / "o2.png")], "is the input photo")
    assert named.read_bytes() == before and not (tmp_path / "o2.png").exists()


@pytest.mark.parametrize("sun, match", [
    (["nan", "90"], "must be a finite number, got nan"),
    (["inf", "90"], "must be a finite number, got inf"),
    (["20", "nan"], "must be a finite number, got nan"),
])
def test_05_a_non_finite_sun_angle_is_its_own_error(photo: Path, tmp_path: Path, capsys, sun: list[str],
                                                    match: str) -> None:
    err = _argparse_refused(capsys, ["relight", str(photo), "--sun", *sun, "-o", str(tmp_path / "o.png")], match)
    assert "ELEV > 0" not in err


@pytest.mark.parametrize("sun, match", [
    (["20", "1000"], "AZIM must lie in [-360, 360]"),
    (["20", "-361"], "AZIM must lie in [-360, 360]"),
    (["91", "0"], "ELEV must lie in (0, 90]"),
    (["0", "10"], "above the horizon"),
])
def test_06_sun_angles_are_bounded(photo: Path, tmp_path: Path, capsys, sun: list[str], match: str) -> None:
    refused(capsys, ["relight", str(photo), "--sun", *sun, "-o", str(tmp_path / "o.png")], match)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["photo.png"]


def test_07_azimuth_is_bounded_and_finite(photo: Path, tmp_path: Path, capsys) -> None:
    for value in ("nan", "720"):
        _argparse_refused(capsys, ["relight", str(photo), "--sun", "20", "0", "--azimuth", value,
                                   "-o", str(tmp_path / "o.png")], "--azimuth")


@pytest.mark.parametrize("where, match", [
    ("FOLDER", "is a folder, not a file"),
    ("FILE/o.png", "is a file, not a folder"),
    ("/proc/nope/o.png", "does not take new files"),
])
def test_08_output_paths_are_checked_before_any_work(photo: Path, tmp_path: Path, capsys, where: str,
                                                     match: str) -> None:
    (tmp_path / "FOLDER").mkdir()
    (tmp_path / "FILE").write_text("x")
    out = where if where.startswith("/") else str(tmp_path / where)
    refused(capsys, ["relight", str(photo), "--sun", "20", "0", "-o", out], match)
    refused(capsys, ["relight", str(photo), "--sun", "20", "0", "--layers", str(tmp_path / "FILE"),
                      "-o", str(tmp_path / "o.png")], "--layers")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["FILE", "FOLDER", "photo.png"]


def test_09_denoise_on_a_photo_without_measurable_noise_says_why_it_does_nothing(tmp_path: Path, capsys) -> None:
    """``--denoise`` is set by the noise floor of the photo's flattest tiles (physrelight.denoise.noise_sigma): a
    JPEG whose compression flattened them (scikit-image's rocket.jpg) measures 0, so the denoise leaves it as it
    is. It says so in one note; on a photo with noise it acts and says nothing."""
    skimage = pytest.importorskip("skimage.data")
    from PIL import Image

    rocket = skimage.rocket()[::4, ::4]
    jpg = tmp_path / "rocket.jpg"
    Image.fromarray(rocket).save(jpg, quality=75)
    args = ["--sun", "20", "120", "--method", "quotient", "--exposure", "keep", "--keep-sky", "--threads", "1",
            "--quiet"]
    assert main(["relight", str(jpg), *args, "--denoise", "-o", str(tmp_path / "on.png")]) == 0
    err = capsys.readouterr().err
    assert "--denoise changes nothing here" in err and err.count("--denoise") == 1
    assert main(["relight", str(jpg), *args, "-o", str(tmp_path / "off.png")]) == 0
    capsys.readouterr()
    assert io.read_image(tmp_path / "on.png").tobytes() == io.read_image(tmp_path / "off.png").tobytes()
    rng = np.random.default_rng(1)
    noisy = tmp_path / "noisy.png"
    io.write_png(noisy, np.clip(rocket / 255.0 + rng.normal(0.0, 0.03, rocket.shape), 0.0, 1.0))
    assert main(["relight", str(noisy), *args, "--denoise", "-o", str(tmp_path / "n.png")]) == 0
    assert "--denoise changes nothing" not in capsys.readouterr().err
