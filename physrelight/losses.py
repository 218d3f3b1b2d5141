"""Training losses of the paper, as plain differentiable functions.

* :func:`shadow_free_loss` -- eq. 3: ``|| min(1, i / s) - albedo * shading(n; L) ||^2``,
  the self-supervised appearance loss in shadow-free space.
* :func:`cross_rendering_loss` -- the same form with the lighting of another view,
  rotated into this view's camera frame, against that view's photo warped here.
* :func:`lab_l2` -- L2 in CIELAB, the neural renderer's reconstruction term.

Images are ``(B, C, H, W)``; masks ``(B, 1, H, W)`` weights in [0, 1] (1 = counts).
Every loss is a masked mean over pixels of the squared error summed over channels, so
values are comparable between calls with different masks.
"""

from __future__ import annotations

import torch

from physrelight import colour, image_model, sh
from physrelight._checks import Array, check_finite, check_image, check_same_spatial, to_tensor


def _mask_like(mask: Array | None, like: torch.Tensor) -> torch.Tensor:
    if mask is None:
        return torch.ones_like(like[:, :1])
    m = to_tensor(mask, "mask")[0].to(like.dtype)
    check_image(m, "mask", 1)
    check_same_spatial(like, m, "image", "mask")
    check_finite(m, "mask")
    return m


def masked_mean_sq(diff: torch.Tensor, mask: torch.Tensor) -> torch.Tensor:
    """``sum_p m_p ||diff_p||^2 / sum_p m_p`` for ``diff (B, C, H, W)``, ``mask (B, 1, H, W)``.

    Raises ``ValueError`` on an empty mask (a zero loss there would hide the problem).
    """
    total = mask.sum()
    if float(total.detach()) <= 0:
        raise ValueError("mask is empty: no pixel contributes to the loss")
    # where() rather than multiplication: garbage (inf) outside the mask must not leak.
    sq = torch.where(mask > 0, diff, torch.zeros_like(diff)).pow(2).sum(dim=1, keepdim=True)
    return (sq * mask).sum() / total


def shadow_free_target(image: torch.Tensor, shadow: torch.Tensor | None, eps: float = 1e-3) -> torch.Tensor:
    """``min(1, i / s)``: the image with the shadow divided out, ``(B, 3, H, W)``.

    ``s`` is floored at ``eps`` so deep shadow gives a large but finite ratio, which the
    ``min(1, .)`` then caps (the paper's LDR assumption: shadow-free radiance <= 1).
    """
    if shadow is None:
        return image.clamp(max=1.0)
    return torch.minimum(image / shadow.clamp_min(eps), torch.ones_like(image))


def shadow_free_loss(image: Array, shadow: Array | None, albedo: Array, normals: Array, lighting: Array,
                     mask: Array | None = None, eps: float = 1e-3) -> Array:
    """The paper's self-supervised appearance loss (eq. 3).

    ``mean_p m_p || min(1, i_p / s_p) - a_p * shading(n_p; L) ||^2``.

    Args:
        image: ``(B, 3, H, W)`` linear image in [0, 1] (a linearised LDR photo).
        shadow: ``(B, 1, H, W)`` in [0, 1], or None for ``s = 1``.
        albedo: ``(B, 3, H, W)``.
        normals: ``(B, 3, H, W)`` unit normals, camera frame.
        lighting: ``(K, 3)`` or ``(B, K, 3)`` radiance SH, camera frame.
        mask: ``(B, 1, H, W)`` foreground weights (0 on sky), or None for all pixels.
        eps: floor of ``s`` in the division.

    Returns:
        Scalar loss (0-dim tensor for torch input, float64 array for numpy input).
    """
    i, restore = to_tensor(image, "image")
    check_image(i, "image", 3)
    m = _mask_like(mask, i)
    s = None
    if shadow is not None:
        s = to_tensor(shadow, "shadow")[0].to(i.dtype)
        check_image(s, "shadow", 1)
        check_same_spatial(i, s, "image", "shadow")
    a = to_tensor(albedo, "albedo")[0].to(i.dtype)
    check_image(a, "albedo", 3)
    check_same_spatial(i, a, "image", "albedo")
    pred = to_tensor(image_model.render(a, normals, to_tensor(lighting, "lighting")[0].to(i.dtype)), "render")[0]
    return restore(masked_mean_sq(shadow_free_target(i, s, eps) - pred, m))


def cross_rendering_loss(image_b_in_a: Array, shadow_b_in_a: Array | None, albedo_a: Array, normals_a: Array,
                         lighting_b: Array, rotation_b_to_a: Array, mask: Array | None = None,
                         eps: float = 1e-3) -> Array:
    """Cross-rendering: view A's albedo and normals lit by view B's lighting.

    The lighting solved in B's camera frame is rotated into A's frame
    (``D(R_b_to_a) L_b`` with ``R_b_to_a = R_a R_b^T`` from the world-to-camera
    rotations) and compared, in shadow-free space, with B's photo and shadow warped
    into A (see :func:`physrelight.camera.warp`); ``mask`` is the warp's validity
    times A's foreground.

    Args:
        image_b_in_a: ``(B, 3, H, W)`` view B's image warped into view A.
        shadow_b_in_a: ``(B, 1, H, W)`` view B's shadow warped into A, or None.
        albedo_a, normals_a: ``(B, 3, H, W)`` of view A.
        lighting_b: ``(K, 3)`` or ``(B, K, 3)`` SH lighting in B's camera frame.
        rotation_b_to_a: ``(3, 3)`` or ``(B, 3, 3)`` rotation from B's to A's camera frame.
        mask: ``(B, 1, H, W)``.

    Returns:
        Scalar loss.
    """
    lb, _ = to_tensor(lighting_b, "lighting_b")
    r, _ = to_tensor(rotation_b_to_a, "rotation_b_to_a")
    la = sh.rotate(lb, r.to(lb.dtype))
    return shadow_free_loss(image_b_in_a, shadow_b_in_a, albedo_a, normals_a, la, mask, eps)


def lab_l2(pred: Array, target: Array, mask: Array | None = None, encoding: str = "linear") -> Array:
    """Masked mean squared CIELAB difference, with Lab divided by 100 (L in 0..1).

    Args:
        pred, target: ``(B, 3, H, W)`` RGB; ``encoding`` says whether linear or
            sRGB-encoded (display) values.
        mask: ``(B, 1, H, W)`` or None.

    Returns:
        Scalar loss: ``mean_p ||Lab(pred_p) - Lab(target_p)||^2 / 100^2``.
    """
    p, restore = to_tensor(pred, "pred")
    t = to_tensor(target, "target")[0].to(p.dtype)
    check_image(p, "pred", 3)
    check_image(t, "target", 3)
    if p.shape != t.shape:
        raise ValueError(f"pred {tuple(p.shape)} and target {tuple(t.shape)} must have the same shape")
    if encoding not in ("linear", "srgb"):
        raise ValueError(f"encoding must be 'linear' or 'srgb', got {encoding!r}")
    if encoding == "srgb":
        p, t = colour.srgb_to_linear(p), colour.srgb_to_linear(t)
    m = _mask_like(mask, p)
    diff = (colour.rgb_to_lab(p, dim=1) - colour.rgb_to_lab(t, dim=1)) / 100.0
    return restore(masked_mean_sq(diff, m))
