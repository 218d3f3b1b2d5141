"""The neural renderer's self-supervised objective (paper section 3.3), from :mod:`physrelight.losses`.

For a batch of photo pairs (a, b) of one scene (:class:`learned.data.Batch`), every photo is
decomposed by the *frozen* inverse network (albedo, normals, shadow, lighting solved and
projected) and rendered twice:

``self_lab``, ``self_ssim`` (self-reconstruction)
    target lighting = the photo's own lighting, target shadow = ShadowNet on it; the output
    must give the photo back: L2 in CIELAB (:func:`physrelight.losses.lab_l2`) plus a
    structural term ``1 - SSIM`` on the sRGB-encoded images (foreground only).
``cross`` (cross-projection)
    a's decomposition lit by b's lighting rotated into a's frame (``D(R_a R_b^T) L_b``),
    with ShadowNet's shadow for it, against b's photo warped into a with a's MVS depth and
    the relative pose (occlusion-tested against b's MVS depth), LAB L2 at 1/4 resolution
    (mask-weighted average pooling: the warp is only as good as the MVS depth), after a
    per-channel least-squares scale of the render onto the photo (``cross_match_scale``:
    b's lighting is solved with b's albedo, so its colour and exposure carry the inverse
    network's albedo/lighting ambiguity, which a global shift would only learn). When a and
    b share the camera (another time of day) the photo is used as it is, over a's foreground.
``cross_full`` (our addition)
    for those same-camera pairs the cross-projection again at full resolution. At 1/4
    resolution zero-mean detail averages out, so that term cannot see the renderer pasting
    the source photo's residual (its noise, texture shaded by the *source* light) into
    the relit image, which self-reconstruction rewards; same-camera pairs need no warp, so
    full resolution is safe there (time-lapse pairs, as in BigTime, give the same signal).
``cycle_albedo``, ``cycle_normal``, ``cycle_lighting``, ``cycle_shadow`` (phase 2)
    the cross-projected output, decomposed again by the frozen inverse network, must give
    a's albedo (squared error weighted by the target shading's luminance: albedo is
    unobservable where the image is dark), a's normals (``1 - cos``), the target lighting
    (relative squared error of the 27-D SH) and the target shadow (squared error).
``adversarial``, ``feature_matching`` (phase 2)
    a 2-scale LSGAN on the foreground (sky blacked out, sRGB-encoded): the cross-projected
    outputs are the fakes, the photos the reals; feature matching of the discriminator's
    features between the self-reconstruction and its photo stands in for the paper's VGG
    perceptual loss (no pretrained VGG offline).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F

from physrelight import camera, colour, image_model, losses, metrics, sh
from physrelight.lighting_prior import LightingPrior
from physrelight.quotient import SMOOTH_RADIUS, quotient_relight

from .data import Batch
from .discriminators import MultiscaleDiscriminator, feature_matching_loss, lsgan_loss
from .neural_renderer import NeuralRenderer, renderer_inputs
from .objectives import _match_scale, decompose_and_solve

__all__ = ["RendererWeights", "cross_targets", "discriminator_loss", "downsample_masked", "renderer_losses"]

PHASE2_TERMS = ("cycle_albedo", "cycle_normal", "cycle_lighting", "cycle_shadow", "adversarial", "feature_matching")


@dataclass(frozen=True)
class RendererWeights:
    """Weights of the renderer's terms (the total is their weighted sum; phase-2 terms count from phase 2)."""

    self_lab: float = 10.0
    self_ssim: float = 1.0
    cross: float = 10.0
    cross_full: float = 10.0
    cycle_albedo: float = 1.0
    cycle_normal: float = 0.2
    cycle_lighting: float = 0.05
    cycle_shadow: float = 0.5
    adversarial: float = 0.05
    feature_matching: float = 1.0

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


def _ldr(x: torch.Tensor) -> torch.Tensor:
    """Linear ``(B, 3, H, W)`` -> sRGB-encoded display values in [0, 1] (differentiable below 1)."""
    return colour.to_ldr(x.clamp_min(0.0))


def _zero(like: torch.Tensor) -> torch.Tensor:
    return like.sum() * 0.0


def downsample_masked(x: torch.Tensor, mask: torch.Tensor, factor: int,
                      min_cover: float = 0.5) -> tuple[torch.Tensor, torch.Tensor]:
    """Mask-weighted average pooling.

    Args:
        x: ``(B, C, H, W)``; mask ``(B, 1, H, W)`` in {0, 1}; factor: pooling size.
        min_cover: a coarse pixel is valid when at least this fraction of it is masked.

    Returns:
        ``(B, C, H/f, W/f)`` averages over the masked fine pixels and the ``(B, 1, h, w)`` float mask.
    """
    if factor == 1:
        return x, mask
    m = F.avg_pool2d(mask, factor, ceil_mode=True)
    y = F.avg_pool2d(x * mask, factor, ceil_mode=True) / m.clamp_min(1e-6)
    return y, (m >= min_cover).to(x.dtype)


def cross_targets(batch: Batch) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, torch.Tensor]:
    """For every row (view a), its partner's photo in a's pixels and where that is valid.

    Returns:
        ``target (2B, 3, H, W)``, ``mask (2B, 1, H, W)`` float, ``rotation (2B, 3, 3)`` from the
        partner's camera frame to the row's (``R_a R_b^T``) and ``same (2B,)`` bool: the
        partner shares the row's camera (same scene and view, another lighting).
    """
    image, sky = batch.image, batch.sky
    T_src = batch.partner(batch.world_to_camera)
    dst_to_src = camera.relative_pose(batch.world_to_camera, T_src)
    warped, valid = camera.warp(batch.partner(image), batch.depth, batch.K, batch.partner(batch.K), dst_to_src,
                                depth_src=batch.partner(batch.depth))
    n = batch.pairs
    keys = batch.keys
    partner_keys = keys[n:] + keys[:n]
    same = torch.tensor([k[:2] == p[:2] for k, p in zip(keys, partner_keys)], device=image.device)[:, None, None, None]
    # Same scene and view: the camera did not move, the photo needs no warp (and no MVS depth).
    target = torch.where(same, batch.partner(image), warped)
    mask = torch.where(same, ~sky, valid & ~sky).to(image.dtype)
    rotation = camera.relative_pose(T_src, batch.world_to_camera)[:, :3, :3]
    return target, mask, rotation, same.flatten()


def _foreground_ldr(x: torch.Tensor, fg: torch.Tensor) -> torch.Tensor:
    """The discriminator's view: sRGB-encoded foreground, sky blacked out."""
    return _ldr(x) * fg


def renderer_losses(renderer: NeuralRenderer, discriminator: MultiscaleDiscriminator | None,
                    inverse: torch.nn.Module, shadow_net: torch.nn.Module, prior: LightingPrior, batch: Batch,
                    decomposition: dict[str, torch.Tensor], weights: RendererWeights = RendererWeights(),
                    phase: int = 1, cross_scale: int = 4, cross_match_scale: bool = True
                    ) -> tuple[torch.Tensor, dict[str, float], dict[str, torch.Tensor]]:
    """The generator's weighted loss for a batch.

    Args:
        renderer: the network being trained.
        discriminator: needed in phase 2 (its parameters get gradients here too: zero them
            before the discriminator's own step).
        inverse, shadow_net: frozen networks (cycle consistency, cross-projected shadows).
        prior: the lighting prior (the cycle's lighting solve).
        batch: photo pairs.
        decomposition: the frozen inverse network's ``albedo, normals, shadow, lighting`` of
            ``batch.image`` and ``self_shadow`` = ShadowNet on the own lighting (no gradients).
        weights: term weights; phase: 1 (self + cross) or 2 (+ cycle + adversarial).
        cross_scale: the cross-projection is compared at ``1 / cross_scale`` resolution.
        cross_match_scale: compare the cross-projections after scaling the render per
            channel onto the photo (least squares over the mask), so the renderer learns
            where light and shadow go, not a global colour/exposure shift that only the
            estimated lightings' errors explain.

    Returns:
        ``(total, terms, outputs)``: the scalar to minimise, every unweighted term as a float,
        and ``self``/``cross`` (the two renders), ``cross_target``, ``cross_mask``,
        ``cross_lighting``, ``cross_shadow``.
    """
    if phase not in (1, 2):
        raise ValueError(f"phase must be 1 or 2, got {phase!r}")
    if phase == 2 and discriminator is None:
        raise ValueError("phase 2 needs a discriminator")
    image, sky = batch.image, batch.sky
    fg = (~sky).to(image.dtype)
    a, n, s, L = (decomposition[k] for k in ("albedo", "normals", "shadow", "lighting"))
    terms: dict[str, torch.Tensor] = {}

    def quotient(target_lighting: torch.Tensor) -> torch.Tensor | None:
        """The quotient image the Relighter hands a quotient-based renderer (None for the Lambertian one)."""
        if renderer.base != "quotient":
            return None
        return quotient_relight(image, n, L, target_lighting, mask=~sky, smooth_radius=SMOOTH_RADIUS)

    x_self = renderer_inputs(image, sky, a, n, s, L, L, decomposition["self_shadow"], quotient(L))
    out_self = torch.where(sky, image, renderer(x_self))
    terms["self_lab"] = losses.lab_l2(out_self, image, fg)
    terms["self_ssim"] = 1.0 - metrics.ssim(_ldr(out_self), _ldr(image), fg)

    target, mask, rotation, same = cross_targets(batch)
    L_cross = sh.rotate(batch.partner(L), rotation.to(L.dtype))
    with torch.no_grad():
        s_cross = shadow_net(n, L_cross)
    out_cross = torch.where(sky, image, renderer(renderer_inputs(image, sky, a, n, s, L, L_cross, s_cross,
                                                                 quotient(L_cross))))
    pred = _match_scale(out_cross, target, mask) if cross_match_scale else out_cross
    pred_d, mask_d = downsample_masked(pred, mask, cross_scale)
    tgt_d, _ = downsample_masked(target, mask, cross_scale)
    terms["cross"] = losses.lab_l2(pred_d, tgt_d, mask_d) if float(mask_d.sum()) > 0 else _zero(out_cross)
    if bool(same.any()) and float(mask[same].sum()) > 0:
        terms["cross_full"] = losses.lab_l2(pred[same], target[same], mask[same])
    else:
        terms["cross_full"] = _zero(out_cross)

    if phase == 2:
        again = decompose_and_solve(inverse, out_cross, sky, prior)
        shade = _shading_luminance(L_cross, n) * s_cross * fg
        terms["cycle_albedo"] = (((again["albedo"] - a) ** 2).sum(1, keepdim=True) * shade).sum() / \
            shade.sum().clamp_min(1e-6)
        cos = (again["normals"] * n).sum(1, keepdim=True)
        terms["cycle_normal"] = ((1.0 - cos) * fg).sum() / fg.sum().clamp_min(1.0)
        rel = ((again["lighting"] - L_cross) ** 2).sum((1, 2)) / (L_cross ** 2).sum((1, 2)).clamp_min(1e-8)
        terms["cycle_lighting"] = rel.mean()
        terms["cycle_shadow"] = losses.masked_mean_sq(again["shadow"] - s_cross, fg)
        fake = discriminator(_foreground_ldr(out_cross, fg))
        terms["adversarial"] = lsgan_loss(fake, real=True)
        real_self = discriminator(_foreground_ldr(image, fg))
        terms["feature_matching"] = feature_matching_loss(discriminator(_foreground_ldr(out_self, fg)), real_self)

    w = weights.as_dict()
    total = sum(w[k] * v for k, v in terms.items())
    outputs = {"self": out_self.detach(), "cross": out_cross.detach(), "cross_target": target, "cross_mask": mask,
               "cross_lighting": L_cross.detach(), "cross_shadow": s_cross}
    return total, {k: float(v.detach()) for k, v in terms.items()}, outputs


def _shading_luminance(lighting: torch.Tensor, normals: torch.Tensor) -> torch.Tensor:
    """``(B, 1, H, W)`` luminance of ``shading(normals; lighting)``, clamped at 0."""
    shading = image_model.shading(normals, lighting)
    lum = torch.tensor(colour.LUMINANCE, dtype=shading.dtype, device=shading.device)[None, :, None, None]
    return (shading * lum).sum(1, keepdim=True).clamp_min(0.0)


def discriminator_loss(discriminator: MultiscaleDiscriminator, batch: Batch,
                       outputs: dict[str, torch.Tensor]) -> torch.Tensor:
    """LSGAN discriminator loss: the photos are real, the cross-projected renders (detached) fake."""
    fg = (~batch.sky).to(batch.image.dtype)
    real = discriminator(_foreground_ldr(batch.image, fg))
    fake = discriminator(_foreground_ldr(outputs["cross"].detach(), fg))
    return 0.5 * (lsgan_loss(real, real=True) + lsgan_loss(fake, real=False))
