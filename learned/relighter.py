"""Inference: decompose a photo and relight it (first stage; the neural renderer comes later).

``Relighter.load()`` reads the weights shipped in ``learned/weights`` (safetensors, no
network access needed). ``decompose(image)`` gives albedo, normals (camera frame),
shadow and the solved, prior-projected SH lighting (camera frame); ``relight(image,
target)`` renders the Lambertian SH relighting ``albedo * shading(n; L_target) *
ShadowNet(n, L_target)`` and keeps the photo's sky.

Images: a photo as numpy ``(H, W, 3)`` (uint8, or float display values in [0, 1]) or torch
``(3, H, W)`` / ``(B, 3, H, W)`` float display values; it is linearised with the sRGB
curve. Results come back as the type given: numpy ``(H, W, C)`` or torch
``(B, C, H, W)`` (``(C, H, W)`` for an unbatched torch image). Lighting is ``(9, 3)``
radiance SH (``(B, 9, 3)`` for a batch).

Targets: SH coefficients ``(9, 3)``, an environment map (array ``(H, 2H, 3)`` or an EXR
path) or a sun direction ``(3,)`` (a sun of its elevation's colour plus a clear or overcast sky), all in the *world* frame (Y up), rotated into the camera with ``world_to_camera``
(``(4, 4)`` or its ``(3, 3)`` rotation); without it the camera is assumed level and
looking along world -Z (camera frame = world frame).
"""

from __future__ import annotations

import functools
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physrelight import colour, image_model, sh, stats
from physrelight.lighting_prior import LightingPrior
from physrelight.quotient import SMOOTH_RADIUS, quotient_relight
from physrelight.sky_mask import GROW_REACH
from physrelight.sky_model import FIT_GLOW_EXPONENT, horizon_clamped, sun_disc

from . import checkpoint as ckpt
from .lighting import WEIGHTS_DIR, load_prior
from .networks import InverseNet, ShadowNet, repair_top_rows
from .objectives import decompose_and_solve
from .source_lighting import SourceLightingConfig, grey_world_level, solve_source_lighting

DEFAULT_METHOD = "proposed"
"""The method of ``relight`` and the command line unless told: the shipped renderer on top of the quotient
image, which beat ``quotient`` on both held-out sets (docs/experiments/29-renderer-on-the-quotient.md)."""

__all__ = ["DEFAULT_FOV_DEG", "LIGHTING_ESTIMATORS", "RELIGHT_METHODS", "SKY_LEVELS", "SKY_SOURCES", "SKY_TYPES", "WEIGHT_FILES", "Relighter", "dc_luminance",
           "envmap_sun", "estimate_camera_pitch", "estimate_pitch", "exposure_scale", "fitted_sky", "fill_weights_folder", "match_exposure", "pitch_from_verticals", "rotate_azimuth", "sky_map_kind",
           "sun_lighting", "sun_sky_map", "target_sky", "transfer_to_full_resolution", "working_resolution"]


DEFAULT_FOV_DEG = 60.0
"""A photo's horizontal field of view when nothing says otherwise (no EXIF focal length, no ``--fov``)."""
SKY_SOURCES = ("target", "fit", "gan", "keep")
"""Where a relit photo's sky comes from: ``"target"``, the target's own sky through the photo's camera (an
env map or a sun target); ``"fit"``, the outdoor sky model fitted to the target's order-2 SH
(:func:`physrelight.sky_model.fit_sky`; any target); ``"gan"``, SkyGAN; ``"keep"``, the photo's own."""
LIGHTING_ESTIMATORS = ("network", "source_map")
"""The source-lighting steps of :meth:`Relighter.decompose_linear`."""


def _as_batch(image: Any) -> tuple[torch.Tensor, str]:
    """A photo's array -> ``(B, 3, H, W)`` as it is (no conversion) and how to give results back ("numpy", "chw",
    "bchw"): the layouts and the least size both kinds of photo take."""
    if isinstance(image, np.ndarray):
        if image.ndim != 3 or image.shape[-1] != 3:
            raise ValueError(f"a numpy image must have shape (H, W, 3), got {image.shape}")
        t = torch.from_numpy(np.ascontiguousarray(image)).permute(2, 0, 1)[None]
        kind = "numpy"
    elif isinstance(image, torch.Tensor):
        if image.ndim == 3:
            t, kind = image[None], "chw"
        elif image.ndim == 4:
            t, kind = image, "bchw"
        else:
            raise ValueError(f"a torch image must have shape (3, H, W) or (B, 3, H, W), got {tuple(image.shape)}")
        if t.shape[1] != 3:
            raise ValueError(f"a torch image must have 3 channels, got shape {tuple(image.shape)}")
    else:
        raise ValueError(f"image must be a numpy array or torch tensor, got {type(image).__name__}")
    if t.shape[-1] < 8 or t.shape[-2] < 8:
        raise ValueError(f"image must be at least 8x8 pixels, got {tuple(t.shape[-2:])}")
    return t, kind


def _as_image(image: Any) -> tuple[torch.Tensor, str]:
    """Photo (display values) -> ``(B, 3, H, W)`` linear float32 and how to give results back (:func:`_as_batch`)."""
    t, kind = _as_batch(image)
    if t.dtype in (torch.uint8,):
        t = t.float() / 255.0
    elif not t.is_floating_point():
        raise ValueError(f"image must be uint8 or float display values in [0, 1], got dtype {t.dtype}")
    lin = colour.from_ldr(t.detach().float().cpu())  # raises on NaN or values outside [0, 1]
    return lin, kind


RADIANCE_WHITE_QUANTILE = 0.999
"""A radiance photo (``radiance=True``) is brought to a display-like range first: its luminance at this quantile
to 1, as a camera exposed not to clip more than a thousandth of the frame (unchanged when that is already at or
below 1). The networks, the sky mask's tests and the display curve all expect a photo's range."""


def _as_radiance(image: Any) -> tuple[torch.Tensor, str, float]:
    """A linear radiance photo -> ``(B, 3, H, W)`` float32 in a display-like range, how to give results back, and
    the gain that brought it there (:data:`RADIANCE_WHITE_QUANTILE`; the photo's units are ``result / gain``)."""
    from physrelight.stats import quantile

    t, kind = _as_batch(image)
    if not t.is_floating_point():
        raise ValueError(f"a radiance photo must hold floats, got dtype {t.dtype}")
    t = t.detach().float().cpu()
    if not bool(torch.isfinite(t).all()):
        raise ValueError("a radiance photo must be finite (it holds NaN or inf)")
    if bool((t < 0).any()):
        raise ValueError(f"a radiance photo must be non-negative, min {float(t.min()):.4g}")
    lum = (t * t.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1)
    white = float(quantile(lum, RADIANCE_WHITE_QUANTILE))
    if white <= 0.0:
        raise ValueError("a radiance photo must not be black")
    gain = 1.0 / white if white > 1.0 else 1.0
    return t * gain, kind, gain


def _give_back(x: torch.Tensor, kind: str) -> Any:
    if kind == "numpy":
        return x[0].permute(1, 2, 0).numpy()
    return x[0] if kind == "chw" else x


def _as_mask(mask: Any, like: torch.Tensor) -> torch.Tensor:
    b, _, h, w = like.shape
    if mask is None:
        return torch.zeros(b, 1, h, w, dtype=torch.bool)
    m = torch.as_tensor(np.asarray(mask) if not isinstance(mask, torch.Tensor) else mask)
    if m.ndim == 2:
        m = m[None, None]
    elif m.ndim == 3:
        m = m[:, None] if m.shape[0] == b and m.shape[1:] == (h, w) else m[None]
    if m.shape != (b, 1, h, w):
        raise ValueError(f"sky_mask must have shape (H, W) = ({h}, {w}) or (B, 1, H, W), got {tuple(m.shape)}")
    return m.bool() if m.dtype == torch.bool else m > 0.5


def _rotation(world_to_camera: Any) -> torch.Tensor:
    if world_to_camera is None:
        return torch.eye(3, dtype=torch.float64)
    r = torch.as_tensor(np.asarray(world_to_camera, dtype=np.float64) if not isinstance(world_to_camera, torch.Tensor)
                        else world_to_camera.double())
    if r.shape == (4, 4):
        r = r[:3, :3]
    if r.shape != (3, 3):
        raise ValueError(f"world_to_camera must have shape (4, 4) or (3, 3), got {tuple(r.shape)}")
    if not torch.allclose(r @ r.T, torch.eye(3, dtype=torch.float64), atol=1e-4) or float(torch.det(r)) <= 0:
        raise ValueError("world_to_camera's rotation block must be a proper rotation")
    return r


# The files of a weights folder, as Relighter.load reads them (the renderer and the sky networks optional).
WEIGHT_FILES = ("inverse.safetensors", "shadow.safetensors", "lighting_prior.npz", "renderer.safetensors",
                "sky_segmentation.safetensors", "sky_gan.safetensors")


def fill_weights_folder(dest: str | os.PathLike, source: str | os.PathLike | None = None) -> list[str]:
    """Copy into ``dest`` each of :data:`WEIGHT_FILES` that it lacks and ``source`` (a weights
    folder; None = the shipped one) has, each atomically: a candidate's exported networks become a
    complete folder for :meth:`Relighter.load`. Returns the names copied."""
    import shutil

    from physrelight import io

    src = Path(source) if source is not None else WEIGHTS_DIR
    if not src.is_dir():
        raise FileNotFoundError(f"no weights folder at {str(src)!r}")
    copied = []
    for name in WEIGHT_FILES:
        if not (Path(dest) / name).exists() and (src / name).is_file():
            with io.atomic_path(Path(dest) / name) as tmp:
                shutil.copyfile(src / name, tmp)
            copied.append(name)
    return copied


class Relighter:
    """The first stage at inference: inverse network + lighting solve + ShadowNet.

    Use :meth:`load`; the constructor takes ready modules.
    """

    def __init__(self, inverse: InverseNet, shadow_net: ShadowNet, prior: LightingPrior, res: int = 64,
                 renderer: torch.nn.Module | None = None, sky_segmenter: torch.nn.Module | None = None,
                 sky_generator: torch.nn.Module | None = None, lighting_estimator: str = "source_map",
                 source_config: SourceLightingConfig | None = None, ratio_radius: int = SMOOTH_RADIUS) -> None:
        if ratio_radius < 0 or int(ratio_radius) != ratio_radius:
            raise ValueError(f"ratio_radius must be a non-negative integer, got {ratio_radius!r}")
        if lighting_estimator not in LIGHTING_ESTIMATORS:
            raise ValueError(f"lighting_estimator must be one of {LIGHTING_ESTIMATORS}, got {lighting_estimator!r}")
        self.inverse, self.shadow_net, self.prior, self.res = inverse.eval(), shadow_net.eval(), prior, res
        # "source_map" (default since issue 26): learned.source_lighting (MAP in the prior's subspace, robust
        # weights, the sky's pixels when K is given; each a switch of source_config); "network": the
        # lighting step exported with the inverse network (map_relative), the figures before.
        self.lighting_estimator = lighting_estimator
        self.source_config = source_config if source_config is not None else SourceLightingConfig()
        self.renderer = renderer.eval() if renderer is not None else None
        self.sky_segmenter = sky_segmenter.eval() if sky_segmenter is not None else None
        self.sky_generator = sky_generator.eval() if sky_generator is not None else None
        # The quotient methods' ratio is guided-filtered at this radius (px at the working resolution; 0 = raw
        # ratio, the figures before study 27): physrelight.quotient.smooth_ratio.
        self.ratio_radius = int(ratio_radius)
        # The segmenter's sky is grown by sky-coloured pixels within this fraction of the short side
        # (learned.sky_segmentation.grow_sky_by_colour): the sky between a lattice's bars (GROW_REACH, study 40;
        # 0: off, the masks before).
        self.sky_grow = GROW_REACH
        # SkyGAN's sky is blurred within the mask by a Gaussian of this fraction of the short side
        # (learned.sky_gan.smooth_sky; None: SMOOTH_SIGMA, 1/8; 0: SkyGAN's own sky; study 31).
        self.sky_smooth: float | None = None
        # The level of the estimated source lighting that a rendered sky (sky source "target" or "fit") is put
        # in, on the estimated track: "grey_world", the level under which the foreground's median albedo is
        # middle grey (learned.source_lighting.grey_world_level; study 36), or "decomposition", the lighting
        # estimate's own (the network's albedo; the figures before). The relit foreground does not depend on
        # it (a quotient of two shadings of one estimate); the sky's brightness against it does.
        self.sky_level = "grey_world"
        # A quotient-based renderer's gain for the target divided by its gain for the source lighting itself,
        # so a photo relit to its own lighting gets the quotient's ratio alone. Off: measured worse on data/val5
        # (l1 +0.0053 against the plain gain, +0.0011 against quotient; study 29).
        self.renderer_gain_ratio = False
        # The photo smoothed before relighting, as (radius, strength) of physrelight.denoise.denoise (DENOISE:
        # study 37's setting, relight --denoise); None, the default: the photo as it is. Off by default: it
        # helps the synthetic bench but its noise estimate reads pixel-scale texture as noise, and real foliage
        # loses its texture (study 37).
        self.denoise: tuple[int, float] | None = None
        # Estimated track with a given source level (relight_linear's source_lighting): the weight of the grey
        # world in the relit level. The estimated lighting's shape, put at the given level, says how much light
        # falls on the visible surfaces; so does the photo's brightness under a middle-grey albedo. The level
        # used is the geometric blend: exponent 0 (the default), the shape alone; 1, the grey world alone
        # (learned.source_lighting.grey_world_level; study 39).
        self.level_prior = 0.0
        # Called with the name of each stage of a relighting as it starts (RELIGHT_STAGES), for a progress
        # display: a 4000 x 2669 photo takes about 40 s at one thread. None: silent.
        self.on_stage: Callable[[str], None] | None = None

    @property
    def renderer_base(self) -> str | None:
        """What the loaded renderer's gain multiplies (:data:`learned.neural_renderer.BASES`), None without one."""
        return None if self.renderer is None else self.renderer.base

    @classmethod
    def load(cls, path: str | os.PathLike | None = None, renderer: str | os.PathLike | None = None,
             lighting_estimator: str = "source_map", source_config: SourceLightingConfig | None = None,
             ratio_radius: int = SMOOTH_RADIUS) -> "Relighter":
        """Load ``inverse.safetensors``, ``shadow.safetensors``, ``lighting_prior.npz`` and, when
        present, ``renderer.safetensors``, ``sky_segmentation.safetensors`` and
        ``sky_gan.safetensors`` from ``path`` (a folder; None = the weights shipped in the
        package). ``renderer`` names another renderer weights file; ``lighting_estimator`` and
        ``source_config`` pick the source-lighting step and ``ratio_radius`` the quotient ratio's guided
        filter (see :class:`Relighter`)."""
        d = Path(path) if path is not None else WEIGHTS_DIR
        if not d.is_dir():
            raise FileNotFoundError(f"no weights folder at {str(d)!r}")
        from .networks import load_network

        inverse = load_network(d / "inverse.safetensors", "inverse")
        shadow = load_network(d / "shadow.safetensors", "shadow")
        inv_m = ckpt.read_metadata(d / "inverse.safetensors")  # for its working resolution
        # The second stage, each part when its weights are there.
        segmenter = generator = None
        rpath = Path(renderer) if renderer is not None else d / "renderer.safetensors"
        if renderer is not None and not rpath.is_file():
            raise FileNotFoundError(f"no renderer weights at {str(rpath)!r}")
        neural = None
        if rpath.is_file():
            from .neural_renderer import load_renderer

            neural = load_renderer(rpath)
        if (d / "sky_segmentation.safetensors").is_file():
            from .sky_segmentation import load_sky_segmenter

            segmenter = load_sky_segmenter(d / "sky_segmentation.safetensors")
        if (d / "sky_gan.safetensors").is_file():
            from .sky_gan import load_sky_generator

            generator = load_sky_generator(d / "sky_gan.safetensors")
        return cls(inverse, shadow, load_prior(d / "lighting_prior.npz"), int(inv_m.get("res", 64)), neural,
                   segmenter, generator, lighting_estimator, source_config, ratio_radius)

    @torch.no_grad()
    def decompose_linear(self, image: torch.Tensor, sky: torch.Tensor,
                         K: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """Tensors in, tensors out: ``image (B, 3, H, W)`` linear, ``sky (B, 1, H, W)`` bool ->
        ``albedo, normals, shadow, lighting (B, 9, 3), lighting_solved, foreground``.

        ``K``: ``(3, 3)`` or ``(B, 3, 3)`` intrinsics of ``image``'s pixel grid, or None; read only by
        the ``"source_map"`` estimator's sky term (:mod:`learned.source_lighting`).

        The layers' top two rows are repaired (:func:`learned.networks.repair_top_rows`: the band
        along the top of every layer) after the lighting is solved, from the layers as the network
        gives them: the shipped lighting step was trained with those rows as they are, and solving
        on repaired rows costs the quick synthetic bench 0.0025 l1."""
        out = decompose_and_solve(self.inverse, image, sky, self.prior)
        if self.lighting_estimator == "source_map":
            out["lighting"] = solve_source_lighting(image, out["albedo"], out["normals"], out["shadow"],
                                                    out["foreground"], self.prior, sky=sky, K=K,
                                                    config=self.source_config)
        out.update({k: repair_top_rows(out[k]) for k in ("albedo", "normals", "shadow")})
        return out

    def sky_mask(self, image: torch.Tensor, sky_mask: Any = None) -> torch.Tensor:
        """``(B, 1, H, W)`` bool sky mask of linear ``image (B, 3, H, W)``: the given mask, else the
        sky segmenter's (when shipped), else all False (every pixel is foreground)."""
        if sky_mask is None and self.sky_segmenter is not None:
            from .sky_segmentation import segment_sky

            return segment_sky(self.sky_segmenter, image)
        return _as_mask(sky_mask, image)

    def decompose(self, image: Any, sky_mask: Any = None) -> dict[str, Any]:
        """Albedo ``(.., 3)``, normals ``(.., 3)`` (camera frame), shadow ``(.., 1)``, lighting
        ``(9, 3)`` (camera-frame radiance SH in the linearised photo's units) and the sky
        mask ``(.., 1)`` (:meth:`sky_mask`: the given one, else the segmenter's).
        """
        lin, kind = _as_image(image)
        sky = self.sky_mask(lin, sky_mask)
        out = self.decompose_linear(lin, sky)
        light = out["lighting"] if kind == "bchw" else out["lighting"][0]
        result = {k: _give_back(out[k], kind) for k in ("albedo", "normals", "shadow")}
        result["lighting"] = light.numpy() if kind == "numpy" else light
        result["sky_mask"] = _give_back(sky, kind)
        return result

    def target_lighting(self, target: Any, world_to_camera: Any = None, sky: str = "clear") -> torch.Tensor:
        """``(9, 3)`` camera-frame radiance SH of a target (SH ``(9, 3)``, env map or EXR path, or a sun
        direction ``(3,)`` towards the sun with ``sky`` in :data:`SKY_TYPES`, see
        :func:`sun_lighting`; all in the world frame)."""
        if isinstance(target, (str, os.PathLike)):
            from physrelight import envmap

            target = envmap.read(target)
        t = torch.as_tensor(np.asarray(target, dtype=np.float64) if not isinstance(target, torch.Tensor)
                            else target.double())
        if t.shape == (3,):
            coeffs = torch.as_tensor(sun_lighting(t.numpy(), sky))
        elif t.ndim == 2 and t.shape == (9, 3):
            coeffs = t
        elif t.ndim == 3 and t.shape[-1] == 3 and t.shape[1] == 2 * t.shape[0]:
            coeffs = torch.as_tensor(sh.project_envmap(t.numpy(), order=2))
        else:
            raise ValueError(f"target must be SH coefficients (9, 3), an env map (H, 2H, 3) or a sun direction (3,), "
                             f"got {tuple(t.shape)}")
        if not torch.isfinite(coeffs).all():
            raise ValueError("target holds NaN or inf")
        return torch.as_tensor(sh.rotate(coeffs, _rotation(world_to_camera)))

    def target_sun(self, target: Any, world_to_camera: Any = None, sky: str = "clear") -> torch.Tensor | None:
        """``(9, 3)`` camera-frame radiance SH of the sun alone within a target (see
        :meth:`target_lighting`), or None when it has none: a sun direction's delta sun (clear sky),
        an environment map's sun as :func:`envmap_sun` finds it, an SH target's the delta sun of the sky
        model fitted to it (:func:`physrelight.sky_model.fit_sky`; study 33); overcast skies: None."""
        if isinstance(target, (str, os.PathLike)):
            from physrelight import envmap

            target = envmap.read(target)
        t = np.asarray(target.detach().cpu().double() if isinstance(target, torch.Tensor) else target, np.float64)
        if t.shape == (3,):
            d = _sun_direction(t)
            coeffs = None if sky == "overcast" else sh.project_sun(d, _sun_rgb(d), order=2)
        elif t.ndim == 3 and t.shape[-1] == 3 and t.shape[1] == 2 * t.shape[0]:
            sun = envmap_sun(t)
            coeffs = None if sun is None else np.asarray(sh.project_envmap(sun, order=2))
        elif t.shape == (9, 3) and np.all(np.isfinite(t)) and np.all(t[0] > 0):
            from physrelight.sky_model import fit_sky

            # An SH target says nothing of its sun; the fitted sky model's sun lets the quotient shade it by
            # its exact cosine, as an env map's is (study 33: data/val5 -0.0009 l1; data/heldout +0.0003, n.s.).
            fit = fit_sky(t)
            coeffs = np.asarray(sh.project_sun(fit.sun_direction, fit.weights[0], order=2)) \
                if bool((fit.weights[0] > 0).any()) else None
        else:
            coeffs = None
        return None if coeffs is None else torch.as_tensor(sh.rotate(coeffs, _rotation(world_to_camera)))

    @torch.no_grad()
    def relight_linear(self, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                       source_lighting: torch.Tensor | None = None, method: str = DEFAULT_METHOD,
                       decomposition: dict[str, torch.Tensor] | None = None,
                       known_source: bool = False, *, target_sun: torch.Tensor | None = None,
                       source_sun: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
        """Relight linear images to a camera-frame SH target; tensors in, tensors out.

        Args:
            image: ``(B, 3, H, W)`` linear photo (runs at this resolution).
            sky: ``(B, 1, H, W)`` bool, True on sky (kept from ``image``).
            target: ``(B, 9, 3)`` or ``(9, 3)`` camera-frame radiance SH of the target lighting.
            source_lighting: ``(B, 9, 3)`` or ``(9, 3)`` the source photo's lighting in the same
                units as ``target``, or None. The decomposition's albedo and lighting share an
                unknown scale, so the target is mapped into the decomposition's units by the
                ratio of DC luminances: estimated source / ``source_lighting`` (None: estimated
                source / ``target``, i.e. the photo keeps its exposure and only the lighting's
                shape changes). An estimate without a positive DC term (no usable foreground)
                takes the lighting prior's mean level instead.
            method: ``"proposed"`` (the default, :data:`DEFAULT_METHOD`: the neural renderer; the
                shipped one is a learned gain on the ``"quotient"`` image, given ShadowNet's target
                shadow, docs/experiments/29-renderer-on-the-quotient.md; ``"shadownet_lambertian"``
                when no renderer weights are loaded), ``"lambertian_sh"`` (``albedo * shading(n; target)``,
                the InverseRenderNet-style baseline), ``"shadownet_lambertian"`` (times
                ShadowNet's shadow for the target), ``"quotient"`` (the photo times
                ``shading(n; target) / shading(n; source)``, :mod:`physrelight.quotient`: the
                albedo is never re-synthesised) or ``"quotient_shadownet"`` (the same with
                ShadowNet's target shadow over the decomposition's source shadow).
            decomposition: :meth:`decompose_linear` of this very ``(image, sky)``, to relight one photo
                to many targets without decomposing it again; None: decompose here.
            known_source: the two lighting tracks of the quotient methods. False (*estimated*, the
                paper's setting): the source shading is the decomposition's estimate, only its level
                taken from ``source_lighting``. True (*known*): the source shading is
                ``source_lighting`` itself (the photo's own environment map, measured on set), so a
                target equal to it gives the photo back exactly. The other methods ignore it.
            target_sun, source_sun: ``(B, 9, 3)`` or ``(9, 3)`` the radiance SH of the sun alone
                within ``target`` / ``source_lighting`` (same units), or None. The quotient methods
                then shade the sun by its exact clamped cosine and the rest by SH
                (:func:`physrelight.quotient.quotient_ratio` ``sun_cosine``); ``source_sun`` is read
                on the known track only (on the estimated one the source is the decomposition's SH).

        Returns:
            ``relit (B, 3, H, W)`` linear, sky pixels equal to ``image``; ``target (B, 9, 3)`` in
            the decomposition's units; ``target_shadow (B, 1, H, W)`` (ones for ``lambertian_sh``);
            the decomposition's ``albedo``, ``normals``, ``shadow``, ``lighting``, ``foreground``.
        """
        if method not in RELIGHT_METHODS:
            raise ValueError(f"method must be one of {RELIGHT_METHODS}, got {method!r}")
        if image.ndim != 4 or image.shape[1] != 3:
            raise ValueError(f"image must have shape (B, 3, H, W), got {tuple(image.shape)}")
        b = image.shape[0]
        if sky.shape != (b, 1, *image.shape[-2:]):
            raise ValueError(f"sky must have shape {(b, 1, *image.shape[-2:])}, got {tuple(sky.shape)}")

        def batch_sh(x: torch.Tensor, name: str) -> torch.Tensor:
            x = torch.as_tensor(x, dtype=torch.float32)
            if x.shape == (9, 3):
                x = x[None].expand(b, -1, -1)
            if x.shape != (b, 9, 3):
                raise ValueError(f"{name} must have shape (9, 3) or ({b}, 9, 3), got {tuple(x.shape)}")
            if not torch.isfinite(x).all():
                raise ValueError(f"{name} holds NaN or inf")
            return x

        tgt = batch_sh(target, "target")
        out = self.decompose_linear(image.float(), sky.bool()) if decomposition is None else decomposition
        source = None if source_lighting is None else batch_sh(source_lighting, "source_lighting")
        if known_source and source is None:
            raise ValueError("known_source needs source_lighting: the photo's own lighting")
        quotient_based = method == "proposed" and self.renderer_base == "quotient"
        if known_source and not (method.startswith("quotient") or quotient_based):
            raise ValueError(f"known_source is a track of the quotient methods and of a quotient-based renderer, "
                             f"not of {method!r}")
        scale = exposure_scale(tgt, out["lighting"], source, fallback=self.prior.mean.reshape(1, 9, 3))[:, None, None]
        if not 0.0 <= self.level_prior <= 1.0:
            raise ValueError(f"level_prior must lie in [0, 1], got {self.level_prior!r}")
        if source is not None and not known_source and self.level_prior:
            scale = scale / self.grey_world_gain(image, sky, out, scale) ** self.level_prior
        tgt = tgt * scale
        if method == "lambertian_sh" or method == "quotient":
            s = torch.ones_like(out["shadow"])
        else:
            s = repair_top_rows(self.shadow_net(out["normals"], tgt))
        if method in ("quotient", "quotient_shadownet") or quotient_based:
            src = source * scale if known_source else out["lighting"]
            src_shadow = out["shadow"] if method == "quotient_shadownet" else None
            t_sun = None if target_sun is None else batch_sh(target_sun, "target_sun") * scale
            s_sun = None
            if known_source and t_sun is not None:
                s_sun = (torch.zeros_like(src) if source_sun is None
                         else batch_sh(source_sun, "source_sun") * scale)
            relit = quotient_relight(image.float(), out["normals"], src, tgt, mask=~sky, source_shadow=src_shadow,
                                     target_shadow=s if method == "quotient_shadownet" else None,
                                     source_sun=s_sun, target_sun=t_sun, sun_cosine=t_sun is not None,
                                     smooth_radius=self.ratio_radius)
        if quotient_based and self.renderer_gain_ratio and not self.renderer.additive:
            from .neural_renderer import positive, renderer_inputs

            # the renderer's gain for the target over its gain for the source itself: relit to its own
            # lighting, the photo gets the quotient's ratio alone (study 29)
            img, fg = image.float(), ~sky.bool()
            q_src = quotient_relight(img, out["normals"], src, src, mask=fg, smooth_radius=self.ratio_radius)
            s_src = repair_top_rows(self.shadow_net(out["normals"], src))
            args = (img, sky.bool(), out["albedo"], out["normals"], out["shadow"], out["lighting"])
            g_t = self.renderer.gain(renderer_inputs(*args, tgt, s, relit))
            g_s = self.renderer.gain(renderer_inputs(*args, src, s_src, q_src))
            relit = torch.where(sky, img, positive(relit * g_t / g_s))
        elif method == "proposed" and self.renderer is not None:
            from .neural_renderer import render_relit

            # a quotient-based renderer is a learned gain on the quotient image just computed
            relit = render_relit(self.renderer, image.float(), sky.bool(), out, tgt, s,
                                 quotient=relit if quotient_based else None)
        elif method not in ("quotient", "quotient_shadownet"):
            relit = image_model.render(out["albedo"], out["normals"], tgt, s)
        relit = torch.where(sky, image.float(), relit.clamp_min(0))
        return {"relit": relit, "target": tgt, "target_shadow": s, **{k: out[k] for k in (
            "albedo", "normals", "shadow", "lighting", "foreground")}}

    @staticmethod
    def grey_world_gain(image: torch.Tensor, sky: torch.Tensor, decomposition: dict[str, torch.Tensor],
                        scale: torch.Tensor) -> torch.Tensor:
        """``(B, 1, 1)`` the foreground's median implied albedo over middle grey, with the estimated lighting's
        shape at the given source level.

        ``decomposition["lighting"] / scale`` is the estimate in the given source's units (``scale`` from
        :func:`exposure_scale`, ``(B, 1, 1)``); the implied albedo is ``lum(image) / lum(shading(n; that))``
        (:func:`learned.source_lighting.grey_world_level`). Above 1, the photo is brighter than a middle-grey
        scene under that lighting would be: more light falls on the visible surfaces than the estimated shape
        puts there. ``image (B, 3, H, W)`` linear, ``sky (B, 1, H, W)`` bool.
        """
        g = grey_world_level(image.float(), decomposition["normals"], decomposition["lighting"] / scale,
                             ~sky.bool())
        return g.to(scale.dtype)[:, None, None]

    def denoised(self, image: torch.Tensor) -> torch.Tensor:
        """``(B, 3, H, W)`` linear ``image`` smoothed by :func:`physrelight.denoise.denoise` at :attr:`denoise`
        (the image itself when :attr:`denoise` is None, the default): what the foreground is relit from."""
        if self.denoise is None:
            return image
        from physrelight.denoise import denoise

        return denoise(image.float(), *self.denoise)

    @torch.no_grad()
    def relight_full_resolution(self, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                                source_lighting: torch.Tensor | None = None, method: str = DEFAULT_METHOD,
                                working_res: int | None = None,
                                decomposition: dict[str, torch.Tensor] | None = None,
                                known_source: bool = False, denoised: torch.Tensor | None = None,
                                **sun: torch.Tensor | None) -> dict[str, Any]:
        """:meth:`relight_linear` at a working resolution, brought back to the image's size.

        The image is resized so its short side is ``working_res`` (None: the networks' ``res``;
        :func:`working_resolution`), relit there, and brought back by ratio transfer
        (:func:`transfer_to_full_resolution`), so detail finer than the working resolution survives. With
        :attr:`denoise` set (off by default, study 37) the foreground is relit from the photo smoothed by
        :func:`physrelight.denoise.denoise`; sky pixels stay the photo's own.

        Args:
            image: ``(B, 3, H, W)`` linear; sky ``(B, 1, H, W)`` bool; target, source_lighting,
                method, known_source, ``target_sun=``, ``source_sun=``: as for :meth:`relight_linear`.
            decomposition: the ``"working"`` dict of an earlier call on the same image and sky at the
                same working resolution (its decomposition is reused), or None.
            denoised: :meth:`denoised` of this very ``image``, when the caller has it (a sequence of
                targets denoises its photo once), or None.

        Returns:
            ``relit`` ``(B, 3, H, W)`` linear at full size (sky pixels = ``image``), ``working``
            (:meth:`relight_linear`'s dict at the working resolution), ``working_image`` and ``working_sky``
            (the image, denoised when :attr:`denoise` is set, and sky mask it was relit from).
        """
        clean = self.denoised(image) if denoised is None else denoised  # the foreground is relit from it
        small, small_sky = working_resolution(clean, sky, self.res if working_res is None else working_res)
        out = self.relight_linear(small, small_sky, target, source_lighting=source_lighting, method=method,
                                  decomposition=decomposition, known_source=known_source, **sun)
        relit = torch.where(sky, image, transfer_to_full_resolution(clean, small, out["relit"]))
        return {"relit": relit, "working": out, "working_image": small, "working_sky": small_sky}

    def paint_sky(self, relit: torch.Tensor, sky: torch.Tensor, working: dict[str, torch.Tensor],
                  working_sky: torch.Tensor, seed: int = 0, smooth: float | None = None) -> torch.Tensor:
        """SkyGAN's sky for the target, smoothed within the mask, composited into a full-resolution relighting.

        Args:
            relit: ``(B, 3, H, W)`` linear relit photo (:meth:`relight_full_resolution`'s ``"relit"``).
            sky: ``(B, 1, H, W)`` bool, where the sky goes.
            working, working_sky: that call's ``"working"`` dict (relit foreground and target at
                the working resolution) and ``"working_sky"``.
            seed: SkyGAN's noise (same seed, same sky).
            smooth: the Gaussian SkyGAN's sky is blurred by within the mask, a fraction of the short
                side (:func:`learned.sky_gan.smooth_sky`); None: ``self.sky_smooth``, or
                :data:`learned.sky_gan.SMOOTH_SIGMA` when that is None; 0: SkyGAN's own sky, blotches and all.

        Returns:
            ``(B, 3, H, W)``: ``relit`` with the generated sky on ``sky``; ``relit`` itself when no
            generator is shipped or there is no sky.
        """
        if self.sky_generator is None or not bool(sky.any()):
            return relit
        # SkyGAN at the working resolution (its training scale), conditioned on the relit
        # foreground and the target; the sky is smooth, so upsampling it loses nothing.
        from .sky_gan import SMOOTH_SIGMA, generate_sky, smooth_sky

        smooth = smooth if smooth is not None else self.sky_smooth if self.sky_smooth is not None else SMOOTH_SIGMA
        if not (isinstance(smooth, (int, float)) and smooth >= 0):
            raise ValueError(f"smooth must be a fraction of the short side >= 0, got {smooth!r}")
        painted = generate_sky(self.sky_generator, working["relit"], working_sky, working["target"], seed=seed)
        painted = torch.nn.functional.interpolate(painted, size=relit.shape[-2:], mode="bilinear", align_corners=False)
        if smooth > 0:
            # SkyGAN's blotches are detail it cannot place: blurred away, its sky scores higher (study 31)
            painted = smooth_sky(painted, sky, float(smooth))
        return torch.where(sky, painted, relit)

    def relight(self, image: Any, target: Any, world_to_camera: Any = None, sky_mask: Any = None,
                method: str = DEFAULT_METHOD, azimuth_deg: float = 0.0, sky: str = "clear", new_sky: bool = True,
                seed: int = 0, sky_source: str | None = None, exposure: str | float = "keep",
                fov_deg: float = DEFAULT_FOV_DEG, pitch_deg: float | None = None, source: Any = None,
                linear: bool = False, radiance: bool = False) -> Any:
        """Relight a photo of any size to a target lighting; the relit photo only.

        See :meth:`relight_layers` for the arguments; returns display values in [0, 1]
        (sRGB), type and layout of ``image`` (a batch is relit photo by photo), or with ``linear`` the
        relit linear radiance before the display curve (see :meth:`relight_layers`).
        """
        lin, kind, gain = _as_radiance(image) if radiance else (*_as_image(image), 1.0)
        frames = [self._relight_tensors(lin[b: b + 1], target, world_to_camera, sky_mask if lin.shape[0] == 1 else
                                        (None if sky_mask is None else _as_mask(sky_mask, lin)[b: b + 1]),
                                        method, azimuth_deg, sky, new_sky, seed, layers=False, sky_source=sky_source,
                                        exposure=exposure, fov_deg=fov_deg, pitch_deg=pitch_deg,
                                        source=source, linear=linear)["relit"]
                  for b in range(lin.shape[0])]
        return _give_back(torch.cat(frames) / gain if linear else torch.cat(frames), kind)

    def relight_sequence(self, image: Any, target: Any, azimuths_deg: Any, world_to_camera: Any = None,
                         sky_mask: Any = None, method: str = DEFAULT_METHOD, sky: str = "clear", new_sky: bool = True,
                         seed: int = 0, progress: bool = False, sky_source: str | None = None,
                         exposure: str | float = "keep", fov_deg: float = DEFAULT_FOV_DEG,
                         pitch_deg: float | None = None, source: Any = None, radiance: bool = False) -> list[Any]:
        """:meth:`relight` for each azimuth of ``azimuths_deg`` (degrees, e.g. a turning sun), the photo
        segmented and decomposed once: the same frames as separate :meth:`relight` calls, cheaper (display
        values; ``radiance`` as for :meth:`relight_layers`). ``progress`` shows a progress bar."""
        from tqdm import tqdm

        lin, kind = _as_radiance(image)[:2] if radiance else _as_image(image)
        if lin.shape[0] != 1:
            raise ValueError(f"relight_sequence takes one image, got a batch of {lin.shape[0]}")
        reuse: dict[str, Any] = {}
        azimuths = np.asarray(azimuths_deg, dtype=np.float64).ravel()
        return [_give_back(self._relight_tensors(lin, target, world_to_camera, sky_mask, method, float(a), sky,
                                                 new_sky, seed, layers=False, reuse=reuse, sky_source=sky_source,
                                                 exposure=exposure, fov_deg=fov_deg, pitch_deg=pitch_deg,
                                                 source=source)["relit"],
                           kind)
                for a in tqdm(azimuths, desc="relight", disable=not progress)]

    def relight_layers(self, image: Any, target: Any, world_to_camera: Any = None, sky_mask: Any = None,
                       method: str = DEFAULT_METHOD, azimuth_deg: float = 0.0, sky: str = "clear", new_sky: bool = True,
                       seed: int = 0, sky_source: str | None = None, exposure: str | float = "keep",
                       fov_deg: float = DEFAULT_FOV_DEG, pitch_deg: float | None = None,
                       source: Any = None, linear: bool = False, radiance: bool = False) -> dict[str, np.ndarray]:
        """Relight a photo of any size and give every layer at full resolution.

        The networks run at their training resolution (the short side resized to ``res``);
        the result comes back at full resolution by ratio transfer: the full-resolution
        linear photo times the ratio ``relit / photo`` of the working resolution, upsampled
        along the photo's edges (:func:`transfer_to_full_resolution`), so fine detail the networks
        never saw survives (where the working photo is black the upsampled relit image is used
        instead). The target's DC luminance is set to the estimated source lighting's, so only the
        lighting's shape and colour change (one photo does not tell the absolute light level;
        :meth:`relight_linear` takes ``source_lighting`` for that); ``exposure`` then picks how the
        result is shown (:mod:`physrelight.exposure`).

        The sky: without ``sky_mask``, the shipped segmenter's, kept only where it is a plausible
        sky (:func:`learned.sky_segmentation.sky_mask_full_resolution`); when it finds none a
        ``UserWarning`` says why and only the foreground is relit. The sky is then replaced from
        ``sky_source`` (:data:`SKY_SOURCES`; None: ``"target"`` for an env-map or sun target, else
        ``"gan"`` when SkyGAN is shipped, else ``"keep"``): ``"target"`` looks the target itself up
        through the photo's camera (:func:`target_sky`), in the relit foreground's units; ``"fit"``
        the sky model fitted to the target's SH (:func:`physrelight.sky_model.fit_sky`), likewise.

        Args:
            image: the photo (see the module doc); a single image.
            target: SH ``(9, 3)``, env map ``(H, 2H, 3)``, EXR path or sun direction ``(3,)``, world frame.
            world_to_camera: ``(4, 4)`` or ``(3, 3)``; None = a level camera looking along world -Z
                whose pitch is ``pitch_deg``.
            sky_mask: optional ``(H, W)`` bool, True on sky; None = the sky segmenter's mask
                (when shipped; else no sky).
            method: see :meth:`relight_linear`.
            new_sky: False keeps the photo's sky whatever ``sky_source`` says.
            seed: SkyGAN's noise (same seed, same sky).
            azimuth_deg: turn the target about the world's vertical axis first (degrees,
                counter-clockwise seen from above).
            sky: sky type of a sun-direction target (:func:`sun_lighting`).
            sky_source: ``"target"``, ``"fit"``, ``"gan"``, ``"keep"`` or None (see above).
            exposure: ``"keep"`` (default here), ``"auto"`` or stops (:func:`physrelight.exposure.exposure_gain`).
            fov_deg: the photo's horizontal field of view (its focal length, e.g. from EXIF).
            pitch_deg: the level camera's pitch; None: estimated from the sky's horizon
                (:func:`estimate_pitch`). Ignored when ``world_to_camera`` is given.
            source: the photo's own lighting (SH, env map, path or sun direction, world frame, the
                target's units), when known (a map captured on set): the *known-source* track of
                :meth:`relight_linear` (quotient methods divide by it; relighting to it gives the
                photo back). None: the decomposition's estimate.
            linear: give ``relit`` as linear radiance instead of display values: the photo's linear
                units (sRGB decoded, or a radiance photo's own) times the exposure's gain, its sky in the same
                units, not clipped. For measuring against a renderer; the other layers stay display values.
            radiance: ``image`` is linear radiance (float, any scale: a render's or an HDR photo's), not display
                values. It is relit at a display-like level (:data:`RADIANCE_WHITE_QUANTILE`; ``exposure="keep"``
                keeps that level for display), and a ``linear`` result is given back in its own units.

        Returns:
            numpy ``(H, W, C)`` display values in [0, 1]: ``relit``, ``albedo``, ``normals``
            (``0.5 * n + 0.5``), ``shadow`` (source), ``target_shadow``, ``shading`` (target
            shading, tone-mapped), ``sky_mask`` (C = 1).
        """
        lin, _, gain = _as_radiance(image) if radiance else (*_as_image(image), 1.0)
        if lin.shape[0] != 1:
            raise ValueError(f"relight_layers takes one image, got a batch of {lin.shape[0]}")
        layers = self._relight_tensors(lin, target, world_to_camera, sky_mask, method, azimuth_deg, sky, new_sky,
                                       seed, sky_source=sky_source, exposure=exposure, fov_deg=fov_deg,
                                       pitch_deg=pitch_deg, source=source, linear=linear)
        if linear:
            layers["relit"] = layers["relit"] / gain
        return {k: v[0].permute(1, 2, 0).numpy() for k, v in layers.items()}

    def _stage(self, name: str) -> None:
        if self.on_stage is not None:
            self.on_stage(name)

    def photo_sky(self, lin: torch.Tensor, sky_mask: Any = None) -> tuple[torch.Tensor, str]:
        """``(sky (1, 1, H, W) bool, reason)`` of one linear photo ``(1, 3, H, W)``: the given mask,
        else the segmenter's plausible sky at full resolution (``reason`` says why there is none),
        else no sky."""
        if sky_mask is None and self.sky_segmenter is not None:
            from .sky_segmentation import sky_mask_full_resolution

            sky, reasons = sky_mask_full_resolution(self.sky_segmenter, lin, grow=self.sky_grow)
            return sky, reasons[0]
        return _as_mask(sky_mask, lin), ""

    def _relight_tensors(self, lin: torch.Tensor, target: Any, world_to_camera: Any, sky_mask: Any, method: str,
                         azimuth_deg: float, sky_type: str, new_sky: bool = True, seed: int = 0,
                         layers: bool = True, reuse: dict[str, Any] | None = None, sky_source: str | None = None,
                         exposure: str | float = "keep", fov_deg: float = DEFAULT_FOV_DEG,
                         pitch_deg: float | None = None, source: Any = None,
                         linear: bool = False) -> dict[str, torch.Tensor]:
        """The relit photo (``"relit"``: display values, or with ``linear`` the linear radiance) and, with
        ``layers``, every layer at full resolution, of one photo ``lin (1, 3, H, W)``.

        ``reuse``, a dict this method fills on its first call for a photo and reads on later
        ones: the sky mask, the camera, the denoised photo and the working-resolution decomposition,
        which do not depend on the target (:meth:`relight_sequence`)."""
        import warnings

        from physrelight import panorama
        from physrelight.exposure import exposure_gain, parse_exposure

        if not math.isfinite(float(azimuth_deg)):
            raise ValueError(f"azimuth must be a finite number of degrees, got {azimuth_deg!r}")
        if not bool((lin > 0).any()):
            # nothing to divide by or to meter: the lighting solve would return NaN and name that instead
            raise ValueError("the photo is black (every pixel 0): there is no light in it to relight")
        if sky_source is not None and sky_source not in SKY_SOURCES:
            raise ValueError(f"sky_source must be one of {SKY_SOURCES} or None, got {sky_source!r}")
        parse_exposure(exposure)
        reuse = {} if reuse is None else reuse
        if isinstance(target, (str, os.PathLike)):
            from physrelight import envmap

            target = envmap.read(target)
        h, w = lin.shape[-2:]
        if "sky" not in reuse:
            self._stage("sky mask")
            reuse["sky"], why = self.photo_sky(lin, sky_mask)
            if why:
                warnings.warn(f"no sky relit: {why}; relighting the foreground only", UserWarning, stacklevel=3)
            elif sky_mask is None and self.sky_segmenter is not None and bool(reuse["sky"].any()):
                from physrelight.sky_mask import is_monochrome

                if is_monochrome(lin):
                    warnings.warn("the photo has no colour: the sky mask cannot tell the sky by its colour and may "
                                  "take white walls for sky; check the sky_mask layer, or give a mask",
                                  UserWarning, stacklevel=3)
            K = panorama.view_intrinsics(float(fov_deg), w, h)
            if world_to_camera is not None:
                T = world_to_camera
            else:
                pitch = estimate_pitch(reuse["sky"][0, 0], K) if pitch_deg is None else float(pitch_deg)
                T = panorama.level_camera(0.0, pitch)
            reuse["camera"] = (K, T)
        sky = reuse["sky"]
        K, T = reuse["camera"]
        turned = rotate_azimuth(target, azimuth_deg) if azimuth_deg else target
        target_cam = self.target_lighting(turned, T, sky_type).float()
        if azimuth_deg and sky_map_kind(target) == "env":
            # rotate_azimuth projects a map to SH: take the map's own sun, turned with the camera as the
            # map's sky is (target_sky), not the sun of a sky model fitted to its SH
            suns: dict[str, torch.Tensor | None] = {
                "target_sun": self.target_sun(target, _turned_camera(T, azimuth_deg), sky_type)}
        else:
            suns = {"target_sun": self.target_sun(turned, T, sky_type)}
        source_cam = None
        if source is not None:
            if isinstance(source, (str, os.PathLike)):
                from physrelight import envmap

                source = envmap.read(source)
            source_cam = self.target_lighting(source, T, sky_type).float()
            suns["source_sun"] = self.target_sun(source, T, sky_type)
        suns = {k: None if v is None else v.float() for k, v in suns.items()}
        if "denoised" not in reuse:  # one photo, one denoise, whatever the targets
            reuse["denoised"] = self.denoised(lin)
        self._stage("relighting")
        full = self.relight_full_resolution(lin, sky, target_cam, method=method, source_lighting=source_cam,
                                            decomposition=reuse.get("decomposition"), known_source=source is not None,
                                            denoised=reuse["denoised"], **suns)
        if "decomposition" not in reuse:
            reuse["decomposition"] = {k: full["working"][k] for k in (
                "albedo", "normals", "shadow", "lighting", "foreground")}
        relit, out, small_sky = full["relit"], full["working"], full["working_sky"]
        size = lin.shape[-2:]

        def up(x: torch.Tensor) -> torch.Tensor:
            return torch.nn.functional.interpolate(x, size=size, mode="bilinear", align_corners=False)

        sky_from = sky_source or ("target" if sky_map_kind(target) != "sh" else "gan" if self.sky_generator else "keep")
        self._stage("sky")
        if new_sky and bool(sky.any()):
            if sky_from in ("target", "fit"):
                # A rendered sky comes in the relit foreground's units: the target was scaled by
                # dc(out target) / dc(target) into the decomposition's (= the photo's linear) units.
                k = float(dc_luminance(out["target"])[0] / dc_luminance(target_cam[None])[0])
                # On the estimated track that level is the estimate's, a guess of the network's albedo; a light
                # meter's (grey world) is closer (study 36), and the sky's brightness against the foreground
                # is proportional to it.
                if source is None and self.sky_level == "grey_world":
                    if "grey_world" not in reuse:  # one decomposition per photo, so one level
                        reuse["grey_world"] = float(grey_world_level(full["working_image"], out["normals"],
                                                                     out["lighting"], ~small_sky)[0])
                    k *= reuse["grey_world"]
                elif source is None and self.sky_level != "decomposition":
                    raise ValueError(f"sky_level must be one of {SKY_LEVELS}, got {self.sky_level!r}")
                radiance = (target_sky(target, K, T, h, w, sky_type, azimuth_deg) if sky_from == "target"
                            else fitted_sky(self.target_lighting(turned, None, sky_type), K, T, h, w)) * k
                relit = torch.where(sky, radiance.permute(2, 0, 1)[None].to(relit.dtype), relit)
            elif sky_from == "gan":
                relit = self.paint_sky(relit, sky, out, small_sky, seed=seed)
        relit = relit * exposure_gain(exposure, relit, lin, ~sky, highlights=sky)[:, None, None, None]

        with torch.no_grad():
            result = {"relit": relit.clamp_min(0) if linear else colour.to_ldr(relit.clamp_min(0))}
            if not layers:  # relight() and sequences need only the photo: skip the full-size layers
                return result
            self._stage("layers")
            shading = image_model.shading(out["normals"], out["target"])
            return {
                **result,
                "albedo": colour.to_ldr(up(out["albedo"]).clamp(0, 1)),
                "normals": (0.5 * up(out["normals"]) + 0.5).clamp(0, 1),
                "shadow": up(out["shadow"]).clamp(0, 1),
                "target_shadow": up(out["target_shadow"]).clamp(0, 1),
                "shading": colour.to_ldr(up(shading).clamp_min(0)),
                "sky_mask": sky.float(),
            }


RELIGHT_METHODS = ("proposed", "lambertian_sh", "shadownet_lambertian", "quotient", "quotient_shadownet")
RELIGHT_STAGES = ("sky mask", "relighting", "sky", "layers")
"""The stages of one relighting, in order, as ``Relighter.on_stage`` is told them: the full-resolution sky mask
and camera (once per photo), the decomposition and relighting at the working resolution brought to full size,
the new sky and the exposure, and the full-size layers (``relight_layers`` only)."""


def dc_luminance(lighting: torch.Tensor) -> torch.Tensor:
    """``(B, 9, 3)`` radiance SH -> ``(B,)`` luminance of the DC term (the lighting's overall level)."""
    lum = torch.tensor(colour.LUMINANCE, dtype=lighting.dtype)
    return (lighting[:, 0] * lum).sum(-1)


def exposure_scale(target: torch.Tensor, estimated_source: torch.Tensor, given_source: torch.Tensor | None = None,
                   fallback: torch.Tensor | None = None) -> torch.Tensor:
    """``(B,)`` the factor that brings ``target (B, 9, 3)`` into a decomposition's units.

    The decomposition's albedo and lighting share an unknown scale. With ``given_source``
    ``(B, 9, 3)`` (the source lighting in the target's units) it is
    ``lum(DC estimated) / lum(DC given)``; without it, ``lum(DC estimated) / lum(DC target)``,
    so the scaled target's DC luminance equals the estimated source lighting's (the photo keeps
    its exposure). Where the estimate has no positive level (below 1e-6 of ``fallback``'s, e.g. a
    photo without usable foreground), ``fallback`` ``(1 or B, 9, 3)`` (the prior's mean) stands in.

    Raises:
        ValueError: the target (or the given source) has no positive DC luminance.
    """
    ref = dc_luminance(given_source.to(target.dtype) if given_source is not None else target)
    if bool((ref <= 0).any()) or bool((dc_luminance(target) <= 0).any()):
        raise ValueError("target (or source) lighting has no positive DC luminance (a dark or invalid lighting)")
    est = dc_luminance(estimated_source.to(target.dtype))
    if fallback is not None:
        fb = dc_luminance(fallback.to(target.dtype)).expand_as(est)
        est = torch.where(est > 1e-6 * fb, est, fb)
    return est.clamp_min(0) / ref


def match_exposure(target: torch.Tensor, estimated_source: torch.Tensor, given_source: torch.Tensor | None = None,
                   fallback: torch.Tensor | None = None) -> torch.Tensor:
    """``target (B, 9, 3)`` times :func:`exposure_scale`: the target in a decomposition's units."""
    return target * exposure_scale(target, estimated_source, given_source, fallback)[:, None, None]


DENOISE = (2, 3.0)
"""The (radius, strength) of ``Relighter.denoise`` when it is turned on (``relight --denoise``): chosen on
data/val5 by study 37's rule; not the default (docs/experiments/37-denoise-before-the-quotient.md)."""

SKY_TYPES = ("clear", "overcast")
SKY_LEVELS = ("grey_world", "decomposition")


def _sun_direction(direction: Any) -> np.ndarray:
    d = np.asarray(direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
        raise ValueError(f"a sun direction must be a finite non-zero (3,) vector, got {d.tolist()}")
    return d / np.linalg.norm(d)


def _clear_sky_sun(direction: Any) -> np.ndarray:
    """:func:`_sun_direction`, above the horizon: a clear day's sun below it lights nothing directly and its
    twilight sky is not modelled (Hosek-Wilkie's sky starts at 2 degrees up), so it is refused."""
    d = _sun_direction(direction)
    if not d[1] > 0:
        raise ValueError(f"a clear sky's sun must be above the horizon (elevation > 0), got "
                         f"{math.degrees(math.asin(float(np.clip(d[1], -1, 1)))):.3g} deg; use sky 'overcast' for a sunless sky")
    return d


def _sun_rgb(direction: np.ndarray) -> np.ndarray:
    """``(3,)`` the colour of a sun towards unit ``direction`` (luminance 1, white at the zenith):
    :func:`physrelight.sky_model.sun_colour` at its elevation."""
    from physrelight.sky_model import sun_colour

    return sun_colour(math.degrees(math.asin(float(np.clip(direction[1], -1.0, 1.0)))))


def sun_sky_map(sky: str = "clear", direction: Any = (0.0, 1.0, 0.0), height: int = 64) -> np.ndarray:
    """``(height, 2 height, 3)`` the sky of :func:`sun_lighting` without its sun, world frame.

    ``"clear"``: a clear day's sky for the sun towards ``direction``,
    :func:`physrelight.sky_model.sunsky_radiance` (Mitsuba 3's Hosek-Wilkie sky, turbidity 3, tabulated),
    in units where the sun's irradiance on a surface facing it has luminance 1: its level against the sun
    is the model's (order-2 irradiance on a horizontal surface 0.29 of the sun's at 5 degrees up,
    0.19-0.22 from 15 degrees up, in luminance), its colour and gradient too (a deep blue zenith, a pale horizon, warm
    under a low sun, the aureole round the sun). ``"overcast"``: the grey CIE overcast sky
    ``L(theta) = L_z (1 + 2 cos theta) / 3``, scaled to order-2 irradiance 1 on a horizontal
    surface; ``direction`` is ignored. Both are dark below the horizon.
    """
    if sky not in SKY_TYPES:
        raise ValueError(f"sky must be one of {SKY_TYPES}, got {sky!r}")
    from physrelight import envmap

    from physrelight.sky_model import overcast_sky, sunsky_radiance

    d = envmap.directions(height, 2 * height)
    if sky == "overcast":
        return np.repeat(overcast_sky(d)[..., None], 3, axis=-1) * _overcast_level()
    return sunsky_radiance(d, _clear_sky_sun(direction))


@functools.lru_cache(maxsize=1)
def _overcast_level() -> float:
    """The factor that gives the CIE overcast sky (:func:`physrelight.sky_model.overcast_sky`) order-2 irradiance 1
    on a horizontal surface, as projected from its 64-row lat-long map."""
    from physrelight import envmap
    from physrelight.sky_model import overcast_sky

    env = np.repeat(overcast_sky(envmap.directions(64, 128))[..., None], 3, axis=-1)
    return 1.0 / float(sh.irradiance(sh.project_envmap(env, order=2), np.array([[0.0, 1.0, 0.0]]))[0, 1])


def sun_lighting(direction: Any, sky: str = "clear") -> np.ndarray:
    """Order-2 radiance SH ``(9, 3)`` (world frame) of a simple outdoor lighting.

    ``"clear"``: a delta sun towards ``direction`` of luminance 1 on a surface facing it, white at the
    zenith and warmer as it sinks (its light crosses more air: :func:`physrelight.sky_model.sun_colour`,
    a clear atmosphere's Rayleigh and aerosol extinction), plus the clear sky of :func:`sun_sky_map`
    (Hosek-Wilkie's, at its level against the sun: the fill light).
    ``"overcast"``: the CIE overcast sky of :func:`sun_sky_map`, no sun; the direction is
    ignored. Skies are projected from a 64 x 128 map.
    """
    d = _sun_direction(direction) if sky == "overcast" else _clear_sky_sun(direction)
    coeffs = np.asarray(sh.project_envmap(sun_sky_map(sky, d), order=2))
    if sky == "overcast":
        return coeffs
    return sh.project_sun(d, _sun_rgb(d), order=2) + coeffs



SUN_SHARE_OF_PEAK = 0.25
SUN_OVER_MEDIAN = 100.0
SUN_RADIUS_CAP_DEG = 3.0


def envmap_sun(env: Any) -> np.ndarray | None:
    """``(H, 2H, 3)`` the sun of an environment map alone (its other texels 0), or None.

    The sun is the set of texels within :data:`SUN_RADIUS_CAP_DEG` of the brightest texel, at least
    :data:`SUN_SHARE_OF_PEAK` of its luminance *and* :data:`SUN_OVER_MEDIAN` times the map's median
    luminance: only a compact source far brighter than the sky passes (a clear sky's sun is
    10^3-10^5 times its sky); an overcast map has none. One direction only: a second bright source
    (a studio's other lamp) stays in the SH part.
    """
    from physrelight import envmap as _envmap

    e = np.asarray(env, dtype=np.float64)
    lum = e @ np.asarray(colour.LUMINANCE, dtype=np.float64)
    peak, median = float(lum.max()), float(np.median(lum))
    if not peak > 0:
        return None
    dirs = np.asarray(_envmap.directions(e.shape[0], e.shape[1]), dtype=np.float64)
    near = dirs @ dirs.reshape(-1, 3)[int(np.argmax(lum))] >= math.cos(math.radians(SUN_RADIUS_CAP_DEG))
    sun = near & (lum >= SUN_SHARE_OF_PEAK * peak) & (lum >= SUN_OVER_MEDIAN * max(median, 1e-12))
    if not sun.any():
        return None
    return np.where(sun[..., None], e, 0.0)


def sky_map_kind(target: Any) -> str:
    """``"env"`` (a lat-long map or its path), ``"sun"`` (a direction ``(3,)``) or ``"sh"``: whether a
    target says what its sky looks like (the first two do; SH coefficients do not)."""
    if isinstance(target, (str, os.PathLike)):
        return "env"
    shape = tuple(np.shape(target))
    if shape == (3,):
        return "sun"
    if len(shape) == 3 and shape[-1] == 3 and shape[1] == 2 * shape[0]:
        return "env"
    return "sh"


def target_sky(target: Any, K: Any, world_to_camera: Any, height: int, width: int, sky: str = "clear",
               azimuth_deg: float = 0.0) -> torch.Tensor:
    """``(height, width, 3)`` the target's own sky as the photo's camera sees it (target units).

    An env map is looked up through the pinhole camera (``K``, ``world_to_camera``) by
    :func:`physrelight.panorama.view`, one ray per pixel, bilinearly where a pixel covers a texel or more
    and by the smooth cubic B-spline where the view magnifies the map
    (:func:`physrelight.panorama.texel_magnification` above 1: a 640-px photo at 60 degrees sees a 1024-wide
    map's texel over 3.4 pixels), so a bright texel is not drawn as a clipped square. A sun target's sky is
    evaluated along each ray (:func:`physrelight.sky_model.sunsky_radiance`, or the CIE overcast sky at
    :func:`sun_sky_map`'s level), smooth at any resolution, plus the sun's disc for a clear sky (radius
    :data:`physrelight.sky_model.SUN_RADIUS_DEG`, luminance 1, the sun's colour). ``azimuth_deg`` turns the
    target about +Y as :func:`rotate_azimuth` does (the camera is turned the other way).

    Raises:
        ValueError: an SH target (it has no sky to render).
    """
    from physrelight import envmap, panorama

    kind = sky_map_kind(target)
    if kind == "sh":
        raise ValueError("an SH target has no sky to render: use sky source 'fit', 'gan' or 'keep'")
    R = _turned_camera(world_to_camera, azimuth_deg)
    if kind == "env":
        env = envmap.read(target) if isinstance(target, (str, os.PathLike)) else np.asarray(target)
        smooth = panorama.texel_magnification(K, env.shape[1]) > 1.0
        return torch.as_tensor(panorama.view(torch.as_tensor(env, dtype=torch.float32), K, R, height, width, 1,
                                             interpolation="bspline" if smooth else "bilinear"))
    rays = horizon_clamped(panorama.camera_rays(K, R, height, width, 1))
    if sky == "overcast":
        from physrelight.sky_model import overcast_sky

        d = rays[..., 0, :].double().numpy()
        return torch.from_numpy(overcast_sky(d) * _overcast_level()).float()[..., None].expand(-1, -1, 3).contiguous()
    # the clear sky along each ray itself (not through a lat-long map): smooth at any resolution
    from physrelight.sky_model import sunsky_radiance

    d = _clear_sky_sun(target)
    out = torch.from_numpy(sunsky_radiance(rays[..., 0, :].double().numpy(), d)).float()
    return out + (sun_disc(rays[..., 0, :], d)[..., None] * torch.from_numpy(_sun_rgb(d))).to(out.dtype)


def _turned_camera(world_to_camera: Any, azimuth_deg: float) -> np.ndarray:
    """``(3, 3)`` the camera rotation that sees a target turned by ``azimuth_deg`` about +Y as
    :func:`rotate_azimuth` turns it: ``target'(w) = target(R_y^T w)``, so ``R = T R_y``."""
    from physrelight import rotations

    return np.asarray(world_to_camera, dtype=np.float64)[:3, :3] @ rotations.about_y(float(azimuth_deg))


def fitted_sky(coeffs: Any, K: Any, world_to_camera: Any, height: int, width: int,
               glow_exponent: float = FIT_GLOW_EXPONENT) -> torch.Tensor:
    """``(height, width, 3)`` the sky implied by world-frame order-2 SH ``coeffs (9, 3)`` as the photo's
    camera (``K``, ``world_to_camera``) sees it, in the coefficients' units: the outdoor sky model
    fitted to them (:func:`physrelight.sky_model.fit_sky`), one ray per pixel
    (:func:`physrelight.sky_model.sky_view`). Smooth by construction."""
    from physrelight import panorama
    from physrelight.sky_model import fit_sky, sky_view

    fit = fit_sky(coeffs, glow_exponent)
    return sky_view(fit, panorama.camera_rays(K, world_to_camera, height, width, 1)).float()


PITCH_QUANTILE = 1.0
"""The percentile of the columns' sky reach :func:`estimate_pitch` takes as the horizon: the sky's lowest
reach, nearest the horizon (study 32: mean absolute error 9.93 -> 8.32 deg on the training panoramas' crops
against 0.9; sunrise, read once afterwards, 5.10 -> 4.20)."""


def estimate_pitch(sky: torch.Tensor, K: Any, limits: tuple[float, float] = (-30.0, 45.0),
                   quantile: float = PITCH_QUANTILE) -> float:
    """The pitch (degrees, up positive) of a level camera, from where its sky comes down to.

    In each column whose top pixel is sky, the sky runs down from the top border to some row;
    between buildings, trees and towers it comes down to the horizon, so the horizon is taken at
    the lowest of those rows (:data:`PITCH_QUANTILE`), ``v_h``, and a level camera pitched up by ``p`` has its
    horizon at ``v_h = c_y + f_y tan(p)``. Without sky at the top: 0 (a level camera).

    Args:
        sky: ``(H, W)`` bool. K: ``(3, 3)`` intrinsics of the photo.
        limits: the estimate is clamped to this range.
        quantile: the percentile of the columns' sky reach taken as the horizon (study 32).
    """
    if sky.ndim != 2:
        raise ValueError(f"sky must have shape (H, W), got {tuple(sky.shape)}")
    if not 0.0 <= float(quantile) <= 1.0:
        raise ValueError(f"quantile must be in [0, 1], got {quantile!r}")
    Kt = np.asarray(K, dtype=np.float64)
    cols = sky[0]
    if not bool(cols.any()):
        return 0.0
    run = torch.cumprod(sky[:, cols].to(torch.int64), dim=0).sum(0).double()  # sky rows from the top
    v_h = float(torch.quantile(run, float(quantile)))
    p = math.degrees(math.atan((v_h - Kt[1, 2]) / Kt[1, 1]))
    return float(min(max(p, limits[0]), limits[1]))


VERTICALS_EDGE_QUANTILE = 0.8
VERTICALS_MAX_TILT_DEG = 20.0
VERTICALS_TOLERANCE_DEG = 1.5
SKY_BOUND_MARGIN_DEG = 2.0
"""How far below the sky's pitch (:func:`estimate_pitch`, a lower bound: the sky comes down to the horizon
or stops above it) the vertical vanishing point's may fall and still be taken (study 34)."""


def pitch_from_verticals(image: torch.Tensor, K: Any, limits: tuple[float, float] = (-30.0, 45.0),
                         step_deg: float = 0.25) -> float | None:
    """The pitch (degrees, up positive) of a level camera from the world's vertical edges.

    A level camera pitched by ``p`` sees world-vertical lines converge to the vanishing point of the
    world's up direction, homogeneous ``(c_x sin p, c_y sin p - f cos p, sin p)`` (parallel for ``p = 0``).
    The photo's strongest edges (the top fifth of the log-luminance gradient, :data:`VERTICALS_EDGE_QUANTILE`)
    within :data:`VERTICALS_MAX_TILT_DEG` of the image vertical vote, weighted by their gradient, for every
    ``p`` on a ``step_deg`` grid whose vanishing point their direction points at within
    :data:`VERTICALS_TOLERANCE_DEG`; the most voted ``p`` wins. Building edges, poles and trunks are vertical;
    a scene without them gives a guess (study 34: trusted only above the sky's bound,
    :func:`estimate_camera_pitch`).

    Args:
        image: ``(3, H, W)`` or ``(1, 3, H, W)`` linear photo. K: ``(3, 3)`` its intrinsics.

    Returns:
        The pitch, or None when fewer than 20 pixels are near-vertical edges.
    """
    from physrelight import colour as _colour

    x = image[0] if image.ndim == 4 else image
    if x.ndim != 3 or x.shape[0] != 3:
        raise ValueError(f"image must have shape (3, H, W) or (1, 3, H, W), got {tuple(image.shape)}")
    Kt = np.asarray(K, dtype=np.float64)
    lum = (x.double().clamp_min(0) * torch.tensor(_colour.LUMINANCE, dtype=torch.float64)[:, None, None]).sum(0)
    g = torch.log(lum.clamp_min(1e-3))[None, None]
    sobel = torch.tensor([[-1.0, 0.0, 1.0], [-2.0, 0.0, 2.0], [-1.0, 0.0, 1.0]], dtype=torch.float64)[None, None] / 8
    pad = torch.nn.functional.pad(g, (1, 1, 1, 1), mode="replicate")
    gx = torch.nn.functional.conv2d(pad, sobel)[0, 0]
    gy = torch.nn.functional.conv2d(pad, sobel.transpose(2, 3))[0, 0]
    mag = torch.sqrt(gx * gx + gy * gy)
    ex, ey = -gy, gx  # along the edge (image x right, y down)
    tilt = torch.rad2deg(torch.atan2(ex.abs(), ey.abs()))  # 0: a vertical edge
    sel = (mag > stats.quantile(mag, VERTICALS_EDGE_QUANTILE)) & (tilt < VERTICALS_MAX_TILT_DEG) & (mag > 0)
    if int(sel.sum()) < 20:
        return None
    h, w = mag.shape
    ys, xs = torch.meshgrid(torch.arange(h, dtype=torch.float64), torch.arange(w, dtype=torch.float64), indexing="ij")
    n = torch.sqrt(ex[sel] ** 2 + ey[sel] ** 2)
    ex, ey, X, Y, wt = ex[sel] / n, ey[sel] / n, xs[sel], ys[sel], mag[sel]
    f, cx, cy = float(Kt[1, 1]), float(Kt[0, 2]), float(Kt[1, 2])
    grid = torch.arange(limits[0], limits[1] + 1e-9, step_deg, dtype=torch.float64)
    sp, cp = torch.sin(torch.deg2rad(grid))[:, None], torch.cos(torch.deg2rad(grid))[:, None]
    dx, dy = sp * (cx - X[None]), -f * cp + sp * (cy - Y[None])  # towards the vanishing point
    cos_angle = (ex[None] * dx + ey[None] * dy).abs() / torch.sqrt(dx * dx + dy * dy)
    votes = (wt[None] * (cos_angle > math.cos(math.radians(VERTICALS_TOLERANCE_DEG)))).sum(1)
    # near p = 0 the lines are nearly parallel and several p tie: the middle of the tied run
    best = torch.nonzero(votes >= votes.max() * (1 - 1e-12)).flatten()
    return float(grid[int(best[len(best) // 2])])


def estimate_camera_pitch(image: torch.Tensor, sky: torch.Tensor, K: Any) -> float:
    """A pitch from both cues: the vertical vanishing point's (:func:`pitch_from_verticals`) where it lies
    above the sky's (:func:`estimate_pitch`) less :data:`SKY_BOUND_MARGIN_DEG`, else the sky's. The sky's
    lowest reach is at or above the horizon, so its pitch is a lower bound; a vanishing point below it is
    taken for a scene without verticals.

    **Not what relight uses** (study 34): it halves the error in streets and courtyards (training side 8.32
    -> 5.79 deg) but triples it on an open landscape (the held-out sunrise, 4.20 -> 12.30 deg), where grass
    and haze give false verticals above the sky's bound.

    Args:
        image: ``(3, H, W)`` or ``(1, 3, H, W)`` linear photo. sky: ``(H, W)`` bool. K: ``(3, 3)``.
    """
    p_sky = estimate_pitch(sky, K)
    p_vp = pitch_from_verticals(image, K)
    return p_vp if p_vp is not None and p_vp >= p_sky - SKY_BOUND_MARGIN_DEG else p_sky


def rotate_azimuth(target: Any, degrees: float) -> Any:
    """Turn a world-frame target (SH ``(9, 3)``, env map, EXR path or sun direction ``(3,)``) by
    ``degrees`` about +Y (the SH rotation is exact; env maps are projected first)."""
    if isinstance(target, (str, os.PathLike)):
        from physrelight import envmap

        target = envmap.read(target)
    a = math.radians(float(degrees))
    R = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
    t = np.asarray(target, dtype=np.float64) if not isinstance(target, torch.Tensor) else target.double().numpy()
    if t.shape == (3,):
        return R @ t
    if t.ndim == 3 and t.shape[-1] == 3 and t.shape[1] == 2 * t.shape[0]:
        t = sh.project_envmap(t, order=2)
    if t.shape != (9, 3):
        raise ValueError(f"target must be SH coefficients (9, 3), an env map (H, 2H, 3) or a sun direction (3,), "
                         f"got {t.shape}")
    return sh.rotate(t, R)


def working_resolution(image: torch.Tensor, sky: torch.Tensor, res: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Resize ``image (B, 3, H, W)`` and ``sky (B, 1, H, W)`` so the short side is ``res``
    (:func:`learned.data.resize_short_side`; the sky mask by majority of the area), long side rounded."""
    from .data import resize_short_side

    small = resize_short_side(image, res)
    if small is image:
        return image, sky
    return small, resize_short_side(sky.float(), res) > 0.5


def transfer_to_full_resolution(full: torch.Tensor, small: torch.Tensor, relit_small: torch.Tensor,
                                eps: float = 1e-3, guided: bool = True) -> torch.Tensor:
    """Bring a working-resolution relighting back to ``full``'s size by ratio transfer.

    ``full (B, 3, H, W)`` linear photo, ``small``/``relit_small (B, 3, h, w)`` the working
    photo and its relighting. Returns ``full * up(relit_small / small)`` where the working
    photo is brighter than ``eps``, ``up(relit_small)`` elsewhere (a black pixel has no ratio).

    ``up`` of the ratio is edge-aware when ``guided``: the log ratio is upsampled by the guided
    filter on ``full``'s log luminance (:func:`physrelight.guided_filter.guided_upsample`), so a
    ratio that changes at an object's edge changes at the photo's edge, not over a band of
    working pixels (no halo); a constant ratio stays exactly constant. ``guided=False``: bilinear.
    """
    if full.shape[-2:] == small.shape[-2:]:
        return relit_small
    size = full.shape[-2:]

    def up(x: torch.Tensor) -> torch.Tensor:
        return torch.nn.functional.interpolate(x, size=size, mode="bilinear", align_corners=False)

    ratio = _fill_dark(relit_small / small.clamp_min(eps), small > eps)
    lit = up(small) > eps
    if guided:
        from physrelight.guided_filter import guided_upsample

        lum = (full.clamp_min(0) * full.new_tensor(colour.LUMINANCE)[None, :, None, None]).sum(1, keepdim=True)
        log_ratio = guided_upsample(torch.log(lum.clamp_min(eps)), torch.log(ratio.clamp_min(1e-6)), eps=GUIDE_EPS)
        ratio_up = torch.exp(log_ratio)
    else:
        ratio_up = up(ratio)
    return torch.where(lit, full * ratio_up, up(relit_small))


def _fill_dark(ratio: torch.Tensor, lit: torch.Tensor) -> torch.Tensor:
    """``ratio (B, C, h, w)`` with its values on unlit pixels (``lit`` False, same shape) replaced by
    the mean of the lit ones nearby (normalised box filters of growing radius; 1 where an image
    channel has no lit pixel at all).

    A black working pixel has no ratio (``relit / eps`` is noise); left in, upsampling spreads it into
    its lit neighbours before the black-pixel fallback applies (a constant ratio of 1.7 next to an
    8x8 black corner came out as low as 0.21 on 241 lit pixels with the guided transfer)."""
    from physrelight.guided_filter import box_filter

    w = lit.to(ratio.dtype)
    out = torch.where(lit, ratio, torch.ones_like(ratio))
    todo = ~lit
    r = 1
    while bool(todo.any()) and r <= 2 * max(ratio.shape[-2:]):
        num, den = box_filter(ratio * w, r), box_filter(w, r)
        fill = todo & (den > 0)
        out = torch.where(fill, num / den.clamp_min(1e-12), out)
        todo = todo & ~fill
        r *= 2
    return out


GUIDE_EPS = 0.05
"""Ridge of the guided upsampling of the log ratio, in (log luminance)^2: where the photo's log luminance
varies by well over sqrt(0.05) = 0.22 (a third of a stop) within a window, that edge is followed;
flatter texture is smoothed over."""
