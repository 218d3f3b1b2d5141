"""Real photo collections (COLMAP workspaces, MegaDepth) as training data, and the exporter's round trip.

A tiny synth set (the shared fixture: 3 scenes x 2 views x 2 lightings, 24 px) is exported to both
layouts (``physrelight export``) and read back by the collection readers: the readers must give
``PairSampler`` what the native reader gives, and a short training run the same losses.
"""

from __future__ import annotations

import csv
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from learned.data import PairSampler, crop_square, data_notes, list_scenes, open_training_data
from learned.train import train
from physrelight import camera
from physrelight import colmap_format as cf
from physrelight.collections import Collection, find_layout
from physrelight.collections.megadepth import read_depth_h5, write_depth_h5
from synth.dataset import SynthDataset
from synth.export import export

from .conftest import tiny_train_config

LAYOUTS = ("colmap", "megadepth")
KEYS = ("photo", "mvs_depth", "sky_mask", "K", "world_to_camera")


@pytest.fixture(scope="module")
def exported(tiny_dataset: Path, tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("exported")
    return {fmt: (export(tiny_dataset, root / fmt, fmt, progress=False), root / fmt)[1] for fmt in LAYOUTS}


def _cli(*args: str, cwd: Path | None = None) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "import sys; from physrelight.cli import main; sys.exit(main())",
                           *args], capture_output=True, text=True, cwd=cwd)


@pytest.mark.parametrize("fmt", LAYOUTS)
def test_01_an_export_reads_back_as_the_native_set(tiny_dataset: Path, exported: dict[str, Path], fmt: str) -> None:
    """Photos bit-equal (the same file bytes too), depth equal, sky equal, cameras within 1e-6, same keys."""
    native = SynthDataset(tiny_dataset, split="all", mode="self_supervised")
    coll = open_training_data(exported[fmt], "all")
    assert isinstance(coll, Collection) and find_layout(exported[fmt]) == fmt
    assert coll.scenes == native.scenes and coll.mvs_scale == 1
    for s in native.scenes:
        assert coll.photo_keys(s) == native.photo_keys(s)
        assert (coll.num_views(s), coll.num_lights(s)) == (native.num_views(s), native.num_lights(s))
        for v, l in native.photo_keys(s):
            a, b = native.load(s, v, l, KEYS), coll.load(s, v, l, KEYS)
            np.testing.assert_array_equal(b["photo"], a["photo"])
            np.testing.assert_array_equal(b["mvs_depth"], a["mvs_depth"])
            np.testing.assert_array_equal(b["sky_mask"], a["sky_mask"])
            assert b["sky_mask"].any() and (~b["sky_mask"]).any()
            np.testing.assert_allclose(b["K"], a["K"], rtol=0, atol=1e-6)
            np.testing.assert_allclose(b["world_to_camera"], a["world_to_camera"], rtol=0, atol=1e-6)
            rec = coll.photo_record(s, v, l)
            assert rec.image.read_bytes() == (tiny_dataset / s / f"view_{v:02d}" / f"light_{l:02d}" /
                                              "photo.png").read_bytes()


@pytest.mark.parametrize("fmt", LAYOUTS)
def test_02_cross_projection_warps_agree_within_1e_4_px(tiny_dataset: Path, exported: dict[str, Path],
                                                       fmt: str) -> None:
    """Every pixel of view a, back-projected with its MVS depth and projected into view b, lands on the
    same spot (1e-4 px) with the export's cameras as with the native ones."""
    native = SynthDataset(tiny_dataset, split="all", mode="self_supervised")
    coll = open_training_data(exported[fmt], "all")

    def landing(ds, s: str, a: int, b: int) -> tuple[torch.Tensor, torch.Tensor]:
        ia, ib = ds.load(s, a, 0, KEYS), ds.load(s, b, 0, KEYS)
        d = torch.from_numpy(ia["mvs_depth"]).double()[None, None]
        p = camera.backproject(d, torch.from_numpy(ia["K"])[None])
        T = camera.relative_pose(torch.from_numpy(ia["world_to_camera"]), torch.from_numpy(ib["world_to_camera"]))
        q = camera.transform_points(T, p[0].reshape(3, -1).T).T[None]
        uv, _ = camera.project(q, torch.from_numpy(ib["K"])[None])
        return uv, camera.valid_depth(d).reshape(-1)

    n = 0
    for s in native.scenes:
        for a, b in native.pairs(s):
            uv0, ok = landing(native, s, a, b)
            uv1, _ = landing(coll, s, a, b)
            assert (uv1 - uv0)[..., ok].abs().max() < 1e-4
            n += int(ok.sum())
    assert n > 500


@pytest.mark.parametrize("fmt", LAYOUTS)
def test_03_the_sampler_draws_the_same_batches(tiny_dataset: Path, exported: dict[str, Path], fmt: str) -> None:
    a = PairSampler(tiny_dataset, split="train", res=16, seed=3, mirror=True)
    b = PairSampler(exported[fmt], split="train", res=16, seed=3, mirror=True)
    assert a.scenes == b.scenes and a.scenes
    for step in range(5):
        x, y = a.batch(3, step), b.batch(3, step)
        assert x.keys == y.keys
        for name in ("image", "depth", "sky"):
            assert torch.equal(getattr(x, name), getattr(y, name)), name
        torch.testing.assert_close(y.K, x.K, rtol=0, atol=1e-6)
        torch.testing.assert_close(y.world_to_camera, x.world_to_camera, rtol=0, atol=1e-6)


def _losses(data: Path, out: Path, prior: Path) -> list[dict[str, float]]:
    train(tiny_train_config(data, out, prior, steps=30, ckpt_every=1000))
    with (out / "train.csv").open() as f:
        return [{k: float(v) for k, v in r.items() if k not in ("seconds", "step", "time")} for r in csv.DictReader(f)]


@pytest.mark.parametrize("fmt", LAYOUTS)
def test_04_thirty_steps_from_the_export_give_the_native_losses(tiny_dataset: Path, exported: dict[str, Path],
                                                                tiny_prior: Path, tmp_path: Path, fmt: str) -> None:
    native = _losses(tiny_dataset, tmp_path / "native", tiny_prior)
    other = _losses(exported[fmt], tmp_path / fmt, tiny_prior)
    assert len(native) == len(other) == 30
    for r0, r1 in zip(native, other):
        assert r0.keys() == r1.keys()
        for k in r0:
            assert abs(r1[k] - r0[k]) <= 1e-5 * max(1.0, abs(r0[k])), (k, r0[k], r1[k])


def test_05_the_exporter_is_atomic_and_refuses_an_existing_folder(tiny_dataset: Path, tmp_path: Path) -> None:
    out = tmp_path / "ws"
    out.mkdir()
    r = _cli("export", str(tiny_dataset), "--format", "colmap", "-o", str(out))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "exists" in r.stderr
    r = _cli("export", str(tmp_path / "nothing"), "--format", "megadepth", "-o", str(tmp_path / "md"))
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "Traceback" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ws"]  # no md, no md.partial
    r = _cli("export", str(tiny_dataset), "--format", "colmap", "-o", str(tmp_path / "ok"), "--quiet")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok", "ws"]
    ws = tmp_path / "ok" / "scene_0000"
    assert (ws / "sparse" / "0" / "cameras.bin").is_file() and (ws / "masks" / "v00_l00.png.png").is_file()
    assert (ws / "stereo" / "depth_maps" / "v00_l00.png.geometric.bin").is_file()
    # ground truth stays behind: only photos, masks, depth and cameras are written
    names = {p.name.split(".")[0] for p in (tmp_path / "ok").rglob("*") if p.is_file()}
    assert names <= {"v00_l00", "v00_l01", "v01_l00", "v01_l01", "cameras", "images", "points3D"}


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def test_06_a_workspace_is_found_in_its_usual_variants(exported: dict[str, Path], tmp_path: Path) -> None:
    """One workspace named after its folder; sparse/ as text instead of sparse/0/ as binary; photometric depth
    when there is no geometric one; a photo without a pose and one without depth skipped and counted."""
    ws = _copy(exported["colmap"] / "scene_0001", tmp_path / "my_scene")
    assert find_layout(ws) == "colmap" and list_scenes(ws) == ["my_scene"]
    model = cf.read_model(ws / "sparse" / "0")
    shutil.rmtree(ws / "sparse")
    cf.write_model(model, ws / "sparse", ".txt")
    for p in (ws / "stereo" / "depth_maps").glob("*.geometric.bin"):
        p.rename(p.with_name(p.name.replace(".geometric.", ".photometric.")))
    (ws / "stereo" / "depth_maps" / "v01_l01.png.photometric.bin").unlink()
    shutil.copyfile(ws / "images" / "v00_l00.png", ws / "images" / "extra.png")
    coll = open_training_data(ws, scenes="my_scene")
    assert coll.photo_keys("my_scene") == [(0, 0), (0, 1), (1, 0)]
    assert coll.skipped() == {"my_scene": {"no pose": 1, "no depth": 1}}
    notes = data_notes(coll)
    assert "skipped 1 without a pose and 1 without depth" in notes[1] and "black = sky" in notes[1]


def test_07_photos_without_masks_get_the_shipped_segmenters_sky(exported: dict[str, Path], tmp_path: Path) -> None:
    from learned.collection_sky import segmenter_sky_fn
    from physrelight import io

    ws = _copy(exported["colmap"] / "scene_0000", tmp_path / "s")
    shutil.rmtree(ws / "masks")
    coll = open_training_data(ws, "all", sky_fn=segmenter_sky_fn())
    assert coll.sky_sources() == {"s": "segmenter"} and "shipped sky segmenter" in data_notes(coll)[1]
    sky = coll.load("s", 0, 1, ("sky_mask",))["sky_mask"]
    expect = segmenter_sky_fn()(io.read_image(ws / "images" / "v00_l01.png"))
    np.testing.assert_array_equal(sky, expect)
    assert coll.load("s", 0, 1, ("sky_mask",))["sky_mask"] is sky  # kept in memory, computed once
    assert not open_training_data(ws, "all").load("s", 0, 0, ("sky_mask",))["sky_mask"].any()
    with pytest.raises(PermissionError, match="albedo"):
        coll.load("s", 0, 0, ("albedo",))


def test_08_a_non_square_photo_is_centre_cropped_with_its_principal_point() -> None:
    """The crop moves cx, cy by its offset: a point projects to the same photo pixel before and after."""
    g = torch.Generator().manual_seed(0)
    image, depth = torch.rand(3, 20, 32, generator=g), torch.rand(1, 40, 64, generator=g) + 1
    sky = torch.rand(1, 20, 32, generator=g) > 0.5
    K = torch.tensor([[30.0, 0, 15.5], [0, 31.0, 10.25], [0, 0, 1]])
    im2, d2, s2, K2 = crop_square(image, depth, sky, K, mvs_scale=2)
    assert im2.shape == (3, 20, 20) and d2.shape == (1, 40, 40) and s2.shape == (1, 20, 20)
    assert torch.equal(im2, image[:, :, 6:26]) and torch.equal(d2, depth[:, :, 12:52])
    p = torch.tensor([[[0.3], [-0.2], [-2.0]]])
    uv, _ = camera.project(p, K[None])
    uv2, _ = camera.project(p, K2[None])
    torch.testing.assert_close(uv2, uv - torch.tensor([6.0, 0.0])[None, :, None])


@pytest.mark.parametrize("fmt", LAYOUTS)
def test_09_scenes_are_listed_and_chosen(tiny_dataset: Path, exported: dict[str, Path], fmt: str) -> None:
    r = _cli("train", "scenes", "--data", str(exported[fmt]))
    assert r.returncode == 0, r.stderr
    assert [ln.split("\t")[0] for ln in r.stdout.splitlines()] == ["scene_0000", "scene_0001", "scene_0002"]
    assert f"{fmt} layout" in r.stderr
    s = PairSampler(exported[fmt], split="test", res=16, scenes="scene_0002,scene_0000")
    assert s.scenes == ["scene_0000", "scene_0002"]
    with pytest.raises(ValueError, match="no scene 'nope'; it has scene_0000, scene_0001, scene_0002"):
        PairSampler(exported[fmt], res=16, scenes="scene_0000,nope")
    assert PairSampler(tiny_dataset, res=16, scenes=["scene_0001"]).scenes == ["scene_0001"]


def _bad(kind: str, exported: dict[str, Path], root: Path) -> tuple[Path, str]:
    """A broken copy of an export and the file the refusal must name."""
    if kind in ("non-pinhole", "missing image", "depth size", "nan depth", "negative depth"):
        ws = _copy(exported["colmap"] / "scene_0000", root / "ws")
        sparse = ws / "sparse" / "0"
        dm = ws / "stereo" / "depth_maps" / "v01_l00.png.geometric.bin"
        if kind == "non-pinhole":
            m = cf.read_model(sparse)
            c = m.cameras[2]
            m.cameras[2] = cf.Camera(2, "SIMPLE_RADIAL", c.width, c.height, np.array([*c.params[[0, 2, 3]], 0.01]))
            cf.write_model(m, sparse)
            return ws, "SIMPLE_RADIAL"
        if kind == "missing image":
            (ws / "images" / "v01_l00.png").unlink()
            return ws, "v01_l00.png"
        d = cf.read_dense_array(dm)
        if kind == "depth size":
            d = d[:-1]
        else:
            d[3, 4] = np.nan if kind == "nan depth" else -1.0
        cf.write_dense_array(d, dm)
        return ws, dm.name
    src = _copy(exported["megadepth"], root / "md")
    h5 = src / "MegaDepth_v1" / "scene_0001" / "dense0" / "depths" / "v00_l01.h5"
    import h5py

    with h5py.File(h5, "w") as f:
        f.create_dataset("not_depth", data=np.zeros((2, 2), np.float32))
    return src, "v00_l01.h5"


@pytest.mark.parametrize("kind", ["non-pinhole", "missing image", "depth size", "nan depth", "negative depth",
                                  "h5 without depth"])
def test_10_bad_data_is_one_line_naming_the_file_and_no_run_folder(exported: dict[str, Path], tmp_path: Path,
                                                                   kind: str) -> None:
    data, name = _bad(kind, exported, tmp_path)
    run = tmp_path / "run"
    r = _cli("train", "inverse", "--data", str(data), "--out", str(run), "--train-split", "all", "--steps", "1",
             "--quiet")
    assert r.returncode == 2, r.stderr
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr and name in r.stderr, r.stderr
    assert not run.exists()
    if kind == "non-pinhole":
        assert "colmap image_undistorter" in r.stderr


def test_11_megadepth_depth_files_and_the_sfm_model_fallback(exported: dict[str, Path], tmp_path: Path) -> None:
    d = np.random.default_rng(0).uniform(0, 5, size=(7, 9)).astype(np.float32)
    write_depth_h5(d, tmp_path / "x.h5")
    np.testing.assert_array_equal(read_depth_h5(tmp_path / "x.h5"), d)
    (tmp_path / "y.h5").write_bytes(b"not hdf5")
    with pytest.raises(ValueError, match="y.h5: not an HDF5 file"):
        read_depth_h5(tmp_path / "y.h5")
    # the release's layout: the model in MegaDepth_v1_SfM/SCENE/sparse/manhattan/0 (distorted there: refused)
    md = _copy(exported["megadepth"], tmp_path / "md")
    dense = md / "MegaDepth_v1" / "scene_0002" / "dense0"
    sfm = md / "MegaDepth_v1_SfM" / "scene_0002" / "sparse" / "manhattan" / "0"
    sfm.parent.mkdir(parents=True)
    shutil.move(dense / "sparse", sfm)
    assert open_training_data(md, scenes="scene_0002").num_views("scene_0002") == 2
    m = cf.read_model(sfm)
    m.cameras[1] = cf.Camera(1, "SIMPLE_RADIAL", 24, 24, np.array([20.0, 12.0, 12.0, 0.02]))
    cf.write_model(m, sfm)
    with pytest.raises(ValueError, match="SIMPLE_RADIAL, not a pinhole model; run `colmap image_undistorter"):
        open_training_data(md, scenes="scene_0002")
