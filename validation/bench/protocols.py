"""The relighting protocols: which photo is relit to which lighting, and what it is compared with.

A :class:`Pair` is one relighting task (docs/bench.md, the evaluation protocol):

* source: the LDR photo of (scene, view v, lighting a), as a user would have it;
* target: the path-traced ``radiance`` of (v, lighting b), b != a, made LDR with the
  *source* photo's exposure and white balance (``radiance * 2**ev_a * wb_gains_a``),
  sRGB curve, no noise, no JPEG, clipped to [0, 1]. Only the light changes;
* foreground: not sky and a valid ground-truth normal; metrics on foreground pixels.

Protocols:

``cross``
    cross-relighting (the paper's Table 2): every view under every lighting relit to every
    other lighting of its scene.
``timelapse``
    one view, the sun moving through a day (the BigTime analogue, the paper's Table 1):
    every frame relit with the lighting of every other frame.

Source variants (robustness strata, cross-relighting only): ``dark`` re-makes the photo
3 stops under-exposed (noise and 8-bit quantisation act on the dark signal: information
is lost); ``noise_jpeg`` re-makes it with strong sensor noise (sigma 0.03 in exposed
units) and JPEG quality 40. For ``dark`` every output is brought back by +3 EV before
the metrics (``eval_stops``), so the stratum measures the information lost, not the
exposure; its target is the normally exposed one.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
import torch

from physrelight import colour
from synth.photo import photo_gain

from .data import BenchView

VARIANTS = ("", "dark", "noise_jpeg")
DARK_STOPS = 3.0
NOISE_SIGMA = 0.03
JPEG_QUALITY = 40


@dataclass
class Pair:
    """One relighting task (see the module doc).

    Attributes:
        view: the scene view.
        source, target: lighting indices a != b.
        protocol: ``"cross"`` or ``"timelapse"``.
        variant: ``""`` (the photo as rendered), ``"dark"`` or ``"noise_jpeg"``.
        photo: ``(H, W, 3)`` float32 display values of the source photo (this variant's).
        gain: ``(3,)`` world radiance -> this photo's linear units (``2**ev * wb_gains``).
        eval_stops: stops added to every output (and to the target) before the metrics.
    """

    view: BenchView
    source: int
    target: int
    protocol: str
    variant: str
    photo: np.ndarray
    gain: np.ndarray
    eval_stops: float = 0.0
    _cache: dict[str, torch.Tensor] = field(default_factory=dict, repr=False)

    @property
    def key(self) -> str:
        v = f"+{self.variant}" if self.variant else ""
        return f"{self.view.name}:{self.source}->{self.target}{v}"

    def image(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the photo linearised with the sRGB curve (the true curve is unknown to methods)."""
        if "image" not in self._cache:
            t = torch.from_numpy(np.ascontiguousarray(self.photo, dtype=np.float32)).permute(2, 0, 1)[None]
            self._cache["image"] = colour.from_ldr(t.clamp(0.0, 1.0))
        return self._cache["image"]

    def sky(self) -> torch.Tensor:
        """``(1, 1, H, W)`` bool."""
        return torch.from_numpy(np.ascontiguousarray(self.view.sky))[None, None]

    def foreground(self) -> torch.Tensor:
        """``(1, 1, H, W)`` bool: the pixels the metrics average over."""
        return torch.from_numpy(self.view.foreground())[None, None]

    def lighting(self, index: int) -> torch.Tensor:
        """``(1, 9, 3)`` float32 camera-frame SH of lighting ``index`` in this photo's linear units."""
        return torch.from_numpy((self.view.sh[index] * self.gain[None, :]).astype(np.float32))[None]

    def sun_lighting(self, index: int) -> torch.Tensor:
        """``(1, 9, 3)`` float32 camera-frame SH of lighting ``index``'s sun alone (zeros without one),
        in this photo's linear units."""
        return torch.from_numpy((self.view.sun_sh[index] * self.gain[None, :]).astype(np.float32))[None]

    def target_lighting(self) -> torch.Tensor:
        return self.lighting(self.target)

    def source_lighting(self) -> torch.Tensor:
        return self.lighting(self.source)

    def target_display(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the path-traced target, exposed like the source (+ ``eval_stops``), sRGB, clipped."""
        if "target" not in self._cache:
            rad = self.view.radiance[self.target] * self.gain[None, None, :] * 2.0**self.eval_stops
            t = torch.from_numpy(np.ascontiguousarray(rad, dtype=np.float32)).permute(2, 0, 1)[None]
            self._cache["target"] = colour.to_ldr(t.clamp_min(0.0))
        return self._cache["target"]

    def target_linear(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the path-traced target in this photo's linear units (+ ``eval_stops``), unclipped."""
        rad = self.view.radiance[self.target] * self.gain[None, None, :] * 2.0**self.eval_stops
        return torch.from_numpy(np.ascontiguousarray(rad, dtype=np.float32)).permute(2, 0, 1)[None].clamp_min(0.0)

    def display_at_best_gain(self, relit: torch.Tensor) -> torch.Tensor:
        """``(1, 3, H, W)`` :meth:`display` of ``relit`` times the single gain that minimises its foreground l1
        against :meth:`target_display` (:func:`display_at_best_gain`): metrics of this image report structure
        with the overall level (exposure) removed."""
        return display_at_best_gain(relit * 2.0**self.eval_stops, self.target_display(),
                                    self.target_linear(), self.foreground())

    def display(self, relit: torch.Tensor) -> torch.Tensor:
        """``(1, 3, H, W)`` a method's linear output (this photo's units) -> display values as the target."""
        return colour.to_ldr(relit.clamp_min(0.0) * 2.0**self.eval_stops)

    def release(self) -> None:
        """Drop cached tensors (memory of large runs)."""
        self._cache.clear()


def _variant_photo(view: BenchView, light: int, variant: str) -> tuple[np.ndarray, np.ndarray, float]:
    """(photo, gain, eval_stops) of a source variant, re-made from the radiance with seeded nuisances."""
    params = view.photo_params[light]
    if not variant:
        return view.photo[light], photo_gain(params), 0.0
    from synth.photo import PhotoParams, make_photo

    d = dict(params)
    d["wb_gains"] = tuple(float(g) for g in d["wb_gains"])
    stops = 0.0
    if variant == "dark":
        d["ev"] = float(d["ev"]) - DARK_STOPS
        stops = DARK_STOPS
    elif variant == "noise_jpeg":
        d["noise_sigma"] = NOISE_SIGMA
        d["jpeg_quality"] = JPEG_QUALITY
    else:
        raise ValueError(f"unknown source variant {variant!r}; expected one of {VARIANTS}")
    p = PhotoParams(**d)
    # str hash() changes per process: seed from the characters instead (same run, same bytes).
    seed = int(np.random.SeedSequence([*map(ord, view.name), light, VARIANTS.index(variant)]).generate_state(1)[0])
    u8 = make_photo(view.radiance[light], p, np.random.default_rng(seed))
    return u8.astype(np.float32) / 255.0, photo_gain(d), stops


def cross_pairs(views: Sequence[BenchView], variants: Sequence[str] = ("",),
                variant_views: Sequence[str] | None = None) -> list[Pair]:
    """Every view x source lighting x other target lighting, for each variant.

    Args:
        views: the views (time-lapse views are left out: they have their own protocol).
        variants: source variants to make (``""`` = the photo as rendered).
        variant_views: names of the views that get the non-empty variants (None = all).
    """
    out: list[Pair] = []
    for v in views:
        if v.group == "timelapse":
            continue
        for variant in variants:
            if variant and variant_views is not None and v.name not in variant_views:
                continue
            for a in range(v.num_lights):
                photo, gain, stops = _variant_photo(v, a, variant)
                for b in range(v.num_lights):
                    if b != a:
                        out.append(Pair(v, a, b, "cross", variant, photo, gain, stops))
    return out


def timelapse_pairs(views: Sequence[BenchView]) -> list[Pair]:
    """Every frame of every time-lapse view relit with the lighting of every other frame."""
    out: list[Pair] = []
    for v in views:
        if v.group != "timelapse":
            continue
        for a in range(v.num_lights):
            photo, gain, _ = _variant_photo(v, a, "")
            out += [Pair(v, a, b, "timelapse", "", photo, gain) for b in range(v.num_lights) if b != a]
    return out


def informative_pairs(pairs: Sequence[Pair]) -> tuple[list[Pair], list[str]]:
    """The pairs that can rank methods, and the keys of those left out.

    A pair whose display target is clipped to 1 in every channel of every foreground pixel
    (:func:`learned.relight_eval.informative_target`, the relighting evaluation's definition)
    scores any bright-enough output as exact: PSNR infinite, which would make every mean over it
    infinite. Such pairs are left out and counted instead.
    """
    from learned.relight_eval import informative_target

    kept, left_out = [], []
    for p in pairs:
        (kept if informative_target(p.target_display()[0], p.foreground()[0]) else left_out).append(p)
    return kept, [p.key for p in left_out]


def describe_pairs(pairs: Sequence[Pair]) -> dict[str, Any]:
    """Counts for the report: pairs, views, scenes per protocol and variant."""
    out: dict[str, Any] = {}
    for p in pairs:
        k = p.protocol + (f"+{p.variant}" if p.variant else "")
        d = out.setdefault(k, {"pairs": 0, "views": set(), "scenes": set()})
        d["pairs"] += 1
        d["views"].add(p.view.name)
        d["scenes"].add(p.view.scene)
    return {k: {"pairs": d["pairs"], "views": len(d["views"]), "scenes": len(d["scenes"])} for k, d in out.items()}


def display_at_best_gain(relit: torch.Tensor, target_display: torch.Tensor, target_linear: torch.Tensor,
                         foreground: torch.Tensor) -> torch.Tensor:
    """``(1, 3, H, W)`` the display values (sRGB, clipped) of ``relit`` times the single gain that minimises their
    foreground l1 against ``target_display``.

    The gain ``g`` is searched as ``g0 * 2**t``, ``t`` in [-4, 4] stops, on a 0.1-stop grid refined by golden
    section, from ``g0`` = :func:`physrelight.metrics.best_gain` (least squares in linear radiance against
    ``target_linear``, which scales as ``1 / k`` when ``relit`` is scaled by ``k``), so the result does not change
    when ``relit`` is scaled. The display curve and the clipping make the linear least-squares gain alone a poor
    fit where the target clips.

    Args:
        relit: ``(1, 3, H, W)`` linear output in the target's units. target_display: ``(1, 3, H, W)`` in [0, 1].
        target_linear: ``(1, 3, H, W)`` the target's linear values. foreground: ``(1, 1, H, W)`` bool, the pixels
            the l1 is taken over.
    """
    from physrelight.metrics import best_gain

    x = relit.clamp_min(0.0).double()
    fg = foreground.expand_as(x)
    tgt = target_display.double()[fg]
    g0 = float(best_gain(x, target_linear.double(), foreground)[0])
    xs = x[fg]

    def loss(t: torch.Tensor) -> torch.Tensor:  # (K,) stops -> (K,) l1
        g = g0 * torch.pow(2.0, t)
        return (colour.to_ldr(xs[None] * g[:, None]) - tgt[None]).abs().mean(1)

    grid = torch.arange(-40, 41, dtype=torch.float64) / 10.0
    best = int(torch.argmin(loss(grid)))
    lo, hi = float(grid[max(best - 1, 0)]), float(grid[min(best + 1, len(grid) - 1)])
    r = (5 ** 0.5 - 1) / 2
    for _ in range(30):  # golden section on the bracketing 0.2 stops: to ~1e-7 stops
        a, b = hi - r * (hi - lo), lo + r * (hi - lo)
        la, lb = loss(torch.tensor([a, b], dtype=torch.float64))
        lo, hi = (lo, b) if la <= lb else (a, hi)
    g = g0 * 2.0 ** ((lo + hi) / 2)
    return colour.to_ldr(x * g).to(relit.dtype)
