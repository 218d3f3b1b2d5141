"""Specification of the dataset writer and reader: layout, determinism, resumption, shards, the guard."""

from __future__ import annotations

import hashlib
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from physrelight import io
from synth import writer
from synth.dataset import GroundTruthAccessError, SynthDataset, split_of

TINY = dict(scenes=2, views=2, lights=2, res=24, spp=4, gbuffer_spp=2, shadow_spp=2, env_resolution=16,
            kinds=("sunsky", "overcast", "hdri"))


def digest(root: Path) -> dict[str, str]:
    """sha256 of every file but timing.json, by relative path."""
    return {str(p.relative_to(root)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file() and p.name != "timing.json"}


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("ds")
    writer.write_dataset(root, writer.SynthConfig(**TINY), progress=False)
    return root


def test_01_layout_has_every_documented_file(dataset: Path) -> None:
    manifest = io.read_json(dataset / "manifest.json")
    assert manifest["format"] == writer.FORMAT and manifest["version"] == writer.VERSION
    for s in ("scene_0000", "scene_0001"):
        rec = io.read_json(dataset / s / "scene.json")
        assert len(rec["views"]) == 2 and len(rec["lights"]) == 2
        for li, light in enumerate(rec["lights"]):
            assert (dataset / s / "lights" / f"light_{li:02d}" / "env.exr").is_file()
            assert set(light["sh"]["world"]) == {"2", "4"} and len(light["sh"]["cameras"]) == 2
        for v in range(2):
            vdir = dataset / s / f"view_{v:02d}"
            for f in ("albedo.exr", "normal.exr", "depth.exr", "sky_mask.png", "mvs_depth.exr", "glossy_mask.png"):
                assert (vdir / f).is_file(), f
            for li in range(2):
                for f in ("radiance.exr", "shadow.exr", "direct_shadow.exr", "photo.png"):
                    assert (vdir / f"light_{li:02d}" / f).is_file(), f


def test_02_sh_in_camera_frames_is_the_rotated_world_sh(dataset: Path) -> None:
    from physrelight import sh

    rec = io.read_json(dataset / "scene_0000" / "scene.json")
    for light in rec["lights"]:
        world = np.asarray(light["sh"]["world"]["2"])
        for v, view in enumerate(rec["views"]):
            r = np.asarray(view["world_to_camera"])[:3, :3]
            np.testing.assert_allclose(light["sh"]["cameras"][v]["2"], sh.rotate(world, r), atol=1e-9)


def test_03_mvs_depth_is_a_degraded_subset_of_the_true_depth(dataset: Path) -> None:
    vdir = dataset / "scene_0000" / "view_00"
    depth, mvs = io.read_exr(vdir / "depth.exr"), io.read_exr(vdir / "mvs_depth.exr")
    sky = io.read_mask(vdir / "sky_mask.png")
    assert np.all(mvs[sky] == 0) and np.all(depth[sky] == 0)
    kept = mvs > 0
    assert 0.3 < kept.sum() / (~sky).sum() < 0.999  # holes, but most of the surface survives
    rel = np.abs(mvs[kept] / depth[kept] - 1)
    assert np.median(rel) < 0.02 and rel.max() < 0.1


def test_04_same_seed_same_bytes(dataset: Path, tmp_path: Path) -> None:
    writer.write_dataset(tmp_path, writer.SynthConfig(**TINY), progress=False)
    assert digest(tmp_path) == digest(dataset)


def test_05_a_killed_run_resumes_and_never_marks_a_partial_scene_complete(dataset: Path, tmp_path: Path) -> None:
    config = writer.SynthConfig(**TINY)
    writer.write_dataset(tmp_path, config, shard=(0, 2), progress=False)  # only scene_0000
    first = (tmp_path / "scene_0000" / "scene.json").stat().st_mtime_ns
    # A run killed half-way through scene_0001 leaves only its partial folder behind.
    partial = tmp_path / ".scene_0001.partial"
    (partial / "view_00").mkdir(parents=True)
    (partial / "view_00" / "albedo.exr").write_bytes(b"half a file")
    assert [p.name for p in writer.finished_scenes(tmp_path)] == ["scene_0000"]
    summary = writer.write_dataset(tmp_path, config, progress=False)
    assert summary["skipped"] == ["scene_0000"] and summary["rendered"] == ["scene_0001"]
    assert (tmp_path / "scene_0000" / "scene.json").stat().st_mtime_ns == first
    assert not partial.exists()
    assert digest(tmp_path) == digest(dataset)


def test_06_shards_partition_the_scenes_and_configs_cannot_mix(tmp_path: Path) -> None:
    config = writer.SynthConfig(**{**TINY, "scenes": 7})
    parts = [writer.shard_scenes(config, (i, 3)) for i in range(3)]
    assert sorted(sum(parts, [])) == list(range(7)) and not set(parts[0]) & set(parts[1])
    writer.write_dataset(tmp_path, writer.SynthConfig(**{**TINY, "scenes": 1}), progress=False)
    with pytest.raises(ValueError, match="different arguments"):
        writer.write_dataset(tmp_path, writer.SynthConfig(**{**TINY, "scenes": 1, "spp": 8}), progress=False)
    for bad in ("3/3", "a/b", "1"):
        with pytest.raises(ValueError, match="shard"):
            writer.parse_shard(bad)


def test_07_self_supervised_reader_exposes_only_what_the_paper_may_use(dataset: Path) -> None:
    ds = SynthDataset(dataset, split="all", mode="self_supervised")
    assert len(ds) == 2 * 2 * 2
    item = ds[0]
    assert set(item) == {"scene", "view", "light", "photo", "mvs_depth", "sky_mask", "K", "world_to_camera"}
    assert item["photo"].shape == (24, 24, 3) and item["photo"].max() <= 1
    for key in ("albedo", "normal", "depth", "shadow", "radiance", "lighting", "sh", "env", "photo_params"):
        with pytest.raises(GroundTruthAccessError):
            ds.load("scene_0000", 0, 0, (key,))
    with pytest.raises(GroundTruthAccessError):
        SynthDataset(dataset, split="all", mode="self_supervised", keys=("photo", "albedo"))
    assert "lights" not in ds.record("scene_0000")  # no lighting ground truth through the record either


def test_08_full_reader_and_splits(dataset: Path) -> None:
    full = SynthDataset(dataset, split="all", mode="full")
    x = full.load("scene_0001", 1, 1, ("albedo", "sh", "radiance", "shadow"))
    assert x["albedo"].shape == (24, 24, 3) and x["sh"]["2"].shape == (9, 3)
    assert 0 <= x["shadow"].min() and x["shadow"].max() <= 1
    splits = {s: set(SynthDataset(dataset, split=s, mode="full").scenes) for s in ("train", "val", "test")}
    assert set.union(*splits.values()) == {"scene_0000", "scene_0001"}
    assert all(not (splits[a] & splits[b]) for a in splits for b in splits if a < b)
    # Splits come from the scene name alone: adding scenes never moves one.
    assert split_of("scene_0042") == split_of("scene_0042")
    shares = [split_of(f"scene_{i:04d}") for i in range(2000)]
    assert 0.77 < shares.count("train") / 2000 < 0.83


def test_09_command_line_errors_are_one_line(tmp_path: Path) -> None:
    res = subprocess.run([sys.executable, "-m", "physrelight.cli", "synth", str(tmp_path), "--shard", "5/2"],
                         capture_output=True, text=True)
    assert res.returncode != 0 and "Traceback" not in res.stderr
    assert res.stderr.strip().count("\n") == 0 and "shard" in res.stderr


def test_10_a_dataset_grows_to_the_bytes_of_the_larger_one_and_never_shrinks(dataset: Path, tmp_path: Path) -> None:
    writer.write_dataset(tmp_path, writer.SynthConfig(**{**TINY, "scenes": 1}), progress=False)
    first = (tmp_path / "scene_0000" / "scene.json").stat().st_mtime_ns
    summary = writer.write_dataset(tmp_path, writer.SynthConfig(**TINY), progress=False)  # 1 -> 2 scenes
    assert summary == {**summary, "skipped": ["scene_0000"], "rendered": ["scene_0001"]}
    assert (tmp_path / "scene_0000" / "scene.json").stat().st_mtime_ns == first
    assert digest(tmp_path) == digest(dataset)  # manifest included: as if rendered at 2 scenes
    assert "scenes" not in io.read_json(tmp_path / "scene_0000" / "scene.json")["config"]
    with pytest.raises(ValueError, match="grow, not shrink"):
        writer.write_dataset(tmp_path, writer.SynthConfig(**{**TINY, "scenes": 1}), progress=False)


def test_11_mvs_scale_changes_the_mvs_depth_only_and_renders_it_at_that_multiple(dataset: Path, tmp_path: Path) -> None:
    """``--mvs-scale 2``: every photo and ground-truth file has the bytes of the set without it; the MVS
    depth is 2x the size, in the same cameras (``K[:2] * 2``), and agrees with the true depth."""
    writer.write_dataset(tmp_path, writer.SynthConfig(**TINY, mvs_scale=2), progress=False)
    plain, scaled = digest(dataset), digest(tmp_path)
    assert plain.keys() == scaled.keys()
    differ = {k for k in plain if plain[k] != scaled[k]}
    assert differ == {"manifest.json"} | {f"scene_000{s}/{f}" for s in (0, 1) for f in
                                         ["scene.json", "view_00/mvs_depth.exr", "view_01/mvs_depth.exr"]}
    for s in ("scene_0000", "scene_0001"):
        a, b = io.read_json(dataset / s / "scene.json"), io.read_json(tmp_path / s / "scene.json")
        assert b["config"].pop("mvs_scale") == 2 and a == b  # only the recorded configuration differs
    assert "mvs_scale" not in io.read_json(dataset / "manifest.json")["config"]  # old sets keep their bytes
    ds = SynthDataset(tmp_path, split="all", mode="full")
    assert ds.mvs_scale == 2 and SynthDataset(dataset, split="all").mvs_scale == 1
    for v in range(2):
        item = ds.load("scene_0000", v, 0, keys=("mvs_depth", "depth", "sky_mask"))
        mvs, depth, sky = item["mvs_depth"], item["depth"], item["sky_mask"]
        assert mvs.shape == (48, 48)
        blocks = mvs.reshape(24, 2, 24, 2).transpose(0, 2, 1, 3).reshape(24, 24, 4)
        full = np.all(blocks > 0, axis=-1) & ~sky  # every sub-pixel has MVS depth
        assert full.sum() > 0.3 * (~sky).sum()
        rel = np.abs(blocks[full].mean(-1) / depth[full] - 1)  # pixel-centre depth vs its four sub-pixels
        assert np.median(rel) < 0.02
        assert np.all(blocks[sky].min(-1) == 0)  # a sky pixel's centre sub-pixels see sky: no depth there


def test_12_mvs_scale_is_checked(tmp_path: Path) -> None:
    for bad in (0, 5, 1.5, True):
        with pytest.raises(ValueError, match="mvs_scale"):
            writer.SynthConfig(**TINY, mvs_scale=bad)


def test_13_an_existing_file_as_output_is_a_one_line_error(tmp_path: Path, capsys) -> None:
    from physrelight.cli import main

    f = tmp_path / "taken"
    f.write_text("not a dataset")
    for out in (f, f / "below"):
        assert main(["synth", str(out), "--scenes", "1"]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "Traceback" not in err and str(out) in err
    assert f.read_text() == "not a dataset" and sorted(tmp_path.iterdir()) == [f]
