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
path) or a sun direction ``(3,)`` (a white sun plus a uniform fill sky), all in the *world* frame (Y up), rotated into the camera with ``world_to_camera``
(``(4, 4)`` or its ``(3, 3)`` rotation); without it the camera is assumed level and
looking along world -Z (camera frame = world frame).
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np
import torch

from physrelight import colour, image_model, sh
from physrelight.lighting_prior import LightingPrior

from . import checkpoint as ckpt
from .lighting import WEIGHTS_DIR, load_prior
from .networks import InverseNet, ShadowNet
from .objectives import decompose_and_solve

__all__ = ["RELIGHT_METHODS", "SKY_TYPES", "WEIGHT_FILES", "Relighter", "fill_weights_folder", "dc_luminance", "match_exposure", "rotate_azimuth",
           "sun_lighting",
           "transfer_to_full_resolution", "working_resolution"]


def _as_image(image: Any) -> tuple[torch.Tensor, str]:
    """Photo -> ``(B, 3, H, W)`` linear float32 and how to give results back ("numpy", "chw", "bchw")."""
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
    if t.dtype in (torch.uint8,):
        t = t.float() / 255.0
    elif not t.is_floating_point():
        raise ValueError(f"image must be uint8 or float display values in [0, 1], got dtype {t.dtype}")
    lin = colour.from_ldr(t.detach().float().cpu())  # raises on NaN or values outside [0, 1]
    return lin, kind


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
                 sky_generator: torch.nn.Module | None = None) -> None:
        self.inverse, self.shadow_net, self.prior, self.res = inverse.eval(), shadow_net.eval(), prior, res
        self.renderer = renderer.eval() if renderer is not None else None
        self.sky_segmenter = sky_segmenter.eval() if sky_segmenter is not None else None
        self.sky_generator = sky_generator.eval() if sky_generator is not None else None

    @classmethod
    def load(cls, path: str | os.PathLike | None = None, renderer: str | os.PathLike | None = None) -> "Relighter":
        """Load ``inverse.safetensors``, ``shadow.safetensors``, ``lighting_prior.npz`` and, when
        present, ``renderer.safetensors``, ``sky_segmentation.safetensors`` and
        ``sky_gan.safetensors`` from ``path`` (a folder; None = the weights shipped in the
        package). ``renderer`` names another renderer weights file."""
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
                   segmenter, generator)

    @torch.no_grad()
    def decompose_linear(self, image: torch.Tensor, sky: torch.Tensor) -> dict[str, torch.Tensor]:
        """Tensors in, tensors out: ``image (B, 3, H, W)`` linear, ``sky (B, 1, H, W)`` bool ->
        ``albedo, normals, shadow, lighting (B, 9, 3), lighting_solved, foreground``."""
        return decompose_and_solve(self.inverse, image, sky, self.prior)

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

    @torch.no_grad()
    def relight_linear(self, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                       source_lighting: torch.Tensor | None = None, method: str = "proposed",
                       decomposition: dict[str, torch.Tensor] | None = None) -> dict[str, torch.Tensor]:
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
            method: ``"proposed"`` (the neural renderer; ``"shadownet_lambertian"`` when no
                renderer weights are loaded), ``"lambertian_sh"`` (``albedo * shading(n; target)``,
                the InverseRenderNet-style baseline) or ``"shadownet_lambertian"`` (times
                ShadowNet's shadow for the target).
            decomposition: :meth:`decompose_linear` of this very ``(image, sky)``, to relight one photo
                to many targets without decomposing it again; None: decompose here.

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
        tgt = match_exposure(tgt, out["lighting"], source, fallback=self.prior.mean.reshape(1, 9, 3))
        if method == "lambertian_sh":
            s = torch.ones_like(out["shadow"])
        else:
            s = self.shadow_net(out["normals"], tgt)
        if method == "proposed" and self.renderer is not None:
            from .neural_renderer import render_relit

            relit = render_relit(self.renderer, image.float(), sky.bool(), out, tgt, s)
        else:
            relit = image_model.render(out["albedo"], out["normals"], tgt, s)
        relit = torch.where(sky, image.float(), relit.clamp_min(0))
        return {"relit": relit, "target": tgt, "target_shadow": s, **{k: out[k] for k in (
            "albedo", "normals", "shadow", "lighting", "foreground")}}

    @torch.no_grad()
    def relight_full_resolution(self, image: torch.Tensor, sky: torch.Tensor, target: torch.Tensor,
                                source_lighting: torch.Tensor | None = None, method: str = "proposed",
                                working_res: int | None = None,
                                decomposition: dict[str, torch.Tensor] | None = None) -> dict[str, Any]:
        """:meth:`relight_linear` at a working resolution, brought back to the image's size.

        The image is resized so its short side is ``working_res`` (None: the networks' ``res``;
        :func:`working_resolution`), relit there, and brought back by ratio transfer
        (:func:`transfer_to_full_resolution`), so detail finer than the working resolution survives.

        Args:
            image: ``(B, 3, H, W)`` linear; sky ``(B, 1, H, W)`` bool; target, source_lighting,
                method: as for :meth:`relight_linear`.
            decomposition: the ``"working"`` dict of an earlier call on the same image and sky at the
                same working resolution (its decomposition is reused), or None.

        Returns:
            ``relit`` ``(B, 3, H, W)`` linear at full size (sky pixels = ``image``), ``working``
            (:meth:`relight_linear`'s dict at the working resolution) and ``working_sky``.
        """
        small, small_sky = working_resolution(image, sky, self.res if working_res is None else working_res)
        out = self.relight_linear(small, small_sky, target, source_lighting=source_lighting, method=method,
                                  decomposition=decomposition)
        relit = torch.where(sky, image, transfer_to_full_resolution(image, small, out["relit"]))
        return {"relit": relit, "working": out, "working_sky": small_sky}

    def paint_sky(self, relit: torch.Tensor, sky: torch.Tensor, working: dict[str, torch.Tensor],
                  working_sky: torch.Tensor, seed: int = 0) -> torch.Tensor:
        """SkyGAN's sky for the target, composited into a full-resolution relighting.

        Args:
            relit: ``(B, 3, H, W)`` linear relit photo (:meth:`relight_full_resolution`'s ``"relit"``).
            sky: ``(B, 1, H, W)`` bool, where the sky goes.
            working, working_sky: that call's ``"working"`` dict (relit foreground and target at
                the working resolution) and ``"working_sky"``.
            seed: SkyGAN's noise (same seed, same sky).

        Returns:
            ``(B, 3, H, W)``: ``relit`` with the generated sky on ``sky``; ``relit`` itself when no
            generator is shipped or there is no sky.
        """
        if self.sky_generator is None or not bool(sky.any()):
            return relit
        # SkyGAN at the working resolution (its training scale), conditioned on the relit
        # foreground and the target; the sky is smooth, so upsampling it loses nothing.
        from .sky_gan import generate_sky

        painted = generate_sky(self.sky_generator, working["relit"], working_sky, working["target"], seed=seed)
        painted = torch.nn.functional.interpolate(painted, size=relit.shape[-2:], mode="bilinear", align_corners=False)
        return torch.where(sky, painted, relit)

    def relight(self, image: Any, target: Any, world_to_camera: Any = None, sky_mask: Any = None,
                method: str = "proposed", azimuth_deg: float = 0.0, sky: str = "clear", new_sky: bool = True,
                seed: int = 0) -> Any:
        """Relight a photo of any size to a target lighting; the relit photo only.

        See :meth:`relight_layers` for the arguments; returns display values in [0, 1]
        (sRGB), type and layout of ``image``.
        """
        lin, kind = _as_image(image)
        layers = self._relight_tensors(lin, target, world_to_camera, sky_mask, method, azimuth_deg, sky, new_sky,
                                       seed, layers=False)
        return _give_back(layers["relit"], kind)

    def relight_sequence(self, image: Any, target: Any, azimuths_deg: Any, world_to_camera: Any = None,
                         sky_mask: Any = None, method: str = "proposed", sky: str = "clear", new_sky: bool = True,
                         seed: int = 0, progress: bool = False) -> list[Any]:
        """:meth:`relight` for each azimuth of ``azimuths_deg`` (degrees, e.g. a turning sun), the photo
        segmented and decomposed once: the same frames as separate :meth:`relight` calls, cheaper.
        ``progress`` shows a progress bar."""
        from tqdm import tqdm

        lin, kind = _as_image(image)
        reuse: dict[str, Any] = {}
        azimuths = np.asarray(azimuths_deg, dtype=np.float64).ravel()
        return [_give_back(self._relight_tensors(lin, target, world_to_camera, sky_mask, method, float(a), sky,
                                                 new_sky, seed, layers=False, reuse=reuse)["relit"], kind)
                for a in tqdm(azimuths, desc="relight", disable=not progress)]

    def relight_layers(self, image: Any, target: Any, world_to_camera: Any = None, sky_mask: Any = None,
                       method: str = "proposed", azimuth_deg: float = 0.0, sky: str = "clear", new_sky: bool = True,
                       seed: int = 0) -> dict[str, np.ndarray]:
        """Relight a photo of any size and give every layer at full resolution.

        The networks run at their training resolution (the short side resized to ``res``);
        the result comes back at full resolution by ratio transfer: the full-resolution
        linear photo times the upsampled ratio ``relit / photo`` of the working resolution,
        so fine detail the networks never saw survives (where the working photo is black
        the upsampled relit image is used instead). The photo keeps its exposure: the
        target's DC luminance is set to the estimated source lighting's, so only the
        lighting's shape and colour change (one photo does not tell the absolute light level;
        :meth:`relight_linear` takes ``source_lighting`` for that).

        Args:
            image: the photo (see the module doc); a single image.
            target: SH ``(9, 3)``, env map ``(H, 2H, 3)``, EXR path or sun direction ``(3,)``, world frame.
            world_to_camera: ``(4, 4)`` or ``(3, 3)``; None = level camera (camera = world frame).
            sky_mask: optional ``(H, W)`` bool, True on sky; None = the sky segmenter's mask
                (when shipped; else no sky).
            method: see :meth:`relight_linear`.
            new_sky: paint a sky for the target with SkyGAN (when shipped); False keeps the photo's.
            seed: SkyGAN's noise (same seed, same sky).
            azimuth_deg: turn the target about the world's vertical axis first (degrees,
                counter-clockwise seen from above).
            sky: sky type of a sun-direction target (:func:`sun_lighting`).

        Returns:
            numpy ``(H, W, C)`` display values in [0, 1]: ``relit``, ``albedo``, ``normals``
            (``0.5 * n + 0.5``), ``shadow`` (source), ``target_shadow``, ``shading`` (target
            shading, tone-mapped), ``sky_mask`` (C = 1).
        """
        lin, _ = _as_image(image)
        if lin.shape[0] != 1:
            raise ValueError(f"relight_layers takes one image, got a batch of {lin.shape[0]}")
        layers = self._relight_tensors(lin, target, world_to_camera, sky_mask, method, azimuth_deg, sky, new_sky,
                                       seed)
        return {k: v[0].permute(1, 2, 0).numpy() for k, v in layers.items()}

    def _relight_tensors(self, lin: torch.Tensor, target: Any, world_to_camera: Any, sky_mask: Any, method: str,
                         azimuth_deg: float, sky_type: str, new_sky: bool = True, seed: int = 0,
                         layers: bool = True, reuse: dict[str, Any] | None = None) -> dict[str, torch.Tensor]:
        """The relit photo (``"relit"``) and, with ``layers``, every layer at full resolution.

        ``reuse``, a dict this method fills on its first call for a photo and reads on later
        ones: the sky mask and the working-resolution decomposition, which do not depend on
        the target (:meth:`relight_sequence`)."""
        if not math.isfinite(float(azimuth_deg)):
            raise ValueError(f"azimuth must be a finite number of degrees, got {azimuth_deg!r}")
        reuse = {} if reuse is None else reuse
        if "sky" not in reuse:
            reuse["sky"] = self.sky_mask(lin, sky_mask)
        sky = reuse["sky"]
        target_cam = self.target_lighting(rotate_azimuth(target, azimuth_deg) if azimuth_deg else target,
                                          world_to_camera, sky_type).float()
        full = self.relight_full_resolution(lin, sky, target_cam, method=method,
                                            decomposition=reuse.get("decomposition"))
        if "decomposition" not in reuse:
            reuse["decomposition"] = {k: full["working"][k] for k in (
                "albedo", "normals", "shadow", "lighting", "foreground")}
        relit, out, small_sky = full["relit"], full["working"], full["working_sky"]
        size = lin.shape[-2:]

        def up(x: torch.Tensor) -> torch.Tensor:
            return torch.nn.functional.interpolate(x, size=size, mode="bilinear", align_corners=False)

        if new_sky:
            relit = self.paint_sky(relit, sky, out, small_sky, seed=seed)

        with torch.no_grad():
            result = {"relit": colour.to_ldr(relit.clamp_min(0))}
            if not layers:  # relight() and sequences need only the photo: skip the full-size layers
                return result
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


RELIGHT_METHODS = ("proposed", "lambertian_sh", "shadownet_lambertian")


def dc_luminance(lighting: torch.Tensor) -> torch.Tensor:
    """``(B, 9, 3)`` radiance SH -> ``(B,)`` luminance of the DC term (the lighting's overall level)."""
    lum = torch.tensor(colour.LUMINANCE, dtype=lighting.dtype)
    return (lighting[:, 0] * lum).sum(-1)


def match_exposure(target: torch.Tensor, estimated_source: torch.Tensor, given_source: torch.Tensor | None = None,
                   fallback: torch.Tensor | None = None) -> torch.Tensor:
    """Scale ``target (B, 9, 3)`` into a decomposition's units.

    The decomposition's albedo and lighting share an unknown scale. With ``given_source``
    ``(B, 9, 3)`` (the source lighting in the target's units) the target is scaled by
    ``lum(DC estimated) / lum(DC given)``; without it, so that its DC luminance equals the
    estimated source lighting's (the photo keeps its exposure). Where the estimate has no
    positive level (below 1e-6 of ``fallback``'s, e.g. a photo without usable foreground),
    ``fallback`` ``(1 or B, 9, 3)`` (the prior's mean) stands in for it.

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
    return target * (est.clamp_min(0) / ref)[:, None, None]
SKY_TYPES = ("clear", "overcast")


def sun_lighting(direction: Any, sky: str = "clear") -> np.ndarray:
    """Order-2 radiance SH ``(9, 3)`` (world frame) of a simple outdoor lighting.

    ``"clear"``: a white delta sun of irradiance 1 towards ``direction`` plus a uniform
    bluish sky (0.75, 0.9, 1.2) adding 0.3 (green) of order-2 irradiance on a horizontal
    surface (soft fill light). ``"overcast"``: the CIE overcast sky
    ``L(theta) = L_z (1 + 2 cos theta) / 3`` (zenith angle theta, dark below the horizon),
    grey, no sun, scaled to order-2 irradiance 1 on a horizontal surface; the direction is
    ignored. Skies are projected from a 64 x 128 map.
    """
    if sky not in SKY_TYPES:
        raise ValueError(f"sky must be one of {SKY_TYPES}, got {sky!r}")
    d = np.asarray(direction, dtype=np.float64)
    if d.shape != (3,) or not np.all(np.isfinite(d)) or not np.linalg.norm(d) > 0:
        raise ValueError(f"a sun direction must be a finite non-zero (3,) vector, got {d.tolist()}")
    from physrelight import envmap

    dirs = envmap.directions(64, 128)
    cos_z = dirs[..., 1]
    if sky == "overcast":
        lum = np.where(cos_z > 0, (1.0 + 2.0 * np.clip(cos_z, 0, 1)) / 3.0, 0.0)
        env = np.repeat(lum[..., None], 3, axis=-1)
        coeffs = sh.project_envmap(env, order=2)
        return coeffs / float(sh.irradiance(coeffs, np.array([[0.0, 1.0, 0.0]]))[0, 1])
    blue = np.array([0.75, 0.9, 1.2])
    env = np.where(cos_z[..., None] > 0, blue, 0.0) * np.ones(3)
    sky_coeffs = sh.project_envmap(env, order=2)
    # Scale so the order-2 irradiance the image model sees on a horizontal surface is 0.3 in green.
    sky_coeffs *= 0.3 / float(sh.irradiance(sky_coeffs, np.array([[0.0, 1.0, 0.0]]))[0, 1])
    return sh.project_sun(d / np.linalg.norm(d), np.ones(3), order=2) + sky_coeffs


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
                                eps: float = 1e-3) -> torch.Tensor:
    """Bring a working-resolution relighting back to ``full``'s size by ratio transfer.

    ``full (B, 3, H, W)`` linear photo, ``small``/``relit_small (B, 3, h, w)`` the working
    photo and its relighting. Returns ``full * up(relit_small / small)`` where the working
    photo is brighter than ``eps``, ``up(relit_small)`` elsewhere (a black pixel has no ratio).
    """
    if full.shape[-2:] == small.shape[-2:]:
        return relit_small
    size = full.shape[-2:]

    def up(x: torch.Tensor) -> torch.Tensor:
        return torch.nn.functional.interpolate(x, size=size, mode="bilinear", align_corners=False)

    ratio = relit_small / small.clamp_min(eps)
    lit = up(small) > eps
    return torch.where(lit, full * up(ratio), up(relit_small))
