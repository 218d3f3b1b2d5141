"""The paper's image model ``i = s * albedo * shading(n; L)`` and the lighting solve.

Images are torch ``(B, C, H, W)``, linear RGB. Normals are unit vectors in the camera
frame (x right, y up, z towards the viewer). Lighting is radiance SH ``(B, K, 3)`` in
the same frame; ``shading = E / pi`` (see :mod:`physrelight.sh`). Pixels without a
surface (sky) carry zero-length normals or are excluded by a mask: their shading is 0
and the lighting solve never reads them.

Functions accept numpy arrays or torch tensors (same layout) and return the type given.
"""

from __future__ import annotations

import math
from typing import Any

import torch

from physrelight import sh
from physrelight._checks import (
    Array,
    check_finite,
    check_image,
    check_same_spatial,
    to_tensor,
)
from physrelight.lighting_prior import LightingPrior


def _lighting(c: torch.Tensor, batch: int, name: str = "lighting") -> tuple[torch.Tensor, int]:
    """Accept ``(K, 3)`` (shared) or ``(B, K, 3)`` lighting; return ``(B, K, 3)`` and the order."""
    if c.ndim == 2:
        c = c.unsqueeze(0).expand(batch, -1, -1)
    if c.ndim != 3 or c.shape[-1] != 3 or c.shape[0] != batch:
        raise ValueError(f"{name} must have shape (K, 3) or (B={batch}, K, 3), got {tuple(c.shape)}")
    order = sh._coeff_order(c, name)
    check_finite(c, name)
    return c, order


def _sq_norm(n: torch.Tensor) -> torch.Tensor:
    """``(B, 1, H, W)`` squared length of ``(B, 3, H, W)`` vectors (elementwise: a channel
    reduction with vector_norm is ~30x slower on CPU)."""
    return (n[:, 0:1] ** 2 + n[:, 1:2] ** 2 + n[:, 2:3] ** 2)


def _valid_normals(n: torch.Tensor) -> torch.Tensor:
    """``(B, 1, H, W)`` True where the normal has non-zero length (a surface, not sky)."""
    return _sq_norm(n.detach()) > 1e-12


def _shading_basis(n: torch.Tensor, order: int) -> torch.Tensor:
    """``(B, K, H, W)``: ``A_l Y_lm(n) / pi`` at each pixel, 0 where there is no normal."""
    valid = _valid_normals(n)
    # Replace missing normals by +z so the basis is defined, then zero those pixels.
    safe = torch.where(valid, n, torch.tensor([0.0, 0.0, 1.0], dtype=n.dtype, device=n.device)[None, :, None, None])
    safe = safe * torch.rsqrt(_sq_norm(safe))
    y = sh._basis_xyz(safe[:, 0], safe[:, 1], safe[:, 2], order, dim=1)  # (B, K, H, W)
    a = sh.irradiance_transfer(order, n.dtype).to(n.device) / math.pi
    return y * (a[None, :, None, None] * valid)


def shading(normals: Array, lighting: Array) -> Array:
    """Lambertian SH shading ``E(n) / pi``.

    Args:
        normals: ``(B, 3, H, W)`` unit normals (camera frame); zero vectors mark pixels
            without a surface and get shading 0.
        lighting: ``(K, 3)`` or ``(B, K, 3)`` radiance SH in the same frame.

    Returns:
        ``(B, 3, H, W)`` shading.
    """
    n, restore = to_tensor(normals, "normals")
    check_image(n, "normals", 3)
    check_finite(n, "normals")
    c, order = _lighting(to_tensor(lighting, "lighting")[0].to(n.dtype), n.shape[0])
    return restore(torch.einsum("bkhw,bkc->bchw", _shading_basis(n, order), c))


def sun_shading(normals: Array, sun: Array) -> Array:
    """Exact Lambertian shading of a delta sun, ``E max(0, n . s) / pi``, from its radiance SH.

    :func:`shading` of the sun's order-2 SH is this clamped cosine band-limited: it rings (light
    behind the terminator, up to ~10 % of ``E / pi`` too little facing the sun). A sun is one
    direction and one colour, so the exact term costs nothing more; the sun is read from its SH by
    :func:`physrelight.sh.sun_of`.

    Args:
        normals: ``(B, 3, H, W)`` unit normals; zero vectors (no surface) get 0.
        sun: ``(K, 3)`` or ``(B, K, 3)`` radiance SH of the sun alone (``K >= 4``), same frame.

    Returns:
        ``(B, 3, H, W)`` shading.
    """
    n, restore = to_tensor(normals, "normals")
    check_image(n, "normals", 3)
    check_finite(n, "normals")
    c, _ = _lighting(to_tensor(sun, "sun")[0].to(n.dtype), n.shape[0], "sun")
    d, e = sh.sun_of(c)
    cos = torch.einsum("bchw,bc->bhw", n, d).clamp_min(0.0)[:, None]
    return restore(cos * e[:, :, None, None] / math.pi * _valid_normals(n).to(n.dtype))


def render(albedo: Array, normals: Array, lighting: Array, shadow: Array | None = None) -> Array:
    """The image model ``i = s * albedo * shading(n; L)``.

    Args:
        albedo: ``(B, 3, H, W)`` diffuse reflectance in [0, 1].
        normals: ``(B, 3, H, W)`` unit normals.
        lighting: ``(K, 3)`` or ``(B, K, 3)`` radiance SH.
        shadow: ``(B, 1, H, W)`` in [0, 1] (1 = unshadowed), or None for no shadow.

    Returns:
        ``(B, 3, H, W)`` linear radiance.
    """
    a, restore = to_tensor(albedo, "albedo")
    check_image(a, "albedo", 3)
    check_finite(a, "albedo")
    n = to_tensor(normals, "normals")[0].to(a.dtype)
    check_same_spatial(a, n, "albedo", "normals")
    out = a * to_tensor(shading(n, to_tensor(lighting, "lighting")[0].to(a.dtype)), "shading")[0]
    if shadow is not None:
        s = _shadow(shadow, a)
        out = out * s
    return restore(out)


def _shadow(shadow: Array, like: torch.Tensor) -> torch.Tensor:
    s = to_tensor(shadow, "shadow")[0].to(like.dtype)
    check_image(s, "shadow", 1)
    check_same_spatial(like, s, "image", "shadow")
    check_finite(s, "shadow")
    if bool(((s.detach() < 0) | (s.detach() > 1)).any()):
        raise ValueError(f"shadow must lie in [0, 1], got range [{float(s.min()):.4g}, {float(s.max()):.4g}]")
    return s


def residual(image: Array, albedo: Array, normals: Array, lighting: Array, shadow: Array | None = None) -> Array:
    """``image - render(albedo, normals, lighting, shadow)``: detail the decomposition lost.

    The neural renderer takes it as input (DESIGN: 3 of its 14 channels).
    Shapes as in :func:`render`; ``image`` is ``(B, 3, H, W)``.
    """
    i, restore = to_tensor(image, "image")
    check_image(i, "image", 3)
    check_finite(i, "image")
    rendered = to_tensor(render(albedo, normals, lighting, shadow), "render")[0].to(i.dtype)
    check_same_spatial(i, rendered, "image", "albedo")
    return restore(i - rendered)


def _lighting_system(image: Array, albedo: Array, normals: Array, mask: Array, shadow: Array | None,
                     order: int, shadow_floor: float) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, bool, torch.dtype, Any]:
    """Checked inputs -> the weighted normal equations of the per-channel lighting fit:
    ``ata (B, 3, K, K)``, ``atb (B, 3, K)``, the mean square of the fitted target ``i / s`` over
    the usable pixels ``(B,)`` (float64), and how to give the result back."""
    i, restore = to_tensor(image, "image")
    unbatched = i.ndim == 3
    if unbatched:
        i = i.unsqueeze(0)
    check_image(i, "image", 3)

    def batched(x: Array, name: str) -> torch.Tensor:
        t = to_tensor(x, name)[0].to(i.dtype)
        return t.unsqueeze(0) if unbatched and t.ndim == 3 else t

    a = batched(albedo, "albedo")
    n = batched(normals, "normals")
    m = batched(mask, "mask")
    check_image(a, "albedo", 3)
    check_image(n, "normals", 3)
    check_image(m, "mask", 1)
    for t, name in ((a, "albedo"), (n, "normals"), (m, "mask")):
        check_same_spatial(i, t, "image", name)
    k = sh.num_coeffs(order)

    w = m.detach() > 0
    if shadow is not None:
        s = batched(shadow, "shadow")
        check_image(s, "shadow", 1)
        check_same_spatial(i, s, "image", "shadow")
        w = w & (s.detach() >= shadow_floor)
    else:
        s = torch.ones_like(m)
    w = w & _valid_normals(n)
    # Only pixels that enter the solve must be finite; the sky is never read.
    for t, name in ((i, "image"), (a, "albedo"), (n, "normals"), (m, "mask"), (s, "shadow")):
        bad = ~torch.isfinite(t.detach()) & w
        if bool(bad.any()):
            raise ValueError(f"{name} holds NaN/inf at {int(bad.sum())} masked pixel(s)")
    counts = w.flatten(1).sum(dim=1)
    if bool((counts < k).any()):
        b = int(torch.argmin(counts))
        raise ValueError(
            f"mask holds {int(counts[b])} usable pixel(s) in image {b}; an order-{order} lighting solve "
            f"needs at least {k} (check the mask, the normals and the shadow)"
        )

    f64 = torch.float64
    wf = torch.where(w, m, torch.zeros_like(m)).to(f64)  # soft weights inside the mask
    zero = torch.zeros((), dtype=f64, device=i.device)
    target = torch.where(w, i.to(f64) / torch.where(w, s.to(f64), torch.ones_like(s, dtype=f64)), zero)
    alb = torch.where(w, a.to(f64), zero)
    nrm = torch.where(w, n.to(f64), torch.tensor([0.0, 0.0, 1.0], dtype=f64, device=i.device)[None, :, None, None])
    basis_img = _shading_basis(nrm, order)  # (B, K, H, W), zero where no normal
    design = alb[:, :, None] * basis_img[:, None]  # (B, 3, K, H, W)
    design = design.flatten(3)  # (B, 3, K, P)
    wflat = wf.flatten(1)[:, None, None, :]  # (B, 1, 1, P)
    ata = (design * wflat) @ design.transpose(-1, -2)  # (B, 3, K, K)
    atb = ((design * wflat) @ target.flatten(2)[:, :, :, None]).squeeze(-1)  # (B, 3, K)
    msq = (target**2 * wf).sum(dim=(1, 2, 3)) / (3.0 * wf.sum(dim=(1, 2, 3))).clamp_min(1e-30)
    return ata, atb, msq, unbatched, i.dtype, restore


def solve_lighting(image: Array, albedo: Array, normals: Array, mask: Array, shadow: Array | None = None,
                   order: int = 2, ridge: float = 1e-8, shadow_floor: float = 1e-3) -> Array:
    """Per-channel weighted least squares for the radiance SH that explains the image.

    Minimises, for each channel c, ``sum_p w_p (i_pc / s_p - a_pc sum_k B_k(n_p) L_kc)^2
    + lambda ||L_c||^2`` with ``B_k = A_l Y_lm / pi``. Pixels outside the mask (sky) get
    weight zero and are never read, so garbage there (even NaN) cannot bias L; pixels
    in deep shadow (``s < shadow_floor``) are dropped because ``i / s`` is unreliable.
    ``lambda = ridge * trace(A^T W A) / K`` keeps the solve defined when the normals do
    not span all directions (a single wall) and is scale-free. Solved in float64 through
    ``torch.linalg.solve``, so it is differentiable w.r.t. every input.

    Args:
        image: ``(B, 3, H, W)`` or ``(3, H, W)`` linear radiance.
        albedo: same shape as ``image``.
        normals: ``(B, 3, H, W)`` unit normals in the frame wanted for L.
        mask: ``(B, 1, H, W)`` weights in [0, 1] (bool or float): 1 on surfaces, 0 on sky.
        shadow: ``(B, 1, H, W)`` in [0, 1] or None (no shadow).
        order: SH order of the result.

    Returns:
        ``(B, K, 3)`` radiance SH, or ``(K, 3)`` for an unbatched ``(3, H, W)`` image.
        Bands with ``A_l = 0`` (l = 3, 5, ...) leave no trace in a Lambertian image;
        they come back as 0 (the minimum-norm solution).

    Raises:
        ValueError: shapes disagree, the mask holds fewer usable pixels than
            coefficients, or a masked pixel holds NaN/inf.
    """
    if not ridge >= 0:
        raise ValueError(f"ridge must be >= 0, got {ridge}")
    ata, atb, _, unbatched, dtype, restore = _lighting_system(image, albedo, normals, mask, shadow, order,
                                                                shadow_floor)
    k = ata.shape[-1]
    eye = torch.eye(k, dtype=ata.dtype, device=ata.device)
    lam = ridge * ata.diagonal(dim1=-2, dim2=-1).sum(-1, keepdim=True)[..., None] / k
    sol = torch.linalg.solve(ata + lam * eye, atb)  # (B, 3, K)
    out = sol.transpose(1, 2).to(dtype)  # (B, K, 3)
    return restore(out[0] if unbatched else out)


def solve_lighting_map(image: Array, albedo: Array, normals: Array, mask: Array, prior: LightingPrior,
                       shadow: Array | None = None, noise: float = 1.0, shadow_floor: float = 1e-3,
                       relative: bool = False) -> Array:
    """The most probable lighting under a lighting prior (MAP) that explains the image.

    The lighting is restricted to the prior's subspace, ``L = mean + C^T diag(scale) z``
    (:class:`physrelight.lighting_prior.LightingPrior`), with ``z ~ N(0, I)``; the image
    model's residual ``i / s - a * shading(n; L)`` is taken as Gaussian with standard
    deviation ``sigma = noise * rms(i / s)`` over the usable pixels. Minimises
    ``sum_p w_p ||i_p / s_p - a_p shading(n_p; L)||^2 + sigma^2 ||z||^2`` (all three channels
    at once: the prior couples them), in closed form, float64, differentiable.

    Why: a single photo sees only some normal directions. :func:`solve_lighting` leaves the
    unseen directions to the ridge, and projecting that solution orthogonally onto the
    subspace (the paper's step) mixes their noise into the plausible ones; the MAP estimate
    fills them from the prior instead. With the true albedo, normals and sun visibility of the
    held-out synthetic photos, the error of the resulting shading on the photo's own normals
    halves (``docs/experiments/01-lighting-solve-and-shadow-start.md``). ``noise -> 0`` gives
    the least-squares fit inside the subspace; a large ``noise`` gives the prior's mean. Unlike
    :func:`solve_lighting` the result is not scale-equivariant: the prior has units (it was
    fitted in photo units).

    ``relative=True`` frees the scale: ``L = t (mean + C^T diag(scale) z)`` with ``t`` the
    least-squares level of the prior's mean lighting on this image (``t > 0``; floored at
    1e-8), so the prior constrains the lighting's *shape* only. A photo's exposure is
    arbitrary, and with the absolute prior a photo 3 stops under-exposed gets a lighting
    pulled towards the prior's level and shape (the benchmark's dark-input stratum,
    ``docs/bench.md``); the relative solve is exactly scale-equivariant: ``c * image`` gives
    ``c * L``.

    Args:
        image, albedo: ``(B, 3, H, W)`` or ``(3, H, W)``; normals ``(B, 3, H, W)`` (frame of L);
            mask, shadow: ``(B, 1, H, W)`` as in :func:`solve_lighting`.
        prior: a lighting prior of order 2 (or the order wanted), its ``(D,)`` mean with ``D = 3 K``.
        noise: residual level relative to the image's rms, > 0.

    Returns:
        ``(B, K, 3)`` radiance SH (``(K, 3)`` for an unbatched image), in the subspace.
    """
    if not (isinstance(noise, (int, float)) and math.isfinite(noise) and noise > 0):
        raise ValueError(f"noise must be a positive number, got {noise!r}")
    order = prior.order
    ata, atb, msq, unbatched, dtype, restore = _lighting_system(image, albedo, normals, mask, shadow, order,
                                                                shadow_floor)
    nb, _, k, _ = ata.shape
    f64 = ata.dtype
    # Coefficient-major flattening (index 3 k + c): the channels' systems are blocks of one 3K system.
    gram = torch.zeros(nb, 3 * k, 3 * k, dtype=f64, device=ata.device)
    for c in range(3):
        idx = torch.arange(k, device=ata.device) * 3 + c
        gram[:, idx[:, None], idx[None, :]] = ata[:, c]
    rhs = atb.transpose(1, 2).reshape(nb, 3 * k)
    mean = prior.mean.to(device=ata.device, dtype=f64)
    basis = prior.components.to(device=ata.device, dtype=f64) * prior.scale.to(device=ata.device, dtype=f64)[:, None]
    lam = (noise**2) * msq  # sigma^2 per image
    g_mean = (gram @ mean[:, None]).squeeze(-1)  # (B, D)
    if relative:  # the level t of the mean that fits best; then the shape, around t * mean
        t = ((rhs @ mean) / (g_mean @ mean).clamp_min(1e-30)).clamp_min(1e-8)
    else:
        t = torch.ones(nb, dtype=f64, device=ata.device)
    eye = torch.eye(basis.shape[0], dtype=f64, device=ata.device)
    lhs = t[:, None, None] ** 2 * (basis @ gram @ basis.T) + lam[:, None, None] * eye
    z = torch.linalg.solve(lhs, (t[:, None] * ((rhs - t[:, None] * g_mean) @ basis.T))[..., None]).squeeze(-1)
    out = (t[:, None] * (mean + z @ basis)).reshape(nb, k, 3).to(dtype)
    return restore(out[0] if unbatched else out)
