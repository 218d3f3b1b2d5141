"""MegaDepth v1 (Li and Snavely, CVPR 2018) as :class:`~physrelight.collections.SceneRecord` s.

Layout (``DIR`` holds the two archives unpacked side by side)::

    DIR/MegaDepth_v1/SCENE/denseN/imgs/NAME.jpg        undistorted photos
    DIR/MegaDepth_v1/SCENE/denseN/depths/STEM.h5       their MVS depth, dataset ``depth`` (H, W) float,
                                                       0 = none
    DIR/MegaDepth_v1/SCENE/denseN/sparse/              the undistorted model, when there (what
                                                       ``colmap image_undistorter`` writes)
    DIR/MegaDepth_v1_SfM/SCENE/sparse/manhattan/N/     else the scene's SfM model
    DIR/MegaDepth_v1/SCENE/denseN/masks/NAME.png       optional sky masks (not in the release; COLMAP's
                                                       mask convention, black = sky)

The SfM model of the MegaDepth release has distorted (``SIMPLE_RADIAL``) cameras: it is refused
with a message saying to undistort it (``colmap image_undistorter --input_path
MegaDepth_v1_SfM/SCENE/sparse/manhattan/N --output_path ...``) and to put the result's ``sparse``
beside ``imgs``. Photos are matched to the model by file name. A scene's ``dense0`` is named
``SCENE``, ``denseN`` (N > 0) ``SCENE-denseN``.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from physrelight import colmap_format as cf

from .common import PhotoRecord, SceneRecord, check_scenes

__all__ = ["DEPTH_DATASET", "is_megadepth", "parse_collection", "parse_scene", "read_depth_h5", "scene_folders",
           "write_depth_h5"]

DEPTH_DATASET = "depth"


def _h5py():
    try:
        import h5py
    except ImportError:
        raise ValueError("reading MegaDepth needs h5py: pip install h5py") from None
    return h5py


def read_depth_h5(path: str | Path) -> np.ndarray:
    """A MegaDepth depth map ``(H, W)`` float32 from ``path``'s dataset ``depth``; ``ValueError`` naming the
    file when it is not HDF5, lacks the dataset or the dataset is not 2-D."""
    h5py = _h5py()
    path = Path(path)
    try:
        with h5py.File(path, "r") as f:
            if DEPTH_DATASET not in f:
                raise ValueError(f"{path}: no dataset {DEPTH_DATASET!r} (has {sorted(f.keys())})")
            d = np.asarray(f[DEPTH_DATASET], dtype=np.float32)
    except OSError as err:
        raise ValueError(f"{path}: not an HDF5 file ({err})") from None
    if d.ndim != 2:
        raise ValueError(f"{path}: dataset {DEPTH_DATASET!r} has shape {d.shape}, a depth map is (H, W)")
    return d


def write_depth_h5(depth: np.ndarray, path: str | Path) -> None:
    """Write ``depth (H, W)`` float32 as MegaDepth does (dataset ``depth``), atomically."""
    from physrelight.io import atomic_path

    h5py = _h5py()
    d = np.asarray(depth)
    if d.ndim != 2 or d.dtype != np.float32:
        raise ValueError(f"depth must be (H, W) float32, got {d.dtype} {d.shape}")
    with atomic_path(path, ".h5") as tmp:
        with h5py.File(tmp, "w") as f:
            f.create_dataset(DEPTH_DATASET, data=d)


def is_megadepth(root: str | Path) -> bool:
    """``root`` holds ``MegaDepth_v1/`` with at least one ``SCENE/denseN/imgs``."""
    return bool(scene_folders(root))


def scene_folders(root: str | Path) -> dict[str, Path]:
    """Scene name -> its ``denseN`` folder (``SCENE`` for dense0, ``SCENE-denseN`` otherwise)."""
    base = Path(root) / "MegaDepth_v1"
    out = {}
    if not base.is_dir():
        return out
    for scene in sorted(p for p in base.iterdir() if p.is_dir()):
        for dense in sorted(scene.glob("dense*")):
            m = re.fullmatch(r"dense(\d+)", dense.name)
            if m and (dense / "imgs").is_dir():
                out[scene.name if m.group(1) == "0" else f"{scene.name}-{dense.name}"] = dense
    return out


def _model_folder(root: Path, dense: Path) -> Path:
    own = cf.find_sparse_model(dense / "sparse")
    if own is not None:
        return own
    n = dense.name[len("dense"):]
    sfm = root / "MegaDepth_v1_SfM" / dense.parent.name / "sparse" / "manhattan" / n
    if cf.find_sparse_model(sfm) is not None:
        return sfm
    raise FileNotFoundError(f"{dense}: no sparse model in {dense / 'sparse'} nor in {sfm}")


def parse_scene(root: str | Path, dense: Path, scene: str) -> SceneRecord:
    """One MegaDepth scene's registered photos with depth (see the module doc for what is refused)."""
    root = Path(root)
    folder = _model_folder(root, dense)
    model = cf.read_model(folder)
    for cam in model.cameras.values():
        if cam.model not in cf.PINHOLE_MODELS:
            raise ValueError(f"{folder}: camera {cam.id} is {cam.model}, not a pinhole model; run `colmap "
                             f"image_undistorter --input_path {folder} --output_path OUT` and put OUT/sparse in "
                             f"{dense}/sparse")
    imgs = dense / "imgs"
    photos, no_depth, registered = [], 0, set()
    for im in sorted(model.images.values(), key=lambda i: i.name):
        name = Path(im.name).name
        path = imgs / name
        if not path.is_file():
            raise ValueError(f"{folder}: the model names image {im.name!r}, but {path} is not there")
        registered.add(name)
        dpath = dense / "depths" / f"{Path(name).stem}.h5"
        if not dpath.is_file():
            no_depth += 1
            continue
        cam = model.cameras[im.camera_id]
        mask = dense / "masks" / f"{name}.png"
        photos.append(PhotoRecord(name, path, cf.pinhole_K(cam, str(folder)),
                                  cf.world_to_camera_from_colmap(im.qvec, im.tvec), cam.width, cam.height, dpath,
                                  read_depth_h5, mask if mask.is_file() else None))
    on_disk = {p.name for p in imgs.iterdir() if p.is_file()}
    return SceneRecord(scene, photos, {"no pose": len(on_disk - registered), "no depth": no_depth})


def parse_collection(root: str | Path, scenes: list[str] | None = None) -> list[SceneRecord]:
    """Every MegaDepth scene in ``root`` (:func:`scene_folders`), or only ``scenes``."""
    found = scene_folders(root)
    check_scenes(root, scenes, list(found))
    return [parse_scene(root, d, name) for name, d in found.items() if scenes is None or name in scenes]
