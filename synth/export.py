"""``physrelight export``: a synth set written in a real collection's layout (COLMAP workspace, MegaDepth).

What a photo collection would hold and nothing more (no ground truth: the set is read with
``SynthDataset(mode="self_supervised")``): each photo as the camera wrote it (the same bytes), its
view's MVS-like depth, its camera, its sky mask in COLMAP's mask convention (black = masked = sky).
Every (view, lighting) becomes one image named ``vVV_lLL.png`` with its view's camera, so
:mod:`physrelight.collections` reads the photos of one view back as one view under several
lightings and ``learned.data.PairSampler`` draws the same batches from the export as from the set.

Layouts (one scene per synth scene, named as in the set)::

    colmap:    OUT/SCENE/images/vVV_lLL.png
               OUT/SCENE/sparse/0/{cameras,images,points3D}.bin     (PINHOLE cameras, one per view;
                                                                      no 3-D points)
               OUT/SCENE/stereo/depth_maps/vVV_lLL.png.geometric.bin
               OUT/SCENE/masks/vVV_lLL.png.png
    megadepth: OUT/MegaDepth_v1/SCENE/dense0/imgs/vVV_lLL.png
               OUT/MegaDepth_v1/SCENE/dense0/depths/vVV_lLL.h5         (dataset "depth")
               OUT/MegaDepth_v1/SCENE/dense0/sparse/{cameras,images,points3D}.bin
               OUT/MegaDepth_v1/SCENE/dense0/masks/vVV_lLL.png.png

The export is atomic: written to ``OUT.partial`` and renamed; an existing ``OUT`` (or a left-over
``OUT.partial``) is refused before anything is written.
"""

from __future__ import annotations

import argparse
import shutil
from pathlib import Path

import numpy as np

from physrelight import colmap_format as cf
from physrelight import io
from physrelight.collections.megadepth import write_depth_h5

from .dataset import SynthDataset

__all__ = ["FORMATS", "add_parser", "export"]

FORMATS = ("colmap", "megadepth")


def _scene_folders(out: Path, fmt: str, scene: str) -> dict[str, Path]:
    if fmt == "colmap":
        ws = out / scene
        return {"images": ws / "images", "sparse": ws / "sparse" / "0", "depth": ws / "stereo" / "depth_maps",
                "masks": ws / "masks"}
    dense = out / "MegaDepth_v1" / scene / "dense0"
    return {"images": dense / "imgs", "sparse": dense / "sparse", "depth": dense / "depths", "masks": dense / "masks"}


def _export_scene(ds: SynthDataset, scene: str, out: Path, fmt: str) -> int:
    dirs = _scene_folders(out, fmt, scene)
    for d in dirs.values():
        d.mkdir(parents=True, exist_ok=True)
    cameras, images = {}, {}
    for view in range(ds.num_views(scene)):
        item = ds.load(scene, view, None, keys=("mvs_depth", "sky_mask", "K", "world_to_camera"))
        K, depth = item["K"], np.asarray(item["mvs_depth"], dtype=np.float32)
        if K[0, 1] != 0:
            raise ValueError(f"{scene} view {view}: K has skew {K[0, 1]}; COLMAP's pinhole cameras have none")
        h, w = item["sky_mask"].shape
        cameras[view + 1] = cf.Camera(view + 1, "PINHOLE", w, h, np.array([K[0, 0], K[1, 1], K[0, 2], K[1, 2]]))
        qvec, tvec = cf.colmap_from_world_to_camera(item["world_to_camera"])
        mask = np.where(item["sky_mask"], 0.0, 1.0)  # COLMAP's mask convention: black (0) is masked, the sky
        for light in range(ds.num_lights(scene)):
            name = f"v{view:02d}_l{light:02d}.png"
            photo = ds.root / scene / f"view_{view:02d}" / f"light_{light:02d}" / "photo.png"
            shutil.copyfile(photo, dirs["images"] / name)  # the bytes the camera wrote
            io.write_png(dirs["masks"] / f"{name}.png", mask)
            if fmt == "colmap":
                cf.write_dense_array(depth, dirs["depth"] / f"{name}.geometric.bin")
            else:
                write_depth_h5(depth, dirs["depth"] / f"{Path(name).stem}.h5")
            iid = len(images) + 1
            images[iid] = cf.Image(iid, qvec, tvec, view + 1, name)
    cf.write_model(cf.SparseModel(cameras, images, {}), dirs["sparse"], ".bin")
    return len(images)


def export(root: str | Path, out: str | Path, fmt: str = "colmap", progress: bool = True) -> dict[str, int]:
    """Write the synth set ``root`` (all its scenes) in ``fmt``'s layout at ``out``; returns photos per scene.

    ``ValueError`` for an unknown format, an existing ``out`` or ``out.partial``, or a set that is not a
    synth set; on any error nothing is left at ``out`` or ``out.partial``.
    """
    if fmt not in FORMATS:
        raise ValueError(f"format must be one of {FORMATS}, got {fmt!r}")
    out = Path(out)
    partial = out.with_name(out.name + ".partial")
    for p in (out, partial):
        if p.exists():
            raise ValueError(f"{p} exists; export writes a new folder (remove it or choose another -o)")
    ds = SynthDataset(root, split="all", mode="self_supervised")
    if not ds.scenes:
        raise ValueError(f"{root}: no scenes to export")
    from tqdm import tqdm

    counts = {}
    try:
        partial.mkdir(parents=True)
        for scene in tqdm(ds.scenes, desc=f"export {fmt}", disable=not progress):
            counts[scene] = _export_scene(ds, scene, partial, fmt)
        partial.rename(out)
    finally:
        if partial.exists():
            shutil.rmtree(partial)
    return counts


def _export_cmd(args: argparse.Namespace) -> int:
    counts = export(args.data, args.output, args.format, progress=not args.quiet)
    print(f"{args.output}: {len(counts)} scenes, {sum(counts.values())} photos in the {args.format} layout")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``export``."""
    p = sub.add_parser("export", help="write a synth set in a real collection's layout (COLMAP, MegaDepth)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("data", metavar="SYNTH_DIR", help="synth dataset folder")
    p.add_argument("--format", choices=FORMATS, required=True, help="the layout to write")
    p.add_argument("-o", "--output", required=True, help="new folder to write (refused if it exists)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_export_cmd, output_folders=("output",))
