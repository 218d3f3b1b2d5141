"""Specification of scripts/make_sun_panel.py, issue 44's picture: three real crops chosen by a stated rule, each
with the sun read from its sky drawn on the estimate's env-map preview beside the true panorama and its sun."""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def script():
    spec = importlib.util.spec_from_file_location("make_sun_panel", ROOT / "scripts" / "make_sun_panel.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    torch.set_num_threads(1)
    return module


def _rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    from physrelight.panorama import level_camera

    return level_camera(yaw_deg, pitch_deg)[:3, :3]


def _peak(lum: np.ndarray) -> tuple[float, float]:
    """Row and column of the centre of a picture's brightest pixels (ties from 8-bit rounding; the column's mean
    taken round the seam)."""
    rows, cols = np.nonzero(lum >= lum.max() - 1e-9)
    a = 2 * math.pi * cols / lum.shape[1]
    col = (math.atan2(np.sin(a).mean(), np.cos(a).mean()) / (2 * math.pi) * lum.shape[1]) % lum.shape[1]
    return float(rows.mean()), col


def _distance(a: tuple[float, float], b: tuple[float, float], width: int) -> float:
    return math.hypot(a[0] - b[0], (a[1] - b[1] + width / 2) % width - width / 2)


def test_01_the_truth_is_drawn_in_the_estimates_layout(script) -> None:
    """A map holding one faint spot (not clipped by the tone map), turned by R into the preview's frame
    (``true_preview``): its brightest pixel is where ``_preview_pixel`` puts R d (within 1.5 px of 256 x 128), and
    so is the peak of that light's order-2 SH in ``lighting_preview`` (the estimate's picture; within 3 px: the
    lobe is broad and flat-topped in 8 bits). So the green cross, the red ring and both pictures share one
    layout."""
    from physrelight import envmap, sh
    from physrelight.colour import LUMINANCE
    from physrelight.sun_from_sky import lighting_preview

    h, w = 128, 256
    lum = np.asarray(LUMINANCE)
    dirs = envmap.directions(256, 512).astype(np.float64)
    for el, az, R in ((30.0, 40.0, _rotation(25.0, 10.0)), (10.0, -120.0, _rotation(-70.0, -5.0)),
                      (55.0, 170.0, np.eye(3))):
        d = envmap.direction_from_angles(el, az)
        env = 1.0 + 0.2 * np.exp((dirs @ d - 1.0) / 0.001)[..., None] * np.ones(3)
        dt = R @ d
        x, y = script._preview_pixel(dt, h, w)
        truth = script.true_preview(env, R, h, w).astype(np.float64) @ lum
        assert truth.max() < 255, "the spot must not be clipped"
        assert _distance(_peak(truth), (y, x), w) < 1.5, (el, az, _peak(truth), (y, x))
        lobe = lighting_preview(np.asarray(sh.project_sun(dt, np.ones(3), order=2))).astype(np.float64) @ lum
        assert _distance(_peak(lobe), (y, x), w) < 3.0, (el, az, _peak(lobe), (y, x))


def test_02_the_crops_follow_the_stated_rule(script) -> None:
    """sunrise (held out), then city and forest (the first two training panoramas in bench --real's order whose sun
    split_sun finds above the horizon); of each, the first of bench --real --full's 16 crops in the "sky" stratum,
    with the camera bench --real gave it."""
    from synth.panorama_crops import make_crops

    crops = script.choose_crops(width=32)
    assert [(c.panorama.name, c.panorama.group) for c in crops] == [
        ("sunrise", "heldout"), ("city", "training"), ("forest", "training")]
    for c in crops:
        full = make_crops(c.panorama, 16, 0)
        first = next(k for k, f in enumerate(full) if f.stratum == "sky")
        assert c.index == first
        assert (c.yaw_deg, c.pitch_deg, c.fov_deg) == (full[first].yaw_deg, full[first].pitch_deg, full[first].fov_deg)
        assert c.size[1] == 32


def test_03_it_runs_at_a_tiny_size_and_writes_the_same_bytes(script, tmp_path: Path, capsys) -> None:
    """At 32-px crops: exit 0, one PNG under 300 KB and nothing else in the folder (atomic), three rows printed, the
    same bytes a second time."""
    out = tmp_path / "panel.png"
    assert script.main(["-o", str(out), "--width", "32"]) == 0
    first = out.read_bytes()
    assert 0 < len(first) < 300_000 and first[:8] == b"\x89PNG\r\n\x1a\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["panel.png"]
    printed = capsys.readouterr().out
    assert all(name in printed for name in ("sunrise/", "city/", "forest/"))
    assert script.main(["-o", str(out), "--width", "32"]) == 0
    assert out.read_bytes() == first


@pytest.mark.parametrize("args, message", [(["-o", "panel.jpg"], "must be a .png"),
                                           (["--width", "8"], "--width must be at least 16"),
                                           (["--width", "4000"], "upsample")])
def test_04_bad_arguments_exit_2_with_one_line_and_write_nothing(script, tmp_path: Path, capsys, args,
                                                                  message) -> None:
    args = [a if a != "panel.jpg" else str(tmp_path / a) for a in args]
    if "-o" not in args:
        args += ["-o", str(tmp_path / "panel.png")]
    assert script.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and "\n" not in err and "Traceback" not in err
    assert list(tmp_path.iterdir()) == []
