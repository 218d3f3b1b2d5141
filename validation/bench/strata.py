"""Failure-mode strata: subsets of the cross-relighting pairs reported on their own.

Each stratum is a predicate on a :class:`validation.bench.protocols.Pair`. The all-data
figure a stratum is compared with is the mean over every cross-relighting pair with the
photo as rendered (no source variant). Strata overlap (a pair can be low-sun and large
azimuth change at once).
"""

from __future__ import annotations

from typing import Callable

from .protocols import Pair

LOW_SUN_DEG = 20.0
NIGHT_SUN_DEG = 4.0
LARGE_AZIMUTH_DEG = 90.0
GLOSSY_SHARE = 0.2
BRIGHT_ALBEDO = 0.45
DARK_ALBEDO = 0.15


def _either(p: Pair, test: Callable[[object], bool]) -> bool:
    return test(p.view.lights[p.source]) or test(p.view.lights[p.target])


def _low_sun(light: object) -> bool:
    e = light.sun_elevation  # type: ignore[attr-defined]
    return e is not None and e < LOW_SUN_DEG


def _night(light: object) -> bool:
    e = light.sun_elevation  # type: ignore[attr-defined]
    return e is not None and e <= NIGHT_SUN_DEG


def _azimuth_change(p: Pair) -> float:
    d = abs(p.view.lights[p.source].dominant_azimuth - p.view.lights[p.target].dominant_azimuth) % 360.0
    return min(d, 360.0 - d)


STRATA: tuple[tuple[str, str, Callable[[Pair], bool]], ...] = (
    ("dark_input", "dark input: the source photo 3 stops under-exposed (outputs compared after +3 EV)",
     lambda p: p.variant == "dark"),
    ("noise_jpeg", "noise + JPEG: sensor noise sigma 0.03 and JPEG quality 40 on the source photo",
     lambda p: p.variant == "noise_jpeg"),
    ("low_sun", f"strong cast shadows: a sun below {LOW_SUN_DEG:.0f} deg in the source or target",
     lambda p: not p.variant and _either(p, _low_sun)),
    ("overcast", "overcast source or target", lambda p: not p.variant and _either(p, lambda l: l.kind == "overcast")),
    ("night_like", f"night-like: twilight, the sun at most {NIGHT_SUN_DEG:.0f} deg above the horizon, in the "
     "source or target", lambda p: not p.variant and _either(p, _night)),
    ("large_azimuth", f"large azimuth change: the dominant light direction turns by more than "
     f"{LARGE_AZIMUTH_DEG:.0f} deg", lambda p: not p.variant and _azimuth_change(p) > LARGE_AZIMUTH_DEG),
    ("glossy", f"glossy materials: at least {GLOSSY_SHARE:.0%} of the foreground non-Lambertian",
     lambda p: not p.variant and p.view.glossy_share() >= GLOSSY_SHARE),
    ("bright_albedo", f"very bright albedo: mean foreground albedo luminance >= {BRIGHT_ALBEDO}",
     lambda p: not p.variant and p.view.albedo_luminance() >= BRIGHT_ALBEDO),
    ("dark_albedo", f"very dark albedo: mean foreground albedo luminance <= {DARK_ALBEDO}",
     lambda p: not p.variant and p.view.albedo_luminance() <= DARK_ALBEDO),
)
"""``(key, description, predicate)`` in report order."""


def members(pairs: list[Pair]) -> dict[str, list[int]]:
    """Stratum key -> indices into ``pairs`` (``"all"``: the cross pairs without a source variant)."""
    out = {"all": [i for i, p in enumerate(pairs) if p.protocol == "cross" and not p.variant]}
    for key, _, test in STRATA:
        out[key] = [i for i, p in enumerate(pairs) if p.protocol == "cross" and test(p)]
    return out
