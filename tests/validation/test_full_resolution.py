"""Specification of ``physrelight bench --full-resolution`` (validation/bench/full_resolution.py): the four
outputs, the low-resolution yardstick, the halo error of the two transfers on a step edge, and the run
end to end on a tiny rendered folder."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
import torch

from physrelight import metrics
from physrelight.cli import main
from synth import writer
from validation.bench import full_resolution as fr

TINY = dict(scenes=1, views=1, lights=2, res=128, spp=4, gbuffer_spp=2, shadow_spp=2, env_resolution=16,
            kinds=("sunsky", "overcast"), seed=3)


@pytest.fixture(scope="module")
def relighter():
    from learned import Relighter

    return Relighter.load()


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("fullres") / "data"
    writer.write_dataset(root, writer.SynthConfig(**TINY), progress=False)
    return root


@pytest.fixture(scope="module")
def report(folder: Path, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fullres_out") / "report"
    torch.set_num_threads(1)
    # --native-data: the folder itself (the same scenes at 128 px), so its l1 must be the direct one
    assert main(["bench", "--full-resolution", "--data", str(folder), "-o", str(out), "--threads", "1",
                 "--native-data", str(folder), "--quiet"]) == 0
    return out


def _step_photo(size: int = 128, edge: int = 62, seed: int = 0) -> dict[str, torch.Tensor]:
    """A near object (left of column ``edge``) in front of a far wall, lightly textured, and its exact
    relighting: the object's ratio 3, the wall's 0.5 (a light change that differs across the edge)."""
    rng = np.random.default_rng(seed)
    albedo = np.where(np.arange(size) < edge, 0.2, 0.6)[None, None, None, :] * np.ones((1, 3, size, 1))
    texture = 1.0 + 0.05 * rng.standard_normal((1, 1, size, size))
    full = torch.from_numpy(albedo * texture).float()
    ratio = torch.from_numpy(np.where(np.arange(size) < edge, 3.0, 0.5)).float()[None, None, None, :]
    depth = torch.from_numpy(np.where(np.arange(size) < edge, 2.0, 20.0) * np.ones((size, size))).float()
    return {"full": full, "relit": full * ratio, "depth": depth[None, None]}


def test_01_box_down_and_low_res_foreground() -> None:
    x = torch.arange(16.0).reshape(1, 1, 4, 4)
    assert torch.equal(fr.box_down(x, 2), torch.tensor([[[[2.5, 4.5], [10.5, 12.5]]]]))
    assert fr.box_down(x, 1) is x
    fg = torch.zeros(1, 1, 4, 4, dtype=torch.bool)
    fg[..., :2, :2] = True  # a whole block
    fg[..., 2, 2:] = True  # half a block: the majority rule keeps it
    fg[..., 0, 3] = True  # a quarter: dropped
    assert fr.low_res_foreground(fg, 2)[0, 0].tolist() == [[True, False], [False, True]]
    with pytest.raises(ValueError, match="multiple"):
        fr.box_down(torch.zeros(1, 1, 6, 6), 4)
    with pytest.raises(ValueError, match="factor"):
        fr.box_down(x, 0)


def test_02_guided_transfer_has_less_halo_than_bilinear_on_a_step_edge() -> None:
    s = _step_photo()
    small = torch.nn.functional.interpolate(s["full"], size=(32, 32), mode="area")
    relit_small = torch.nn.functional.interpolate(s["relit"], size=(32, 32), mode="area")  # a perfect working result
    sky = torch.zeros(1, 1, 128, 128, dtype=torch.bool)
    out = fr.transfer_variants(s["full"], small, relit_small, sky)
    halo = {k: float(metrics.edge_band_l1(v, s["relit"], s["depth"], k=2)) for k, v in out.items()}
    # the bilinear ratio blurs 3 -> 0.5 over two working pixels (8 px) across the edge
    assert halo["bilinear"] > 0.1
    assert halo["fast_guided"] < halo["guided"] < halo["bilinear"], halo
    # where the ratio changes most: at the photo's edge (columns 61 | 62) for both guided transfers;
    # the bilinear ratio's largest column step is under a quarter of the whole 3 -> 0.5 change
    for name, v in out.items():
        r = (v / s["full"]).mean(dim=(0, 1, 2))
        steps = (r[1:] - r[:-1]).abs()
        if name == "bilinear":
            assert float(steps.max()) < 0.25 * 2.5
        else:
            assert int(steps.argmax()) == 61, name
    # away from the edge every transfer is the exact relighting, up to the texture the ratio does not see
    far = torch.zeros_like(sky)
    far[..., :, :40] = True
    for v in out.values():
        assert float(metrics.l1(v, s["relit"], far)) < 1e-3


def test_02b_fast_guided_keeps_a_constant_ratio_and_falls_back_on_black() -> None:
    s = _step_photo()
    full = s["full"].clone()
    full[..., :8, :8] = 0.0  # a black corner: no ratio there
    small = torch.nn.functional.interpolate(full, size=(32, 32), mode="area")
    got = fr.transfer_fast_guided(full, small, 1.7 * small)
    lit = torch.nn.functional.interpolate(small, size=(128, 128), mode="bilinear") > 1e-3
    assert torch.allclose(got[lit], 1.7 * full[lit], rtol=1e-5, atol=0)
    assert torch.equal(got[~lit], torch.zeros_like(got[~lit]))  # up(relit_small) of a black corner
    assert fr.transfer_fast_guided(small, small, 2 * small).equal(2 * small)


def test_03_at_working_resolution_every_output_is_the_working_one(relighter) -> None:
    s = _step_photo(size=64)
    sky = torch.zeros(1, 1, 64, 64, dtype=torch.bool)
    sky[..., :6, :] = True
    L = torch.zeros(1, 9, 3)
    L[:, 0] = 1.0
    L[:, 1] = 0.5  # light from above
    target = L.clone()
    target[:, 3] = 0.6  # and from the right
    out = fr.relight_variants(relighter, s["full"], sky, target, L, "quotient", working_res=64)
    assert out["working"].shape == (1, 3, 64, 64)
    for k in ("bilinear", "guided", "direct"):
        assert torch.equal(out[k], out["working"]), k
    assert torch.equal(out["working"][sky.expand(-1, 3, -1, -1)], s["full"][sky.expand(-1, 3, -1, -1)])
    with pytest.raises(ValueError, match="method"):
        fr.relight_variants(relighter, s["full"], sky, target, L, "lambertian_sh", working_res=64)


def test_04_low_res_target_at_factor_one_is_the_protocol_target(folder: Path) -> None:
    from validation.bench.data import load_dataset
    from validation.bench.protocols import cross_pairs

    p = cross_pairs(load_dataset(folder, with_physical=False))[0]
    assert torch.allclose(fr.low_res_target(p, 1), p.target_display(), atol=1e-6)
    lo = fr.low_res_target(p, 2)
    assert lo.shape == (1, 3, 64, 64)
    # display of the block mean lies between the block's extreme displays
    hi_res = p.target_display()
    blocks = hi_res.unfold(2, 2, 2).unfold(3, 2, 2).reshape(1, 3, 64, 64, 4)
    assert bool((lo >= blocks.min(-1).values - 1e-6).all() and (lo <= blocks.max(-1).values + 1e-6).all())


def test_05_end_to_end_report_is_complete_and_consistent(report: Path) -> None:
    r = json.loads((report / "full_resolution.json").read_text())
    assert r["full_res"] == 128 and r["working_res"] == 64 and r["pairs"] == 2
    assert len(r["records"]) == 2 * len(fr.METHODS)
    for rec in r["records"]:
        for c in fr.CONFIGS:
            assert math.isfinite(rec[f"l1_{c}"]) and 0 <= rec[f"l1_{c}"] < 1, (rec["key"], c)
        for c in fr.CONFIGS[1:]:
            assert math.isfinite(rec[f"halo_{c}"]), (rec["key"], c)  # the view has sky: depth edges exist
        assert 0 < rec["band_share"] < 1
        assert rec["l1_native"] == pytest.approx(rec["l1_direct"], abs=1e-9)  # same photo, relit at its size
    for method in fr.METHODS:
        s = r["summary"][method]
        rs = [x for x in r["records"] if x["method"] == method]
        # the paired difference is the difference of the means (same pairs, nothing dropped)
        d = s["differences"]["halo_guided - halo_bilinear"]
        assert d["diff"] == pytest.approx(np.mean([x["halo_guided"] - x["halo_bilinear"] for x in rs]), abs=1e-12)
        assert s["means"]["l1_guided"]["mean"] == pytest.approx(np.mean([x["l1_guided"] for x in rs]), abs=1e-12)
        for c in fr.CONFIGS:
            assert r["seconds_per_image_1_thread"][method][c] > 0
    md = (report / "full_resolution.md").read_text()
    assert "## quotient" in md and "## proposed" in md and "halo: guided - bilinear" in md


def test_06_a_folder_not_above_the_working_resolution_is_refused(folder: Path, tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="multiple of the working resolution"):
        fr.run_full_resolution(folder, tmp_path / "out", "test", working_res=128)
    with pytest.raises(ValueError, match="multiple of the working resolution"):
        fr.run_full_resolution(folder, tmp_path / "out", "test", working_res=48)
    assert not (tmp_path / "out").exists()
