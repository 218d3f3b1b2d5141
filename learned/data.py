"""Training batches of photo pairs from the self-supervised loader.

Only what the paper may use goes in: photos, MVS-like depth, cameras (K, world_to_camera)
and sky masks, read through :class:`synth.dataset.SynthDataset` in
``mode="self_supervised"`` (which raises ``GroundTruthAccessError`` for anything else).

A pair is two photos of one scene: view a under lighting la and view b under lighting lb
(``(b, lb) != (a, la)``; b may equal a with another lighting). Photos are linearised with
:func:`physrelight.colour.from_ldr` (sRGB curve: the true response is unknown to the
learner) and resized to the training resolution (area averaging for photos, nearest for
depth and masks, intrinsics scaled to match).

The data may also be a real photo collection (a COLMAP workspace or MegaDepth, read by
:mod:`physrelight.collections`; :func:`open_training_data` finds the layout): it serves the same
five keys, its photos are centre-cropped to a square (:func:`crop_square`, the principal point moved
with it) before the resize, and photos without a sky mask get the shipped sky segmenter's
(:func:`learned.collection_sky.segmenter_sky_fn`, passed in by training; kept in memory).

Batches are a pure function of ``(seed, step, rank)`` (:meth:`PairSampler.batch`), so a
resumed or distributed run sees exactly the batches an uninterrupted one would.

Optional augmentation (``PairSampler(mirror=True)``): a pair is mirrored left-right as a whole
(:func:`mirror_view` on both photos), i.e. it becomes two photos of the mirror image of the
scene under the mirror image of its lighting. Photos, MVS depth, sky, intrinsics and poses stay
mutually consistent, so every multi-view term (warps, relative rotations of the lighting) holds
as before; it doubles the scene geometry a network sees (the held-out normal error of the
shipped networks is twice their error on the training scenes: they memorise geometry).

Optional augmentation (``PairSampler(degrade=True)``): the network sees each photo with a camera's
nuisances put back at the training resolution (:func:`degrade_photo`: sensor noise, 8-bit
quantisation, JPEG half the time, drawn as :func:`synth.photo.sample_photo_params` draws them),
while every loss and the lighting solve read the clean photo. A photo area-downsampled from a
higher-resolution set has half the native noise per halving and smoothed JPEG blocks; the held-out
photos do not, and fine-tuning on such native photos directly cost lighting accuracy
(docs/experiments/10-native-photos-e2-f-g.md, the eleventh to thirteenth rules). Clean targets, degraded inputs.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Sequence, TypeVar

import dataclasses

import numpy as np
import torch
import torch.nn.functional as F

from physrelight import camera, colour
from physrelight.full_resolution import resize_short_side  # the core's: the relighter's working size uses it too
from physrelight.collections import Collection, SkyFn, find_layout, open_collection
from synth.dataset import SynthDataset, to_chw
from synth.photo import PhotoParams, make_photo, sample_photo_params

__all__ = ["Batch", "PairSampler", "TrainingData", "check_under_ev", "crop_square", "data_notes", "degrade_photo",
           "evenly_spread", "list_scenes", "load_photo", "mirror_view", "open_training_data", "pooled_mvs_normals",
           "resize_short_side", "resize_view"]

TrainingData = SynthDataset | Collection

T = TypeVar("T")


def evenly_spread(items: Sequence[T], n: int | None) -> list[T]:
    """``n`` of ``items`` spread evenly from the first to the last (all of them when ``n`` is None or
    at least ``len(items)``): how evaluations cap their photos or cases without favouring the first
    scenes. Deterministic (no sampling), so a capped figure is reproducible."""
    if n is not None and n < 1:
        raise ValueError(f"n must be >= 1 or None, got {n!r}")
    if n is None or len(items) <= n:
        return list(items)
    return [items[i] for i in np.linspace(0, len(items) - 1, n).round().astype(int)]


@dataclass
class Batch:
    """A batch of ``B`` pairs; every tensor has the pair's views ``a`` then ``b`` stacked.

    Attributes:
        image: ``(2B, 3, H, W)`` linearised photos, rows ``[a_0..a_{B-1}, b_0..b_{B-1}]``.
        depth: ``(2B, 1, H, W)`` MVS-like z-depth (0 = missing).
        sky: ``(2B, 1, H, W)`` bool, True on sky.
        K: ``(2B, 3, 3)`` intrinsics at the training resolution.
        world_to_camera: ``(2B, 4, 4)``.
        keys: ``[(scene, view, light)]`` of the ``2B`` photos.
        mvs_normal, mvs_valid: ``(2B, 3, H, W)`` and ``(2B, 1, H, W)`` bool, the MVS normals taken at
            the dataset's own resolution and pooled to the training one
            (``PairSampler(mvs_pooled=True)``, :func:`pooled_mvs_normals`); None: :func:`mvs_normals`
            takes them from ``depth`` at the training resolution.
        network_image: ``(2B, 3, H, W)``, the photos the network sees (``PairSampler(degrade=True)``:
            :func:`degrade_photo` of ``image``); None: the network sees ``image``. The losses and the
            lighting solve always read ``image``.
    """

    image: torch.Tensor
    depth: torch.Tensor
    sky: torch.Tensor
    K: torch.Tensor
    world_to_camera: torch.Tensor
    keys: list[tuple[str, int, int]]
    mvs_normal: torch.Tensor | None = None
    mvs_valid: torch.Tensor | None = None
    network_image: torch.Tensor | None = None

    @property
    def pairs(self) -> int:
        return self.image.shape[0] // 2

    def partner(self, x: torch.Tensor) -> torch.Tensor:
        """Rows reordered so row i holds the other photo of row i's pair (``[b; a]``)."""
        n = self.pairs
        return torch.cat([x[n:], x[:n]], 0)


def resize_view(image: torch.Tensor, depth: torch.Tensor, sky: torch.Tensor, K: torch.Tensor,
                res: int) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """Resize one view to ``res x res``.

    Args:
        image: ``(3, H, W)``; depth ``(1, H, W)``; sky ``(1, H, W)`` bool; K ``(3, 3)``.
        res: output size (square; the source must be square too).

    Returns:
        The same four, at ``res``; K scaled by ``res / W`` (pixel centres stay centred:
        ``u' = u * res / W`` with corners at 0).
    """
    h, w = image.shape[-2:]
    if h != w:
        raise ValueError(f"only square images are supported, got {h}x{w}")
    if res == w:
        return image, depth, sky, K
    s = res / w
    img = F.interpolate(image[None], size=(res, res), mode="area" if res < w else "bilinear",
                        align_corners=None if res < w else False)[0]
    d = F.interpolate(depth[None], size=(res, res), mode="nearest")[0]
    m = F.interpolate(sky[None].float(), size=(res, res), mode="nearest")[0] > 0.5
    return img, d, m, camera.scale_intrinsics(K, s)


_MIRROR_X = torch.diag(torch.tensor([-1.0, 1.0, 1.0, 1.0]))


def mirror_view(image: torch.Tensor, depth: torch.Tensor, sky: torch.Tensor, K: torch.Tensor,
                world_to_camera: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor,
                                                        torch.Tensor]:
    """One view of the scene mirrored in the world's x = 0 plane, seen by the mirrored camera.

    Mirroring world and camera together (``M = diag(-1, 1, 1)`` on both sides) maps a camera
    point ``p`` to ``M p``: the image is flipped left-right (column ``j -> W - 1 - j``, i.e.
    ``u -> W - u``), z-depth is unchanged, ``cx -> W - cx`` and the skew changes sign,
    ``world_to_camera -> M T M`` (still a proper rigid transform). Normals, directions and SH
    lighting in the new camera frame are the old ones with x negated. Applying it to every
    photo of a pair keeps the pair consistent: relative poses become ``M T_ab M``.

    Args:
        image: ``(C, H, W)``; depth ``(1, H, W)``; sky ``(1, H, W)``; K ``(3, 3)``;
            world_to_camera ``(4, 4)``.

    Returns:
        The same five, mirrored (new tensors; the inputs are not modified).
    """
    if image.ndim != 3 or depth.ndim != 3 or sky.ndim != 3 or K.shape != (3, 3) or world_to_camera.shape != (4, 4):
        raise ValueError(f"mirror_view expects image (C, H, W), depth and sky (1, H, W), K (3, 3) and "
                         f"world_to_camera (4, 4); got {tuple(image.shape)}, {tuple(depth.shape)}, "
                         f"{tuple(sky.shape)}, {tuple(K.shape)}, {tuple(world_to_camera.shape)}")
    w = image.shape[-1]
    k = K.clone()
    k[0, 1] = -K[0, 1]
    k[0, 2] = w - K[0, 2]
    m = _MIRROR_X.to(world_to_camera.dtype)
    return (image.flip(-1), depth.flip(-1), sky.flip(-1), k, m @ world_to_camera @ m)


def pooled_mvs_normals(depth: torch.Tensor, K: torch.Tensor, res: int, stencil: str = "central"
                       ) -> tuple[torch.Tensor, torch.Tensor]:
    """MVS normals taken at the depth's own resolution, then area-pooled to ``res``.

    MVS runs on the full-size photos and the network on downsampled ones (the paper's setting):
    the simulator's holes are a fixed number of pixels wide and its noise is per pixel, so normals
    of the full-size depth, averaged over each training pixel, cover more of the foreground at the
    accuracy of the low resolution than normals of the depth resized first
    (docs/experiments/07-normal-upper-bound-and-mvs-coverage.md, "Would a higher resolution give
    more normal targets?").

    Args:
        depth: ``(1, S, S)`` MVS-like z-depth (0 = missing) at the dataset's resolution ``S``.
        K: ``(3, 3)`` intrinsics at that resolution.
        res: the training resolution; ``S`` must be a multiple of it.
        stencil: as in :func:`physrelight.camera.normals_from_depth`.

    Returns:
        ``(3, res, res)`` unit normals (0 where invalid) and ``(1, res, res)`` bool, valid where at
        least half of a pixel's ``(S / res)**2`` sub-pixels have an MVS normal. At ``S == res`` the
        normals of ``depth`` itself.
    """
    if depth.ndim != 3 or depth.shape[0] != 1 or depth.shape[1] != depth.shape[2]:
        raise ValueError(f"depth must have shape (1, S, S), got {tuple(depth.shape)}")
    size = depth.shape[-1]
    if not (isinstance(res, int) and res >= 1 and size % res == 0):
        raise ValueError(f"the depth's resolution {size} must be a multiple of res, got res={res!r}")
    n, ok = camera.normals_from_depth(depth[None], K[None], max_rel_jump=0.1, stencil=stencil)
    k = size // res
    if k > 1:
        ok_share = F.avg_pool2d(ok.to(n.dtype), k)
        n = F.normalize(F.avg_pool2d(n * ok, k), dim=1)
        ok = ok_share >= 0.5
        n = n * ok
    return n[0], ok[0]


def check_under_ev(value: float, name: str = "under_ev") -> None:
    """``ValueError`` naming ``name`` unless ``value`` is a number of stops in [0, 8] (a bool is not)."""
    if isinstance(value, bool) or not (isinstance(value, (int, float)) and 0 <= value <= 8):
        raise ValueError(f"{name} must be a number of stops in [0, 8], got {value!r}")


def degrade_photo(image: torch.Tensor, rng: np.random.Generator,
                  under_ev: float = 0.0) -> tuple[torch.Tensor, PhotoParams]:
    """A clean linear photo with a camera's nuisances put back at its own resolution.

    The nuisances are drawn by :func:`synth.photo.sample_photo_params` (sensor noise
    ``sigma ~ U(0, 0.01)`` in linear exposed units, JPEG at quality ``U{60..95}`` with probability
    1/2) and applied by :func:`synth.photo.make_photo` with no exposure, white balance or curve
    change (``ev = 0``, unit gains, the sRGB curve that :func:`load_photo` linearises with), so the
    result is re-encoded, quantised to 8 bits, compressed and linearised again as a native photo is.

    With ``under_ev > 0``, half the time the photo is first taken ``d ~ U(0, under_ev)`` stops under
    (``params.ev = -d``: noise and quantisation act on the dark signal, as the benchmark's dark-input
    stratum makes it) and brought back by ``2**d`` after linearising, as exposure metering
    (:func:`learned.networks.metered`) brings an under-exposed photo back before the network.

    Args:
        image: ``(3, H, W)`` linear photo in [0, 1] (as :func:`load_photo` gives it).
        rng: the generator the nuisances are drawn from (same state, same bytes).
        under_ev: the most stops of under-exposure drawn (0: none, and no extra draws, so the
            bytes are those of a call without it).

    Returns:
        ``(degraded, params)``: the degraded photo ``(3, H, W)`` float32 and what was applied.
    """
    if image.ndim != 3 or image.shape[0] != 3:
        raise ValueError(f"degrade_photo expects image (3, H, W), got {tuple(image.shape)}")
    check_under_ev(under_ev)
    hwc = image.detach().permute(1, 2, 0).double().numpy()
    drawn = sample_photo_params(rng, hwc)
    stops = 0.0
    if under_ev > 0 and rng.uniform() < 0.5:
        stops = float(rng.uniform(0.0, under_ev))
    params = dataclasses.replace(drawn, ev=-stops, wb_gains=(1.0, 1.0, 1.0), curve="srgb")
    u8 = make_photo(hwc, params, rng)
    linear = colour.from_ldr(u8)
    if stops:
        linear = linear * 2.0**stops
    return to_chw(linear).float(), params


def crop_square(image: torch.Tensor, depth: torch.Tensor, sky: torch.Tensor, K: torch.Tensor, mvs_scale: int = 1
                ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """The centred square of one view (a real photo is rarely square; the networks train on squares).

    Args:
        image: ``(C, H, W)``; depth ``(1, s H, s W)`` with ``s = mvs_scale``; sky ``(1, H, W)``; K ``(3, 3)``
            at the photo's resolution.

    Returns:
        The same four cropped to ``min(H, W)`` (depth to ``s`` times that), the principal point moved by
        the crop's offset (``cx - x0, cy - y0``); the inputs themselves when already square.
    """
    h, w = image.shape[-2:]
    if h == w:
        return image, depth, sky, K
    n = min(h, w)
    y0, x0 = (h - n) // 2, (w - n) // 2
    k = K.clone()
    k[0, 2] -= x0
    k[1, 2] -= y0
    s = mvs_scale
    return (image[..., y0:y0 + n, x0:x0 + n], depth[..., s * y0:s * (y0 + n), s * x0:s * (x0 + n)],
            sky[..., y0:y0 + n, x0:x0 + n], k)


def _scene_list(scenes: str | Sequence[str] | None) -> list[str] | None:
    if scenes is None:
        return None
    names = [s.strip() for s in scenes.split(",")] if isinstance(scenes, str) else [str(s) for s in scenes]
    if not names or not all(names):
        raise ValueError(f"scenes must name at least one scene, without empty names, got {scenes!r}")
    return names


def open_training_data(root: str | Path, split: str = "train", scenes: str | Sequence[str] | None = None,
                       sky_fn: SkyFn | None = None) -> TrainingData:
    """The self-supervised data in ``root``, whatever its layout (:func:`physrelight.collections.find_layout`):
    a synth set (:class:`synth.dataset.SynthDataset`, ``mode="self_supervised"``) or a photo collection
    (:class:`physrelight.collections.Collection`). Every file is checked here, before any run folder is made.

    Args:
        split: the scenes' split (by the hash of their names, the same rule for both); ignored when
            ``scenes`` names them.
        scenes: ``"a,b"`` or a list: only these scenes (an unknown name is a ``ValueError`` listing the known).
        sky_fn: for a collection's photos without a mask file, ``photo (H, W, 3) -> sky (H, W) bool``
            (training passes the shipped segmenter's, :func:`learned.collection_sky.segmenter_sky_fn`);
            None: no sky.
    """
    names = _scene_list(scenes)
    if find_layout(root) == "synth":
        ds = SynthDataset(root, split="all" if names else split, mode="self_supervised")
        if names:
            missing = [n for n in names if n not in ds.scenes]
            if missing:
                raise ValueError(f"{root}: no scene {', '.join(map(repr, missing))}; it has {', '.join(ds.scenes)}")
            ds.scenes = sorted(set(names))
            ds.items = [it for it in ds.items if it.scene in ds.scenes]
        return ds
    return open_collection(root, split, names, sky_fn)


def list_scenes(root: str | Path) -> list[str]:
    """Every scene name in ``root``, whatever its split (``physrelight train scenes``)."""
    if find_layout(root) == "synth":
        return SynthDataset(root, split="all", mode="self_supervised").scenes
    return open_collection(root, "all", validate=False).all_scenes


def data_notes(ds: TrainingData) -> list[str]:
    """One line per fact a training log should hold about its data: layout, scenes, photos, and for a
    collection the photos skipped (no pose, no depth) and where each scene's sky comes from."""
    if isinstance(ds, SynthDataset):
        n = sum(ds.num_views(s) * ds.num_lights(s) for s in ds.scenes)
        return [f"data: synth set {ds.root}, {len(ds.scenes)} scenes, {n} photos"]
    lines = [f"data: {ds.layout} collection {ds.root}, {len(ds.scenes)} scenes, {len(ds)} photos"]
    sky = ds.sky_sources()
    for s, skipped in ds.skipped().items():
        lines.append(f"data: {s}: {len(ds.photo_keys(s)) if s in ds.scenes else 0} photos, skipped "
                     f"{skipped.get('no pose', 0)} without a pose and {skipped.get('no depth', 0)} without depth; "
                     f"sky from {_SKY_WORDS.get(sky.get(s, 'none'), sky.get(s, 'none'))}")
    return lines


_SKY_WORDS = {"masks": "masks/ (COLMAP's mask convention, black = sky)",
              "segmenter": "the shipped sky segmenter (kept in memory)", "none": "nowhere (no sky)",
              "masks+segmenter": "masks/ where there, else the shipped sky segmenter (kept in memory)"}


def load_photo(ds: TrainingData, scene: str, view: int, light: int, res: int,
               mvs_pooled: bool = False, stencil: str = "central") -> dict[str, torch.Tensor]:
    """One photo and its view data, linearised and resized (self-supervised keys only); with
    ``mvs_pooled`` also ``"mvs_normal"`` / ``"mvs_valid"`` from :func:`pooled_mvs_normals`, taken at
    the MVS depth's own resolution (``ds.mvs_scale`` times the photo's).

    A set written with ``--mvs-scale s`` has its depth brought to the photo's size by nearest
    sampling first (sub-pixel ``(s i, s j)``, as :func:`resize_view` samples any depth it shrinks), so
    ``"depth"`` always matches ``"image"`` and ``"K"``."""
    item = ds.load(scene, view, light, keys=("photo", "mvs_depth", "sky_mask", "K", "world_to_camera"))
    image = to_chw(colour.from_ldr(np.clip(item["photo"], 0.0, 1.0)))
    depth = to_chw(item["mvs_depth"])
    sky = to_chw(item["sky_mask"].astype(np.float32)) > 0.5
    K = torch.from_numpy(item["K"]).float()
    if depth.shape[-2:] != tuple(s * ds.mvs_scale for s in image.shape[-2:]):
        raise ValueError(f"{scene} view {view}: mvs_depth is {tuple(depth.shape[-2:])}, expected the photo's "
                         f"{tuple(image.shape[-2:])} times the set's mvs_scale {ds.mvs_scale}")
    image, depth, sky, K = crop_square(image, depth, sky, K, ds.mvs_scale)  # a collection's photos; synth's are square
    extra = {}
    if mvs_pooled:
        extra["mvs_normal"], extra["mvs_valid"] = pooled_mvs_normals(depth, camera.scale_intrinsics(K, ds.mvs_scale),
                                                                     res, stencil)
    if ds.mvs_scale > 1:
        depth = F.interpolate(depth[None], size=tuple(image.shape[-2:]), mode="nearest")[0]
    image, depth, sky, K = resize_view(image, depth, sky, K, res)
    return {"image": image, "depth": depth, "sky": sky, "K": K,
            "world_to_camera": torch.from_numpy(item["world_to_camera"]).float(), **extra}


class PairSampler:
    """Deterministic batches of photo pairs from a dataset's training scenes.

    Args:
        root: dataset folder.
        split: scene split to draw from ("train" for training).
        res: training resolution.
        seed: base seed.
        cache: keep loaded photos in memory (a 64-px photo with its depth is ~65 kB).
        mirror: mirror each pair left-right with probability 1/2 (:func:`mirror_view`); the
            choice is a pure function of ``(seed, step, rank)`` like the pairs, drawn from its own
            stream, so the pairs are those of an unmirrored sampler.
        mvs_pooled: batches carry MVS normals taken at the MVS depth's resolution (the dataset's times
            its ``mvs_scale``) and pooled to ``res`` (:func:`pooled_mvs_normals`, with ``stencil``); that
            resolution must be a multiple of ``res``.
        degrade: batches carry ``network_image``, each photo through :func:`degrade_photo` (after any
            mirroring), drawn from a stream of ``(seed, step, rank)`` of its own; ``image`` stays clean.
        degrade_under_ev: :func:`degrade_photo`'s ``under_ev`` (needs ``degrade``).
        scenes: only these scenes (``"a,b"`` or a list; the split is then ignored), see
            :func:`open_training_data`.
        data: an already opened dataset to draw from (``root``, ``split`` and ``scenes`` are then unused).

    ``root`` may be a synth set or a photo collection (:func:`open_training_data`); the pairs are drawn
    from each scene's :meth:`photo_keys`, so a synth set exported to a collection gives the same batches.
    """

    def __init__(self, root: str | Path, split: str = "train", res: int = 64, seed: int = 0,
                 cache: bool = True, mirror: bool = False, mvs_pooled: bool = False,
                 stencil: str = "central", degrade: bool = False, degrade_under_ev: float = 0.0,
                 scenes: str | Sequence[str] | None = None, data: TrainingData | None = None) -> None:
        if not (isinstance(res, int) and res >= 8):
            raise ValueError(f"res must be an integer >= 8, got {res!r}")
        self.ds = data if data is not None else open_training_data(root, split, scenes)
        if not self.ds.scenes:
            hint = "; name scenes with --scenes or use --train-split all" if isinstance(self.ds, Collection) else ""
            raise ValueError(f"{str(root)!r} has no scenes in split {split!r}{hint}")
        self.res, self.seed, self.cache, self.mirror = res, seed, cache, bool(mirror)
        self.mvs_pooled, self.stencil, self.degrade = bool(mvs_pooled), stencil, bool(degrade)
        check_under_ev(degrade_under_ev, "degrade_under_ev")
        if degrade_under_ev and not self.degrade:
            raise ValueError("degrade_under_ev needs degrade=True (it is one of degrade_photo's nuisances)")
        self.degrade_under_ev = degrade_under_ev
        if self.mvs_pooled and "res" not in self.ds.config:
            raise ValueError("mvs_pooled needs photos of one size; this collection's differ")
        depth_res = int(self.ds.config.get("res", res)) * self.ds.mvs_scale
        if self.mvs_pooled and depth_res % res:
            raise ValueError(f"mvs_pooled needs the MVS depth's resolution ({depth_res}: the dataset's "
                             f"{self.ds.config['res']} x mvs_scale {self.ds.mvs_scale}) to be a multiple of res ({res})")
        self._cache: dict[tuple[str, int, int], dict[str, torch.Tensor]] = {}
        self.scenes = self.ds.scenes
        self._photo_keys = {s: self.ds.photo_keys(s) for s in self.scenes}
        for s in self.scenes:
            if len(self._photo_keys[s]) < 2:
                raise ValueError(f"scene {s} has a single photo; pairs need at least two")

    def photo(self, key: tuple[str, int, int]) -> dict[str, torch.Tensor]:
        if key in self._cache:
            return self._cache[key]
        p = load_photo(self.ds, *key, res=self.res, mvs_pooled=self.mvs_pooled, stencil=self.stencil)
        if self.cache:
            self._cache[key] = p
        return p

    def pair_keys(self, batch_size: int, step: int, rank: int = 0) -> list[tuple[tuple, tuple]]:
        """The ``batch_size`` pairs of ``(step, rank)``: same arguments, same pairs."""
        rng = np.random.default_rng([self.seed, step, rank])
        out = []
        for _ in range(batch_size):
            s = self.scenes[int(rng.integers(len(self.scenes)))]
            photos = self._photo_keys[s]  # (view, lighting), view-major: a synth set's v * nl + l
            n = len(photos)
            a = int(rng.integers(n))
            b = (a + 1 + int(rng.integers(n - 1))) % n  # any other photo of the scene
            out.append(((s, *photos[a]), (s, *photos[b])))
        return out

    def mirrored_pairs(self, batch_size: int, step: int, rank: int = 0) -> list[bool]:
        """Which of the ``batch_size`` pairs of ``(step, rank)`` are mirrored (all False unless ``mirror``)."""
        if not self.mirror:
            return [False] * batch_size
        rng = np.random.default_rng([self.seed, step, rank, 1])  # its own stream: the pairs stay as they are
        return [bool(f) for f in rng.random(batch_size) < 0.5]

    def batch(self, batch_size: int, step: int, rank: int = 0) -> Batch:
        """A :class:`Batch` of ``batch_size`` pairs for ``(step, rank)``."""
        if not (isinstance(batch_size, int) and batch_size >= 1):
            raise ValueError(f"batch_size must be a positive integer, got {batch_size!r}")
        pairs = self.pair_keys(batch_size, step, rank)
        keys = [p[0] for p in pairs] + [p[1] for p in pairs]
        items = [self.photo(k) for k in keys]
        flips = self.mirrored_pairs(batch_size, step, rank) * 2  # both photos of a pair together
        items = [_mirrored(it) if f else it for it, f in zip(items, flips)]
        stack = {name: torch.stack([it[name] for it in items]) for name in items[0]}
        network_image = None
        if self.degrade:
            rng = np.random.default_rng([self.seed, step, rank, 2])  # its own stream, like the mirroring's
            network_image = torch.stack([degrade_photo(im, rng, self.degrade_under_ev)[0] for im in stack["image"]])
        return Batch(image=stack["image"], depth=stack["depth"], sky=stack["sky"], K=stack["K"],
                     world_to_camera=stack["world_to_camera"], keys=keys, mvs_normal=stack.get("mvs_normal"),
                     mvs_valid=stack.get("mvs_valid"), network_image=network_image)


_VIEW_KEYS = ("image", "depth", "sky", "K", "world_to_camera")


def _mirrored(photo: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """:func:`mirror_view` of one loaded photo, its pooled MVS normals (if any) mirrored with it."""
    out = dict(zip(_VIEW_KEYS, mirror_view(*(photo[n] for n in _VIEW_KEYS))))
    if "mvs_normal" in photo:
        flip_x = photo["mvs_normal"].new_tensor([-1.0, 1.0, 1.0])[:, None, None]
        out["mvs_normal"] = photo["mvs_normal"].flip(-1) * flip_x
        out["mvs_valid"] = photo["mvs_valid"].flip(-1)
    return out


def mvs_normals(batch: Batch, stencil: str = "central") -> tuple[torch.Tensor, torch.Tensor]:
    """Normals of the MVS-like depth ``(2B, 3, H, W)`` and where they are valid ``(2B, 1, H, W)`` bool.

    Depth edges (relative jump > 10 %) and sky are excluded. ``stencil``: ``"central"`` or
    ``"one_sided"`` (normals next to holes and edges too, see
    :func:`physrelight.camera.normals_from_depth`).
    """
    if batch.mvs_normal is not None:  # taken at the dataset's resolution (PairSampler(mvs_pooled=True))
        return batch.mvs_normal, batch.mvs_valid & ~batch.sky
    n, valid = camera.normals_from_depth(batch.depth, batch.K, max_rel_jump=0.1, stencil=stencil)
    return n, valid & ~batch.sky
