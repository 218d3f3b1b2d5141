"""Validation of the first stage against ground truth (never used for training).

Metrics, each next to a trivial baseline:

* **albedo si-MSE**: per image, the prediction is scaled by the least-squares scalar
  ``alpha = <p, g> / <p, p>`` over foreground pixels and channels (the albedo/lighting
  scale is ambiguous from one photo), then the MSE; mean over images.
  Baseline: the linearised photo as albedo. Reference (``oracle_albedo_si_mse``): the photo
  divided by its true shading and true direct-light ratio, ``i / (s shading(n; L))`` clipped to
  [0, 1]: what the image model itself allows, given a perfect decomposition of everything else
  (clipping, noise, JPEG, interreflections and the order-2 truncation remain). Where the
  network's albedo error comes from, a ladder of image-model albedos ``i / (s shading(n; L))``
  clipped to [0, 1]: from the network's own ``n, L, s`` (``implied_albedo_si_mse``), with the
  true lighting in place of its own (``..._true_lighting``), with true lighting and normals
  (``..._true_normals_lighting``), and with everything true (the reference above).
* **normal MAE**: mean angular error in degrees over foreground pixels (mean per image,
  then over images). Baseline: the camera-facing constant ``(0, 0, 1)``. Where it fails:
  the median over all foreground pixels, and the MAE split by whether the MVS-like depth
  gives a normal there (the pixels the normal loss supervises) or not, and by whether the
  true surface faces up (within 10 deg of the world's +Y: ground, tops) or not (per image,
  then over the images that have such pixels).
* **shadow AP**: average precision of ``1 - s`` for detecting shadowed pixels
  (ground-truth ``s < 0.5``), pooled over all foreground pixels. Baseline: no shadow
  (a constant score), whose AP is the fraction of shadowed pixels (chance). Reference
  (``oracle_shadow_ap``): the shadow the image model implies given everything else true,
  ``s = mean_c i / (albedo * shading(n; L))``: how much a perfect decomposition could find.
* **lighting relative error**: ``||L - L_gt|| / ||L_gt||`` (27-D) with ``L_gt`` the true
  camera-frame SH in the photo's units (true SH times ``2**ev`` times the white-balance
  gains of the photo), raw and scale-invariant (``L`` scaled by its optimal scalar, since
  albedo and lighting trade a global scale). Baseline: the prior's mean lighting.
* **lighting shading error**: what the lighting does to this photo: the scale-invariant
  relative error of ``shading(n; L)`` against ``shading(n; L_gt)`` on the photo's true
  foreground normals. The coefficient error above also counts directions no pixel of the
  photo faces, which no solve can see (a solve with the *true* albedo, normals and shadow is
  further from ``L_gt`` in coefficients than the prior's mean); this one does not. Baseline:
  the prior's mean; reference (``oracle_``): the pipeline's own solve and projection
  (:func:`learned.objectives.solve_projected`) fed the true albedo, normals and sun visibility,
  i.e. the best a perfect network could get from this lighting step, (``oracle_map_``) the
  MAP solve in the prior's subspace (:func:`physrelight.image_model.solve_lighting_map`) fed
  the same, and (``oracle_map_relative_``) its exposure-equivariant form (``relative=True``, the
  shipped network's ``map_relative`` step) fed the same.

* **level error** (``level_err_stops``): every metric above is blind to the one scale that albedo
  and lighting share, but a relit photo is not: the relighter brings the target lighting into the
  decomposition's units by its DC level (:func:`physrelight.exposure.match_exposure`), so the relit
  photo's brightness follows the level of albedo x lighting, ``mean_fg lum(albedo) * lum(DC of L)``,
  against the truth's in photo units. Per photo ``|log2(level / level_gt)|`` in stops, clipped at 10
  (:func:`level_log2_ratio`; ``level_log2_ratio`` is its signed mean: + = too bright). Invariant to
  the ambiguity (``k albedo, L / k``); baseline: the linearised photo with the prior's mean.

Ground truth is read with ``SynthDataset(mode="full")``; photos go through the same
linearisation as in training.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Callable

import numpy as np
import torch
import torch.nn.functional as F

from physrelight import camera, colour, image_model
from physrelight.lighting_prior import LightingPrior
from physrelight.stats import paired_bootstrap
from synth.dataset import SynthDataset, to_chw
from synth.photo import photo_gain

from .data import evenly_spread, load_photo
from .objectives import solve_projected

if TYPE_CHECKING:  # for the annotation only: evaluation does not load weights
    from .relighter import Relighter

__all__ = ["PER_IMAGE_METRICS", "average_precision", "compare_decompositions", "evaluate", "evaluate_relighter",
           "level_log2_ratio", "load_ground_truth", "normal_angle_deg", "scene_intervals", "shading_error", "si_mse"]

#: The per-photo metrics :func:`evaluate` can return one value per photo of (means over photos;
#: shadow AP is pooled over pixels, so it has no per-photo value).
PER_IMAGE_METRICS = ("normal_mae_deg", "albedo_si_mse", "lighting_shading_err", "lighting_si_rel_err",
                     "level_err_stops")


def si_mse(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> float:
    """Scale-invariant MSE of ``(3, H, W)`` images over ``mask (1, H, W)`` (bool)."""
    m = mask.expand_as(pred)
    p, g = pred[m].double(), target[m].double()
    if p.numel() == 0:
        raise ValueError("si_mse: empty mask")
    alpha = float((p * g).sum() / (p * p).sum().clamp_min(1e-12))
    return float(((alpha * p - g) ** 2).mean())


def _angle_map_deg(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """``(1, H, W)`` angle in degrees between ``(3, H, W)`` normals, pixel by pixel."""
    cos = (F.normalize(pred.double(), dim=0) * F.normalize(target.double(), dim=0)).sum(0, keepdim=True)
    return torch.rad2deg(torch.acos(cos.clamp(-1.0, 1.0)))


def _masked_mean(values: torch.Tensor, mask: torch.Tensor, name: str) -> float:
    picked = values[mask].numpy()
    if picked.size == 0:
        raise ValueError(f"{name}: empty mask")
    return float(picked.mean())


def normal_angle_deg(pred: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> float:
    """Mean angle in degrees between ``(3, H, W)`` unit normals over ``mask (1, H, W)``."""
    return _masked_mean(_angle_map_deg(pred, target), mask, "normal_angle_deg")


def average_precision(scores: np.ndarray, labels: np.ndarray) -> float:
    """Average precision ``sum_n (R_n - R_{n-1}) P_n`` over distinct score thresholds.

    Tied scores form one threshold, so a constant score gives the positive rate.
    """
    scores, labels = np.asarray(scores, dtype=np.float64).ravel(), np.asarray(labels, dtype=bool).ravel()
    if scores.shape != labels.shape:
        raise ValueError(f"scores {scores.shape} and labels {labels.shape} differ")
    npos = int(labels.sum())
    if npos == 0:
        return float("nan")
    order = np.argsort(-scores, kind="mergesort")
    s, y = scores[order], labels[order]
    tp, fp = np.cumsum(y), np.cumsum(~y)
    last = np.r_[np.nonzero(np.diff(s))[0], s.size - 1]  # last index of each distinct score
    precision = tp[last] / (tp[last] + fp[last])
    recall = tp[last] / npos
    return float(np.sum(np.diff(np.r_[0.0, recall]) * precision))


def shading_error(lighting: torch.Tensor, target: torch.Tensor, normals: torch.Tensor, mask: torch.Tensor) -> float:
    """Scale-invariant relative error of ``shading(n; lighting)`` vs ``shading(n; target)``
    (both ``(9, 3)``) over the unit ``normals (3, H, W)`` where ``mask (1, H, W)``."""
    n = F.normalize(normals.double(), dim=0)[:, mask[0]][None, :, :, None]  # (1, 3, P, 1)
    if n.shape[2] == 0:
        raise ValueError("shading_error: empty mask")
    a = image_model.shading(n, lighting.double()[None]).reshape(-1)
    b = image_model.shading(n, target.double()[None]).reshape(-1)
    alpha = float((a @ b) / (a @ a).clamp_min(1e-30))
    return float((alpha * a - b).norm() / b.norm().clamp_min(1e-30))


def level_log2_ratio(albedo: torch.Tensor, lighting: torch.Tensor, true_albedo: torch.Tensor,
                     true_lighting: torch.Tensor, mask: torch.Tensor, clip_stops: float = 10.0) -> float:
    """``log2`` of the level of albedo x lighting against the truth's, in stops (+ = too bright).

    The level is ``mean over mask of lum(albedo) * lum(DC of lighting)``: the one scale that a
    photo leaves free between albedo and lighting cancels in it, so it measures the product that
    a relight by DC level (:func:`physrelight.exposure.match_exposure`) carries into its output.

    Args:
        albedo, true_albedo: ``(3, H, W)``.
        lighting, true_lighting: ``(9, 3)`` radiance SH, the truth in the photo's units.
        mask: ``(1, H, W)`` bool, the foreground.
        clip_stops: the ratio is clipped to ``[-clip_stops, clip_stops]``; an estimate with no
            positive level (a lighting whose DC is not positive, as an untrained network can give)
            counts as ``-clip_stops``, so one such photo weighs a bounded amount in a mean.

    Raises:
        ValueError: an empty mask, or a true level that is not positive.
    """
    from physrelight.exposure import dc_luminance  # the DC level the relighter matches by

    if not bool(mask.any()):
        raise ValueError("level_log2_ratio: empty mask")
    lum = torch.tensor(colour.LUMINANCE, dtype=torch.float64)

    def level(a: torch.Tensor, light: torch.Tensor) -> float:
        return float((a.double()[:, mask[0]] * lum[:, None]).sum(0).mean() * dc_luminance(light.double()[None])[0])

    est, true = level(albedo, lighting), level(true_albedo, true_lighting)
    if not true > 0:
        raise ValueError(f"level_log2_ratio: the true level must be positive, got {true!r}")
    if not est > 0:
        return -clip_stops
    return min(max(math.log2(est / true), -clip_stops), clip_stops)


def _lighting_errors(pred: torch.Tensor, gt: torch.Tensor) -> tuple[float, float]:
    p, g = pred.double().reshape(-1), gt.double().reshape(-1)
    raw = float((p - g).norm() / g.norm())
    alpha = float((p @ g) / (p @ p).clamp_min(1e-30))
    return raw, float((alpha * p - g).norm() / g.norm())


def load_ground_truth(ds: SynthDataset, scene: str, view: int, light: int, res: int) -> dict[str, torch.Tensor]:
    """Ground truth of one photo at ``res``: albedo, normals, shadow (sun visibility), direct_shadow
    (the direct-light ratio, the quantity the image model's ``s`` stands for), lighting in photo units."""
    gt = ds.load(scene, view, light, keys=("albedo", "normal", "shadow", "direct_shadow", "sh", "photo_params"))
    albedo, normal, shadow = to_chw(gt["albedo"]), to_chw(gt["normal"]), to_chw(gt["shadow"])
    direct = to_chw(gt["direct_shadow"])
    if albedo.shape[-1] != res:
        albedo = F.interpolate(albedo[None], size=(res, res), mode="area")[0]
        shadow = F.interpolate(shadow[None], size=(res, res), mode="area")[0]
        direct = F.interpolate(direct[None], size=(res, res), mode="area")[0]
        normal = F.interpolate(normal[None], size=(res, res), mode="nearest")[0]
    lighting = torch.from_numpy(gt["sh"]["2"] * photo_gain(gt["photo_params"])[None, :])
    return {"albedo": albedo, "normal": normal, "shadow": shadow, "direct_shadow": direct, "lighting": lighting}


def evaluate(decompose: Callable[[torch.Tensor, torch.Tensor], dict[str, torch.Tensor]], root: str | Path,
             split: str, res: int, prior: LightingPrior, max_images: int | None = None,
             shadow_fn: Callable[[dict[str, torch.Tensor]], torch.Tensor] | None = None,
             batch_size: int = 16, return_per_image: bool = False
             ) -> dict[str, float] | tuple[dict[str, float], dict[str, np.ndarray]]:
    """Metrics of a decomposition on a dataset split, with the trivial baselines.

    Args:
        decompose: ``(image (B, 3, H, W), sky (B, 1, H, W) bool) -> {"albedo", "normals",
            "shadow", "lighting" (B, 9, 3)}``.
        root, split: dataset and split (held-out scenes).
        res: resolution the network runs at.
        prior: gives the lighting baseline (its mean).
        max_images: evaluate at most this many photos (evenly spread), None = all.
        shadow_fn: optional second shadow predictor (ShadowNet) on the decomposition;
            reported as ``shadownet_ap``.
        return_per_image: also return, per evaluated photo, ``"scene"`` (its scene name) and
            each of :data:`PER_IMAGE_METRICS` and their ``baseline_`` versions, ``(N,)`` arrays
            whose means are the reported figures (for :func:`scene_intervals` and
            :func:`compare_decompositions`).

    Returns:
        Flat dict: ``albedo_si_mse``, ``normal_mae_deg`` (and ``normal_median_deg``,
        ``normal_mae_deg_mvs`` / ``_no_mvs``, ``normal_mae_deg_up`` / ``_not_up``), ``shadow_ap`` (labels: sun visibility
        < 0.5), ``shadow_ap_direct`` (labels: direct-light ratio < 0.5),
        ``lighting_rel_err``, ``lighting_si_rel_err``, ``lighting_shading_err`` (and
        ``oracle_lighting_shading_err``, ``oracle_map_lighting_shading_err``,
        ``oracle_map_relative_lighting_shading_err``), ``oracle_albedo_si_mse``,
        ``oracle_shadow_ap``, ``oracle_lighting_si_rel_err``, ``implied_albedo_si_mse`` (and
        ``_true_lighting``, ``_true_normals_lighting``), ``level_err_stops`` and
        ``level_log2_ratio``, the same with ``baseline_`` prefixed, ``shadow_positive_rate``,
        ``images``; with ``return_per_image`` the tuple ``(metrics, per_image)``.
    """
    ds = SynthDataset(root, split=split, mode="full")
    items = ds.items
    if not items:
        raise ValueError(f"{str(root)!r} has no photos in split {split!r}")
    items = evenly_spread(items, max_images)
    mean_light = prior.mean.reshape(-1, 3).double()
    acc: dict[str, list[float]] = {k: [] for k in (
        "albedo_si_mse", "normal_mae_deg", "lighting_rel_err", "lighting_si_rel_err", "baseline_albedo_si_mse",
        "baseline_normal_mae_deg", "baseline_lighting_rel_err", "baseline_lighting_si_rel_err")}
    for key in ("normal_mae_deg_mvs", "normal_mae_deg_no_mvs", "normal_mae_deg_up", "normal_mae_deg_not_up",
                "lighting_shading_err", "baseline_lighting_shading_err", "oracle_lighting_shading_err",
                "oracle_map_lighting_shading_err", "oracle_map_relative_lighting_shading_err",
                "oracle_lighting_si_rel_err", "oracle_albedo_si_mse",
                "implied_albedo_si_mse", "implied_albedo_si_mse_true_lighting",
                "implied_albedo_si_mse_true_normals_lighting", "level_log2_ratio", "level_err_stops",
                "baseline_level_err_stops"):
        acc[key] = []
    angles: list[np.ndarray] = []
    scene_of: list[str] = []
    scores, scores_sn, scores_oracle, labels, labels_direct = [], [], [], [], []
    for start in range(0, len(items), batch_size):
        chunk = items[start:start + batch_size]
        photos = [load_photo(ds, it.scene, it.view, it.light, res) for it in chunk]
        image = torch.stack([p["image"] for p in photos])
        sky = torch.stack([p["sky"] for p in photos])
        with torch.no_grad():
            out = decompose(image, sky)
            sn = shadow_fn(out) if shadow_fn is not None else None
        for j, it in enumerate(chunk):
            gt = load_ground_truth(ds, it.scene, it.view, it.light, res)
            fg = ~sky[j] & (gt["normal"].norm(dim=0, keepdim=True) > 0.5)
            if int(fg.sum()) == 0:
                continue
            scene_of.append(it.scene)
            acc["albedo_si_mse"].append(si_mse(out["albedo"][j], gt["albedo"], fg))
            acc["baseline_albedo_si_mse"].append(si_mse(image[j], gt["albedo"], fg))
            true_normal = F.normalize(gt["normal"].double(), dim=0)
            true_shading = image_model.shading(true_normal[None], gt["lighting"].double()[None])[0]
            ceiling = (image[j].double() / (true_shading * gt["direct_shadow"].double()).clamp_min(1e-4)).clamp(0, 1)
            acc["oracle_albedo_si_mse"].append(si_mse(ceiling.float(), gt["albedo"], fg))
            net_n, net_s = out["normals"][j:j + 1].double(), out["shadow"][j].double()
            for key, shading_ in (
                    ("implied_albedo_si_mse", image_model.shading(net_n, out["lighting"][j].double()[None])[0]),
                    ("implied_albedo_si_mse_true_lighting",
                     image_model.shading(net_n, gt["lighting"].double()[None])[0]),
                    ("implied_albedo_si_mse_true_normals_lighting", true_shading)):
                implied_albedo = (image[j].double() / (shading_ * net_s).clamp_min(1e-4)).clamp(0, 1)
                acc[key].append(si_mse(implied_albedo.float(), gt["albedo"], fg))
            implied = (image[j].double() / (gt["albedo"].double() * true_shading).clamp_min(1e-4)).mean(0, keepdim=True)
            scores_oracle.append((1.0 - implied[fg]).numpy())
            angle = _angle_map_deg(out["normals"][j], gt["normal"])  # once; every normal figure reads it
            acc["normal_mae_deg"].append(_masked_mean(angle, fg, "normal_mae_deg"))
            _, mvs = camera.normals_from_depth(photos[j]["depth"][None], photos[j]["K"][None], max_rel_jump=0.1)
            # Upward-facing surfaces (true normal within 10 deg of the world's +Y): ground and
            # tops, the easy part; everything else: walls, risers, statues.
            up = photos[j]["world_to_camera"][:3, 1].double()  # world +Y in the camera frame
            facing_up = (true_normal * up[:, None, None]).sum(0, keepdim=True) > math.cos(math.radians(10.0))
            for key, where in (("normal_mae_deg_mvs", fg & mvs[0]), ("normal_mae_deg_no_mvs", fg & ~mvs[0]),
                               ("normal_mae_deg_up", fg & facing_up), ("normal_mae_deg_not_up", fg & ~facing_up)):
                if bool(where.any()):
                    acc[key].append(_masked_mean(angle, where, key))
            angles.append(angle[fg].numpy())
            flat = torch.zeros_like(gt["normal"])
            flat[2] = 1.0
            acc["baseline_normal_mae_deg"].append(normal_angle_deg(flat, gt["normal"], fg))
            for name, light in (("", out["lighting"][j]), ("baseline_", mean_light)):
                raw, si = _lighting_errors(light, gt["lighting"])
                acc[f"{name}lighting_rel_err"].append(raw)
                acc[f"{name}lighting_si_rel_err"].append(si)
            ratio = level_log2_ratio(out["albedo"][j], out["lighting"][j], gt["albedo"], gt["lighting"], fg)
            acc["level_log2_ratio"].append(ratio)
            acc["level_err_stops"].append(abs(ratio))
            acc["baseline_level_err_stops"].append(abs(level_log2_ratio(image[j], mean_light, gt["albedo"],
                                                                        gt["lighting"], fg)))
            im, alb, nrm, vis, m = image[j:j + 1], gt["albedo"][None], gt["normal"][None], gt["shadow"][None], \
                fg[None].to(image.dtype)
            _, oracle = solve_projected(im, alb, nrm, vis, m, prior)
            oracle_map = image_model.solve_lighting_map(im, alb, nrm, m, prior, shadow=vis)
            oracle_rel = image_model.solve_lighting_map(im, alb, nrm, m, prior, shadow=vis, relative=True)
            for name, light in (("", out["lighting"][j]), ("baseline_", mean_light), ("oracle_", oracle[0]),
                                ("oracle_map_", oracle_map[0]), ("oracle_map_relative_", oracle_rel[0])):
                acc[f"{name}lighting_shading_err"].append(shading_error(light, gt["lighting"], gt["normal"], fg))
            acc["oracle_lighting_si_rel_err"].append(_lighting_errors(oracle[0], gt["lighting"])[1])
            labels.append((gt["shadow"][fg] < 0.5).numpy())
            labels_direct.append((gt["direct_shadow"][fg] < 0.5).numpy())
            scores.append((1.0 - out["shadow"][j][fg]).numpy())
            if sn is not None:
                scores_sn.append((1.0 - sn[j][fg]).numpy())
    res_: dict[str, float] = {k: float(np.mean(v)) if v else math.nan for k, v in acc.items()}
    y = np.concatenate(labels)
    res_["shadow_ap"] = average_precision(np.concatenate(scores), y)
    res_["baseline_shadow_ap"] = average_precision(np.zeros(y.size), y)
    res_["oracle_shadow_ap"] = average_precision(np.concatenate(scores_oracle), y)
    res_["shadow_positive_rate"] = float(y.mean())
    # The same against the direct-light ratio (< 0.5): a sky-lit umbra counts only if it lost
    # most of its direct light, which is what s in i = s * albedo * shading can explain.
    yd = np.concatenate(labels_direct)
    res_["shadow_ap_direct"] = average_precision(np.concatenate(scores), yd)
    res_["baseline_shadow_ap_direct"] = average_precision(np.zeros(yd.size), yd)
    if scores_sn:
        res_["shadownet_ap"] = average_precision(np.concatenate(scores_sn), y)
        res_["shadownet_ap_direct"] = average_precision(np.concatenate(scores_sn), yd)
    res_["normal_median_deg"] = float(np.median(np.concatenate(angles)))
    res_["images"] = float(len(acc["albedo_si_mse"]))
    if not return_per_image:
        return res_
    per_image = {"scene": np.asarray(scene_of)}
    for key in PER_IMAGE_METRICS:
        for name in (key, f"baseline_{key}"):
            per_image[name] = np.asarray(acc[name], dtype=np.float64)
    return res_, per_image


def scene_intervals(per_image: dict[str, np.ndarray], samples: int = 2000, seed: int = 0,
                    level: float = 0.95) -> dict[str, dict[str, float]]:
    """Scene-bootstrap confidence intervals of the per-photo means of :func:`evaluate`.

    The photos of one scene share its geometry and materials, so they are not independent:
    whole scenes are resampled (:func:`physrelight.stats.paired_bootstrap` against zero).

    Args:
        per_image: the second value of ``evaluate(..., return_per_image=True)``.

    Returns:
        ``{metric: {"mean", "lo", "hi", "scenes"}}`` for every metric of ``per_image``.
    """
    scenes = _scenes(per_image)
    out = {}
    for key, values in per_image.items():
        if key == "scene":
            continue
        d = paired_bootstrap(values, np.zeros_like(values), groups=scenes, samples=samples, seed=seed, level=level)
        out[key] = {"mean": d.diff, "lo": d.lo, "hi": d.hi, "scenes": d.groups}
    return out


def compare_decompositions(per_image: dict[str, np.ndarray], reference: dict[str, np.ndarray],
                           samples: int = 2000, seed: int = 0, level: float = 0.95) -> dict[str, dict[str, float]]:
    """Paired differences ``per_image - reference`` of two decompositions on the same photos.

    Args:
        per_image, reference: ``evaluate(..., return_per_image=True)[1]`` of two
            decompositions on the same dataset, split and ``max_images``.

    Returns:
        ``{metric: {"diff", "lo", "hi", "groups"}}`` for :data:`PER_IMAGE_METRICS`: mean
        difference (negative = ``per_image`` has the lower error) and its scene-bootstrap
        interval.

    Raises:
        ValueError: if the two were not evaluated on the same photos.
    """
    scenes = _scenes(per_image)
    if not np.array_equal(scenes, _scenes(reference)):
        raise ValueError("the two decompositions were evaluated on different photos "
                         f"({scenes.size} and {_scenes(reference).size}, or in a different order)")
    return {key: paired_bootstrap(per_image[key], reference[key], groups=scenes, samples=samples, seed=seed,
                                  level=level)._asdict() for key in PER_IMAGE_METRICS}


def _scenes(per_image: dict[str, np.ndarray]) -> np.ndarray:
    if "scene" not in per_image:
        raise ValueError("per_image has no 'scene' labels: pass the second value of "
                         "evaluate(..., return_per_image=True)")
    return np.asarray(per_image["scene"])


def evaluate_relighter(relighter: Relighter, root: str | Path, split: str = "all",
                       max_images: int | None = None, return_per_image: bool = False
                       ) -> dict[str, float] | tuple[dict[str, float], dict[str, np.ndarray]]:
    """:func:`evaluate` of a loaded :class:`learned.Relighter`: its decomposition, working
    resolution and prior, and its ShadowNet as the second shadow predictor (the metrics of
    ``physrelight train evaluate --weights``)."""
    return evaluate(relighter.decompose_linear, root, split, relighter.res, relighter.prior, max_images,
                    shadow_fn=lambda out: relighter.shadow_net(out["normals"], out["lighting"]),
                    return_per_image=return_per_image)
