"""Specification of ``physrelight bench --real``: the quick run end to end on the shipped panoramas
(held-out sunrise apart, every section (a)-(e), its ceilings), the pieces it stands on, and the
one-line refusals of bad input."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from physrelight import sh
from physrelight.cli import main
from validation.bench import real
from validation.bench.real_report import cross_view


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("bench_real") / "report"
    assert main(["bench", "--real", "--quick", "-o", str(out), "--threads", "1", "--quiet"]) == 0
    return out


def test_01_quick_run_writes_every_section_with_the_held_out_panorama_apart(quick) -> None:
    report = json.loads((quick / "real.json").read_text())
    md = (quick / "real.md").read_text()
    assert report["command"] == f"physrelight bench --real --quick -o {quick}"
    more_outdoor = {"pm_city", "pm_dawn", "pm_night", "pm_sky", "pm_venice"}  # hdri_more's masked outdoor maps
    rooms = {"pm_apartment", "pm_esplanade", "pm_hall", "pm_lab", "pm_lobby", "pm_studio", "pm_warehouse",
             "pm_workshop"}
    assert {c["panorama"] for c in report["crops"]} == {"city", "courtyard", "forest", "studio", "sunrise"} \
        | more_outdoor | rooms
    assert len(report["crops"]) == 4 * 18
    groups = {p["name"]: p["group"] for p in report["panoramas"]}
    assert {n for n, g in groups.items() if g == "indoor"} == rooms | {"studio"}
    assert {n for n, g in groups.items() if g == "training"} == {"city", "courtyard", "forest"} | more_outdoor
    assert all(c["stratum"] == "no_sky" for c in report["crops"] if groups[c["panorama"]] == "indoor")
    assert set(report["summary"]) == {"heldout", "training", "indoor"}
    assert report["summary"]["heldout"]["panoramas"] == ["sunrise"]
    for title in ("(a) Sky segmentation", "(b) Lighting", "(c) The relit sky", "(d) Self-relighting", "(e) Panels",
                  "seen in training", "held out (sunrise)"):
        assert title in md
    for p in report["panels"] + report["charts"]:
        assert (quick / p).is_file()
    # (a)'s stability table: every camera variant of every crop, as figures in [0, 1], and in the report
    from validation.bench.real_metrics import CAMERA_VARIANTS

    for c in report["crops"]:
        assert set(c["stability"]) == set(CAMERA_VARIANTS)
        assert all(0.0 <= x <= 1.0 for v in c["stability"].values() for x in v.values())
    assert "Stability: the same crops as another camera setting" in md and "| warm cast |" in md
    # (b)'s: the lighting estimated from each camera setting's photo, a scale-invariant error in [0, 1]
    for c in report["crops"]:
        assert set(c["lighting_stability"]) == set(CAMERA_VARIANTS)
        assert all(0.0 <= v["shading_error"] <= 1.0 for v in c["lighting_stability"].values())
    assert "`proposed`'s shading error when the crop comes as another camera setting" in md


def test_02_the_ceilings_are_ceilings(quick) -> None:
    """The exact target view beats every other sky source wherever there is sky; the panorama's own
    order-2 truncation beats every estimate of the lighting; identity self-relights exactly."""
    s = json.loads((quick / "real.json").read_text())["summary"]
    for g in ("heldout", "training"):
        sky = s[g]["sky"]
        assert all(sky["exact_view"]["l1"]["mean"] < sky[o]["l1"]["mean"] for o in ("fit", "skygan", "sh_radiance", "keep"))
        light = s[g]["lighting"]
        assert light["truth_order2"]["shading_error"]["mean"] < 0.1
        assert all(light["truth_order2"]["shading_error"]["mean"] < light[e]["shading_error"]["mean"]
                   for e in ("proposed", "prior_mean"))
        for iv in (sky["skygan"]["psnr"], light["proposed"]["shading_error"]):
            assert iv["lo"] <= iv["mean"] <= iv["hi"]
    crops = json.loads((quick / "real.json").read_text())["crops"]
    assert all(c["self"] is None or (c["self"]["identity"]["l1"] == 0.0
                                     and c["self"]["identity"]["psnr"] == pytest.approx(real.PSNR_CAP)) for c in crops)
    assert all(c["sky"] == {} for c in crops if c["stratum"] == "no_sky")
    # (d) at each output's best single gain: never worse than as it is (the search starts from the least-squares
    # gain and minimises this l1), the identity and the known-source quotient still exact
    with_self = [c["self"] for c in crops if c["self"] is not None]
    assert with_self
    for rows in with_self:
        assert rows["identity"]["l1_at_best_gain"] == 0.0
        assert rows["quotient_known"]["l1_at_best_gain"] < 1e-4
        for m in real.SELF_METHODS:
            assert rows[m]["l1_at_best_gain"] <= rows[m]["l1"] + 1e-4, m
    md = (quick / "real.md").read_text()
    assert "after each output's best single gain" in md


def test_02b_the_sun_section_has_every_estimate_and_falls_back_to_todays(quick) -> None:
    """(b)'s sun: on crops with sky under a panorama's sun (the panorama's own, by ``split_sun``), the azimuth and
    elevation errors of each estimate, median <= 90th percentile, azimuths within 0-180; where the sky's reading
    falls back the relighter's estimate is today's (the same direction, shading error and self-relighting); the
    report has the table."""
    report = json.loads((quick / "real.json").read_text())
    sunny = [c for c in report["crops"] if c["stratum"] == "sky" and c["sun"]["truth"] is not None]
    assert {c["panorama"] for c in sunny} >= {"sunrise", "city"}
    for c in sunny:
        est = c["sun"]["estimates"]
        assert set(est) == {"sky_reader", "proposed", "prior_mean"} | ({"sky_only"} if c["sun"]["source"] == "sky"
                                                                         else set())
        assert all(0.0 <= e["azimuth_error_deg"] <= 180.0 and e["elevation_error_deg"] >= 0.0 for e in est.values())
        if c["sun"]["source"] == "fallback":
            assert est["sky_reader"] == est["proposed"]
            assert c["lighting"]["sky_reader"] == c["lighting"]["proposed"]
            assert c["self"]["quotient_sky"] == c["self"]["quotient"]
        else:
            assert est["sky_reader"] == est["sky_only"]
    for g in ("heldout", "training"):
        sun = report["summary"][g]["sun"]
        assert sun["crops_with_sun"] == sum(c["panorama"] in report["summary"][g]["panoramas"] for c in sunny)
        from validation.bench.real_metrics import SUN_ESTIMATES

        for e in SUN_ESTIMATES:
            x = sun[e]
            if x is not None:
                assert x["azimuth_error_deg"]["median"] <= x["azimuth_error_deg"]["p90"]
    assert "### The sun's position" in (quick / "real.md").read_text()


def test_03_shading_error_is_scale_invariant_and_sees_direction() -> None:
    n = sh.fibonacci_sphere(128)
    L = np.zeros((9, 3))
    L[0] = 1.0
    L[2] = 0.5  # light from above (+z in the frame of n)
    E = np.asarray(sh.irradiance(L, n))
    assert real.shading_error(E, E) < 1e-12
    assert real.shading_error(7.3 * E, E) < 1e-12
    flipped = L.copy()
    flipped[2] = -0.5
    assert real.shading_error(np.asarray(sh.irradiance(flipped, n)), E) > 0.2
    assert real.shading_error(np.zeros_like(E), E) == 1.0
    assert real.level_stops(2 * L, L) == pytest.approx(1.0)


def test_04_cross_view_of_a_consistent_estimate_is_zero() -> None:
    L = np.asarray(sh.project_sun(np.array([0.3, 0.8, -0.5]) / np.linalg.norm([0.3, 0.8, -0.5]), np.ones(3)))
    crops = [{"panorama": "p", "world_sh": {"proposed": (L * k).tolist()}} for k in (1.0, 2.0, 0.5)]
    errs = cross_view(crops, sh.fibonacci_sphere(64), "proposed")
    assert len(errs) == 3 and max(e for _, e in errs) < 1e-12


def test_05_baselines_top_rows_and_otsu_brightness() -> None:
    top = real.top_rows_sky(9, 4)
    assert top[:3].all() and not top[3:].any()
    img = np.full((10, 10, 3), 0.1)
    img[:4] = 0.9
    np.testing.assert_array_equal(real.brightness_sky(img)[:, 0], np.arange(10) < 4)


def test_05b_camera_variants_are_what_they_say() -> None:
    """Exposure and casts are gains on the linear photo (to 8-bit quantisation), JPEG changes it a little, the
    noise is seeded (the same seed, the same bytes) and an unknown name is refused by name."""
    import torch

    from physrelight import colour
    from validation.bench.real_metrics import CAMERA_VARIANTS, camera_variant

    x = colour.from_ldr(torch.linspace(0.2, 0.8, 3 * 24 * 32).reshape(1, 3, 24, 32))
    for name, gain in (("-1 EV", (0.5, 0.5, 0.5)), ("warm cast", (1.1, 1.0, 0.9)), ("cool cast", (0.9, 1.0, 1.1))):
        y = camera_variant(x, name)
        want = colour.to_ldr(x * torch.tensor(gain)[None, :, None, None])
        assert float((colour.to_ldr(y) - want).abs().max()) <= 0.5 / 255 + 1e-6
    assert 0 < float((camera_variant(x, "JPEG 50") - x).abs().mean()) < 0.02
    a, b = camera_variant(x, "noise 2 %", seed=3), camera_variant(x, "noise 2 %", seed=3)
    assert torch.equal(a, b) and not torch.equal(a, camera_variant(x, "noise 2 %", seed=4))
    assert abs(float((colour.to_ldr(a) - colour.to_ldr(x)).std()) - 0.02) < 0.005
    assert len(CAMERA_VARIANTS) == 6
    with pytest.raises(ValueError, match="camera variant"):
        camera_variant(x, "sepia")


def _exr(path: Path, env: np.ndarray) -> None:
    import OpenEXR

    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    with OpenEXR.File(header, {"RGB": np.ascontiguousarray(env, dtype=np.float32)}) as f:
        f.write(str(path))


@pytest.mark.parametrize("case", ["not_2_1", "nan", "negative", "empty", "fov"])
def test_06_bad_input_gets_one_line_and_a_non_zero_exit_before_any_work(tmp_path, capsys, case) -> None:
    maps = tmp_path / "maps"
    maps.mkdir()
    env = np.ones((16, 32, 3), np.float32)
    if case == "not_2_1":
        env = np.ones((16, 20, 3), np.float32)
    elif case == "nan":
        env[2, 2, 0] = math.nan
    elif case == "negative":
        env[2, 2, 0] = -1.0
    if case != "empty":
        _exr(maps / "m.exr", env)
    out = tmp_path / "out"
    args = ["bench", "--real", "--hdri-dir", str(maps), "-o", str(out)]
    if case == "fov":
        args += ["--fov", "60", "181"]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("physrelight: error:") and "\n" not in err
    assert {"not_2_1": "2:1", "nan": "NaN", "negative": "negative", "empty": "no .exr", "fov": "179"}[case] in err
    assert not out.exists()


def test_07_the_sun_errors_against_a_hand_computed_case() -> None:
    """A sun 10 deg up at azimuth 170 and an estimate 30 deg up at -170: 20 deg apart in azimuth the short way
    round (across the seam), 20 in elevation, and by the spherical law of cosines
    acos(sin 10 sin 30 + cos 10 cos 30 cos 20) = 27.345 deg apart. Median and 90th percentile of 10, 20, 30, 40:
    25 and 37 (linear between the 3rd and 4th). The dominant direction of an order-2 lighting is its luminance
    band 1, (x, y, z) = (c[3], c[1], c[2])."""
    from physrelight.envmap import direction_from_angles
    from validation.bench.real_metrics import dominant_direction, sun_angles, sun_error_summary, sun_errors

    truth, est = direction_from_angles(10.0, 170.0), direction_from_angles(30.0, -170.0)
    assert sun_angles(truth) == pytest.approx((10.0, 170.0))
    e = sun_errors(est, truth)
    r = math.radians
    by_hand = math.degrees(math.acos(math.sin(r(10)) * math.sin(r(30)) + math.cos(r(10)) * math.cos(r(30)) * math.cos(r(20))))
    assert e == pytest.approx({"azimuth_error_deg": 20.0, "elevation_error_deg": 20.0, "angle_deg": by_hand})
    assert by_hand == pytest.approx(27.345, abs=0.001)
    s = sun_error_summary([{"azimuth_error_deg": a, "elevation_error_deg": 0.0, "angle_deg": a} for a in (10, 20, 30, 40)])
    assert s["crops"] == 4 and s["azimuth_error_deg"] == pytest.approx({"median": 25.0, "p90": 37.0})
    assert sun_error_summary([]) is None
    c = np.zeros((9, 3))
    c[1], c[2], c[3] = 0.0, -2.0, 2.0  # y, z, x in every channel: light from +x and -z
    np.testing.assert_allclose(dominant_direction(c), np.array([1.0, 0.0, -1.0]) / math.sqrt(2.0))
