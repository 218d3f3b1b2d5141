"""Specification of the regression scenes: their pinned figures hold within statistical
tolerances, and a figure that moves fails with a message naming it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from validation import regression, scenes

PINS = Path(__file__).with_name("regression_pins.json")


@pytest.fixture(scope="module")
def measured() -> dict:
    return regression.measure()


def test_01_every_pinned_figure_holds_within_its_statistical_tolerance(measured) -> None:
    problems = regression.compare(regression.load(PINS), measured)
    assert not problems, "\n".join(problems)


def test_02_every_scene_pins_radiance_shadow_and_loss_figures() -> None:
    pinned = regression.load(PINS)
    assert set(pinned) == set(regression.SCENES)
    for scene, figs in pinned.items():
        kinds = {name.split("/")[0] for name in figs}
        assert {"radiance", "loss"} <= kinds, (scene, kinds)
        assert kinds & {"shadow_coverage", "direct_ratio"}, (scene, kinds)
    assert any(name.startswith("sh/") for figs in pinned.values() for name in figs)


def test_03_a_shifted_radiance_fails_and_the_message_names_the_figure(measured) -> None:
    pinned = regression.load(PINS)
    moved = {s: dict(f) for s, f in measured.items()}
    value, se, kind = moved["box_evening"]["radiance/ground_shadow"]
    moved["box_evening"]["radiance/ground_shadow"] = (value * 1.05, se, kind)  # 5 %: far beyond 5 sigma here
    problems = regression.compare(pinned, moved)
    assert len(problems) == 1
    assert "box_evening" in problems[0] and "radiance/ground_shadow" in problems[0]


def test_04_a_frame_convention_change_moves_the_sh_figures() -> None:
    # The lighting in the world frame instead of the camera frame: the pinned camera-frame
    # SH coefficients must catch it.
    light = scenes.get_lighting("sunsky", 32)
    pinned = regression.load(PINS)["sphere_on_ground_sunsky"]
    world = light.sh(2)
    cam_figs = {f"sh/L{i}_{'rgb'[c]}": (float(world[i, c]), 0.0, "exact") for i in range(9) for c in range(3)}
    problems = regression.compare({"s": {k: pinned[k] for k in cam_figs}}, {"s": cam_figs})
    assert problems and all("sh/" in p for p in problems)


def test_05_tolerances_come_from_the_standard_errors_and_the_figure_kind() -> None:
    stat = regression.tolerance((1.0, 0.03, "stat"), (1.0, 0.04, "stat"))
    assert math.isclose(stat, 5 * 0.05)
    exact = regression.tolerance((2.0, 0.0, "exact"), (2.0, 0.0, "exact"))
    assert 0 < exact <= 2.0 * 1e-9 + 1e-15
    count = regression.tolerance((0.25, 0.0, "count:400"), (0.25, 0.0, "count:400"))
    assert math.isclose(count, 1 / 400)


def test_06_the_same_seeds_give_the_same_figures(measured) -> None:
    again = regression.measure(["box_evening"])["box_evening"]
    for name, (value, _, _) in again.items():
        assert np.isclose(value, measured["box_evening"][name][0], rtol=0, atol=0), name
