"""The common type of photo collections (:class:`Collection`, :class:`SceneRecord`, :class:`PhotoRecord`)
and the checks every parser shares; see :mod:`physrelight.collections`."""


from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable

import numpy as np

from physrelight import io

__all__ = ["SELF_SUPERVISED_KEYS", "SPLITS", "Collection", "PhotoRecord", "SceneRecord", "SkyFn", "check_depth",
           "check_scenes", "group_views", "split_of"]

SELF_SUPERVISED_KEYS = frozenset({"photo", "mvs_depth", "sky_mask", "K", "world_to_camera"})
SPLITS = ("train", "val", "test", "all")
SkyFn = Callable[[np.ndarray], np.ndarray]


def split_of(scene: str, fractions: tuple[float, float, float] = (0.8, 0.1, 0.1)) -> str:
    """The split a scene belongs to, from a hash of its name: stable when scenes are added (the synth
    reader's rule too, so an exported set keeps its scenes' splits)."""
    u = int.from_bytes(hashlib.sha256(scene.encode()).digest()[:8], "big") / 2.0**64
    if u < fractions[0]:
        return "train"
    if u < fractions[0] + fractions[1]:
        return "val"
    return "test"


@dataclass
class PhotoRecord:
    """One registered photo of a collection.

    Attributes:
        name: the photo's name in the collection (COLMAP's image name).
        image: its file.
        K: ``(3, 3)`` float64 pinhole intrinsics at the photo's resolution (pixel centres at half-integers).
        world_to_camera: ``(4, 4)`` float64, this library's camera frame (x right, y up, z toward the viewer).
        width, height: the photo's size in pixels.
        depth: its MVS depth map (z-depth, 0 = none).
        depth_reader: reads ``depth`` as ``(h, w)`` float32.
        mask: its sky mask file (black = sky), or None.
    """

    name: str
    image: Path
    K: np.ndarray
    world_to_camera: np.ndarray
    width: int
    height: int
    depth: Path
    depth_reader: Callable[[Path], np.ndarray]
    mask: Path | None = None


@dataclass
class SceneRecord:
    """A scene's registered photos (sorted by name) and how many were skipped, by reason."""

    name: str
    photos: list[PhotoRecord]
    skipped: dict[str, int] = field(default_factory=dict)


def check_depth(depth: np.ndarray, path: Path, width: int, height: int) -> int:
    """``ValueError`` naming ``path`` unless ``depth (h, w)`` is finite, non-negative and ``s`` times the
    image's ``width x height`` for an integer ``s >= 1``; returns ``s``."""
    if depth.ndim != 2:
        raise ValueError(f"{path}: a depth map has one channel, got shape {depth.shape}")
    h, w = depth.shape
    s = w // width if width else 0
    if s < 1 or (h, w) != (s * height, s * width):
        raise ValueError(f"{path}: depth map is {w}x{h}, its image is {width}x{height} (sizes must match)")
    if not np.all(np.isfinite(depth)):
        raise ValueError(f"{path}: depth map holds NaN or inf (missing depth is 0)")
    if np.any(depth < 0):
        raise ValueError(f"{path}: depth map holds negative depth ({float(depth.min()):g})")
    return s


def check_scenes(root: str | Path, wanted: list[str] | None, found: list[str]) -> None:
    """``ValueError`` naming the scenes of ``wanted`` that ``root`` does not have (and those it has)."""
    unknown = [s for s in wanted or [] if s not in found]
    if unknown:
        raise ValueError(f"{root}: no scene {', '.join(map(repr, unknown))}; "
                         f"it has {', '.join(sorted(found)) or 'none'}")


def group_views(photos: list[PhotoRecord]) -> list[list[PhotoRecord]]:
    """Photos grouped into views: those with bit-equal size, ``K`` and pose are one view (its lightings
    in name order); views in the order of their first photo's name."""
    groups: dict[bytes, list[PhotoRecord]] = {}
    for p in sorted(photos, key=lambda r: r.name):
        key = (np.asarray([p.width, p.height], np.int64).tobytes() + np.asarray(p.K, np.float64).tobytes()
               + np.asarray(p.world_to_camera, np.float64).tobytes())
        groups.setdefault(key, []).append(p)
    return list(groups.values())


class Collection:
    """Scenes of real photos served as the synth reader serves a self-supervised set.

    Args:
        records: the parsed scenes (a parser's output).
        root: the folder they came from (for messages).
        layout: ``"colmap"`` or ``"megadepth"``.
        split: ``"train"``, ``"val"``, ``"test"`` (scenes by :func:`split_of`, as the synth reader) or
            ``"all"``; ignored when ``scenes`` names them.
        scenes: the scenes to keep (None: the split's).
        sky_fn: ``photo (H, W, 3) display values -> sky (H, W) bool`` for photos without a mask file;
            None: such photos get no sky.
        validate: read every depth map now (size, NaN, negative) so bad data fails before any work.
    """

    mode = "self_supervised"

    def __init__(self, records: list[SceneRecord], root: str | Path, layout: str, split: str = "train",
                 scenes: list[str] | None = None, sky_fn: SkyFn | None = None, validate: bool = True) -> None:
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        self.root, self.layout, self.split, self.sky_fn = Path(root), layout, split, sky_fn
        by_name = {r.name: r for r in records}
        self.all_scenes = sorted(by_name)
        if scenes is not None:
            check_scenes(self.root, scenes, self.all_scenes)
            chosen = sorted(set(scenes))
        else:
            chosen = [s for s in self.all_scenes if split == "all" or split_of(s) == split]
        self.scenes = [s for s in chosen if by_name[s].photos]
        self.records = {s: by_name[s] for s in chosen}
        self._views = {s: group_views(by_name[s].photos) for s in self.scenes}
        self._sky_cache: dict[tuple[str, str], np.ndarray] = {}
        scales = set()
        if validate:
            for s in self.scenes:
                for p in by_name[s].photos:
                    scales.add(self._check_photo(p))
        if len(scales) > 1:
            raise ValueError(f"{self.root}: depth maps are {sorted(scales)} times their images' size in different "
                             f"photos; one factor for the whole collection")
        self.mvs_scale = scales.pop() if scales else 1
        sizes = {(p.width, p.height) for s in self.scenes for p in by_name[s].photos}
        # the square crop's side when every photo has one size (what mvs_pooled needs), as the synth config's res
        self.config: dict[str, Any] = {"res": min(sizes.pop())} if len(sizes) == 1 else {}
        self.items = [(s, v, l) for s in self.scenes for v, l in self.photo_keys(s)]

    @staticmethod
    def _check_photo(p: PhotoRecord) -> int:
        from PIL import Image, UnidentifiedImageError

        try:
            with Image.open(p.image) as im:
                size = im.size
        except (UnidentifiedImageError, OSError) as err:
            raise ValueError(f"cannot read {p.image} as an image: {err}") from None
        if size != (p.width, p.height):
            raise ValueError(f"{p.image}: the image is {size[0]}x{size[1]}, its camera says {p.width}x{p.height}")
        return check_depth(p.depth_reader(p.depth), p.depth, p.width, p.height)

    # ------------------------------------------------------------ structure (the synth reader's interface)

    def num_views(self, scene: str) -> int:
        return len(self._scene_views(scene))

    def num_lights(self, scene: str) -> int:
        """The most lightings of any view of ``scene`` (views may differ; :meth:`photo_keys` lists them)."""
        return max(len(v) for v in self._scene_views(scene))

    def photo_keys(self, scene: str) -> list[tuple[int, int]]:
        """Every photo of ``scene`` as ``(view, lighting)``, view-major."""
        return [(v, l) for v, group in enumerate(self._scene_views(scene)) for l in range(len(group))]

    def photo_record(self, scene: str, view: int, light: int) -> PhotoRecord:
        views = self._scene_views(scene)
        if not (0 <= view < len(views) and 0 <= light < len(views[view])):
            raise ValueError(f"{scene}: no photo (view {view}, lighting {light})")
        return views[view][light]

    def _scene_views(self, scene: str) -> list[list[PhotoRecord]]:
        if scene not in self._views:
            raise ValueError(f"scene {scene!r} is not in this collection's {self.split!r} scenes of {str(self.root)!r}")
        return self._views[scene]

    def skipped(self) -> dict[str, dict[str, int]]:
        """Per chosen scene, photos skipped by reason (``no pose``, ``no depth``)."""
        return {s: dict(r.skipped) for s, r in self.records.items()}

    def sky_sources(self) -> dict[str, str]:
        """Per scene, where its sky masks come from: ``"masks"`` (files), ``"segmenter"`` (``sky_fn``,
        kept in memory), ``"none"`` or a mix ``"masks+segmenter"``."""
        out = {}
        for s in self.scenes:
            has = {p.mask is not None for p in self.records[s].photos}
            kinds = (["masks"] if True in has else []) + (
                [("segmenter" if self.sky_fn is not None else "none")] if False in has else [])
            out[s] = "+".join(kinds)
        return out

    def __len__(self) -> int:
        return len(self.items)

    # ------------------------------------------------------------ loading

    def load(self, scene: str, view: int, light: int | None = None, keys: tuple[str, ...] = ("photo",)
             ) -> dict[str, Any]:
        """``keys`` of one photo, as the synth reader gives them: ``photo (H, W, 3)`` float32 display
        values, ``mvs_depth (s H, s W)`` float32, ``sky_mask (H, W)`` bool, ``K (3, 3)`` and
        ``world_to_camera (4, 4)`` float64. ``light`` None means lighting 0 (per-view keys)."""
        for k in keys:
            if k not in SELF_SUPERVISED_KEYS:
                raise PermissionError(f"{k!r} is not in a photo collection; it has only {sorted(SELF_SUPERVISED_KEYS)}")
        rec = self.photo_record(scene, view, 0 if light is None else light)
        out: dict[str, Any] = {}
        for k in keys:
            if k == "photo":
                out[k] = io.read_image(rec.image)
            elif k == "mvs_depth":
                out[k] = rec.depth_reader(rec.depth)
            elif k == "K":
                out[k] = np.array(rec.K, dtype=np.float64)
            elif k == "world_to_camera":
                out[k] = np.array(rec.world_to_camera, dtype=np.float64)
            else:
                out[k] = self._sky(scene, rec)
        return out

    def _sky(self, scene: str, rec: PhotoRecord) -> np.ndarray:
        if rec.mask is not None:
            sky = ~io.read_mask(rec.mask)  # COLMAP: black (0) is masked, here the sky
        elif self.sky_fn is None:
            sky = np.zeros((rec.height, rec.width), dtype=bool)
        else:
            key = (scene, rec.name)
            if key not in self._sky_cache:
                self._sky_cache[key] = np.asarray(self.sky_fn(io.read_image(rec.image)), dtype=bool)
            sky = self._sky_cache[key]
        if sky.shape != (rec.height, rec.width):
            raise ValueError(f"{rec.mask or 'the sky segmenter'}: sky mask is {sky.shape[1]}x{sky.shape[0]}, "
                             f"{rec.image} is {rec.width}x{rec.height}")
        return sky
