"""Specification of the command line: the demo runs and reports sane physics; bad input is one line."""

from __future__ import annotations

import json
import math
import subprocess
import sys

import pytest

from physrelight import cli


def test_01_demo_writes_a_panel_and_metrics_that_favour_order_4(tmp_path) -> None:
    assert cli.main(["demo", "-o", str(tmp_path), "--size", "40", "--targets", "courtyard"]) == 0
    assert (tmp_path / "demo.png").stat().st_size > 10_000
    metrics = json.loads((tmp_path / "metrics.json").read_text())
    for entry in metrics["targets"].values():
        # Order 4 models the target lighting better than order 2, and both are close.
        assert entry["order4"]["linear_rel_error"] < entry["order2"]["linear_rel_error"] < 0.1
        assert entry["order2"]["psnr"] > 30


def test_02_bad_input_is_a_one_line_error_and_nonzero_exit(tmp_path) -> None:
    res = subprocess.run([sys.executable, "-m", "physrelight.cli", "demo", "-o", str(tmp_path), "--source", "moon"],
                         capture_output=True, text=True)
    assert res.returncode != 0
    assert res.stderr.strip().count("\n") == 0 and "unknown HDRI 'moon'" in res.stderr
    assert "Traceback" not in res.stderr


@pytest.mark.parametrize("args", [["demo", "--size", "0"], ["nonsense"]])
def test_03_argument_errors_exit_nonzero(args) -> None:
    with pytest.raises(SystemExit) as exc:
        cli.main(args)
    assert exc.value.code != 0


def test_05_pipeline_demo_relights_a_path_traced_scene_and_a_real_photo(tmp_path) -> None:
    pytest.importorskip("mitsuba")
    assert cli.main(["demo", "-o", str(tmp_path), "--size", "24", "--targets", "forest",
                     "--scene-size", "48"]) == 0
    res = json.loads((tmp_path / "relight_metrics.json").read_text())
    assert (tmp_path / "relight_demo.png").stat().st_size > 20_000
    assert len(res["targets"]) == 3 and "real_photo" in res
    for entry in res["targets"].values():
        for method in ("proposed", "lambertian_sh", "identity"):
            m = entry[method]
            assert all(math.isfinite(v) for v in m.values())
            assert 0 <= m["l1"] < 1 and 0 < m["ssim"] <= 1
