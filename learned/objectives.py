"""The inverse network's self-supervised objective, composed from :mod:`physrelight.losses`.

For a batch of photo pairs (a, b) of one scene (:class:`learned.data.Batch`), the
network decomposes all ``2B`` photos; the lighting of each is *solved*
(:func:`physrelight.image_model.solve_lighting` over non-sky pixels, shadow divided out;
differentiable) and projected onto the outdoor lighting subspace
(:class:`physrelight.lighting_prior.LightingPrior`). Terms (no ground truth anywhere):

``appearance``
    the paper's shadow-free loss ``|| min(1, i / s) - albedo * shading(n; L) ||^2`` on
    non-sky pixels, with the projected lighting.
``albedo``
    albedo consistency: albedo of a vs albedo of b warped into a with a's MVS depth
    and the relative pose (occlusion-tested against b's MVS depth), squared error after
    scaling b's per channel onto a's (exposure and white balance differ between photos).
``normal``
    normal supervision: squared distance to the normals of the MVS-like depth where
    they are valid (depth edges and holes excluded).
``cross``
    cross-rendering: a's albedo and normals lit by b's lighting rotated into a's frame
    (``D(R_a R_b^T) L_b``) against b's photo warped into a, shadow-free with b's shadow
    warped into a (:func:`physrelight.losses.cross_rendering_loss`).
``prior``
    lighting prior: mean squared whitened coordinates of the solved lighting.
``shadow``
    a small sparsity term ``mean(1 - s)`` on non-sky pixels (our addition: without it
    ``min(1, i / s)`` lets the shadow explain the whole image, ``s -> 0``, target 1).

Every term is symmetric in the pair (computed for a <- b and b <- a).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch

from physrelight import camera, image_model, losses
from physrelight.lighting_prior import LightingPrior

from .data import Batch, mvs_normals
from .networks import metered, mirror_averaged

__all__ = ["LossWeights", "SMOOTHNESS_EDGE_GAIN", "decompose_and_solve", "edge_aware_smoothness", "inverse_losses",
           "solve_projected"]


@dataclass(frozen=True)
class LossWeights:
    """Weights of the self-supervised terms (the total is their weighted sum)."""

    appearance: float = 10.0
    albedo: float = 1.0
    normal: float = 0.5
    cross: float = 5.0
    prior: float = 1e-3
    shadow: float = 1e-2
    normal_smooth: float = 0.0  # off by default; runs B and D (shipped) used 2: see edge_aware_smoothness

    def as_dict(self) -> dict[str, float]:
        return asdict(self)


SMOOTHNESS_EDGE_GAIN = 10.0  # per unit of display-space gradient: an occlusion edge (~0.3) weighs ~0.05


def edge_aware_smoothness(normals: torch.Tensor, image: torch.Tensor, foreground: torch.Tensor) -> torch.Tensor:
    """Mean ``|n_p - n_q|_1 exp(-g |I_p - I_q|)`` over 4-neighbour pairs inside the foreground.

    A prior for the pixels no MVS normal reaches (depth-edge holes, ~30 % of the synthetic
    foreground): normals vary smoothly where the photo does, and may break where it has an
    edge. ``I`` is the photo in display values (``linear ** (1 / 2.2)``, channel mean of the
    absolute difference), ``g`` = :data:`SMOOTHNESS_EDGE_GAIN`.

    Args:
        normals: ``(B, 3, H, W)``; image: ``(B, 3, H, W)`` linear; foreground: ``(B, 1, H, W)`` 0/1.

    Returns:
        A scalar (0 with a graph when no pair lies inside the foreground).
    """
    disp = image.clamp_min(0.0) ** (1.0 / 2.2)
    num = normals.sum() * 0.0
    den = 0.0
    for dim in (2, 3):
        n = normals.shape[dim] - 1
        dn = (normals.narrow(dim, 1, n) - normals.narrow(dim, 0, n)).abs().sum(1, keepdim=True)
        di = (disp.narrow(dim, 1, n) - disp.narrow(dim, 0, n)).abs().mean(1, keepdim=True)
        both = foreground.narrow(dim, 1, n) * foreground.narrow(dim, 0, n)
        num = num + (dn * torch.exp(-SMOOTHNESS_EDGE_GAIN * di) * both).sum()
        den += float(both.sum())
    return num / max(den, 1.0)


def solve_projected(image: torch.Tensor, albedo: torch.Tensor, normals: torch.Tensor, shadow: torch.Tensor,
                    foreground: torch.Tensor, prior: LightingPrior,
                    method: str = "project") -> tuple[torch.Tensor, torch.Tensor]:
    """Solve the lighting over ``foreground`` and bring it into the prior's subspace.

    Args:
        image, albedo, normals: ``(B, 3, H, W)``; shadow, foreground ``(B, 1, H, W)``.
        method: ``"project"``: least squares (:func:`physrelight.image_model.solve_lighting`),
            then the orthogonal projection onto the subspace (the paper); ``"map"``: the most
            probable lighting in the subspace (:func:`physrelight.image_model.solve_lighting_map`,
            ``noise=1``); ``"map_relative"``: the same with the prior on the lighting's shape
            only, its level fitted to the image (``relative=True``: exposure-equivariant).

    Returns:
        ``(solved, lighting)``, each ``(B, 9, 3)`` camera-frame radiance SH: the unconstrained
        least-squares solution (the prior loss reads it) and the lighting in the subspace; both
        carry gradients to every input.
    """
    mask = foreground.to(image.dtype)
    solved = image_model.solve_lighting(image, albedo, normals, mask, shadow)
    if method == "project":
        return solved, prior.project(solved)
    if method in ("map", "map_relative"):
        lighting = image_model.solve_lighting_map(image, albedo, normals, mask, prior, shadow=shadow,
                                                  relative=method == "map_relative")
        return solved, lighting.to(image.dtype)
    raise ValueError(f"method must be 'project', 'map' or 'map_relative', got {method!r}")


def decompose_and_solve(net: torch.nn.Module, image: torch.Tensor, sky: torch.Tensor,
                        prior: LightingPrior, mirror_average: bool | None = None,
                        meter_exposure: bool | None = None,
                        network_input: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
    """Run the network and solve each photo's lighting.

    Args:
        net: an :class:`learned.networks.InverseNet` (or a DDP wrapper of one).
        image: ``(B, 3, H, W)`` linear photos; sky ``(B, 1, H, W)`` bool.
        mirror_average: average the layers of the photo and its mirror image before the solve
            (:func:`learned.networks.mirror_averaged`); None = the network's own
            ``mirror_average`` (an inference choice made at export). Training passes False.
        meter_exposure: the network sees :func:`learned.networks.metered` photos (the lighting is
            solved against ``image`` as given); None = the network's own ``meter_exposure``.
        network_input: ``(B, 3, H, W)``, what the network sees instead of ``image`` (a degraded copy in
            training, :class:`learned.data.Batch` ``network_image``); the lighting is still solved against
            ``image``. None: ``image``.

    Returns:
        ``albedo, normals, shadow`` as the network gives them, ``lighting_solved`` and
        ``lighting`` (in the prior's subspace, by the network's ``lighting_solve``) ``(B, 9, 3)``,
        ``foreground`` ``(B, 1, H, W)`` float.
    """
    module = getattr(net, "module", net)  # DDP wraps the network
    if mirror_average is None:
        mirror_average = getattr(module, "mirror_average", False)
    if meter_exposure is None:
        meter_exposure = getattr(module, "meter_exposure", False)
    if network_input is None:
        network_input = image
    elif network_input.shape != image.shape:
        raise ValueError(f"network_input must have the image's shape {tuple(image.shape)}, "
                         f"got {tuple(network_input.shape)}")
    seen = metered(network_input) if meter_exposure else network_input
    out = dict(mirror_averaged(net, seen) if mirror_average else net(seen))
    fg = (~sky).to(image.dtype)
    method = getattr(module, "lighting_solve", "project")
    out["lighting_solved"], out["lighting"] = solve_projected(image, out["albedo"], out["normals"], out["shadow"],
                                                              fg, prior, method)
    out["foreground"] = fg
    return out


def _match_scale(x: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``x (B, C, H, W)`` times its per-image, per-channel least-squares scale onto ``target`` over ``mask``.

    Two photos of a scene differ in exposure and white balance, which one photo cannot
    reveal; comparing albedos up to a per-channel scale keeps the consistency term from
    rewarding flat (low-contrast) albedo as the safest guess.
    """
    num = (x * target * mask).sum((2, 3), keepdim=True)
    den = (x * x * mask).sum((2, 3), keepdim=True)
    scale = torch.where(den > 1e-8, num / den.clamp_min(1e-8), torch.ones_like(den))
    return x * scale


def _masked(x: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``masked_mean_sq`` that gives 0 (with a graph) for an empty mask instead of raising."""
    if float(mask.sum()) <= 0:
        return x.sum() * 0.0
    return losses.masked_mean_sq(x, mask)


def inverse_losses(net: torch.nn.Module, batch: Batch, prior: LightingPrior,
                   weights: LossWeights = LossWeights(),
                   mvs_stencil: str = "central") -> tuple[torch.Tensor, dict[str, float], dict[str, torch.Tensor]]:
    """The weighted self-supervised loss of a batch.

    ``mvs_stencil`` is how the normal term's targets are taken from the MVS-like depth
    (see :func:`physrelight.camera.normals_from_depth`).

    Returns:
        ``(total, terms, outputs)``: the scalar to minimise, each unweighted term as a
        float, and the decomposition (see :func:`decompose_and_solve`).
    """
    image, sky = batch.image, batch.sky
    out = decompose_and_solve(net, image, sky, prior, mirror_average=False, meter_exposure=False,
                              network_input=batch.network_image)
    fg = out["foreground"]
    albedo, normals, shadow = out["albedo"], out["normals"], out["shadow"]

    terms: dict[str, torch.Tensor] = {}
    terms["appearance"] = losses.shadow_free_loss(image, shadow, albedo, normals, out["lighting"], fg)

    # Warp every photo's partner into it: dst = row i, src = partner of row i.
    T_src = batch.partner(batch.world_to_camera)
    dst_to_src = camera.relative_pose(batch.world_to_camera, T_src)
    src = torch.cat([batch.partner(image), batch.partner(albedo), batch.partner(shadow)], 1)
    warped, valid = camera.warp(src, batch.depth, batch.K, batch.partner(batch.K), dst_to_src,
                                depth_src=batch.partner(batch.depth))
    # The occlusion test against the partner's MVS depth already rejects its sky and holes.
    overlap = (valid & ~sky).to(image.dtype)
    image_w, albedo_w, shadow_w = warped[:, 0:3], warped[:, 3:6], warped[:, 6:7]
    terms["albedo"] = _masked(albedo - _match_scale(albedo_w, albedo, overlap), overlap)

    n_mvs, n_valid = mvs_normals(batch, mvs_stencil)
    terms["normal"] = _masked(normals - n_mvs, n_valid.to(image.dtype))
    terms["normal_smooth"] = edge_aware_smoothness(normals, image, fg)

    # Lighting of the partner (its camera frame) rotated into this view: R_dst R_src^T.
    src_to_dst = camera.relative_pose(T_src, batch.world_to_camera)[:, :3, :3]
    if float(overlap.sum()) > 0:
        terms["cross"] = losses.cross_rendering_loss(image_w, shadow_w.clamp(0.0, 1.0), albedo, normals,
                                                     batch.partner(out["lighting"]), src_to_dst, overlap)
    else:
        terms["cross"] = image.sum() * 0.0
    terms["prior"] = prior.loss(out["lighting_solved"])
    terms["shadow"] = ((1.0 - shadow) * fg).sum() / fg.sum().clamp_min(1.0)

    w = weights.as_dict()
    total = sum(w[k] * v for k, v in terms.items())
    return total, {k: float(v.detach()) for k, v in terms.items()}, out
