"""Real multi-view photo collections (COLMAP workspaces, MegaDepth) read as one common type.

One parser per format (:mod:`.colmap`, :mod:`.megadepth`; nerfstudio's data parsers are the model)
turns a folder into :class:`SceneRecord` s: for every registered photo its file, pinhole
intrinsics ``K (3, 3)``, ``world_to_camera (4, 4)`` in this library's (OpenGL) camera frame, its
MVS depth map and, when there is one, its sky mask. :class:`Collection` serves them with the
interface of the synth reader in ``mode="self_supervised"`` (``scenes``, ``num_views``,
``num_lights``, :meth:`Collection.photo_keys`, :meth:`Collection.load` with the keys ``photo``,
``mvs_depth``, ``sky_mask``, ``K``, ``world_to_camera``), so ``learned.data.PairSampler`` draws the
same pairs from either. A collection holds nothing else: asking for ground truth raises
``PermissionError`` as the synth reader does.

Views and lightings: photos taken from exactly the same camera (same size, ``K`` and pose, bit for
bit; a static camera's time-lapse) are one *view* under several *lightings*, in the order of their
file names; every other photo is a view of its own with one lighting. Exporting a synth set
(``physrelight export``) writes each (view, lighting) as one photo with its view's camera, so
reading the export back gives the synth set's keys.

Checks at the door (when the collection is opened, before any training run folder is made): a
non-pinhole camera, a model naming an image file that is not there, a depth map whose size is not
its image's (or an integer multiple of it, the same for the whole collection: ``mvs_scale``), a
depth map holding NaN or negative values, an unreadable file: each a ``ValueError`` naming the
file. Photos the model does not register (no pose) and registered photos without a depth map are
skipped and counted (:attr:`SceneRecord.skipped`).

Sky masks: a real collection has none. A parser gives a mask file when the collection has one
(COLMAP's mask convention: ``masks/<image name>.png``, black = masked = sky); otherwise
:class:`Collection` calls ``sky_fn`` (the learned package passes its shipped sky segmenter) on the
photo and keeps the mask in memory. :meth:`Collection.sky_sources` says which, per scene.
"""

from __future__ import annotations

from pathlib import Path

from . import colmap, megadepth
from .common import (SELF_SUPERVISED_KEYS, SPLITS, Collection, PhotoRecord, SceneRecord, SkyFn, check_depth,
                     check_scenes, group_views, split_of)

__all__ = ["SELF_SUPERVISED_KEYS", "SPLITS", "Collection", "PhotoRecord", "SceneRecord", "SkyFn", "check_depth",
           "check_scenes", "find_layout", "group_views", "open_collection", "split_of"]


def find_layout(root: str | Path) -> str:
    """Which layout ``root`` holds: ``"synth"`` (``manifest.json``), ``"megadepth"``
    (``MegaDepth_v1/``), ``"colmap"`` (a workspace: ``images/`` and a sparse model in ``sparse/``,
    ``sparse/0/`` or beside ``images/``; or folders of such workspaces, one per scene).
    ``ValueError`` saying what was looked for when it is none of them."""
    root = Path(root)
    if not root.is_dir():
        raise FileNotFoundError(f"no data folder {str(root)!r}")
    if (root / "manifest.json").is_file():
        return "synth"
    if megadepth.is_megadepth(root):
        return "megadepth"
    if colmap.workspaces(root):
        return "colmap"
    raise ValueError(f"{root}: not a training data folder: no manifest.json (synth set), no MegaDepth_v1/ "
                     f"(MegaDepth), no COLMAP workspace (images/ with sparse/ or sparse/0/, here or one per "
                     f"sub-folder)")


def open_collection(root: str | Path, split: str = "train", scenes: list[str] | None = None,
                    sky_fn: SkyFn | None = None, validate: bool = True) -> Collection:
    """The :class:`Collection` in ``root`` (a COLMAP or MegaDepth layout, :func:`find_layout`)."""
    layout = find_layout(root)
    if layout == "synth":
        raise ValueError(f"{root}: a synth dataset; read it with synth.dataset.SynthDataset")
    parse = colmap.parse_collection if layout == "colmap" else megadepth.parse_collection
    return Collection(parse(root, scenes), root, layout, split, scenes, sky_fn, validate)
