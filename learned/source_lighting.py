"""The photo's own (source) lighting from a decomposition: MAP in the prior's subspace, the sky's
pixels as evidence, robust weights (issue 26, "a better source-lighting estimate").

The estimate is the most probable order-2 radiance SH ``L (9, 3)`` (camera frame, the
decomposition's units) under three switchable terms, all linear least squares once the weights
and two scalars are fixed, solved in closed form (float64):

**Foreground** (the image model). For each foreground pixel ``p`` and channel ``c``,
``y_pc = a_pc shading_c(n_p; L)`` with ``y = i / s`` (the photo divided by the decomposition's
shadow where ``s >= SHADOW_FLOOR``, or ``i`` itself with ``use_shadow=False``), Gaussian noise of
standard deviation ``noise * rms(y)`` (a stated constant relative to the image's level).

**Prior.** ``L = t (mean + C^T diag(scale) z)``, ``z ~ N(0, I)``
(:class:`physrelight.lighting_prior.LightingPrior`); the level ``t`` is the least-squares level of the
prior's mean on the foreground (as ``solve_lighting_map(relative=True)``): the prior speaks for the
lighting's *shape* only, so the estimate is exposure-equivariant.

**Sky** (optional; needs the intrinsics ``K``). An unclipped sky pixel looking along ``d`` records the
radiance ``L(d)`` itself, in the photo's linear units. An order-2 SH fitted to such point samples is
*not* the order-2 projection of the sky: the true radiance has everything above order 2 too (above
all, an unseen sun's order-2 lobe is cancelled in the visible sky by its higher bands). So the sky
pixels are modelled by the radiance up to order :data:`SKY_ORDER`, ``r_qc = k (Y_2(d_q) L_c +
Y_h(d_q) h_c)``, where the higher bands ``h`` are nuisance unknowns with a zero-mean Gaussian prior
whose per-band spread :data:`BAND_RMS` (relative to the DC) was measured on the shipped training
panoramas, and ``k`` is a free scale between the photo's units and the decomposition's (the
albedo's scale is the network's guess; ``k`` is solved by alternation). The order-2 part is the
projection's, the higher bands absorb what order 2 cannot say. Sky residuals have standard deviation
``sky_noise * rms(r)``. Pixels with any channel at or above ``clip_level`` (and their 8 neighbours:
at a working resolution a clipped pixel is averaged into them) are lower bounds only and are dropped.

**Robust weights** (optional). Iteratively reweighted least squares with Cauchy weights
``1 / (1 + (e / (c sigma))^2)`` on each pixel's residual (sigma: 1.4826 x the median absolute
residual, ``c = ROBUST_C``), separately for the foreground and the sky: cast shadows and speculars,
where the image model fails, stop pulling the lighting.

Every term is a switch of :class:`SourceLightingConfig`; with all three off, the solve is the
relative MAP of :func:`physrelight.image_model.solve_lighting_map` (``relative=True``).
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, replace
from typing import Any

import torch

from physrelight import sh
from physrelight.lighting_prior import LightingPrior

__all__ = ["BAND_RMS", "GREY_WORLD_ALBEDO", "ROBUST_C", "SHADOW_FLOOR", "SKY_ORDER", "SourceLightingConfig",
           "camera_directions", "cauchy_weights", "grey_world_level", "sky_observations", "solve_source_lighting"]

SKY_ORDER = 6
"""Highest SH band of the sky pixels' radiance model (bands 3..6 are nuisance unknowns)."""
BAND_RMS = {3: 0.31, 4: 0.28, 5: 0.25, 6: 0.21}
"""Per-coefficient rms of band ``l`` over the DC ``L_00`` (channel mean) of the shipped training panoramas
(city 0.33 / 0.30 / 0.27 / 0.26, courtyard 0.34 / 0.34 / 0.29 / 0.18, forest 0.26 / 0.22 / 0.20 / 0.19
for l = 3..6; ``sh.project_envmap(env, order=8)`` of each full map; sunrise, held out, not read)."""
ROBUST_C = 2.385
"""Cauchy tuning constant (95 % efficiency at Gaussian residuals), in units of the robust sigma."""
SHADOW_FLOOR = 1e-3
"""Pixels whose decomposition shadow is below this are dropped (``i / s`` is unreliable there)."""


@dataclass(frozen=True)
class SourceLightingConfig:
    """Switches and constants of :func:`solve_source_lighting`.

    The defaults are the setting chosen on the validation set ``data/val5`` (lowest mean lighting
    shading error over 70 settings, ``docs/experiments/23-source-lighting.md``): the prior trusted
    far more than the network's layers (``noise`` 24), no division by the network's shadow, robust
    weights on; the sky term off (at that noise it did not help on val5) with, when switched on, its
    best val5 setting next to it (``sky_noise`` 0.3, ``band_scale`` 3).

    Attributes:
        noise: foreground residual std relative to ``rms(i / s)`` (> 0); larger trusts the prior more.
        use_shadow: divide the photo by the decomposition's shadow (the paper's shadow-free fit).
        robust: Cauchy IRLS on the residuals (foreground and sky).
        iterations: reweighting / scale alternations (>= 1; 1 = one plain solve).
        sky: use the sky pixels (needs ``K``; without it the term is off).
        sky_noise: sky residual std relative to ``rms(r)`` over the kept sky pixels (> 0).
        band_scale: multiplies :data:`BAND_RMS` (> 0): the higher bands' prior spread.
        clip_level: linear value at or above which a sky pixel is clipped (a lower bound).
        max_sky_pixels: at most this many sky pixels, evenly strided (cost).
    """

    noise: float = 24.0
    use_shadow: bool = False
    robust: bool = True
    iterations: int = 8
    sky: bool = False
    sky_noise: float = 0.3
    band_scale: float = 3.0
    clip_level: float = 0.95
    max_sky_pixels: int = 512

    def __post_init__(self) -> None:
        for name in ("noise", "sky_noise", "band_scale", "clip_level"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive number, got {v!r}")
        if not (isinstance(self.iterations, int) and self.iterations >= 1):
            raise ValueError(f"iterations must be an integer >= 1, got {self.iterations!r}")
        if not (isinstance(self.max_sky_pixels, int) and self.max_sky_pixels >= 16):
            raise ValueError(f"max_sky_pixels must be an integer >= 16, got {self.max_sky_pixels!r}")

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)

    def but(self, **changes: Any) -> "SourceLightingConfig":
        """A copy with ``changes`` (a switch flipped for an ablation)."""
        return replace(self, **changes)


def camera_directions(K: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """``(height, width, 3)`` float64 unit camera-frame directions of the pixel centres of a pinhole
    camera with intrinsics ``K (3, 3)`` (x right, y up, z towards the viewer: the camera looks along -z).
    The same rays as :func:`physrelight.panorama.camera_rays` with an identity rotation."""
    K = torch.as_tensor(K, dtype=torch.float64)
    if K.shape != (3, 3) or not bool(torch.isfinite(K).all()):
        raise ValueError(f"K must be a finite (3, 3) matrix, got shape {tuple(K.shape)}")
    if not (float(K[0, 0]) > 0 and float(K[1, 1]) > 0):
        raise ValueError(f"K must have positive focal lengths, got fx={float(K[0, 0])}, fy={float(K[1, 1])}")
    from physrelight.panorama import camera_rays

    return camera_rays(K, torch.eye(3, dtype=torch.float64), height, width, 1)[..., 0, :]


def sky_observations(image: torch.Tensor, sky: torch.Tensor, K: torch.Tensor, clip_level: float = 0.95,
                     max_pixels: int = 512) -> tuple[torch.Tensor, torch.Tensor]:
    """The usable sky pixels of one photo: ``(directions (Q, 3), radiance (Q, 3))`` float64.

    Args:
        image: ``(3, H, W)`` linear photo. sky: ``(1, H, W)`` bool. K: ``(3, 3)`` for this pixel grid.
        clip_level: pixels with a channel at or above it, and their 8 neighbours, are dropped.
        max_pixels: keep at most this many (an even stride through the kept ones).
    """
    if image.ndim != 3 or image.shape[0] != 3:
        raise ValueError(f"image must have shape (3, H, W), got {tuple(image.shape)}")
    if sky.shape != (1, *image.shape[-2:]):
        raise ValueError(f"sky must have shape (1, {image.shape[-2]}, {image.shape[-1]}), got {tuple(sky.shape)}")
    clipped = (image.max(dim=0, keepdim=True).values >= clip_level).double()
    clipped = torch.nn.functional.max_pool2d(clipped[None], 3, stride=1, padding=1)[0] > 0
    keep = sky.bool() & ~clipped & torch.isfinite(image).all(dim=0, keepdim=True)
    d = camera_directions(K, *image.shape[-2:])[keep[0]]
    r = image.double().permute(1, 2, 0)[keep[0]]
    if d.shape[0] > max_pixels:
        idx = torch.linspace(0, d.shape[0] - 1, max_pixels).round().long()
        d, r = d[idx], r[idx]
    return d, r


def cauchy_weights(residual: torch.Tensor, c: float = ROBUST_C) -> torch.Tensor:
    """``(N,)`` Cauchy IRLS weights of ``(N,)`` residuals, scale 1.4826 x median |residual|."""
    sigma = 1.4826 * residual.abs().median().clamp_min(1e-12)
    return 1.0 / (1.0 + (residual / (c * sigma)) ** 2)


def _check(image: torch.Tensor, albedo: torch.Tensor, normals: torch.Tensor, shadow: torch.Tensor,
           foreground: torch.Tensor, sky: torch.Tensor | None, K: torch.Tensor | None) -> torch.Tensor | None:
    if image.ndim != 4 or image.shape[1] != 3:
        raise ValueError(f"image must have shape (B, 3, H, W), got {tuple(image.shape)}")
    b, _, h, w = image.shape
    for name, x, c in (("albedo", albedo, 3), ("normals", normals, 3), ("shadow", shadow, 1),
                       ("foreground", foreground, 1)):
        if tuple(x.shape) != (b, c, h, w):
            raise ValueError(f"{name} must have shape {(b, c, h, w)}, got {tuple(x.shape)}")
    if sky is not None and tuple(sky.shape) != (b, 1, h, w):
        raise ValueError(f"sky must have shape {(b, 1, h, w)}, got {tuple(sky.shape)}")
    if K is None:
        return None
    K = torch.as_tensor(K, dtype=torch.float64)
    if K.shape == (3, 3):
        K = K[None].expand(b, 3, 3)
    if K.shape != (b, 3, 3):
        raise ValueError(f"K must have shape (3, 3) or ({b}, 3, 3), got {tuple(K.shape)}")
    return K


def _one_image(y: torch.Tensor, a: torch.Tensor, nb: torch.Tensor, fw: torch.Tensor, prior: LightingPrior,
               sky_dirs: torch.Tensor | None, sky_rad: torch.Tensor | None,
               cfg: SourceLightingConfig) -> torch.Tensor:
    """The solve of one photo. ``y, a (P, 3)`` target and albedo, ``nb (P, 9)`` the shading basis
    ``A_l Y_lm(n) / pi``, ``fw (P,)`` base weights; sky ``(Q, 3)`` each or None. Returns ``(9, 3)``."""
    f64 = torch.float64
    mean = prior.mean.to(f64).reshape(9, 3)
    basis = (prior.components.to(f64) * prior.scale.to(f64)[:, None]).reshape(-1, 9, 3)  # (k, 9, 3)
    nz = basis.shape[0]
    # Foreground design: pred_pc = a_pc nb_p . L_c, with L = t (mean + sum_j z_j basis_j).
    pred_mean = a * (nb @ mean)  # (P, 3)
    use_sky = sky_dirs is not None and sky_rad is not None and sky_dirs.shape[0] >= 9
    sky_only = y.shape[0] == 0  # no usable foreground: the level is the sky's, in the photo's units
    if sky_only:
        if not use_sky:
            raise ValueError("no usable foreground pixels and no usable sky pixels: nothing to solve from")
        pred_mean_sky = torch.as_tensor(sh.basis(sky_dirs, 2), dtype=f64) @ mean
        num, den = float((pred_mean_sky * sky_rad).sum()), float((pred_mean_sky**2).sum())
    else:
        num, den = float((fw[:, None] * pred_mean * y).sum()), float((fw[:, None] * pred_mean**2).sum())
    t = max(num / den, 1e-8) if den > 0 else 1e-8
    dz = t * a[:, None, :] * torch.einsum("pk,jkc->pjc", nb, basis)  # (P, nz, 3)
    fg_rows = dz.permute(0, 2, 1).reshape(-1, nz)  # row (p, c)
    fg_rhs = (y - t * pred_mean).reshape(-1)
    sigma_f2 = 1.0 if sky_only else (cfg.noise**2) * float((fw[:, None] * y**2).sum() / (3.0 * fw.sum()))
    if use_sky:
        ys = torch.as_tensor(sh.basis(sky_dirs, SKY_ORDER), dtype=f64)  # (Q, (SKY_ORDER + 1)^2)
        y2, yh = ys[:, :9], ys[:, 9:]
        nh = yh.shape[1]
        band = torch.cat([torch.full((2 * l + 1,), BAND_RMS[l]) for l in range(3, SKY_ORDER + 1)]).to(f64)
        dc = (t * mean[0]).abs().clamp_min(1e-12)  # (3,) the level-fitted mean's DC per channel
        h_std = cfg.band_scale * band[:, None] * dc[None, :]  # (nh, 3)
        sigma_s2 = (cfg.sky_noise**2) * float((sky_rad**2).mean())
        q = sky_dirs.shape[0]
        sw = torch.ones(q, dtype=f64)
    n_unk = nz + (3 * nh if use_sky else 0)
    fwr = fw.clone()
    z = torch.zeros(nz, dtype=f64)
    h = torch.zeros(nh, 3, dtype=f64) if use_sky else None
    k_s = 1.0
    for it in range(cfg.iterations):
        light = t * (mean + torch.einsum("j,jkc->kc", z, basis))
        if use_sky and not sky_only:  # the scale between the photo's units and the decomposition's
            m = y2 @ light + yh @ h  # (Q, 3)
            num, den_k = float((sw[:, None] * m * sky_rad).sum()), float((sw[:, None] * m * m).sum())
            if den_k > 0 and num > 0:  # else keep the last scale (a sky the model cannot match at all)
                k_s = num / den_k
        if cfg.robust and it > 0 and not sky_only:
            # Relative residuals: a cast shadow or a highlight is a factor on the pixel, whatever its level.
            pred = a * (nb @ light)
            res = (y - pred).norm(dim=1) / pred.norm(dim=1).clamp_min(1e-3 * float(pred.norm(dim=1).mean()))
            fwr = fw * cauchy_weights(res)
        if cfg.robust and it > 0 and use_sky:
            sw = cauchy_weights((sky_rad - k_s * (y2 @ light + yh @ h)).norm(dim=1))
        wrow = fwr.repeat_interleave(3) / sigma_f2
        lhs = torch.zeros(n_unk, n_unk, dtype=f64)
        rhs = torch.zeros(n_unk, dtype=f64)
        lhs[:nz, :nz] = (fg_rows * wrow[:, None]).T @ fg_rows + torch.eye(nz, dtype=f64)
        rhs[:nz] = (fg_rows * wrow[:, None]).T @ fg_rhs
        if use_sky:
            # Sky rows per channel c: k (t y2 . basis_jc z_j + yh . h_c) = r_c - k t y2 . mean_c
            for c in range(3):
                dz_s = k_s * t * (y2 @ basis[:, :, c].T)  # (Q, nz)
                dh = k_s * yh  # (Q, nh)
                rows = torch.cat([dz_s, torch.zeros(q, 3 * nh, dtype=f64)], dim=1)
                rows[:, nz + c * nh: nz + (c + 1) * nh] = dh
                target = sky_rad[:, c] - k_s * t * (y2 @ mean[:, c])
                wr = sw / sigma_s2
                lhs += (rows * wr[:, None]).T @ rows
                rhs += (rows * wr[:, None]).T @ target
                idx = torch.arange(nz + c * nh, nz + (c + 1) * nh)
                lhs[idx, idx] += 1.0 / h_std[:, c] ** 2
        sol = torch.linalg.solve(lhs, rhs)
        z = sol[:nz]
        if use_sky:
            h = sol[nz:].reshape(3, nh).T
        if not (cfg.robust or use_sky):
            break  # nothing to re-weight or re-scale: one solve is the answer
    return t * (mean + torch.einsum("j,jkc->kc", z, basis))


@torch.no_grad()
def solve_source_lighting(image: torch.Tensor, albedo: torch.Tensor, normals: torch.Tensor, shadow: torch.Tensor,
                          foreground: torch.Tensor, prior: LightingPrior, sky: torch.Tensor | None = None,
                          K: torch.Tensor | None = None,
                          config: SourceLightingConfig | None = None) -> torch.Tensor:
    """The source lighting of each photo (see the module doc).

    Args:
        image: ``(B, 3, H, W)`` linear photos.
        albedo, normals: ``(B, 3, H, W)`` the decomposition's (normals in the camera frame).
        shadow: ``(B, 1, H, W)`` the decomposition's shadow in [0, 1] (read when ``use_shadow``).
        foreground: ``(B, 1, H, W)`` bool or 0/1: the pixels the image model explains.
        prior: an order-2 :class:`LightingPrior` (photo units).
        sky: ``(B, 1, H, W)`` bool, the sky pixels (read by the sky term only).
        K: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics of this pixel grid, or None (the sky term is off).
        config: switches and constants (None: :class:`SourceLightingConfig` defaults).

    Returns:
        ``(B, 9, 3)`` float32 camera-frame radiance SH in the decomposition's units.

    Raises:
        ValueError: shapes disagree, a prior of another order, or a photo with fewer than 9 usable
            foreground pixels and fewer than 9 usable sky pixels (with 9 sky pixels and no foreground the
            sky alone speaks, its level in the photo's units).
    """
    cfg = SourceLightingConfig() if config is None else config
    Kb = _check(image, albedo, normals, shadow, foreground, sky, K)
    if prior.order != 2:
        raise ValueError(f"the prior must be of order 2, got order {prior.order}")
    f64 = torch.float64
    out = []
    for b in range(image.shape[0]):
        n = normals[b].to(f64)
        valid = (n.norm(dim=0) > 1e-6) & (foreground[b, 0] > 0.5) & torch.isfinite(image[b]).all(0)
        s = shadow[b, 0].to(f64)
        if cfg.use_shadow:
            valid &= s >= SHADOW_FLOOR
        dirs = rad = None
        if cfg.sky and Kb is not None and sky is not None:
            dirs, rad = sky_observations(image[b], sky[b], Kb[b], cfg.clip_level, cfg.max_sky_pixels)
        if int(valid.sum()) < 9:
            if dirs is None or dirs.shape[0] < 9:
                raise ValueError(f"photo {b} has {int(valid.sum())} usable foreground pixels and no usable sky; "
                                 "the lighting needs 9 of either")
            valid = torch.zeros_like(valid)  # too few to fit: the sky alone speaks
        nn = torch.nn.functional.normalize(n[:, valid].T, dim=1)  # (P, 3)
        nb = torch.as_tensor(sh.basis(nn, 2), dtype=f64) * (sh.irradiance_transfer(2, f64) / math.pi)[None, :]
        i = image[b].to(f64)[:, valid].T
        y = i / s[valid][:, None] if cfg.use_shadow else i
        a = albedo[b].to(f64)[:, valid].T
        fw = torch.ones(y.shape[0], dtype=f64)
        out.append(_one_image(y, a, nb, fw, prior, dirs, rad, cfg))
    return torch.stack(out).to(torch.float32)


GREY_WORLD_ALBEDO = 0.18
"""The median foreground albedo :func:`grey_world_level` assumes: a light meter's middle grey (fixed a priori,
study 36)."""


def grey_world_level(image: torch.Tensor, normals: torch.Tensor, lighting: torch.Tensor, foreground: torch.Tensor,
                     albedo: float = GREY_WORLD_ALBEDO) -> torch.Tensor:
    """``(B,)`` the factor that gives ``lighting`` the level a light meter would read: the one under which
    the foreground's median implied albedo ``lum(image) / lum(shading(n; g L))`` is ``albedo``.

    A camera's auto exposure brings a scene's average to middle grey, and a meter reads the light by assuming
    the scene reflects as middle grey does; the network's albedo, the other source of the level, is a guess
    (study 36: on ``bench --real``'s crops the level's mean absolute error 0.786 -> 0.612 stops on the training
    side, 0.936 -> 0.815 on sunrise). Exposure-equivariant: twice the image, twice the factor. 1 where fewer
    than 16 foreground pixels have shading above 1e-6 of its mean.

    Args:
        image: ``(B, 3, H, W)`` linear photo. normals: ``(B, 3, H, W)`` camera frame. lighting: ``(B, 9, 3)``
            radiance SH in the same frame. foreground: ``(B, 1, H, W)`` bool.
        albedo: the assumed median albedo, in (0, 1].
    """
    from physrelight import colour, image_model

    if image.ndim != 4 or image.shape[1] != 3:
        raise ValueError(f"image must have shape (B, 3, H, W), got {tuple(image.shape)}")
    b, _, h, w = image.shape
    if normals.shape != image.shape or foreground.shape != (b, 1, h, w) or lighting.shape != (b, 9, 3):
        raise ValueError(f"normals {tuple(normals.shape)}, foreground {tuple(foreground.shape)} and lighting "
                         f"{tuple(lighting.shape)} must be ({b}, 3, {h}, {w}), ({b}, 1, {h}, {w}) and ({b}, 9, 3)")
    if not 0 < albedo <= 1:
        raise ValueError(f"albedo must lie in (0, 1], got {albedo}")
    lum = torch.tensor(colour.LUMINANCE, dtype=torch.float64)
    s = torch.einsum("bchw,c->bhw", image_model.shading(normals.double(), lighting.double()), lum)
    y = torch.einsum("bchw,c->bhw", image.double().clamp_min(0), lum)
    out = torch.ones(b, dtype=torch.float64)
    for i in range(b):
        fg = foreground[i, 0].bool()
        if int(fg.sum()) == 0:
            continue
        ok = fg & (s[i] > 1e-6 * s[i][fg].mean().clamp_min(1e-12))
        if int(ok.sum()) >= 16:
            out[i] = torch.median(y[i][ok] / s[i][ok]) / albedo
    return out
