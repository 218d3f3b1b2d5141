"""The outdoor check on real rooms: a pinhole crop of an indoor panorama (``physrelight/data/hdri_more``, the eight
``indoor`` maps of its ``kinds.json``) must come out of relight's sky mask (the shipped segmenter, then
:func:`physrelight.sky_mask.plausible_sky`) with no sky at all, else relight paints a sky into a room.

Measured when these negatives were added (issue 43, 8 crops per room, seed 0, 45-75 deg, the bench's crops): the
check declines every crop of pm_apartment, pm_warehouse and pm_workshop, and calls sky on 12 of the 40 crops of the
other five (looked at overlaid: smooth white or grey ceilings and upper walls, esplanade's glass roof, pm_studio's
large octagonal softbox; each reaches the top border and passes the colour and smoothness tests). The 16 crops
per room of `bench --real --full` find sky in pm_apartment and pm_workshop too (1 and 2 crops; docs/bench.md):
passing here is no proof that a room is always declined. Those five are marked
``xfail(strict=True)``: the check is not loosened or special-cased here, and the day a segmenter or check declines
them all, the strict xfail fails and the mark must go."""

from __future__ import annotations

import pytest
import torch

from physrelight import data

ROOMS = data.hdri_names(collection="more", kind="indoor")
CALLED_SKY_TODAY = {"pm_esplanade", "pm_hall", "pm_lab", "pm_lobby", "pm_studio"}
"""Rooms with at least one crop called sky by the shipped segmenter and check (the measurement above)."""


@pytest.fixture(scope="module")
def relighter():
    from learned import Relighter

    torch.set_num_threads(1)
    return Relighter.load()


def test_01_the_eight_rooms_are_the_negatives() -> None:
    assert len(ROOMS) == 8 and CALLED_SKY_TODAY < set(ROOMS)


@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.xfail(
    strict=True, reason="the shipped segmenter and plausible_sky call sky on some of this room's crops (issue 43)"))
    if n in CALLED_SKY_TODAY else n for n in ROOMS])
def test_02_no_crop_of_a_room_is_called_outdoor(relighter, name) -> None:
    from synth.panorama_crops import load_panorama, make_crops

    pano = load_panorama(data.hdri(name, collection="more"), "indoor")
    called = []
    for crop in make_crops(pano, 8, seed=0, samples=2):
        sky, why = relighter.photo_sky(crop.linear())
        if bool(sky.any()):
            called.append(f"crop {crop.index} (yaw {crop.yaw_deg:.0f}, pitch {crop.pitch_deg:.0f}): "
                          f"{100 * float(sky.float().mean()):.0f} % sky")
        else:
            assert why, "an empty mask must say why there is no sky"
    assert not called, f"{name}: " + "; ".join(called)
