"""Fit the sun prior (:mod:`physrelight.sun_prior`) to the training side's outdoor panoramas.

The training side is the outdoor maps of ``physrelight/data/hdri`` (city, courtyard, forest; studio is indoor) and
of ``physrelight/data/hdri_more`` (``kinds.json``: outdoor). ``hdri_heldout`` (sunrise) is never read: it scores
``bench --real``. Each map's sun is found by :func:`physrelight.envmap.split_sun` (its elevation is a sample); each
map's sky kind is the label below, given by eye on tone-mapped views of the maps (2026-12-05): a sun hidden from
the panorama's camera (under a roof, behind the canopy) still shows by hard shadows on the ground, so the kind
says "sun" where ``split_sun`` finds no disc. The prior is written atomically (same input, same bytes).

    python scripts/fit_sun_prior.py                       # -> physrelight/data/sun_prior.safetensors
    python scripts/fit_sun_prior.py -o /tmp/prior.safetensors
"""

from __future__ import annotations

import argparse
import math
import sys

KINDS_BY_EYE = {
    "city": "hazy",          # a bright cloud layer, the sun's disc through it (split_sun finds it: 22 % of the light)
    "courtyard": "clear",    # hard shadows across the sunlit yard; the sun itself is hidden by the roof
    "forest": "clear",       # the sun through the canopy (split_sun: 7 %), hard shadows on the path
    "pm_city": "overcast",   # an even grey sky, no shadows
    "pm_dawn": "night",      # twilight: a glow on the horizon, the sun below it (no shadows)
    "pm_forest": "clear",    # sun flecks and hard shadows on the forest floor; the disc hidden by the canopy
    "pm_night": "night",     # stars, a glow along the horizon
    "pm_sky": "clear",       # blue sky with cumulus, the sun's disc at 48 degrees
    "pm_venice": "hazy",     # a pale sky, a low bright haze to one side, soft shadows
}
"""The sky kind of each training map (:data:`physrelight.sun_prior.PRIOR_KINDS`), by eye."""


def training_maps() -> list[tuple[str, str]]:
    """``(collection, name)`` of every outdoor map of the training side."""
    from physrelight import data

    out = [("shipped", n) for n in data.hdri_names(collection="shipped", kind="outdoor")]
    out += [("more", n) for n in data.hdri_names(collection="more", kind="outdoor")]
    return out


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("-o", "--output", default=None, help="where to write (default: the shipped prior's path)")
    args = parser.parse_args(argv)
    from physrelight import data, envmap
    from physrelight.sun_prior import SUN_PRIOR, fit_sun_prior

    maps = training_maps()
    if any(name not in KINDS_BY_EYE for _, name in maps):
        print(f"fit_sun_prior: error: no kind for {[n for _, n in maps if n not in KINDS_BY_EYE]}", file=sys.stderr)
        return 2
    elevations, kinds = [], []
    for coll, name in maps:
        split = envmap.split_sun(envmap.read(data.hdri(name, collection=coll)))
        line = f"{name:10s} {KINDS_BY_EYE[name]:9s}"
        if split.has_sun:
            e = math.degrees(math.asin(float(split.direction[1])))
            if e > 0:
                elevations.append(e)
            line += f" sun at {e:5.1f} deg ({split.fraction:.0%} of the light)"
        print(line)
        kinds.append(KINDS_BY_EYE[name])
    prior = fit_sun_prior(elevations, kinds, tuple(name for _, name in maps))
    out = args.output or SUN_PRIOR
    prior.save(out)
    print(f"wrote {out}: {len(elevations)} sun elevations, kinds "
          + ", ".join(f"{k} {p:.2f}" for k, p in zip(("clear", "hazy", "overcast", "night"), prior.kind_probability)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
