"""Inference: the relighting pipeline on a photo: sky mask, decomposition, target shading and shadow, the neural
renderer on the quotient image, the new sky.

``Relighter.load()`` reads the weights shipped in ``learned/weights`` (safetensors, no network access needed);
its tuning is one frozen :class:`learned.relight_options.RelightOptions` given at construction.
``decompose(image)`` gives albedo, normals (camera frame), shadow and the solved, prior-projected SH lighting
(camera frame); ``relight(image, target)``, ``relight_sequence`` and ``relight_layers`` relight a photo of any
size, one step under three wrappers (:class:`learned.relight_options.RelightRequest` names their keyword arguments
once).

What is not learned lives in the core: the photo at the door (:mod:`physrelight.image_input`), the target
lighting and its sun (:mod:`physrelight.target_lighting`), the target's sky through the camera
(:mod:`physrelight.sky_view`), the camera's pitch (:mod:`physrelight.horizon`), the lighting's level and the
display exposure (:mod:`physrelight.exposure`) and the working resolution and ratio transfer
(:mod:`physrelight.full_resolution`).

Images: a photo as numpy ``(H, W, 3)`` (uint8, or float display values in [0, 1]) or torch ``(3, H, W)`` /
``(B, 3, H, W)`` float display values; it is linearised with the sRGB curve. Results come back as the type given:
numpy ``(H, W, C)`` or torch ``(B, C, H, W)`` (``(C, H, W)`` for an unbatched torch image). Lighting is ``(9, 3)``
radiance SH (``(B, 9, 3)`` for a batch). Targets: SH ``(9, 3)``, an environment map (``(H, 2H, 3)`` or an EXR
path) or a sun, as a direction ``(3,)`` or as :class:`physrelight.target_lighting.Sun` ``(elevation_deg,
azimuth_deg)`` (``relight --sun``'s angles), world frame (Y up), rotated into the camera with ``world_to_camera``
(``(4, 4)`` or ``(3, 3)``); without it the camera is level, looking along world -Z, pitched as estimated.
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physrelight import colour, image_model
from physrelight.exposure import dc_luminance, exposure_gain, exposure_scale, parse_exposure
from physrelight.full_resolution import transfer_to_full_resolution, working_resolution
from physrelight.horizon import photo_camera
from physrelight.image_input import as_image, as_mask, as_radiance, give_back
from physrelight.lighting_prior import LightingPrior
from physrelight.parallel import single_threaded
from physrelight.quotient import quotient_relight
from physrelight.sky_view import rendered_sky
from physrelight.target_lighting import as_lighting_batch, camera_target, read_target, sky_map_kind

from . import checkpoint as ckpt
from .lighting import WEIGHTS_DIR, load_prior
from .networks import InverseNet, ShadowNet, repair_top_rows
from .objectives import decompose_and_solve
from .relight_options import DEFAULT_METHOD, RELIGHT_METHODS, SKY_SOURCES, RelightOptions, RelightRequest
from .source_lighting import grey_world_level, solve_source_lighting

__all__ = ["RELIGHT_STAGES", "WEIGHT_FILES", "RelitLayers", "Relighter", "fill_weights_folder"]

RELIGHT_STAGES = ("sky mask", "relighting", "sky", "layers")
"""The stages of one relighting, in order, as ``Relighter.on_stage`` is told them: the full-resolution sky mask
and camera (once per photo), the decomposition and relighting at the working resolution brought to full size,
the new sky and the exposure, and the full-size layers (``relight_layers`` only)."""


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


_log = logging.getLogger(__name__)
_OPTION_NAMES = frozenset(f.name for f in dataclasses.fields(RelightOptions))


class RelitLayers(dict):
    """:meth:`Relighter.relight_layers`'s layers (name -> ``(H, W, C)`` array) and what the photo's own lighting was
    taken to be, for ``lighting.json``.

    Attributes:
        sky_lighting: the sky's reading (:class:`learned.sky_lighting.SkyLighting`) when the estimated track read it
            (:attr:`RelightOptions.source_estimate` ``"sky"``), else None.
        decomposition_lighting: ``(9, 3)`` the decomposition's camera-frame lighting at the working resolution.
        source_lighting: ``(9, 3)`` the camera-frame lighting the relighting took as the photo's (the quotient's
            divisor, in the decomposition's units): the sky's reading at the decomposition's level, else
            ``decomposition_lighting``.
        K, world_to_camera: the camera the photo was relit through.
    """

    sky_lighting: Any = None
    decomposition_lighting: np.ndarray | None = None
    source_lighting: np.ndarray | None = None
    K: Any = None
    world_to_camera: Any = None


class Relighter:
    """The relighting pipeline at inference: sky mask, inverse network + lighting solve, ShadowNet, the neural
    renderer, SkyGAN.

    Use :meth:`load`; the constructor takes ready modules and the tuning (:class:`RelightOptions`, read-only
    afterwards: :meth:`with_options` gives a variant). :attr:`on_stage`, called with the name of each stage of a
    relighting as it starts (:data:`RELIGHT_STAGES`), is for a progress display (a 4000 x 2669 photo takes
    about 12 s at one thread from the command line, docs/bench.md); None: silent.
    """

    def __init__(self, inverse: InverseNet, shadow_net: ShadowNet, prior: LightingPrior, res: int = 64,
                 renderer: torch.nn.Module | None = None, sky_segmenter: torch.nn.Module | None = None,
                 sky_generator: torch.nn.Module | None = None, options: RelightOptions | None = None) -> None:
        if options is not None and not isinstance(options, RelightOptions):
            raise ValueError(f"options must be a RelightOptions, got {type(options).__name__}")
        self.inverse, self.shadow_net, self.prior, self.res = inverse.eval(), shadow_net.eval(), prior, res
        self.renderer = renderer.eval() if renderer is not None else None
        self.sky_segmenter = sky_segmenter.eval() if sky_segmenter is not None else None
        self.sky_generator = sky_generator.eval() if sky_generator is not None else None
        self.options = options if options is not None else RelightOptions()
        self.on_stage: Callable[[str], None] | None = None

    def __setattr__(self, name: str, value: Any) -> None:
        # the tuning attributes of old are options now: setting one on the instance would silently do nothing
        if name in _OPTION_NAMES:
            raise AttributeError(f"{name} is a relighting option, fixed at construction: "
                                 f"Relighter.load(options=RelightOptions({name}=...)) or .with_options({name}=...)")
        super().__setattr__(name, value)

    def with_options(self, **changes: Any) -> "Relighter":
        """A relighter sharing this one's networks, its :class:`RelightOptions` with ``changes`` (by name)."""
        other = Relighter(self.inverse, self.shadow_net, self.prior, self.res, self.renderer, self.sky_segmenter,
                          self.sky_generator, dataclasses.replace(self.options, **changes))
        other.on_stage = self.on_stage
        return other

    @property
    def renderer_base(self) -> str | None:
        """What the loaded renderer's gain multiplies (:data:`learned.neural_renderer.BASES`), None without one."""
        return None if self.renderer is None else self.renderer.base

    @classmethod
    def load(cls, path: str | os.PathLike | None = None, renderer: str | os.PathLike | None = None,
             options: RelightOptions | None = None) -> "Relighter":
        """Load ``inverse.safetensors``, ``shadow.safetensors``, ``lighting_prior.npz`` and, when
        present, ``renderer.safetensors``, ``sky_segmentation.safetensors`` and
        ``sky_gan.safetensors`` from ``path`` (a folder; None = the weights shipped in the
        package). ``renderer`` names another renderer weights file; ``options`` the tuning
        (:class:`RelightOptions`; None: the shipped defaults)."""
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
                   segmenter, generator, options)

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
        if self.options.lighting_estimator == "source_map":
            out["lighting"] = solve_source_lighting(image, out["albedo"], out["normals"], out["shadow"],
                                                    out["foreground"], self.prior, sky=sky, K=K,
                                                    config=self.options.source_config)
        out.update({k: repair_top_rows(out[k]) for k in ("albedo", "normals", "shadow")})
        return out

    def sky_mask(self, image: torch.Tensor, sky_mask: Any = None) -> torch.Tensor:
        """``(B, 1, H, W)`` bool sky mask of linear ``image (B, 3, H, W)``: the given mask, else the
        sky segmenter's (when shipped), else all False (every pixel is foreground)."""
        if sky_mask is None and self.sky_segmenter is not None:
            from .sky_segmentation import segment_sky

            return segment_sky(self.sky_segmenter, image)
        return as_mask(sky_mask, image)

    def decompose(self, image: Any, sky_mask: Any = None) -> dict[str, Any]:
        """Albedo ``(.., 3)``, normals ``(.., 3)`` (camera frame), shadow ``(.., 1)``, lighting
        ``(9, 3)`` (camera-frame radiance SH in the linearised photo's units) and the sky
        mask ``(.., 1)`` (:meth:`sky_mask`: the given one, else the segmenter's).
        """
        lin, kind = as_image(image)
        sky = self.sky_mask(lin, sky_mask)
        out = self.decompose_linear(lin, sky)
        light = out["lighting"] if kind == "bchw" else out["lighting"][0]
        result = {k: give_back(out[k], kind) for k in ("albedo", "normals", "shadow")}
        result["lighting"] = light.numpy() if kind == "numpy" else light
        result["sky_mask"] = give_back(sky, kind)
        return result

    @torch.no_grad()
    def relight_linear(self, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                       source_lighting: torch.Tensor | None = None, method: str = DEFAULT_METHOD,
                       decomposition: dict[str, torch.Tensor] | None = None,
                       known_source: bool = False, *, target_sun: torch.Tensor | None = None,
                       source_sun: torch.Tensor | None = None, read_source: torch.Tensor | None = None,
                       read_source_sun: torch.Tensor | None = None) -> dict[str, torch.Tensor]:
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
            read_source, read_source_sun: ``(B, 9, 3)`` or ``(9, 3)`` camera-frame radiance SH of the photo's own
                lighting read from elsewhere (its sky: :func:`learned.sky_lighting.read_sky_lighting`, any level) and
                its sun's part, or None. On the estimated track it stands for the decomposition's lighting, put at
                that lighting's level (DC luminance): the quotient divides by it (its sun by the exact cosine when
                ``target_sun`` is given), the renderer is given it. Ignored on the known track.

        Returns:
            ``relit (B, 3, H, W)`` linear, sky pixels equal to ``image``; ``target (B, 9, 3)`` in
            the decomposition's units; ``target_shadow (B, 1, H, W)`` (ones for ``lambertian_sh``);
            the decomposition's ``albedo``, ``normals``, ``shadow``, ``lighting``, ``foreground``; ``source
            (B, 9, 3)`` the source lighting the estimated track used (``read_source`` at the decomposition's
            level, else the decomposition's ``lighting``).
        """
        if method not in RELIGHT_METHODS:
            raise ValueError(f"method must be one of {RELIGHT_METHODS}, got {method!r}")
        if image.ndim != 4 or image.shape[1] != 3:
            raise ValueError(f"image must have shape (B, 3, H, W), got {tuple(image.shape)}")
        b = image.shape[0]
        if sky.shape != (b, 1, *image.shape[-2:]):
            raise ValueError(f"sky must have shape {(b, 1, *image.shape[-2:])}, got {tuple(sky.shape)}")

        tgt = as_lighting_batch(target, b, "target")
        out = self.decompose_linear(image.float(), sky.bool()) if decomposition is None else decomposition
        source = None if source_lighting is None else as_lighting_batch(source_lighting, b, "source_lighting")
        if known_source and source is None:
            raise ValueError("known_source needs source_lighting: the photo's own lighting")
        quotient_based = method == "proposed" and self.renderer_base == "quotient"
        if known_source and not (method.startswith("quotient") or quotient_based):
            raise ValueError(f"known_source is a track of the quotient methods and of a quotient-based renderer, "
                             f"not of {method!r}")
        estimate, estimate_sun = out["lighting"], None
        if read_source is not None and not known_source:
            # the shape read from the sky at the decomposition's level: the albedo's scale and every level
            # downstream (the target's, the grey world's) stay the decomposition's
            read = as_lighting_batch(read_source, b, "read_source").to(estimate.dtype)
            prior_level = dc_luminance(self.prior.mean.reshape(1, 9, 3).to(estimate.dtype))
            level = dc_luminance(estimate)
            level = torch.where(level > 1e-6 * prior_level, level, prior_level)
            k = (level / dc_luminance(read).clamp_min(torch.finfo(read.dtype).tiny))[:, None, None]
            estimate = read * k
            if read_source_sun is not None:
                estimate_sun = as_lighting_batch(read_source_sun, b, "read_source_sun").to(estimate.dtype) * k
        est_out = out if estimate is out["lighting"] else {**out, "lighting": estimate}
        scale = exposure_scale(tgt, estimate, source, fallback=self.prior.mean.reshape(1, 9, 3))[:, None, None]
        if source is not None and not known_source and self.options.level_prior:
            scale = scale / self.grey_world_gain(image, sky, est_out, scale) ** self.options.level_prior
        tgt = tgt * scale
        if method == "lambertian_sh" or method == "quotient":
            s = torch.ones_like(out["shadow"])
        else:
            s = repair_top_rows(self.shadow_net(out["normals"], tgt))
        if method in ("quotient", "quotient_shadownet") or quotient_based:
            src = source * scale if known_source else estimate
            src_shadow = out["shadow"] if method == "quotient_shadownet" else None
            t_sun = None if target_sun is None else as_lighting_batch(target_sun, b, "target_sun") * scale
            s_sun = None
            if known_source and t_sun is not None:
                s_sun = (torch.zeros_like(src) if source_sun is None
                         else as_lighting_batch(source_sun, b, "source_sun") * scale)
            elif t_sun is not None and estimate_sun is not None:  # the sun read from the sky: its exact cosine too
                s_sun = estimate_sun
            relit = quotient_relight(image.float(), out["normals"], src, tgt, mask=~sky, source_shadow=src_shadow,
                                     target_shadow=s if method == "quotient_shadownet" else None,
                                     source_sun=s_sun, target_sun=t_sun, sun_cosine=t_sun is not None,
                                     smooth_radius=self.options.ratio_radius)
        if quotient_based and self.options.renderer_gain_ratio and not self.renderer.additive:
            from .neural_renderer import positive, renderer_inputs

            # the renderer's gain for the target over its gain for the source itself: relit to its own
            # lighting, the photo gets the quotient's ratio alone (study 29)
            img, fg = image.float(), ~sky.bool()
            q_src = quotient_relight(img, out["normals"], src, src, mask=fg, smooth_radius=self.options.ratio_radius)
            s_src = repair_top_rows(self.shadow_net(out["normals"], src))
            args = (img, sky.bool(), out["albedo"], out["normals"], out["shadow"], estimate)
            g_t = self.renderer.gain(renderer_inputs(*args, tgt, s, relit))
            g_s = self.renderer.gain(renderer_inputs(*args, src, s_src, q_src))
            relit = torch.where(sky, img, positive(relit * g_t / g_s))
        elif method == "proposed" and self.renderer is not None:
            from .neural_renderer import render_relit

            # a quotient-based renderer is a learned gain on the quotient image just computed
            relit = render_relit(self.renderer, image.float(), sky.bool(), est_out, tgt, s,
                                 quotient=relit if quotient_based else None)
        elif method not in ("quotient", "quotient_shadownet"):
            relit = image_model.render(out["albedo"], out["normals"], tgt, s)
        relit = torch.where(sky, image.float(), relit.clamp_min(0))
        return {"relit": relit, "target": tgt, "target_shadow": s, "source": estimate, **{k: out[k] for k in (
            "albedo", "normals", "shadow", "lighting", "foreground")}}

    @staticmethod
    def grey_world_gain(image: torch.Tensor, sky: torch.Tensor, decomposition: dict[str, torch.Tensor],
                        scale: torch.Tensor) -> torch.Tensor:
        """``(B, 1, 1)`` the foreground's median implied albedo over middle grey, with the estimated lighting's
        shape at the given source level.

        ``decomposition["lighting"] / scale`` is the estimate in the given source's units (``scale`` from
        :func:`physrelight.exposure.exposure_scale`, ``(B, 1, 1)``); the implied albedo is
        ``lum(image) / lum(shading(n; that))``
        (:func:`learned.source_lighting.grey_world_level`). Above 1, the photo is brighter than a middle-grey
        scene under that lighting would be: more light falls on the visible surfaces than the estimated shape
        puts there. ``image (B, 3, H, W)`` linear, ``sky (B, 1, H, W)`` bool.
        """
        g = grey_world_level(image.float(), decomposition["normals"], decomposition["lighting"] / scale,
                             ~sky.bool())
        return g.to(scale.dtype)[:, None, None]

    def denoised(self, image: torch.Tensor) -> torch.Tensor:
        """``(B, 3, H, W)`` linear ``image`` smoothed by :func:`physrelight.denoise.denoise` at
        :attr:`RelightOptions.denoise` (the image itself when that is None, the default): what the foreground is
        relit from."""
        if self.options.denoise is None:
            return image
        from physrelight.denoise import denoise

        return denoise(image.float(), *self.options.denoise)

    @torch.no_grad()
    def relight_full_resolution(self, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                                source_lighting: torch.Tensor | None = None, method: str = DEFAULT_METHOD,
                                working_res: int | None = None,
                                decomposition: dict[str, torch.Tensor] | None = None,
                                known_source: bool = False, denoised: torch.Tensor | None = None,
                                **sun: torch.Tensor | None) -> dict[str, Any]:
        """:meth:`relight_linear` at a working resolution, brought back to the image's size.

        The image is resized so its short side is ``working_res`` (None: the networks' ``res``;
        :func:`physrelight.full_resolution.working_resolution`), relit there, and brought back by ratio transfer
        (:func:`physrelight.full_resolution.transfer_to_full_resolution`), so detail finer than the working
        resolution survives. With :attr:`RelightOptions.denoise` set (off by default, study 37) the foreground is
        relit from the photo smoothed by :func:`physrelight.denoise.denoise`; sky pixels stay the photo's own.

        Args:
            image: ``(B, 3, H, W)`` linear; sky ``(B, 1, H, W)`` bool; target, source_lighting,
                method, known_source, ``target_sun=``, ``source_sun=``, ``read_source=``, ``read_source_sun=``: as for
                :meth:`relight_linear`.
            decomposition: the ``"working"`` dict of an earlier call on the same image and sky at the
                same working resolution (its decomposition is reused), or None.
            denoised: :meth:`denoised` of this very ``image``, when the caller has it (a sequence of
                targets denoises its photo once), or None.

        Returns:
            ``relit`` ``(B, 3, H, W)`` linear at full size (sky pixels = ``image``), ``working``
            (:meth:`relight_linear`'s dict at the working resolution), ``working_image`` and ``working_sky``
            (the image, denoised when :attr:`RelightOptions.denoise` is set, and sky mask it was relit from).
        """
        clean = self.denoised(image) if denoised is None else denoised  # the foreground is relit from it
        small, small_sky = working_resolution(clean, sky, self.res if working_res is None else working_res)
        with single_threaded():  # 64 px: threads cost more than they save (physrelight.parallel.single_threaded)
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
                side (:func:`learned.sky_gan.smooth_sky`); None: :attr:`RelightOptions.sky_smooth`, or
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

        opt = self.options.sky_smooth
        smooth = smooth if smooth is not None else opt if opt is not None else SMOOTH_SIGMA
        if not (isinstance(smooth, (int, float)) and smooth >= 0):
            raise ValueError(f"smooth must be a fraction of the short side >= 0, got {smooth!r}")
        painted = generate_sky(self.sky_generator, working["relit"], working_sky, working["target"], seed=seed)
        painted = torch.nn.functional.interpolate(painted, size=relit.shape[-2:], mode="bilinear", align_corners=False)
        if smooth > 0:
            # SkyGAN's blotches are detail it cannot place: blurred away, its sky scores higher (study 31)
            painted = smooth_sky(painted, sky, float(smooth))
        return torch.where(sky, painted, relit)

    def relight(self, image: Any, target: Any, world_to_camera: Any = None, sky_mask: Any = None,
                radiance: bool = False, **request: Any) -> Any:
        """Relight a photo of any size to a target lighting; the relit photo only.

        See :meth:`relight_layers` for ``image``, ``target`` and ``radiance`` and :class:`RelightRequest` for the
        rest; returns display values in [0, 1] (sRGB), type and layout of ``image`` (a batch is relit photo by
        photo), or with ``linear`` the relit linear radiance before the display curve.
        """
        req = RelightRequest(world_to_camera, sky_mask, **request)
        lin, kind, gain = as_radiance(image) if radiance else (*as_image(image), 1.0)
        reqs = [req if lin.shape[0] == 1 else dataclasses.replace(
            req, sky_mask=None if sky_mask is None else as_mask(sky_mask, lin)[b: b + 1]) for b in range(lin.shape[0])]
        frames = [self._relight_tensors(lin[b: b + 1], target, reqs[b], layers=False, radiance=radiance)["relit"]
                  for b in range(lin.shape[0])]
        return give_back(torch.cat(frames) / gain if req.linear else torch.cat(frames), kind)

    def relight_sequence(self, image: Any, target: Any, azimuths_deg: Any, world_to_camera: Any = None,
                         sky_mask: Any = None, progress: bool = False, radiance: bool = False,
                         **request: Any) -> list[Any]:
        """:meth:`relight` for each azimuth of ``azimuths_deg`` (degrees clockwise seen from above, as
        :class:`RelightRequest`'s ``azimuth_deg``; e.g. a turning sun), the photo
        segmented and decomposed once: the same frames as separate :meth:`relight` calls, cheaper (display
        values, or linear radiance with ``linear``; ``radiance`` as for :meth:`relight_layers`; the rest
        :class:`RelightRequest`'s but ``azimuth_deg``). ``progress`` shows a progress bar."""
        from tqdm import tqdm

        if "azimuth_deg" in request:
            raise TypeError("relight_sequence takes azimuths_deg, not azimuth_deg")
        req = RelightRequest(world_to_camera, sky_mask, **request)
        lin, kind, gain = as_radiance(image) if radiance else (*as_image(image), 1.0)
        if lin.shape[0] != 1:
            raise ValueError(f"relight_sequence takes one image, got a batch of {lin.shape[0]}")
        reuse: dict[str, Any] = {}
        azimuths = np.asarray(azimuths_deg, dtype=np.float64).ravel()
        frames = (self._relight_tensors(lin, target, dataclasses.replace(req, azimuth_deg=float(a)), layers=False,
                                        reuse=reuse, radiance=radiance)["relit"]
                  for a in tqdm(azimuths, desc="relight", disable=not progress))
        return [give_back(f / gain if req.linear else f, kind) for f in frames]

    def relight_layers(self, image: Any, target: Any, world_to_camera: Any = None, sky_mask: Any = None,
                       radiance: bool = False, **request: Any) -> dict[str, np.ndarray]:
        """Relight a photo of any size and give every layer at full resolution.

        The networks run at their training resolution (the short side resized to ``res``);
        the result comes back at full resolution by ratio transfer: the full-resolution
        linear photo times the ratio ``relit / photo`` of the working resolution, upsampled
        along the photo's edges (:func:`physrelight.full_resolution.transfer_to_full_resolution`), so fine detail
        the networks never saw survives (where the working photo is black the upsampled relit image is used
        instead). The target's DC luminance is set to the estimated source lighting's, so only the
        lighting's shape and colour change (one photo does not tell the absolute light level;
        :meth:`relight_linear` takes ``source_lighting`` for that); ``exposure`` then picks how the
        result is shown (:mod:`physrelight.exposure`). The sky is the given mask or the segmenter's, replaced
        from ``sky_source`` (:class:`RelightRequest`).

        Args:
            image: the photo (see the module doc); a single image.
            target: SH ``(9, 3)``, env map ``(H, 2H, 3)``, EXR path, sun direction ``(3,)`` or
                :class:`physrelight.target_lighting.Sun`, world frame.
            radiance: ``image`` is linear radiance (float, any scale: a render's or an HDR photo's), not display
                values. It is relit at a display-like level
                (:data:`physrelight.image_input.RADIANCE_WHITE_QUANTILE`; ``exposure="keep"`` keeps that level for
                display), and a ``linear`` result is given back in its own units.
            world_to_camera, sky_mask, **request: :class:`RelightRequest` (``method``, ``azimuth_deg``, ``sky``,
                ``new_sky``, ``seed``, ``sky_source``, ``exposure``, ``fov_deg``, ``pitch_deg``, ``source``,
                ``linear``).

        Returns:
            :class:`RelitLayers`, numpy ``(H, W, C)`` display values in [0, 1]: ``relit``, ``albedo``, ``normals``
            (``0.5 * n + 0.5``), ``shadow`` (source), ``target_shadow``, ``shading`` (target
            shading, tone-mapped), ``sky_mask`` (C = 1); and, as attributes, the photo's lighting as read.
        """
        req = RelightRequest(world_to_camera, sky_mask, **request)
        lin, _, gain = as_radiance(image) if radiance else (*as_image(image), 1.0)
        if lin.shape[0] != 1:
            raise ValueError(f"relight_layers takes one image, got a batch of {lin.shape[0]}")
        reuse: dict[str, Any] = {}
        layers = self._relight_tensors(lin, target, req, reuse=reuse, radiance=radiance)
        if req.linear:
            layers["relit"] = layers["relit"] / gain
        out = RelitLayers({k: v[0].permute(1, 2, 0).numpy() for k, v in layers.items()})
        out.sky_lighting = reuse.get("sky_lighting")
        out.decomposition_lighting = reuse["decomposition"]["lighting"][0].double().numpy()
        out.source_lighting = reuse["source"][0].double().numpy()
        out.K, out.world_to_camera = reuse["camera"]
        return out

    def _stage(self, name: str) -> None:
        if self.on_stage is not None:
            self.on_stage(name)

    def photo_sky(self, lin: torch.Tensor, sky_mask: Any = None) -> tuple[torch.Tensor, str]:
        """``(sky (1, 1, H, W) bool, reason)`` of one linear photo ``(1, 3, H, W)``: the given mask,
        else the segmenter's plausible sky at full resolution (``reason`` says why there is none),
        else no sky."""
        if sky_mask is None and self.sky_segmenter is not None:
            from .sky_segmentation import sky_mask_full_resolution

            sky, reasons = sky_mask_full_resolution(self.sky_segmenter, lin, grow=self.options.sky_grow)
            return sky, reasons[0]
        return as_mask(sky_mask, lin), ""

    def _relight_tensors(self, lin: torch.Tensor, target: Any, req: RelightRequest, layers: bool = True,
                         reuse: dict[str, Any] | None = None, radiance: bool = False) -> dict[str, torch.Tensor]:
        """The relit photo (``"relit"``: display values, or with ``req.linear`` the linear radiance) and, with
        ``layers``, every layer at full resolution, of one photo ``lin (1, 3, H, W)``: the one step under
        :meth:`relight`, :meth:`relight_sequence` and :meth:`relight_layers`.

        ``reuse``, a dict this method fills on its first call for a photo and reads on later
        ones: the sky mask, the camera, the denoised photo and the working-resolution decomposition,
        which do not depend on the target (:meth:`relight_sequence`); and the sky's reading of the photo's lighting
        (``"sky_lighting"``, on the estimated track with :attr:`RelightOptions.source_estimate` ``"sky"``;
        ``radiance``: ``lin`` is a radiance photo, read as linear)."""
        import warnings

        azimuth_deg, sky_type, sky_mask, source = req.azimuth_deg, req.sky, req.sky_mask, req.source
        if not math.isfinite(float(azimuth_deg)):
            raise ValueError(f"azimuth must be a finite number of degrees, got {azimuth_deg!r}")
        if not bool((lin > 0).any()):
            # nothing to divide by or to meter: the lighting solve would return NaN and name that instead
            raise ValueError("the photo is black (every pixel 0): there is no light in it to relight")
        if req.sky_source is not None and req.sky_source not in SKY_SOURCES:
            raise ValueError(f"sky_source must be one of {SKY_SOURCES} or None, got {req.sky_source!r}")
        parse_exposure(req.exposure)
        reuse = {} if reuse is None else reuse
        target = read_target(target)  # a map's path read, a Sun as its direction, two bare numbers refused
        source = None if source is None else read_target(source)  # checked, like the target, before any work
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
            reuse["camera"] = photo_camera(reuse["sky"][0, 0], req.fov_deg, req.world_to_camera, req.pitch_deg)
        sky = reuse["sky"]
        K, T = reuse["camera"]
        target_cam, sun = camera_target(target, T, azimuth_deg, sky_type)
        suns: dict[str, torch.Tensor | None] = {"target_sun": sun}
        source_cam = None
        if source is not None:
            source_cam, suns["source_sun"] = camera_target(source, T, 0.0, sky_type)
        if "denoised" not in reuse:  # one photo, one denoise, whatever the targets
            reuse["denoised"] = self.denoised(lin)
        if source is None and self.options.source_estimate == "sky":
            if "sky_lighting" not in reuse:  # one photo, one reading
                from .sky_lighting import read_sky_lighting

                reuse["sky_lighting"] = reading = read_sky_lighting(lin, sky, K, T, radiance=radiance)
                if reading.source == "sky":
                    p = reading.posterior
                    _log.info("the photo's lighting: read from its sky (sun %.1f deg up, %.1f deg from straight "
                              "ahead; %s)", p.elevation_deg, p.azimuth_deg, p.sky_kind)
                else:
                    _log.info("the photo's lighting: the decomposition's estimate (fallback: %s)", reading.reason)
            if reuse["sky_lighting"].source == "sky":
                sh_c, sun_c = reuse["sky_lighting"].camera(T)
                suns.update(read_source=torch.from_numpy(sh_c).float(), read_source_sun=torch.from_numpy(sun_c).float())
        self._stage("relighting")
        full = self.relight_full_resolution(lin, sky, target_cam, method=req.method, source_lighting=source_cam,
                                            decomposition=reuse.get("decomposition"), known_source=source is not None,
                                            denoised=reuse["denoised"], **suns)
        if "decomposition" not in reuse:
            reuse["decomposition"] = {k: full["working"][k] for k in (
                "albedo", "normals", "shadow", "lighting", "foreground")}
        reuse["source"] = full["working"]["source"]
        relit, out, small_sky = full["relit"], full["working"], full["working_sky"]
        size = lin.shape[-2:]

        def up(x: torch.Tensor) -> torch.Tensor:
            return torch.nn.functional.interpolate(x, size=size, mode="bilinear", align_corners=False)

        sky_from = req.sky_source or ("target" if sky_map_kind(target) != "sh" else "gan" if self.sky_generator
                                      else "keep")
        self._stage("sky")
        if req.new_sky and bool(sky.any()):
            if sky_from in ("target", "fit"):
                # A rendered sky comes in the relit foreground's units: the target was scaled by
                # dc(out target) / dc(target) into the decomposition's (= the photo's linear) units.
                k = float(dc_luminance(out["target"])[0] / dc_luminance(target_cam[None])[0])
                # On the estimated track that level is the estimate's, a guess of the network's albedo; a light
                # meter's (grey world) is closer (study 36), and the sky's brightness against the foreground
                # is proportional to it.
                if source is None and self.options.sky_level == "grey_world":
                    if "grey_world" not in reuse:  # one decomposition per photo, so one level
                        reuse["grey_world"] = float(grey_world_level(full["working_image"], out["normals"],
                                                                     out["source"], ~small_sky)[0])
                    k *= reuse["grey_world"]
                # rendered over the sky's bounding box only: a camera whose principal point moves with the crop
                # sees the same rays (to float64 rounding), and most photos' sky is a band at the top
                rows, cols = torch.nonzero(sky[0, 0].any(1))[:, 0], torch.nonzero(sky[0, 0].any(0))[:, 0]
                r0, r1, c0, c1 = int(rows[0]), int(rows[-1]) + 1, int(cols[0]), int(cols[-1]) + 1
                K_box = np.array(K, dtype=np.float64)
                K_box[0, 2] -= c0
                K_box[1, 2] -= r0
                radiance = rendered_sky(sky_from, target, K_box, T, r1 - r0, c1 - c0, sky_type, azimuth_deg) * k
                relit = relit.clone()
                relit[..., r0:r1, c0:c1] = torch.where(sky[..., r0:r1, c0:c1],
                                                       radiance.permute(2, 0, 1)[None].to(relit.dtype),
                                                       relit[..., r0:r1, c0:c1])
            elif sky_from == "gan":
                relit = self.paint_sky(relit, sky, out, small_sky, seed=req.seed)
        relit = relit * exposure_gain(req.exposure, relit, lin, ~sky, highlights=sky)[:, None, None, None]

        with torch.no_grad():
            result = {"relit": relit.clamp_min(0) if req.linear else colour.to_ldr(relit.clamp_min(0))}
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
