"""What a relighting can be asked: the relighter's tuning, fixed at construction (:class:`RelightOptions`), and
one relighting's request beyond the photo and the target (:class:`RelightRequest`, the keyword arguments of
``Relighter.relight``, ``relight_sequence`` and ``relight_layers``), with the names each choice takes.

``from learned.relight_options import RelightOptions``; ``Relighter.load(options=RelightOptions(denoise=DENOISE))``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from physrelight.quotient import SMOOTH_RADIUS

from physrelight.sky_mask import GROW_REACH
from .source_lighting import SourceLightingConfig

__all__ = ["DEFAULT_FOV_DEG", "DEFAULT_METHOD", "DENOISE", "LIGHTING_ESTIMATORS", "RELIGHT_METHODS", "SKY_LEVELS",
           "SKY_SOURCES", "SOURCE_ESTIMATES", "RelightOptions", "RelightRequest"]

DEFAULT_METHOD = "proposed"
"""The method of ``relight`` and the command line unless told: the shipped renderer on top of the quotient
image, which beat ``quotient`` on both held-out sets (docs/experiments/29-renderer-on-the-quotient.md)."""

RELIGHT_METHODS = ("proposed", "lambertian_sh", "shadownet_lambertian", "quotient", "quotient_shadownet")
"""The methods of ``Relighter.relight_linear`` (which documents each)."""
DEFAULT_FOV_DEG = 60.0
"""A photo's horizontal field of view when nothing says otherwise (no EXIF focal length, no ``--fov``)."""
SKY_SOURCES = ("target", "fit", "gan", "keep")
"""Where a relit photo's sky comes from: ``"target"``, the target's own sky through the photo's camera (an
env map or a sun target); ``"fit"``, the outdoor sky model fitted to the target's order-2 SH
(:func:`physrelight.sky_model.fit_sky`; any target); ``"gan"``, SkyGAN; ``"keep"``, the photo's own."""
LIGHTING_ESTIMATORS = ("network", "source_map")
"""The source-lighting steps of ``Relighter.decompose_linear`` (:attr:`RelightOptions.lighting_estimator`)."""
DENOISE = (2, 3.0)
"""The (radius, strength) of :attr:`RelightOptions.denoise` when it is turned on (``relight --denoise``): chosen on
data/val5 by study 37's rule; not the default (docs/experiments/37-denoise-before-the-quotient.md)."""

SKY_LEVELS = ("grey_world", "decomposition")
"""The levels a rendered sky can be put at (:attr:`RelightOptions.sky_level`)."""
SOURCE_ESTIMATES = ("decomposition", "sky")
"""What the estimated track takes as the photo's own lighting (:attr:`RelightOptions.source_estimate`)."""


@dataclass(frozen=True)
class RelightOptions:
    """The relighter's tuning, fixed at construction (:meth:`learned.relighter.Relighter.load`'s ``options``; a
    variant: :meth:`learned.relighter.Relighter.with_options`). Each default is the shipped setting, chosen by the
    study named.

    Attributes:
        lighting_estimator: the source-lighting step (:data:`LIGHTING_ESTIMATORS`): ``"source_map"`` (default
            since issue 26), :mod:`learned.source_lighting` (MAP in the prior's subspace, robust weights, the sky's
            pixels when K is given; each a switch of ``source_config``); ``"network"``, the lighting step exported
            with the inverse network (map_relative), the figures before.
        source_config: the switches of ``"source_map"`` (:class:`learned.source_lighting.SourceLightingConfig`).
        ratio_radius: the quotient methods' ratio is guided-filtered at this radius (px at the working
            resolution; 0 = raw ratio, the figures before study 27): :func:`physrelight.quotient.smooth_ratio`.
        sky_grow: the segmenter's sky is grown by sky-coloured pixels within this fraction of the short side
            (:func:`physrelight.sky_mask.grow_sky_by_colour`): the sky between a lattice's bars
            (:data:`physrelight.sky_mask.GROW_REACH`, study 40; 0: off, the masks before).
        sky_smooth: SkyGAN's sky is blurred within the mask by a Gaussian of this fraction of the short side
            (:func:`learned.sky_gan.smooth_sky`; None: ``SMOOTH_SIGMA``, 1/8; 0: SkyGAN's own sky; study 31).
        sky_level: the level of the estimated source lighting that a rendered sky (sky source ``"target"`` or
            ``"fit"``) is put in, on the estimated track (:data:`SKY_LEVELS`): ``"grey_world"``, the level under
            which the foreground's median albedo is middle grey (:func:`learned.source_lighting.grey_world_level`;
            study 36), or ``"decomposition"``, the lighting estimate's own (the network's albedo; the figures
            before). The relit foreground does not depend on it (a quotient of two shadings of one estimate);
            the sky's brightness against it does.
        renderer_gain_ratio: a quotient-based renderer's gain for the target divided by its gain for the source
            lighting itself, so a photo relit to its own lighting gets the quotient's ratio alone. Off: measured
            worse on data/val5 (l1 +0.0053 against the plain gain, +0.0011 against quotient; study 29).
        denoise: the photo smoothed before relighting, as (radius, strength) of :func:`physrelight.denoise.denoise`
            (:data:`DENOISE`: study 37's setting, relight --denoise); None, the default: the photo as it is. Off by
            default: it helps the synthetic bench but its noise estimate reads pixel-scale texture as noise, and
            real foliage loses its texture (study 37).
        level_prior: estimated track with a given source level (``relight_linear``'s ``source_lighting``): the
            weight of the grey world in the relit level. The estimated lighting's shape, put at the given level,
            says how much light falls on the visible surfaces; so does the photo's brightness under a middle-grey
            albedo. The level used is the geometric blend: exponent 0 (the default), the shape alone; 1, the grey
            world alone (:func:`learned.source_lighting.grey_world_level`; study 39).
        source_estimate: the photo's own lighting on the estimated track (:data:`SOURCE_ESTIMATES`):
            ``"decomposition"``, the decomposition's order-2 estimate (the figures before issue 44); ``"sky"``, the sun
            and sky read from the photo's sky through its camera (:func:`learned.sky_lighting.read_sky_lighting`: the
            posterior's MAP sky, sun and a ground, as order-2 SH at the decomposition's level; the quotient shades
            its sun by the exact cosine when the target's sun is too), falling back to the decomposition's where the
            sky says nothing (no sky, night, overcast, blown out, a sky the model cannot draw, a sun not seen where
            the fit puts it, a sun it does not place). The default stays ``"decomposition"``, chosen on the training
            panoramas' crops (bench --real --full's 118 training crops with sky: self-relighting ``quotient`` 22.83
            dB today, 21.84 dB with ``"sky"``; the sky reads 32 of them, and its misread suns, on dawn, night and
            hazy skies, cost more than its right ones gain) and on bench --quick's synthetic pairs (``proposed`` l1
            0.1194 today, 0.1297 with ``"sky"``); docs/experiments/61-sun-in-relighter.md, 64, 65.

    Raises:
        ValueError: an option out of its range, named.
    """

    lighting_estimator: str = "source_map"
    source_config: SourceLightingConfig = field(default_factory=SourceLightingConfig)
    ratio_radius: int = SMOOTH_RADIUS
    sky_grow: float = GROW_REACH
    sky_smooth: float | None = None
    sky_level: str = "grey_world"
    renderer_gain_ratio: bool = False
    denoise: tuple[int, float] | None = None
    level_prior: float = 0.0
    source_estimate: str = "decomposition"

    def __post_init__(self) -> None:
        def number(x: Any) -> bool:
            return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)

        if self.lighting_estimator not in LIGHTING_ESTIMATORS:
            raise ValueError(f"lighting_estimator must be one of {LIGHTING_ESTIMATORS}, "
                             f"got {self.lighting_estimator!r}")
        if not isinstance(self.source_config, SourceLightingConfig):
            raise ValueError(f"source_config must be a SourceLightingConfig, got {type(self.source_config).__name__}")
        if not number(self.ratio_radius) or self.ratio_radius < 0 or int(self.ratio_radius) != self.ratio_radius:
            raise ValueError(f"ratio_radius must be a non-negative integer, got {self.ratio_radius!r}")
        if not number(self.sky_grow) or not 0.0 <= self.sky_grow <= 1.0:
            raise ValueError(f"sky_grow must be a number in [0, 1], got {self.sky_grow!r}")
        if self.sky_smooth is not None and not (number(self.sky_smooth) and self.sky_smooth >= 0):
            raise ValueError(f"sky_smooth must be None or a fraction of the short side >= 0, got {self.sky_smooth!r}")
        if self.sky_level not in SKY_LEVELS:
            raise ValueError(f"sky_level must be one of {SKY_LEVELS}, got {self.sky_level!r}")
        if not isinstance(self.renderer_gain_ratio, bool):
            raise ValueError(f"renderer_gain_ratio must be True or False, got {self.renderer_gain_ratio!r}")
        if self.denoise is not None and not (isinstance(self.denoise, tuple) and len(self.denoise) == 2
                                             and all(number(x) for x in self.denoise)):
            raise ValueError(f"denoise must be None or a (radius, strength) pair, got {self.denoise!r}")
        if not number(self.level_prior) or not 0.0 <= self.level_prior <= 1.0:
            raise ValueError(f"level_prior must lie in [0, 1], got {self.level_prior!r}")
        if self.source_estimate not in SOURCE_ESTIMATES:
            raise ValueError(f"source_estimate must be one of {SOURCE_ESTIMATES}, got {self.source_estimate!r}")
        object.__setattr__(self, "ratio_radius", int(self.ratio_radius))


@dataclass(frozen=True)
class RelightRequest:
    """What one relighting of a photo asks beyond the photo and the target: the keyword arguments of
    ``Relighter.relight``, ``Relighter.relight_sequence`` (all but ``azimuth_deg``) and ``Relighter.relight_layers``
    (:mod:`learned.relighter`).

    Attributes:
        world_to_camera: ``(4, 4)`` or ``(3, 3)``; None = a level camera looking along world -Z whose pitch is
            ``pitch_deg``.
        sky_mask: ``(H, W)`` bool, True on sky; None = the sky segmenter's plausible sky at full resolution
            (:func:`learned.sky_segmentation.sky_mask_full_resolution`; when shipped, else no sky); when it finds
            none a ``UserWarning`` says why and only the foreground is relit.
        method: see ``Relighter.relight_linear`` (:data:`RELIGHT_METHODS`).
        azimuth_deg: turn the target about the world's vertical axis first, in degrees clockwise seen from above,
            as ``relight --sun``'s and ``--azimuth``'s angles count (a sun at azimuth ``a`` goes to ``a + azimuth_deg``;
            :func:`physrelight.target_lighting.rotate_azimuth`, docs/conventions.md).
        sky: sky type of a sun-direction target (:data:`physrelight.target_lighting.SKY_TYPES`).
        new_sky: False keeps the photo's sky whatever ``sky_source`` says.
        seed: SkyGAN's noise (same seed, same sky).
        sky_source: :data:`SKY_SOURCES` or None: ``"target"`` for an env-map or sun target, else ``"gan"`` when
            SkyGAN is shipped, else ``"keep"``. ``"target"`` looks the target itself up through the photo's camera
            (:func:`physrelight.sky_view.target_sky`), ``"fit"`` the sky model fitted to the target's SH
            (:func:`physrelight.sky_view.fitted_sky`), both in the relit foreground's units.
        exposure: ``"auto"`` (the default, as the command line's ``--exposure``): meter the relit photo as a camera
            would; ``"keep"``: the photo's camera settings; or stops added to ``"keep"``
            (:func:`physrelight.exposure.exposure_gain`).
        fov_deg: the photo's horizontal field of view (its focal length, e.g. from EXIF).
        pitch_deg: the level camera's pitch; None: estimated from the sky's horizon
            (:func:`physrelight.horizon.estimate_pitch`). Ignored when ``world_to_camera`` is given.
        source: the photo's own lighting (SH, env map, path, sun direction or ``Sun``, world frame, the target's units),
            when known (a map captured on set): the *known-source* track of ``Relighter.relight_linear``
            (quotient methods divide by it; relighting to it gives the photo back). None: the decomposition's
            estimate.
        linear: give ``relit`` as linear radiance instead of display values: the photo's linear units (sRGB
            decoded, or a radiance photo's own) times the exposure's gain, its sky in the same units, not clipped.
            For measuring against a renderer; the other layers stay display values.
    """

    world_to_camera: Any = None
    sky_mask: Any = None
    method: str = DEFAULT_METHOD
    azimuth_deg: float = 0.0
    sky: str = "clear"
    new_sky: bool = True
    seed: int = 0
    sky_source: str | None = None
    exposure: str | float = "auto"
    fov_deg: float = DEFAULT_FOV_DEG
    pitch_deg: float | None = None
    source: Any = None
    linear: bool = False
