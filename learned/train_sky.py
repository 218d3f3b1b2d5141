"""Training, export and held-out measurement of SkyGAN and the sky segmenter.

``physrelight train sky --data DIR --out RUN`` and ``physrelight train segmentation --data
DIR --out RUN`` (see :mod:`learned.cli`). Both loops are, like :mod:`learned.train`:

* **seeded**: the networks are initialised from ``torch.manual_seed(seed)``; the photos,
  flips, augmentation and noise of step ``t`` are a pure function of ``(seed, t)``;
* **resumable to the same numbers**: a checkpoint (model, Adam state(s), RNG state)
  every ``ckpt_every`` steps; re-running the same command continues from the latest one
  and ends bit-identical to an uninterrupted run (``tests/learned/test_sky.py``);
* **logged**: ``train.csv``, ``val.csv`` (validation split), TensorBoard, PNG panels.

SkyGAN is *not* part of the self-supervised claim: it reads the photos' ground-truth SH
(``SynthDataset(mode="full")``, brought into the photo's units as ``sh * 2**ev *
wb_gains``, like :func:`learned.evaluate.load_ground_truth`). The segmenter uses the photo
and its sky mask only.

SkyGAN losses (generator ``G``, 2-scale PatchGAN ``D`` on the log composite, the mask and
the tiled SH): LSGAN, discriminator feature matching (weight ``fm``; stands in for the
paper's VGG perceptual loss: no pretrained VGG here) and an L1 between the 1/8-resolution
masked means of the generated and the real log sky (weight ``lowres``: it anchors the
sky's overall brightness, colour and gradient; the GAN terms supply the texture).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from physrelight import colour, io
from synth.dataset import SynthDataset, to_chw
from synth.photo import photo_gain

from . import checkpoint as ckpt
from .data import evenly_spread, load_photo
from .discriminators import MultiscaleDiscriminator, feature_matching_loss, lsgan_loss
from .networks import count_parameters
from .sky_gan import LOG_EPS, SkyGenerator, condition_map, generate_sky, lighting_scale
from .sky_segmentation import SkySegmenter, cloud_sky, dusk_sky, photometric_augment, segment_sky
from .runs import RunConfig, RunLogs, display

__all__ = ["RealCrops", "SkyTrainConfig", "SkyData", "evaluate_segmentation", "export_sky", "mirror_lighting",
           "sky_follows_lighting", "train_sky", "SKY_STAGES"]

SKY_STAGES = ("sky", "segmentation")
SKY_LOSS_WEIGHTS = {"gan": 1.0, "fm": 10.0, "lowres": 2.0}
# SH coefficients odd in camera x (Y11 ~ x, Y2-2 ~ xy, Y21 ~ xz): a horizontal flip negates them.
_ODD_IN_X = [3, 4, 7]


@dataclass
class SkyTrainConfig(RunConfig):
    """Everything that determines a SkyGAN or segmentation run (recorded in every checkpoint)."""

    stage: str
    data: str
    out: str
    val_data: str | None = None
    val_split: str = "val"
    train_split: str = "train"
    width: int = 8
    depth: int = 3
    res: int = 64
    batch: int = 8
    steps: int = 2000
    lr: float = 2e-4
    lr_d: float = 2e-4
    seed: int = 0
    z_dim: int = 16
    noise_channels: int = 4
    hidden: int = 16
    d_width: int = 16
    augment: bool = True
    wide_augment: bool = False
    dusk: bool = False
    clouds: bool = False
    real_panoramas: str | None = None
    real_exclude: tuple[str, ...] = ()
    real_fraction: float = 0.5
    real_views: int = 1024
    val_every: int = 250
    val_images: int = 96
    ckpt_every: int = 250
    log_every: int = 10
    threads: int = 1
    weights: dict[str, float] = field(default_factory=lambda: dict(SKY_LOSS_WEIGHTS))
    progress: bool = True

    def __post_init__(self) -> None:
        if self.stage not in SKY_STAGES:
            raise ValueError(f"stage must be one of {SKY_STAGES}, got {self.stage!r}")
        self.check_common(("width", "depth", "res", "batch", "steps", "z_dim", "noise_channels", "hidden",
                           "d_width", "val_every", "val_images", "ckpt_every", "log_every", "threads"),
                          ("lr", "lr_d"), SKY_LOSS_WEIGHTS)
        if self.res < 8:
            raise ValueError(f"res must be >= 8, got {self.res}")
        self.real_exclude = tuple(self.real_exclude)
        if self.real_panoramas is not None:
            if self.stage != "segmentation":
                raise ValueError("real panoramas train the segmenter only (stage 'segmentation')")
            if not (isinstance(self.real_fraction, (int, float)) and 0.0 < self.real_fraction <= 1.0):
                raise ValueError(f"real_fraction must be a number in (0, 1], got {self.real_fraction!r}")
        self.weights = {**SKY_LOSS_WEIGHTS, **self.weights}


# ------------------------------------------------------------------------- data


def mirror_lighting(lighting: torch.Tensor) -> torch.Tensor:
    """Camera-frame SH ``(..., 9, 3)`` of the horizontally mirrored view (x -> -x)."""
    out = lighting.clone()
    out[..., _ODD_IN_X, :] = -out[..., _ODD_IN_X, :]
    return out


class SkyData:
    """All photos of a split in memory: linearised image, sky mask, GT SH in photo units.

    Args:
        root: dataset folder.
        split: scene split.
        res: resolution.
        lighting: also read the ground-truth SH (``mode="full"``; SkyGAN only).
        max_images: keep at most this many photos, evenly spread (None: all).
        progress: a progress bar while loading.
        exclude_hdri: drop the photos lit by (and showing) these real panoramas (file stems).

    Attributes:
        image ``(N, 3, res, res)``, sky ``(N, 1, res, res)`` bool, lighting ``(N, 9, 3)``
        float32 (zeros without ``lighting``), items ``[(scene, view, light)]``.
    """

    def __init__(self, root: str | Path, split: str, res: int, lighting: bool, max_images: int | None = None,
                 progress: bool = False, exclude_hdri: tuple[str, ...] = ()) -> None:
        ds = SynthDataset(root, split=split, mode="full" if lighting else "self_supervised")
        items = ds.items
        if exclude_hdri:  # leave-one-panorama-out: no photo whose background is a left-out panorama
            items = [it for it in items if _hdri_name(Path(root), it.scene, it.light) not in exclude_hdri]
        if not items:
            raise ValueError(f"{str(root)!r} has no photos in split {split!r}")
        items = evenly_spread(items, max_images)
        from tqdm import tqdm

        images, skies, lights = [], [], []
        for it in tqdm(items, desc=f"load {Path(root).name}/{split}", disable=not progress, dynamic_ncols=True):
            p = load_photo(ds, it.scene, it.view, it.light, res)
            images.append(p["image"])
            skies.append(p["sky"])
            if lighting:
                gt = ds.load(it.scene, it.view, it.light, keys=("sh", "photo_params"))
                lights.append(torch.from_numpy(gt["sh"]["2"] * photo_gain(gt["photo_params"])[None, :]).float())
            else:
                lights.append(torch.zeros(9, 3))
        self.image, self.sky, self.lighting = torch.stack(images), torch.stack(skies), torch.stack(lights)
        self.items = [(it.scene, it.view, it.light) for it in items]
        self.ds, self.res = ds, res

    def __len__(self) -> int:
        return len(self.items)

    def batch(self, size: int, seed: int, step: int, flip: bool = True) -> tuple[torch.Tensor, ...]:
        """Photos of ``(seed, step)``: image, sky, lighting; half of them mirrored (SH mirrored too)."""
        rng = np.random.default_rng([seed, step, 7])
        idx = torch.from_numpy(rng.integers(len(self), size=size))
        image, sky, light = self.image[idx].clone(), self.sky[idx].clone(), self.lighting[idx].clone()
        if flip:
            mirror = torch.from_numpy(rng.random(size) < 0.5)
            image[mirror] = image[mirror].flip(-1)
            sky[mirror] = sky[mirror].flip(-1)
            light[mirror] = mirror_lighting(light[mirror])
        return image, sky, light


def _hdri_name(root: Path, scene: str, light: int) -> str | None:
    """The real panorama (file stem) lighting ``scene``'s lighting ``light``, or None for a sky model."""
    import json

    path = root / scene / "lights" / f"light_{light:02d}" / "lighting.json"
    if not path.is_file():
        return None
    return json.loads(path.read_text()).get("params", {}).get("hdri")


REAL_PITCH_RANGE = (-15.0, 30.0)
REAL_FOV_RANGE = (40.0, 80.0)
REAL_LOW_RES = (0.4, 0.9)


class RealCrops:
    """Random pinhole views of real HDR panoramas and their sky masks: real skies for the segmenter.

    ``views`` views are made once (a bank; a pure function of ``seed``): each draws a panorama
    in turn, a level camera with yaw ``U(0, 360)``, pitch ``U(-15, 30)`` and horizontal field of view
    ``U(40, 80)`` degrees (:data:`REAL_PITCH_RANGE`, :data:`REAL_FOV_RANGE`), is looked up at
    ``res x res`` (2 x 2 rays per pixel) and metered like a camera (log-average luminance to 0.18,
    :func:`synth.photo.metered_ev`); half of the views are looked up smaller (``U(0.4, 0.9) res``)
    and brought back bilinearly: small, soft photos too. The sky is the view of the panorama's
    sky mask (coverage > 1/2), as ``bench --real`` makes it. :meth:`batch` draws from the bank
    (half of them mirrored); the caller's photometric augmentation makes every draw another photo.

    Several folders (a sequence, or one string of paths joined by ``os.pathsep``, as ``--real-panoramas
    physrelight/data/hdri:physrelight/data/hdri_more`` gives it) pool their panoramas. Only maps with a reviewed
    mask (``NAME_sky.png`` beside them) are used: a room's empty mask makes its views no-sky negatives (the
    outdoor maps are the sky); a map without one (pm_forest, the walkway pm_bridge of hdri_more) is left out
    (:attr:`left_out`), not masked by the unreviewed procedure.

    Args:
        folder: a folder (or several, see above) of lat-long ``.exr`` panoramas with their ``NAME_sky.png`` masks.
        res: the views' size.
        exclude: panorama names (file stems) left out (leave-one-panorama-out runs).
        views: the bank's size.
        seed: the bank's cameras.

    Raises:
        ValueError: no panorama left, or one of them is a held-out panorama (never trained on).
    """

    def __init__(self, folder: str | Path | Sequence[str | Path], res: int, exclude: tuple[str, ...] = (),
                 views: int = 1024, seed: int = 0) -> None:
        import os

        from synth.panorama_crops import HELDOUT_DIR, load_panorama
        from synth.panorama_sky import mask_path

        folders = ([Path(f) for f in str(folder).split(os.pathsep)] if isinstance(folder, (str, Path))
                   else [Path(f) for f in folder])
        for d in folders:
            if not d.is_dir():
                raise ValueError(f"real panorama folder {str(d)!r} does not exist")
        if isinstance(views, bool) or not isinstance(views, int) or views < 1:
            raise ValueError(f"views must be a positive integer, got {views!r}")
        held = {p.stem for p in HELDOUT_DIR.glob("*.exr")}
        paths = [p for d in folders for p in sorted(d.glob("*.exr")) if p.stem not in exclude]
        bad = [p.name for p in paths if p.stem in held or p.resolve().parent == HELDOUT_DIR.resolve()]
        if bad:
            raise ValueError(f"{bad} are held-out panoramas: they are scored, never trained on")
        self.left_out = [p.stem for p in paths if not mask_path(p).is_file()]
        """Maps without a reviewed sky mask, left out (file stems)."""
        paths = [p for p in paths if mask_path(p).is_file()]
        if not paths:
            where = ", ".join(repr(str(d)) for d in folders)
            raise ValueError(f"no .exr panorama left in {where} with its NAME_sky.png mask "
                             f"(excluded: {list(exclude)}; without a mask: {self.left_out})")
        self.panoramas = [load_panorama(p, "training") for p in paths]
        self.res = res
        rng = np.random.default_rng([seed, 11])
        bank = [self.view(self.panoramas[k % len(self.panoramas)], rng) for k in range(views)]
        # float16 keeps the bank small; the metered radiance is far below its range
        self.image = torch.stack([b[0] for b in bank]).half()
        self.sky = torch.stack([b[1] for b in bank])

    def __len__(self) -> int:
        return self.image.shape[0]

    def view(self, pano: Any, rng: np.random.Generator) -> tuple[torch.Tensor, torch.Tensor]:
        """One random view of ``pano``: linear photo ``(3, res, res)`` (metered) and sky ``(1, res, res)`` bool."""
        from physrelight import panorama
        from synth.photo import metered_ev

        yaw, pitch = float(rng.uniform(0.0, 360.0)), float(rng.uniform(*REAL_PITCH_RANGE))
        fov = float(rng.uniform(*REAL_FOV_RANGE))
        n = self.res if rng.random() < 0.5 else max(8, round(self.res * float(rng.uniform(*REAL_LOW_RES))))
        K = panorama.view_intrinsics(fov, n, n)
        rays = panorama.camera_rays(K, panorama.level_camera(yaw, pitch), n, n, 2).to(torch.float32)
        rad = panorama.look_up(torch.from_numpy(pano.env), rays)
        cover = panorama.look_up(torch.from_numpy(pano.sky.astype(np.float32))[..., None], rays)[..., 0]
        image = rad.permute(2, 0, 1) * 2.0 ** metered_ev(rad.numpy())
        sky = cover[None]
        if n != self.res:
            image = F.interpolate(image[None], size=(self.res, self.res), mode="bilinear", align_corners=False)[0]
            sky = F.interpolate(sky[None], size=(self.res, self.res), mode="bilinear", align_corners=False)[0]
        return image.float(), sky > 0.5

    def batch(self, size: int, seed: int, step: int) -> tuple[torch.Tensor, torch.Tensor]:
        """``size`` views of ``(seed, step)``: ``(size, 3, res, res)`` linear, ``(size, 1, res, res)`` bool."""
        rng = np.random.default_rng([seed, step, 13])
        idx = torch.from_numpy(rng.integers(len(self), size=size))
        image, sky = self.image[idx].float(), self.sky[idx].clone()
        mirror = torch.from_numpy(rng.random(size) < 0.5)
        image[mirror] = image[mirror].flip(-1)
        sky[mirror] = sky[mirror].flip(-1)
        return image, sky


def _step_generator(seed: int, step: int, salt: int) -> torch.Generator:
    return torch.Generator().manual_seed(int(np.random.default_rng([seed, step, salt]).integers(2**62)))


# ------------------------------------------------------------------------- SkyGAN pieces


def _disc_input(log_image: torch.Tensor, cond: torch.Tensor) -> torch.Tensor:
    """D sees the log composite (3), the sky mask (1) and the tiled SH (27): a conditional GAN."""
    return torch.cat([log_image, cond[:, :1], cond[:, 6:]], 1)


def _lowres_mean(x: torch.Tensor, mask: torch.Tensor, factor: int = 8) -> tuple[torch.Tensor, torch.Tensor]:
    """Masked means of ``x`` over ``factor x factor`` cells and the cells' mask coverage."""
    m = mask.to(x.dtype)
    cover = F.avg_pool2d(m, factor, ceil_mode=True)
    mean = F.avg_pool2d(x * m, factor, ceil_mode=True) / cover.clamp_min(1e-6)
    return mean, cover


def sky_gan_losses(model: nn.ModuleDict, image: torch.Tensor, sky: torch.Tensor, lighting: torch.Tensor,
                   z: torch.Tensor, noise: torch.Tensor, weights: dict[str, float]) -> dict[str, torch.Tensor]:
    """Generator and discriminator losses of one batch.

    Args:
        model: ``{"g": SkyGenerator, "d": MultiscaleDiscriminator}``.
        image: ``(B, 3, H, W)`` linear photos (the real sky inside ``sky``).
        sky: ``(B, 1, H, W)`` bool.
        lighting: ``(B, 9, 3)`` SH in the photos' units.
        z, noise: the generator's noise (:func:`learned.sky_gan.sky_noise` shapes).
        weights: ``gan``, ``fm``, ``lowres``.

    Returns:
        ``g`` (total generator loss), ``d`` (discriminator loss on the detached fake) and the terms.
    """
    cond = condition_map(image, sky, lighting)
    s = lighting_scale(lighting)
    log_fake = model["g"](cond, z, noise)
    real_log = torch.log(image.clamp_min(0) / s + LOG_EPS)
    fake_log = torch.where(sky, torch.log(torch.exp(log_fake) + LOG_EPS), real_log)
    real_in, fake_in = _disc_input(real_log, cond), _disc_input(fake_log, cond)
    d_real, d_fake_det = model["d"](real_in), model["d"](fake_in.detach())
    d_loss = 0.5 * (lsgan_loss(d_real, True) + lsgan_loss(d_fake_det, False))
    d_fake = model["d"](fake_in)
    gan = lsgan_loss(d_fake, True)
    fm = feature_matching_loss(d_fake, d_real)
    mf, cover = _lowres_mean(fake_log, sky)
    mr, _ = _lowres_mean(real_log, sky)
    lowres = ((mf - mr).abs() * cover).sum() / (cover.sum() * 3).clamp_min(1e-6)
    g_loss = weights["gan"] * gan + weights["fm"] * fm + weights["lowres"] * lowres
    return {"g": g_loss, "d": d_loss, "g_gan": gan, "g_fm": fm, "g_lowres": lowres}


def build_sky_model(config: SkyTrainConfig) -> nn.ModuleDict:
    """The freshly initialised networks of a run, seeded by ``config.seed``: ``{"g", "d"}`` for SkyGAN, ``{"seg"}``
    for the segmenter."""
    torch.manual_seed(config.seed)
    if config.stage == "sky":
        g = SkyGenerator(config.width, config.z_dim, config.noise_channels, config.hidden)
        d = MultiscaleDiscriminator(31, config.d_width, 3, scales=2)
        return nn.ModuleDict({"g": g, "d": d})
    return nn.ModuleDict({"seg": SkySegmenter(config.width, config.depth, config.res)})


def _noise(model: nn.ModuleDict, b: int, h: int, w: int, gen: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    g = model["g"]
    return (torch.randn(b, g.z_dim, generator=gen),
            torch.randn(b, g.noise_channels, math.ceil(h / 8), math.ceil(w / 8), generator=gen))


# ------------------------------------------------------------------------- the loop


def train_sky(config: SkyTrainConfig) -> dict[str, Any]:
    """Run (or resume) a SkyGAN or segmentation run; return the last validation metrics and timings."""
    torch.set_num_threads(config.threads)
    run = Path(config.out)
    (run / "panels").mkdir(parents=True, exist_ok=True)
    model = build_sky_model(config)
    if config.stage == "sky":
        opt: dict[str, torch.optim.Optimizer] = {
            "g": torch.optim.Adam(model["g"].parameters(), lr=config.lr, betas=(0.5, 0.999)),
            "d": torch.optim.Adam(model["d"].parameters(), lr=config.lr_d, betas=(0.5, 0.999))}
    else:
        opt = {"seg": torch.optim.Adam(model.parameters(), lr=config.lr)}

    start, seconds = ckpt.resume(run, model, opt, config)
    if start >= config.steps:
        print(f"{run}: already at step {start} >= {config.steps}")
        return {"step": start, "train_seconds": seconds}

    lighting = config.stage == "sky"
    data = SkyData(config.data, config.train_split, config.res, lighting, progress=config.progress,
                   exclude_hdri=config.real_exclude)
    val = SkyData(config.val_data or config.data, config.val_split, config.res, lighting,
                  max_images=config.val_images)
    real = (RealCrops(config.real_panoramas, config.res, config.real_exclude, config.real_views, config.seed)
            if config.real_panoramas else None)
    n_real = 0 if real is None else max(1, round(config.batch * config.real_fraction))
    logs = RunLogs(run, start, True)
    if start == 0:
        io.write_json(run / "config.json", {**asdict(config), "parameters": {k: count_parameters(m) for k, m in
                                                                             model.items()}, "photos": len(data)})
    from tqdm import tqdm

    bar = tqdm(total=config.steps, initial=start, disable=not config.progress, dynamic_ncols=True,
               desc=f"train {config.stage}")
    metrics: dict[str, float] = {}
    model.train()
    for step in range(start, config.steps):
        t0 = time.perf_counter()
        if n_real:  # the real views replace part of the synthetic batch
            image, sky, light = data.batch(config.batch - n_real, config.seed, step)
            real_image, real_sky = real.batch(n_real, config.seed, step)
            image, sky = torch.cat([image, real_image]), torch.cat([sky, real_sky])
        else:
            image, sky, light = data.batch(config.batch, config.seed, step)
        if config.stage == "sky":
            z, noise = _noise(model, *image.shape[:1], *image.shape[-2:], _step_generator(config.seed, step, 1))
            losses = sky_gan_losses(model, image, sky, light, z, noise, config.weights)
            # D first on the detached fake, then G (D's graph for G's loss uses D's weights
            # before this step: both gradients are taken before either optimizer steps).
            opt["d"].zero_grad(set_to_none=True)
            opt["g"].zero_grad(set_to_none=True)
            d_grads = torch.autograd.grad(losses["d"], list(model["d"].parameters()))
            losses["g"].backward(inputs=list(model["g"].parameters()))
            for p, gr in zip(model["d"].parameters(), d_grads):
                p.grad = gr
            opt["d"].step()
            opt["g"].step()
            terms = {k: float(v.detach()) for k, v in losses.items()}
            shown = terms["g"]
        else:
            if config.augment:
                if config.clouds:  # its own stream: every other draw of the step is as without it
                    image = cloud_sky(image, sky, _step_generator(config.seed, step, 4))
                if config.wide_augment or config.dusk:
                    image = dusk_sky(image, sky, _step_generator(config.seed, step, 3))
                image = photometric_augment(image, _step_generator(config.seed, step, 2), wide=config.wide_augment)
            logits = model["seg"](image)
            loss = F.binary_cross_entropy_with_logits(logits, sky.float())
            opt["seg"].zero_grad(set_to_none=True)
            loss.backward()
            opt["seg"].step()
            terms = {"bce": float(loss.detach())}
            shown = terms["bce"]
        seconds += time.perf_counter() - t0
        done = step + 1
        bar.update(1)
        bar.set_postfix(loss=f"{shown:.4g}")
        if done % config.log_every == 0 or done == config.steps:
            logs.write("train.csv", done, {**terms, "seconds": seconds})
        if done % config.ckpt_every == 0 or done == config.steps:
            ckpt.save_checkpoint(run, done, model, opt, {"config": asdict(config), "train_seconds": seconds})
        if done % config.val_every == 0 or done == config.steps:
            model.eval()
            metrics = _validate(model, config, val, run / "panels" / f"step_{done:07d}.png")
            logs.write("val.csv", done, metrics)
            model.train()
    bar.close()
    logs.close()
    summary = {"step": config.steps, "train_seconds": seconds, "val": metrics,
               "parameters": {k: count_parameters(m) for k, m in model.items()}}
    io.write_json(run / "summary.json", summary)
    return summary


def _validate(model: nn.ModuleDict, config: SkyTrainConfig, val: SkyData, panel: Path) -> dict[str, float]:
    with torch.no_grad():
        if config.stage == "segmentation":
            pred = segment_sky(model["seg"], val.image)
            iou = _iou(pred, val.sky)
            _seg_panel(panel, val.image[:6], pred[:6], val.sky[:6])
            return {"iou_mean": float(np.nanmean(iou)), "iou_pooled": _pooled_iou(pred, val.sky)}
        g = model["g"]
        shuffled = val.lighting.roll(1, 0)
        out = {}
        for name, light in (("", val.lighting), ("shuffled_", shuffled)):
            gen = generate_sky(g, val.image, val.sky, light, seed=0)
            s = lighting_scale(light)
            a = torch.log(gen.clamp_min(0) / s + LOG_EPS)
            b = torch.log(val.image.clamp_min(0) / s + LOG_EPS)
            mf, cover = _lowres_mean(a, val.sky)
            mr, _ = _lowres_mean(b, val.sky)
            out[f"{name}lowres_l1"] = float(((mf - mr).abs() * cover).sum() / (cover.sum() * 3))
            if not name:
                rows = [val.image[:4], gen[:4], generate_sky(g, val.image[:4], val.sky[:4], val.lighting[:4], seed=1)]
            else:
                rows.append(gen[:4])
        _gan_panel(panel, rows)
        return out


def _iou(pred: torch.Tensor, gt: torch.Tensor) -> np.ndarray:
    """Per-image IoU of ``(B, 1, H, W)`` bool masks (NaN where both are empty)."""
    inter = (pred & gt).flatten(1).sum(1).double()
    union = (pred | gt).flatten(1).sum(1).double()
    return torch.where(union > 0, inter / union.clamp_min(1), torch.full_like(union, float("nan"))).numpy()


def _pooled_iou(pred: torch.Tensor, gt: torch.Tensor) -> float:
    return float((pred & gt).sum()) / max(float((pred | gt).sum()), 1.0)


def _seg_panel(path: Path, image: torch.Tensor, pred: torch.Tensor, gt: torch.Tensor) -> None:
    """Rows: photo | predicted mask | ground-truth mask."""
    rows = []
    for j in range(image.shape[0]):
        rows.append(np.concatenate([display(image[j]), np.repeat(pred[j].permute(1, 2, 0).float().numpy(), 3, -1),
                                    np.repeat(gt[j].permute(1, 2, 0).float().numpy(), 3, -1)], 1))
    io.write_png(path, np.concatenate(rows, 0))


def _gan_panel(path: Path, columns: list[torch.Tensor]) -> None:
    """Rows: photo | SkyGAN seed 0 | seed 1 | shuffled SH (all exposed as the photo)."""
    rows = [np.concatenate([display(c[j]) for c in columns], 1) for j in range(columns[0].shape[0])]
    io.write_png(path, np.concatenate(rows, 0))


# ------------------------------------------------------------------------- export


def export_sky(run: str | Path, dest: str | Path, average: tuple[int, int] | None = None) -> Path:
    """Export the latest checkpoint of a ``sky`` or ``segmentation`` run to ``dest`` (weights only).

    For SkyGAN only the generator is written (``g.*`` tensors, kind ``"sky_gan"``): the
    discriminator is needed for training only. The segmenter is kind ``"sky_segmentation"``;
    with ``average = (first, last)`` it is the uniform mean of the run's checkpoints of steps
    ``first..last`` (:func:`learned.checkpoint.export_weights`; the segmenter has no running
    statistics), which smooths the step-to-step wander of a run without a learning-rate schedule.
    """
    import json

    side = ckpt.latest_checkpoint(run)
    if side is None:
        raise ValueError(f"no checkpoint in {str(run)!r}")
    meta = json.loads(side.read_text())
    cfg = meta["config"]
    if average is not None and cfg.get("stage") != "segmentation":
        raise ValueError("averaged exports are for the segmenter only")
    if cfg.get("stage") == "segmentation":
        if average is None:
            return ckpt.export_weights(side, dest, "sky_segmentation")
        sides = ckpt.checkpoints_between(run, *average)
        return ckpt.export_weights(sides[-1], dest, "sky_segmentation", average=sides)
    if cfg.get("stage") != "sky":
        raise ValueError(f"{str(run)!r} is not a sky or segmentation run")
    return ckpt.export_weights(side, dest, "sky_gan", submodule="g", strip_submodule=False)


# ------------------------------------------------------------------------- held-out measurements


def _sky_stats(image: torch.Tensor, sky: torch.Tensor) -> np.ndarray:
    """Per image ``(N, 4)``: log mean sky luminance, log(mean B / mean R), and the slopes of
    log luminance along y (up) and x (right), image coordinates in [-1, 1] (least squares over
    sky pixels; NaN when the sky spans fewer than 2 rows/columns)."""
    out = []
    luma = image.new_tensor(colour.LUMINANCE).reshape(3, 1, 1)
    for x, m in zip(image.double(), sky):
        m = m[0]
        h, w = m.shape
        px = x[:, m].clamp_min(1e-6)
        mean = px.mean(1)
        lum = torch.log((x.clamp_min(1e-6) * luma.double()).sum(0)[m])
        ys, xs = torch.meshgrid(torch.linspace(1, -1, h, dtype=torch.float64),
                                torch.linspace(-1, 1, w, dtype=torch.float64), indexing="ij")
        slopes = []
        for c in (ys[m], xs[m]):
            c = c - c.mean()
            var = float((c * c).sum())
            slopes.append(float((c * (lum - lum.mean())).sum()) / var if var > 1e-9 and len(torch.unique(c)) > 1
                          else math.nan)
        lmean = float((mean * luma[:, 0, 0].double()).sum())
        out.append([math.log(lmean), math.log(float(mean[2]) / float(mean[0])), *slopes])
    return np.asarray(out)


_STAT_NAMES = ("log_brightness", "log_blue_over_red", "vertical_gradient", "horizontal_gradient")


def _compare(pred: np.ndarray, gt: np.ndarray) -> dict[str, dict[str, float]]:
    out = {}
    for k, name in enumerate(_STAT_NAMES):
        ok = np.isfinite(pred[:, k]) & np.isfinite(gt[:, k])
        p, g = pred[ok, k], gt[ok, k]
        r = float(np.corrcoef(p, g)[0, 1]) if ok.sum() > 2 and p.std() > 0 and g.std() > 0 else math.nan
        out[name] = {"pearson_r": r, "mean_abs_err": float(np.abs(p - g).mean()), "n": int(ok.sum())}
    return out


def _sh_features(lighting: torch.Tensor) -> np.ndarray:
    """``(N, 9, 3)`` -> ``(N, 4)`` SH-only predictors of the four sky statistics: log of the DC
    mean radiance ``s``, log(L00 blue / L00 red), and the luminance of the y (Y1-1) and x (Y11)
    terms over the DC's (light from above / from the right)."""
    luma = lighting.new_tensor(colour.LUMINANCE)
    lum = (lighting.double() * luma.double()).sum(-1)
    l00 = lighting[:, 0].double().clamp_min(1e-12)
    return torch.stack([torch.log(lighting_scale(lighting).flatten().double()), torch.log(l00[:, 2] / l00[:, 0]),
                        lum[:, 1] / lum[:, 0], lum[:, 3] / lum[:, 0]], 1).numpy()


def sky_follows_lighting(generator: SkyGenerator, root: str | Path, split: str = "all", res: int = 64,
                         seed: int = 0, max_images: int | None = None, panel: str | Path | None = None) -> dict[str, Any]:
    """Does the generated sky follow the SH it is given? Held-out figures (ground truth used for scoring only).

    For every photo (scene, view, lighting a) and the next lighting b of the same view:

    * ``same``: foreground = the linearised photo, SH = its own lighting a; reference = the
      path-traced radiance of a in the photo's units (``radiance * 2**ev_a * wb_a``, clipped
      at 1 like the photo's sensor).
    * ``relight``: the relighting case: foreground = path-traced radiance of b in a's units (an
      ideal relit foreground), SH = b's in a's units (the evaluation protocol); reference =
      that radiance's sky. Baseline ``keep_source_sky``: the photo's own sky (a), what a
      relighting without SkyGAN keeps.

    Each with the true SH (``conditioned``), with the SH of another photo (``shuffled``, a
    fixed derangement) and with that SH rescaled to the true DC luminance
    (``shuffled_same_dc``: the sky's scale ``s`` is then right, only the SH's shape and
    colour are wrong): if the SH drives the sky, conditioned beats both. Statistics
    per image: log mean sky luminance, log(B/R), vertical and horizontal log-luminance
    slopes; reported as Pearson r against the reference over images, and mean abs error.
    ``sh_feature_baseline``: the statistic read straight off the SH (:func:`_sh_features`), no network.

    ``panel``: also write a PNG, six photos with large skies, columns: photo | SkyGAN (own SH) |
    SkyGAN (seed + 1) | SkyGAN (another photo's SH) | path-traced lighting b | SkyGAN (b's
    foreground and SH), all in the photo's units through the sRGB curve, 2x nearest.
    """
    ds = SynthDataset(root, split=split, mode="full")
    items = ds.items
    items = evenly_spread(items, max_images)
    if len(items) < 3:
        raise ValueError(f"need at least 3 photos in {str(root)!r} split {split!r}, got {len(items)}")
    photos, skies, ref_a, ref_b, fg_b, light_a, light_b = [], [], [], [], [], [], []
    for it in items:
        p = load_photo(ds, it.scene, it.view, it.light, res)
        lb = (it.light + 1) % ds.num_lights(it.scene)
        gt_a = ds.load(it.scene, it.view, it.light, keys=("radiance", "sh", "photo_params"))
        gt_b = ds.load(it.scene, it.view, lb, keys=("radiance", "sh"))
        gain = photo_gain(gt_a["photo_params"])
        rad = []
        for g in (gt_a, gt_b):
            r = to_chw(g["radiance"] * gain[None, None, :].astype(np.float32))
            if r.shape[-1] != res:
                r = F.interpolate(r[None], size=(res, res), mode="area")[0]
            rad.append(r)
        photos.append(p["image"])
        skies.append(p["sky"])
        ref_a.append(rad[0].clamp(0, 1))
        ref_b.append(rad[1].clamp(0, 1))
        fg_b.append(rad[1])
        light_a.append(torch.from_numpy(gt_a["sh"]["2"] * gain[None, :]).float())
        light_b.append(torch.from_numpy(gt_b["sh"]["2"] * gain[None, :]).float())
    image, sky = torch.stack(photos), torch.stack(skies)
    la, lb_, fgb = torch.stack(light_a), torch.stack(light_b), torch.stack(fg_b)
    n = len(items)
    perm = np.random.default_rng(seed).permutation(n)
    derange = np.empty(n, dtype=int)
    derange[perm] = perm[np.r_[1:n, 0]]  # every photo gets another photo's SH
    generator = generator.eval()
    results: dict[str, Any] = {"images": n, "res": res, "seed": seed, "statistics": list(_STAT_NAMES)}
    for case, fg, light, ref in (("same", image, la, torch.stack(ref_a)), ("relight", fgb, lb_, torch.stack(ref_b))):
        ref_stats = _sky_stats(ref, sky)
        case_out: dict[str, Any] = {}
        other = light[torch.from_numpy(derange)]
        # The other photo's SH rescaled to this one's DC luminance: only its shape and colour differ,
        # so the brightness normalisation (s) cannot explain a difference.
        same_dc = other * (lighting_scale(light) / lighting_scale(other)).reshape(-1, 1, 1)
        for name, l in (("conditioned", light), ("shuffled", other), ("shuffled_same_dc", same_dc)):
            gen = generate_sky(generator, fg, sky, l, seed=seed)
            case_out[name] = _compare(_sky_stats(gen, sky), ref_stats)
        if case == "relight":
            case_out["keep_source_sky"] = _compare(_sky_stats(image, sky), ref_stats)
        # Reading the statistic straight off the SH (no network): Pearson r only, the scales differ.
        case_out["sh_feature_baseline"] = {k: {"pearson_r": v["pearson_r"], "n": v["n"]} for k, v in
                                           _compare(_sh_features(light), ref_stats).items()}
        results[case] = case_out
    if panel is not None:
        frac = sky.float().mean((1, 2, 3))
        pick = torch.argsort(frac, descending=True)[: max(6, n // 6)][:: max(1, max(6, n // 6) // 6)][:6]
        other = la[torch.from_numpy(derange)]
        cols = [image[pick], generate_sky(generator, image[pick], sky[pick], la[pick], seed=seed),
                generate_sky(generator, image[pick], sky[pick], la[pick], seed=seed + 1),
                generate_sky(generator, image[pick], sky[pick], other[pick], seed=seed),
                torch.stack(ref_b)[pick], generate_sky(generator, fgb[pick], sky[pick], lb_[pick], seed=seed)]
        rows = [np.concatenate([display(c[j]) for c in cols], 1) for j in range(len(pick))]
        grid = np.concatenate(rows, 0)
        io.write_png(panel, np.clip(grid.repeat(2, 0).repeat(2, 1), 0, 1))
    return results


def _fit_baselines(data: SkyData) -> dict[str, float]:
    """Fit the trivial baselines' single parameter on training photos (best mean IoU)."""
    h = data.res
    best_rows = max(range(0, h + 1), key=lambda k: np.nanmean(_iou(_top_rows(data.image, k), data.sky)))
    feat = _brightness(data.image)
    grid = np.linspace(0.05, 1.0, 39)
    best_t = max(grid, key=lambda t: np.nanmean(_iou(feat > t, data.sky)))
    return {"top_rows_fraction": best_rows / h, "brightness_threshold": float(best_t)}


def _top_rows(image: torch.Tensor, k: int) -> torch.Tensor:
    b, _, h, w = image.shape
    m = torch.zeros(b, 1, h, w, dtype=torch.bool)
    m[:, :, :k] = True
    return m


def _brightness(image: torch.Tensor) -> torch.Tensor:
    """Luminance over the image's 99th percentile luminance ``(B, 1, H, W)``."""
    lum = (image * image.new_tensor(colour.LUMINANCE).reshape(1, 3, 1, 1)).sum(1, keepdim=True)
    q = torch.quantile(lum.flatten(1), 0.99, dim=1).reshape(-1, 1, 1, 1).clamp_min(1e-6)
    return lum / q


def evaluate_segmentation(model: SkySegmenter, root: str | Path, split: str = "all", res: int = 64,
                          fit_root: str | Path | None = None, fit_split: str = "train",
                          fit_images: int = 300) -> dict[str, Any]:
    """Held-out sky IoU of the segmenter and of two trivial baselines.

    Baselines, each with one parameter fitted for the best mean IoU on ``fit_images``
    photos of ``fit_root``/``fit_split`` (the training data): *top rows* (the top ``k``
    rows are sky) and *brightness threshold* (luminance / the image's 99th percentile > t).
    IoU per image (mean over images) and pooled over all pixels. The segmenter also runs
    on photometrically augmented photos (seeded) to show its robustness.
    """
    data = SkyData(root, split, res, lighting=False)
    fit = _fit_baselines(SkyData(fit_root or root, fit_split, res, lighting=False, max_images=fit_images))
    model = model.eval()
    aug = photometric_augment(data.image, torch.Generator().manual_seed(1234))
    preds = {"network": segment_sky(model, data.image), "network_augmented_input": segment_sky(model, aug),
             "baseline_top_rows": _top_rows(data.image, round(fit["top_rows_fraction"] * res)),
             "baseline_brightness": _brightness(data.image) > fit["brightness_threshold"]}
    out: dict[str, Any] = {"images": len(data), "res": res, "fitted": fit, "sky_fraction": float(data.sky.float().mean())}
    for name, p in preds.items():
        out[name] = {"iou_mean": float(np.nanmean(_iou(p, data.sky))), "iou_pooled": _pooled_iou(p, data.sky),
                     "pixel_accuracy": float((p == data.sky).float().mean())}
    return out
