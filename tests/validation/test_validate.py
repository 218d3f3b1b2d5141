"""Specification of ``physrelight validate``: the quick run passes end to end and its report
reads on its own; the pieces it stands on (convex scenes, SH bounds, statistics) hold."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from physrelight.cli import main
from validation import common


@pytest.fixture(scope="module")
def quick_report(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("validate") / "report"
    assert main(["validate", "--quick", "-o", str(out), "--quiet"]) == 0
    return out


def test_01_quick_run_passes_every_verdict(quick_report: Path) -> None:
    report = json.loads((quick_report / "report.json").read_text())
    assert report["passed"] is True
    failed = [v["name"] for c in report["checks"].values() for v in c["verdicts"] if not v["passed"]]
    assert not failed, failed
    assert set(report["checks"]) >= {"renderer_irradiance", "sh_model", "shadow_loss", "lighting_solve",
                                     "relight_ceiling", "speed"}
    # every check but the speed measurements decides something
    assert all(c["verdicts"] for k, c in report["checks"].items() if k != "speed")


def test_02_report_json_holds_the_headline_figures(quick_report: Path) -> None:
    report = json.loads((quick_report / "report.json").read_text())
    assert abs(report["sphere_pathtrace_over_exact"] - 1.0) < 0.02
    sh_err = report["sh_irradiance_error"]
    assert set(sh_err) == set(common.QUICK.lightings)
    for per_order in sh_err.values():
        assert set(per_order) == {"1", "2", "4"}
        assert per_order["2"]["max_fraction"] <= 0.09375 + 1e-3
    loss = report["shadow_free_loss"]
    assert loss["with_gt_shadow"] > 0 and loss["without_shadow"] > 0
    assert math.isfinite(report["lighting_solve_rel_error"])
    assert report["machine"]["cores"] >= 1 and report["command"].startswith("physrelight validate --quick")


def test_03_report_md_reads_on_its_own_with_every_chart_inline(quick_report: Path) -> None:
    md = (quick_report / "report.md").read_text()
    assert "**Overall: PASS**" in md
    for title in ("1. Renderer vs exact irradiance", "2. SH irradiance model", "3. Shadow-free loss",
                  "4. Lighting solve", "5. Relighting ceiling", "6. Speed vs accuracy"):
        assert f"## {title}" in md
    links = re.findall(r"!\[[^\]]*\]\((charts/[^)]+\.png)\)", md)
    assert len(links) >= 8
    for link in links:
        png = quick_report / link
        assert png.is_file() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", link
    assert "tolerance" in md and "Machine:" in md and "Command:" in md


def test_04_bad_arguments_exit_non_zero_with_one_line(capsys) -> None:
    assert main(["validate", "--checks", "9"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "unknown check" in err
    with pytest.raises(SystemExit) as exc:
        main(["validate", "--quick", "--full"])
    assert exc.value.code != 0


def test_05_sh_truncation_bounds_are_design_figures() -> None:
    from validation.sh_model import truncation_bounds

    b2 = truncation_bounds(2)
    assert math.isclose(b2["max"], 0.09375, rel_tol=1e-6)  # DESIGN: 0.094 int L dw
    assert abs(b2["mean"] - 0.031) < 5e-4  # DESIGN: mean <= 0.031 int L dw
    assert truncation_bounds(3) == truncation_bounds(2)  # A_3 = 0
    assert truncation_bounds(4)["max"] < b2["max"] < truncation_bounds(1)["max"]


def test_06_a_single_directional_light_meets_the_order_2_bound() -> None:
    # Equality case of the theorem: one delta light; the worst normal is at grazing.
    from physrelight import sh

    s = np.array([0.0, 1.0, 0.0])
    coeffs = sh.project_sun(s, np.ones(3), 2)
    n = sh.fibonacci_sphere(20000)
    err = np.abs(np.asarray(sh.irradiance(coeffs, n))[:, 0] - np.clip(n @ s, 0, None))
    assert math.isclose(err.max(), 0.09375, rel_tol=2e-3)


def test_07_convex_objects_have_outward_normals_and_their_declared_albedo() -> None:
    from validation import scenes

    for shape in scenes.CONVEX_SHAPES:
        mesh = scenes.convex_spec(shape).parts[0].mesh
        v = np.asarray(mesh.vertices)
        n = np.asarray(mesh.vertex_normals)
        assert np.all(np.sum(n * (v - v.mean(axis=0)), axis=1) > 0), shape
        np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-6)


def test_08_the_z_test_null_rate_follows_student_t() -> None:
    assert math.isclose(common.t_tail(4.0, 10_000), 6.3e-5, rel_tol=0.05)  # ~ normal tail
    assert common.t_tail(4.0, 7) > 10 * common.t_tail(4.0, 10_000)  # few seeds: heavier tails
    assert common.binomial_upper(0.01, 1000) > 0.01


def test_09_report_md_tables_have_as_many_cells_per_row_as_their_header(quick_report: Path) -> None:
    md = (quick_report / "report.md").read_text()
    cells = lambda row: len(re.findall(r"(?<!\\)\|", row))  # noqa: E731  (unescaped pipes)
    header = None
    for line in md.splitlines():
        if not line.startswith("|"):
            header = None
            continue
        if header is None:
            header = cells(line)
        assert cells(line) == header, line
    assert "scene -1" not in md  # the bank's sphere is named, not numbered


def test_10_help_and_selection_count_every_check(capsys) -> None:
    from validation.checks import CHECKS, check_keys
    from validation.scenes import SPHERE_SEED, scene_label

    with pytest.raises(SystemExit):
        main(["validate", "--help"])
    out = capsys.readouterr().out
    assert f"numbers 1-{len(CHECKS)}" in " ".join(out.split())
    for i, (_, _, what) in enumerate(CHECKS, start=1):
        assert f"{i} {what}" in " ".join(out.split())
    assert check_keys([str(len(CHECKS))]) == [CHECKS[-1][0]]
    assert scene_label(SPHERE_SEED) == "sphere" and scene_label(7) == "scene 7"
