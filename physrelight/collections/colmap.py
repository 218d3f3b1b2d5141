"""COLMAP workspaces as :class:`~physrelight.collections.SceneRecord` s.

A workspace (what ``colmap image_undistorter`` writes, or any folder laid out the same way)::

    SCENE/images/NAME                         the photos (COLMAP's image names are paths below images/)
    SCENE/sparse/{cameras,images,points3D}.{bin,txt}   (or sparse/0/, or beside images/ as the
                                              undistorter's "sparse" folder)
    SCENE/stereo/depth_maps/NAME.geometric.bin   else NAME.photometric.bin
    SCENE/masks/NAME.png                      optional sky masks, COLMAP's mask convention: black
                                              (0) = masked = sky; the same files serve
                                              ``colmap feature_extractor --ImageReader.mask_path``

``DIR`` is one workspace (its scene is named after the folder) or a folder of workspaces, one per
scene. Only pinhole cameras are read (:func:`physrelight.colmap_format.pinhole_K`).
"""

from __future__ import annotations

from pathlib import Path

from physrelight import colmap_format as cf

from .common import PhotoRecord, SceneRecord, check_scenes

__all__ = ["DEPTH_SUFFIXES", "depth_path", "is_workspace", "parse_collection", "parse_workspace", "sparse_folder",
           "workspaces"]

DEPTH_SUFFIXES = (".geometric.bin", ".photometric.bin")  # geometric first: consistency-filtered


def sparse_folder(ws: Path) -> Path | None:
    """The workspace's sparse model folder: ``sparse/``, ``sparse/0/``, else none."""
    return cf.find_sparse_model(ws / "sparse")


def is_workspace(folder: Path) -> bool:
    """``folder`` has ``images/`` and a sparse model."""
    return (folder / "images").is_dir() and sparse_folder(folder) is not None


def workspaces(root: str | Path) -> dict[str, Path]:
    """Scene name -> workspace: ``root`` itself when it is one (named after it), else its sub-folders that are."""
    root = Path(root)
    if is_workspace(root):
        return {root.resolve().name: root}
    return {p.name: p for p in sorted(root.iterdir()) if p.is_dir() and is_workspace(p)} if root.is_dir() else {}


def depth_path(ws: Path, name: str) -> Path | None:
    """The image's depth map, geometric before photometric, or None."""
    for suffix in DEPTH_SUFFIXES:
        p = ws / "stereo" / "depth_maps" / f"{name}{suffix}"
        if p.is_file():
            return p
    return None


def parse_workspace(ws: str | Path, scene: str) -> SceneRecord:
    """One workspace's registered photos with depth. ``ValueError`` naming the file for a non-pinhole
    camera or a registered image whose file is missing; photos in ``images/`` without a pose and
    registered photos without a depth map are skipped and counted."""
    ws = Path(ws)
    folder = sparse_folder(ws)
    if folder is None:
        raise FileNotFoundError(f"{ws}: no sparse model in sparse/ or sparse/0/")
    model = cf.read_model(folder)
    photos, no_depth = [], 0
    registered = set()
    for im in sorted(model.images.values(), key=lambda i: i.name):
        cam = model.cameras[im.camera_id]
        K = cf.pinhole_K(cam, str(folder))
        path = ws / "images" / im.name
        if not path.is_file():
            raise ValueError(f"{folder}: the model names image {im.name!r}, but {path} is not there")
        registered.add(im.name)
        dpath = depth_path(ws, im.name)
        if dpath is None:
            no_depth += 1
            continue
        mask = ws / "masks" / f"{im.name}.png"
        photos.append(PhotoRecord(im.name, path, K, cf.world_to_camera_from_colmap(im.qvec, im.tvec), cam.width,
                                  cam.height, dpath, cf.read_dense_array, mask if mask.is_file() else None))
    on_disk = {p.relative_to(ws / "images").as_posix() for p in (ws / "images").rglob("*") if p.is_file()}
    return SceneRecord(scene, photos, {"no pose": len(on_disk - registered), "no depth": no_depth})


def parse_collection(root: str | Path, scenes: list[str] | None = None) -> list[SceneRecord]:
    """Every workspace in ``root`` (:func:`workspaces`), or only ``scenes``."""
    found = workspaces(root)
    check_scenes(root, scenes, list(found))
    return [parse_workspace(ws, name) for name, ws in found.items() if scenes is None or name in scenes]
