"""Specification of ``physrelight bench``: the quick run end to end (its own held-out set, every
method, both protocols, the strata, the charts), its physics ordering, and the pieces it stands on
(protocol units, the oracle identity, the sun path, the strata predicates)."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import torch

from physrelight.cli import main

METHOD_NAMES = {"proposed", "lambertian_sh", "shadownet_lambertian", "quotient", "quotient_known", "proposed_known",
                "oracle_sh",
                "oracle_sh_shadow", "identity", "mitsuba_analysis_by_synthesis"}
METRICS = ("l1", "mse", "ssim", "dssim", "psnr", "ciede2000", "gain_l1", "gain_ssim", "gain_psnr")


@pytest.fixture(scope="module")
def quick(tmp_path_factory) -> Path:
    # One torch thread: on a shared 2-core machine two threads can be 10-30x slower.
    out = tmp_path_factory.mktemp("bench") / "report"
    assert main(["bench", "--quick", "-o", str(out), "--threads", "1", "--quiet"]) == 0
    return out


def _finite_numbers(obj) -> bool:
    if isinstance(obj, dict):
        return all(_finite_numbers(v) for v in obj.values())
    if isinstance(obj, list):
        return all(_finite_numbers(v) for v in obj)
    if isinstance(obj, float):
        return math.isfinite(obj)
    return True


def test_01_quick_run_scores_every_method_without_nan_and_the_physics_ordering_holds(quick: Path) -> None:
    r = json.loads((quick / "bench.json").read_text())
    assert set(r["methods"]) == METHOD_NAMES
    for name, m in r["methods"].items():
        for k in METRICS:
            assert isinstance(m[k], float) and math.isfinite(m[k]), (name, k)
        assert m["seconds_per_image"] > 0 and m["nonfinite"] == 0 and m["failures"] == 0, name
    # NaN would have been written as null: every number in the report is finite.
    assert _finite_numbers(r) and r["verdicts"]["finite"]["passed"]
    m = r["methods"]
    # Physics: the true target shadow brings the image model closer to the path tracer.
    assert m["oracle_sh_shadow"]["l1"] < m["oracle_sh"]["l1"]
    assert r["verdicts"]["physics_ordering"]["passed"]
    # The ceiling is far ahead of doing nothing, and ground truth ahead of learned decompositions.
    assert m["oracle_sh"]["l1"] < 0.6 * m["identity"]["l1"]
    assert m["oracle_sh_shadow"]["l1"] < m["lambertian_sh"]["l1"]
    # Metrics agree with each other: DSSIM is (1 - SSIM) / 2.
    for x in m.values():
        assert x["dssim"] == pytest.approx((1 - x["ssim"]) / 2, abs=1e-9)
    # `proposed` runs the shipped neural renderer: it no longer equals shadownet_lambertian.
    from learned.lighting import WEIGHTS_DIR

    shipped = (WEIGHTS_DIR / "renderer.safetensors").is_file()
    assert r["renderer_weights"] is shipped
    if shipped:
        # Without the renderer both methods are the same computation and score bit-identically;
        # the shipped renderer (200 steps from its init, which is shadownet_lambertian) moves
        # every metric a little (quick, weights of 2026-12-02 05:30 UTC: l1 0.1086 vs 0.1079,
        # CIEDE2000 12.58 vs 12.39).
        for k in ("l1", "ciede2000"):
            assert m["proposed"][k] != m["shadownet_lambertian"][k], k
    # proposed is far ahead of doing nothing (quick: 0.109 vs 0.182, better on all 4 scenes). Its lead
    # over lambertian_sh (0.1086 vs 0.1141) is better on 18 of 28 pairs but only 2 of 4 scenes (scene
    # means +0.0001 +- 0.0077): a coin flip, so it stays a reported verdict and is not asserted here.
    assert m["proposed"]["l1"] < 0.85 * m["identity"]["l1"]
    paired = r["verdicts"]["proposed_ordering"]["paired"]
    cross = r["protocols"]["cross"]["pairs"]
    for other, q in paired.items():
        # The paired figures agree with the table: the mean difference is the difference of means.
        assert q["mean_diff"] == pytest.approx(m["proposed"]["l1"] - m[other]["l1"], abs=1e-9), other
        assert q["pairs"] == cross and 0 <= q["pairs_better"] <= cross and 0 <= q["scenes_better"] <= q["scenes"]
        assert q["scenes"] >= 3 and math.isfinite(q["scene_se"]) and q["scene_se"] >= 0
    assert paired["identity"]["scenes_better"] > paired["identity"]["scenes"] / 2
    # Analysis by synthesis ran on a small subset and is slow, as stated.
    a = m["mitsuba_analysis_by_synthesis"]
    assert a["photos"] == 2 and 2 <= a["pairs"] <= 6
    assert a["seconds_per_image"] > 10 * m["proposed"]["seconds_per_image"]


def test_02_protocols_strata_and_sweep_are_all_populated(quick: Path) -> None:
    r = json.loads((quick / "bench.json").read_text())
    assert r["protocols"]["cross"]["pairs"] >= 20 and r["protocols"]["timelapse"]["pairs"] >= 12
    for name in ("proposed", "identity", "oracle_sh_shadow"):
        assert set(r["methods"][name]["by_source_lighting"]) >= {"sunsky", "evening", "overcast"}
        assert math.isfinite(r["methods"][name]["timelapse"]["l1"])
    for key in ("dark_input", "low_sun", "overcast", "night_like", "noise_jpeg", "large_azimuth", "glossy",
                "bright_albedo", "dark_albedo"):
        s = r["strata"][key]
        assert s["pairs"] >= 1, key
        for name, x in s["methods"].items():
            assert math.isfinite(x["l1"]) and x["l1_vs_all"] > 0, (key, name)
    # The oracles never see the photo: darkening or degrading it cannot change them.
    for key in ("dark_input", "noise_jpeg"):
        assert r["strata"][key]["methods"]["oracle_sh"]["l1_vs_same_pairs"] == pytest.approx(1.0, abs=1e-6)
    sweep = r["speed"]["sweep"]
    assert sorted(s["res"] for s in sweep if s["kind"] == "resolution") == [32, 64, 128]
    assert all(math.isfinite(s["l1"]) and s["seconds_per_image"] > 0 for s in sweep)
    assert r["machine"]["torch_threads"] == 1 and r["command"].startswith("physrelight bench --quick")


def test_03_bench_md_has_the_tables_verdicts_and_charts(quick: Path) -> None:
    md = (quick / "bench.md").read_text()
    for heading in ("## Verdicts", "## Cross-relighting (the paper's Table 2 layout)",
                    "## Time-lapse (the paper's Table 1 layout)", "## Analysis by synthesis",
                    "## Speed vs accuracy", "## Failure modes (strata)"):
        assert heading in md
    assert "**Physics ordering: PASS**" in md
    assert re.search(r"\*\*Proposed vs baselines: (PASS|FAIL)\*\*", md)
    links = re.findall(r"!\[[^\]]*\]\((charts/[^)]+\.png)\)", md)
    assert len(links) == 3
    for link in links:
        assert (quick / link).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", link


def _toy_view(h: int, w: int, **fields):
    """A two-lighting toy view: camera-facing normals, the top 3 rows sky, albedo 0.5, overcast SH
    ``np.eye(9, 3)``, black radiance, no shadow, no sun, a grey photo; ``fields`` replace any of these."""
    from validation.bench import data

    normal = np.zeros((h, w, 3), np.float32)
    normal[..., 2] = 1.0
    sky = np.zeros((h, w), bool)
    sky[:3] = True
    normal[sky] = 0
    base = dict(scene="toy", view=0, group="quick", albedo=np.full((h, w, 3), 0.5, np.float32), normal=normal,
                sky=sky, glossy=np.zeros((h, w), np.float32), sh=[np.eye(9, 3)] * 2,
                radiance=[np.zeros((h, w, 3), np.float32)] * 2, shadow=[np.ones((h, w), np.float32)] * 2,
                direct_shadow=[np.ones((h, w), np.float32)] * 2, sun_sh=[np.zeros((9, 3))] * 2,
                photo=[np.full((h, w, 3), 0.5, np.float32)] * 2,
                photo_params=[{"ev": 0.0, "wb_gains": [1.0, 1.0, 1.0]}] * 2)
    base.update(fields)
    base.setdefault("lights", [data.light_info("overcast", None, s) for s in base["sh"]])
    return data.BenchView(**base)


def test_04_oracle_with_true_shading_and_shadow_is_the_image_model_and_units_follow_the_photo() -> None:
    from validation.bench import methods, protocols

    h = w = 16
    rng = np.random.default_rng(0)
    albedo = rng.uniform(0.2, 0.6, (h, w, 3)).astype(np.float32)
    sh = [np.zeros((9, 3)), np.zeros((9, 3))]
    sh[0][0], sh[1][0] = 1.0, 2.0
    sh[1][2] = 0.5  # light from the camera side (+z) brightens camera-facing surfaces
    view = _toy_view(h, w, albedo=albedo, sh=sh, direct_shadow=[np.full((h, w), 0.5, np.float32)] * 2,
                     photo_params=[{"ev": 1.0, "wb_gains": [1.1, 1.0, 0.9]}] * 2)
    sky, normal = view.sky, view.normal
    pair = protocols.cross_pairs([view])[0]
    assert (pair.source, pair.target) == (0, 1)
    np.testing.assert_allclose(pair.gain, [2.2, 2.0, 1.8])
    plain = methods.OracleSH(None)(pair)[0].permute(1, 2, 0).numpy()
    from physrelight import sh as _sh

    e = _sh.irradiance(sh[1], np.array([[0.0, 0.0, 1.0]]))[0] / np.pi  # shading of a camera-facing normal
    np.testing.assert_allclose(plain[~sky], (albedo * e * pair.gain)[~sky], rtol=1e-5)
    # Without a sun the true shadow is the direct-light ratio (0.5 here).
    shadowed = methods.OracleSH("true")(pair)[0].permute(1, 2, 0).numpy()
    np.testing.assert_allclose(shadowed[~sky], 0.5 * plain[~sky], rtol=1e-5)
    # Sky pixels are the input's.
    assert torch.equal(methods.Identity()(pair)[0][:, sky], pair.image()[0][:, sky])
    # A target clipped on the whole foreground cannot rank methods: left out and named, not scored as inf dB.
    view.radiance = [np.full((h, w, 3), 0.1, np.float32), np.full((h, w, 3), 50.0, np.float32)]
    kept, left_out = protocols.informative_pairs(protocols.cross_pairs([view]))
    assert [(p.source, p.target) for p in kept] == [(1, 0)]
    assert left_out == [p.key for p in protocols.cross_pairs([view]) if p.target == 1]


def test_05_sun_path_is_symmetric_about_noon_and_highest_there() -> None:
    from validation.bench.data import sun_path

    path = sun_path([8.0, 12.0, 16.0], latitude_deg=40.0, declination_deg=10.0)
    (h0, e0, a0), (h1, e1, a1), (h2, e2, a2) = path
    assert e1 == pytest.approx(90 - 40 + 10, abs=1e-9)  # noon elevation = 90 - latitude + declination
    assert a1 == pytest.approx(180.0, abs=1e-6)  # due south at noon in the northern hemisphere
    assert e0 == pytest.approx(e2) and e0 < e1
    assert a0 < 180 < a2 and a0 + a2 == pytest.approx(360.0)  # morning east of south, evening west
    assert [p[0] for p in sun_path([3.0, 12.0])] == [12.0]  # the sun is below the horizon at 3 am


def test_06_bad_arguments_fail_with_one_line(tmp_path, capsys) -> None:
    from physrelight.cli import main as cli

    with pytest.raises(SystemExit):
        cli(["bench", "--threads", "0", "-o", str(tmp_path)])
    assert "positive integer" in capsys.readouterr().err
    rc = cli(["bench", "--quick", "--data", str(tmp_path / "nowhere"), "-o", str(tmp_path / "o"), "--quiet"])
    assert rc != 0
    assert "no synth dataset" in capsys.readouterr().err
    # A candidate's weights folder is checked before any rendering.
    rc = cli(["bench", "--quick", "--weights", str(tmp_path / "nowhere"), "-o", str(tmp_path / "o"), "--quiet"])
    assert rc != 0
    assert "no weights folder" in capsys.readouterr().err


# Today's quick-bench l1 (shipped weights of 2026-12-02 05:32 UTC, commit 8611da9; bench code of 2026-12-03),
# bit-identical over two runs on one machine. A narrow band, not a bound: 0.0003 is ~300x the float noise
# between machines and far below what a real change moves (feeding the renderer the source shadow took
# proposed from 0.10862 to 0.1030). When the weights, the quick data or a method change on purpose,
# regenerate these deliberately from a fresh `physrelight bench --quick --threads 1` and say so in the commit.
# Regenerated 2026-12-03 when the decomposition's top two rows were repaired after the lighting solve
# (learned.networks.repair_top_rows, the band along the top of the layers): proposed 0.10862 -> 0.10910,
# lambertian_sh 0.11405 -> 0.11443, shadownet_lambertian 0.10794 -> 0.10844; the oracles unchanged.
# 2026-12-03: quotient (estimated track) 0.10640 and quotient_known (known track) 0.09776 added (issue 26).
# Regenerated 2026-12-03 when the Relighter's source lighting became learned.source_lighting (issue 26,
# docs/experiments/23-source-lighting.md; lighting_estimator="source_map"), on commit 1d2777e (the sun shaded
# exactly in the quotient methods) plus that change alone: proposed 0.10910 -> 0.10418, lambertian_sh
# 0.11443 -> 0.10632, shadownet_lambertian 0.10844 -> 0.10395 (the estimator); quotient 0.10640 -> 0.10232
# (both: the estimator alone, before 1d2777e, 0.10640 -> 0.10436); quotient_known 0.09776 -> 0.08963 (1d2777e's
# sun, which did not re-pin it); the oracles unchanged.
# Regenerated 2026-12-04 when the quotient methods' ratio became guided-filtered (physrelight.quotient.smooth_ratio,
# Relighter(ratio_radius=3), study 27): quotient 0.10232 -> 0.10135, quotient_known 0.08963 -> 0.08711; the
# others within 0.00006 of their pins on this machine (left as they were).
# Regenerated 2026-12-04 when the shipped renderer became the quotient-based one (study 29, step 800 of
# runs/renderer_q; proposed now a learned gain on the quotient image, the sun by its exact cosine): proposed
# 0.10418 -> 0.09673; the others within 0.00006 of their pins (left as they were). The same day proposed_known
# (the renderer on the known track's quotient image) was added at its first figure, 0.08428.
QUICK_L1_PINS = {"proposed": 0.09673, "proposed_known": 0.08428, "lambertian_sh": 0.10632, "shadownet_lambertian": 0.10395,
                 "quotient": 0.10135, "quotient_known": 0.08711, "oracle_sh": 0.05557, "oracle_sh_shadow": 0.04682}
QUICK_L1_BAND = 0.0003


def test_07_quick_l1_figures_lie_in_a_narrow_band_around_their_pins(quick: Path) -> None:
    """The quick bench's l1 of proposed, lambertian_sh, shadownet_lambertian and the two oracles is each
    within +-0.0003 of its pin (issue 25: a renderer fed the wrong shadow moved proposed by 0.0056 and
    nothing failed). The pins are regenerated deliberately when the weights change, never to quiet a
    failure unexamined."""
    m = json.loads((quick / "bench.json").read_text())["methods"]
    off = {name: round(m[name]["l1"] - pin, 6) for name, pin in QUICK_L1_PINS.items()
           if abs(m[name]["l1"] - pin) > QUICK_L1_BAND}
    assert not off, f"quick l1 moved beyond +-{QUICK_L1_BAND} of its pin (now - pin): {off}"


def test_08_exposure_invariant_metrics_do_not_move_with_a_gain_and_never_lose_to_gain_one() -> None:
    """The bench's exposure-invariant display (``Pair.display_at_best_gain``) is the same image whatever
    gain the output carries (1e-6), its l1 is never above the l1 at gain 1, and an output that is the
    target times a constant scores l1 0 after the gain (up to the display's 8-bit-free rounding)."""
    from validation.bench import protocols

    h = w = 16
    rng = np.random.default_rng(3)
    view = _toy_view(h, w, radiance=[rng.uniform(0.05, 0.6, (h, w, 3)).astype(np.float32) for _ in range(2)],
                     photo_params=[{"ev": 0.5, "wb_gains": [1.0, 1.0, 1.0]}] * 2)
    pair = protocols.cross_pairs([view])[0]
    fg, tgt = pair.foreground(), pair.target_display()
    out = torch.from_numpy(rng.uniform(0.0, 1.0, (1, 3, h, w)).astype(np.float32))
    ref = pair.display_at_best_gain(out)
    for k in (0.2, 1.0, 6.0):
        torch.testing.assert_close(pair.display_at_best_gain(k * out), ref, atol=1e-6, rtol=0)
    l1 = lambda x: float(((x - tgt).abs() * fg).sum() / (3 * fg.sum()))  # noqa: E731
    assert l1(ref) <= l1(pair.display(out)) + 1e-9
    assert l1(pair.display_at_best_gain(0.37 * pair.target_linear())) < 1e-6
