"""Read a dataset written by :mod:`synth.writer`, split by scene, with a guarded self-supervised mode.

The paper trains without ground truth: from an internet photo collection it may use the
photos, multi-view-stereo depth, camera poses and sky masks, nothing else. In
``mode="self_supervised"`` this reader hands out exactly those and raises
:class:`GroundTruthAccessError` when anything else (albedo, normals, true depth, shadows,
radiance, lighting, photo parameters) is asked for, so a training loop cannot use ground
truth by accident. ``mode="full"`` (validation, benchmarks) exposes everything.

Images come back as float32 numpy arrays ``(H, W, C)`` (``(H, W)`` for one channel);
:func:`to_chw` turns them into the library's torch ``(C, H, W)``. ``mvs_depth`` is
``(s H, s W)`` with ``s`` = :attr:`SynthDataset.mvs_scale` (1 unless the set was written with
``--mvs-scale``); its intrinsics are ``K[:2] * s`` (:func:`physrelight.camera.scale_intrinsics`).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import numpy as np
import torch

from physrelight import io
from physrelight.collections.common import split_of  # the rule photo collections split by too

from .writer import FORMAT, VERSION

SELF_SUPERVISED_KEYS = frozenset({"photo", "mvs_depth", "sky_mask", "K", "world_to_camera"})
GROUND_TRUTH_KEYS = frozenset({
    "albedo", "normal", "depth", "radiance", "shadow", "direct_shadow", "lighting", "sh", "env", "photo_params",
    "glossy_mask",
})
ALL_KEYS = SELF_SUPERVISED_KEYS | GROUND_TRUTH_KEYS
SPLITS = ("train", "val", "test", "all")
MODES = ("self_supervised", "full")

_VIEW_FILES = {"albedo": "albedo.exr", "normal": "normal.exr", "depth": "depth.exr", "mvs_depth": "mvs_depth.exr"}
_LIGHT_FILES = {"radiance": "radiance.exr", "shadow": "shadow.exr", "direct_shadow": "direct_shadow.exr"}


class GroundTruthAccessError(PermissionError):
    """Ground truth requested from a dataset opened in self-supervised mode."""


@dataclass(frozen=True)
class Item:
    """One photo: scene name, view index, lighting index."""

    scene: str
    view: int
    light: int


class SynthDataset:
    """A synth dataset folder.

    Args:
        root: folder with ``manifest.json``.
        split: "train", "val", "test" (by scene, see :func:`split_of`) or "all".
        mode: "self_supervised" (training: photos, MVS depth, cameras, sky masks only) or "full".
        fractions: train/val/test shares.
        keys: what ``dataset[i]`` returns (default: everything the mode allows).
    """

    def __init__(self, root: str | Path, split: str = "train", mode: str = "self_supervised",
                 fractions: tuple[float, float, float] = (0.8, 0.1, 0.1), keys: tuple[str, ...] | None = None) -> None:
        self.root = Path(root)
        if split not in SPLITS:
            raise ValueError(f"split must be one of {SPLITS}, got {split!r}")
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        if len(fractions) != 3 or min(fractions) < 0 or abs(sum(fractions) - 1) > 1e-9:
            raise ValueError(f"fractions must be three non-negative shares summing to 1, got {fractions}")
        manifest = io.read_json(self.root / "manifest.json")
        if manifest.get("format") != FORMAT or manifest.get("version") != VERSION:
            raise ValueError(f"{str(self.root)!r} is not a {FORMAT} v{VERSION} dataset")
        self.mode, self.split, self.config = mode, split, manifest["config"]
        self.mvs_scale = int(self.config.get("mvs_scale", 1))  # absent from sets written before the option
        names = sorted(p.parent.name for p in self.root.glob("scene_*/scene.json"))
        self.scenes = [n for n in names if split == "all" or split_of(n, fractions) == split]
        self._records: dict[str, dict] = {}
        self.keys = tuple(sorted(SELF_SUPERVISED_KEYS if mode == "self_supervised" else ALL_KEYS)) if keys is None \
            else tuple(keys)
        for k in self.keys:
            self._check_key(k)
        self.items = [Item(s, v, l) for s in self.scenes for v in range(self.num_views(s))
                      for l in range(self.num_lights(s))]

    # ------------------------------------------------------------ access control

    def _check_key(self, key: str) -> None:
        if key not in ALL_KEYS:
            raise ValueError(f"unknown key {key!r}; known keys are {sorted(ALL_KEYS)}")
        if self.mode == "self_supervised" and key in GROUND_TRUTH_KEYS:
            raise GroundTruthAccessError(
                f"{key!r} is ground truth; a self-supervised dataset exposes only {sorted(SELF_SUPERVISED_KEYS)}"
            )

    # ------------------------------------------------------------ structure

    def record(self, scene: str) -> dict:
        """``scene.json`` of a scene (cameras always; ground truth removed in self-supervised mode)."""
        if scene not in self._records:
            if scene not in self.scenes:
                raise ValueError(f"scene {scene!r} is not in the {self.split!r} split of {str(self.root)!r}")
            rec = io.read_json(self.root / scene / "scene.json")
            if self.mode == "self_supervised":
                rec = {"views": rec["views"], "index": rec["index"], "num_lights": len(rec["lights"])}
            self._records[scene] = rec
        return self._records[scene]

    def num_views(self, scene: str) -> int:
        return len(self.record(scene)["views"])

    def num_lights(self, scene: str) -> int:
        rec = self.record(scene)
        return rec["num_lights"] if "num_lights" in rec else len(rec["lights"])

    def photo_keys(self, scene: str) -> list[tuple[int, int]]:
        """Every photo of ``scene`` as ``(view, lighting)``, view-major (the interface photo collections
        share: :meth:`physrelight.collections.Collection.photo_keys`)."""
        return [(v, l) for v in range(self.num_views(scene)) for l in range(self.num_lights(scene))]

    def __len__(self) -> int:
        return len(self.items)

    def __iter__(self) -> Iterator[dict[str, Any]]:
        for i in range(len(self)):
            yield self[i]

    def __getitem__(self, i: int) -> dict[str, Any]:
        it = self.items[i]
        return {"scene": it.scene, "view": it.view, "light": it.light, **self.load(it.scene, it.view, it.light, self.keys)}

    # ------------------------------------------------------------ loading

    def load(self, scene: str, view: int, light: int | None = None, keys: tuple[str, ...] = ("photo",)) -> dict[str, Any]:
        """Load ``keys`` of one view (and lighting, for per-lighting keys).

        Returns numpy float32 images ``(H, W, C)`` / ``(H, W)``, ``K (3, 3)``,
        ``world_to_camera (4, 4)``, ``sh`` as ``{"2": (9, 3), "4": (25, 3)}`` in the view's
        camera frame, ``lighting`` as the scene.json entry, ``env`` as the sky map.
        """
        rec = self.record(scene)
        if not 0 <= view < len(rec["views"]):
            raise ValueError(f"view {view} out of range for {scene} ({len(rec['views'])} views)")
        vdir = self.root / scene / f"view_{view:02d}"
        out: dict[str, Any] = {}
        for key in keys:
            self._check_key(key)
            if key in ("K", "world_to_camera"):
                out[key] = np.asarray(rec["views"][view][key], dtype=np.float64)
            elif key in ("sky_mask", "glossy_mask"):
                out[key] = io.read_mask(vdir / f"{key}.png")
            elif key in _VIEW_FILES:
                out[key] = io.read_exr(vdir / _VIEW_FILES[key])
            else:
                if light is None or not 0 <= light < self.num_lights(scene):
                    raise ValueError(f"{key!r} needs a lighting index in [0, {self.num_lights(scene)}), got {light}")
                ldir = vdir / f"light_{light:02d}"
                if key == "photo":
                    out[key] = io.read_image(ldir / "photo.png")
                elif key in _LIGHT_FILES:
                    out[key] = io.read_exr(ldir / _LIGHT_FILES[key])
                elif key == "lighting":
                    out[key] = rec["lights"][light]
                elif key == "sh":
                    cams = rec["lights"][light]["sh"]["cameras"][view]
                    out[key] = {o: np.asarray(c, dtype=np.float64) for o, c in cams.items()}
                elif key == "env":
                    out[key] = io.read_exr(self.root / scene / "lights" / f"light_{light:02d}" / "env.exr")
                elif key == "photo_params":
                    out[key] = rec["photos"][view][light]
        return out

    def pairs(self, scene: str) -> list[tuple[int, int]]:
        """All ordered view pairs ``(a, b)``, ``a != b``, of a scene (for the multi-view losses)."""
        n = self.num_views(scene)
        return [(a, b) for a in range(n) for b in range(n) if a != b]


def to_chw(image: np.ndarray) -> torch.Tensor:
    """``(H, W, C)`` or ``(H, W)`` numpy -> torch ``(C, H, W)`` float32."""
    t = torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32))
    return t[None] if t.ndim == 2 else t.permute(2, 0, 1).contiguous()
