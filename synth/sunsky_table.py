"""The clear sky of a ``--sun`` target, tabulated from Mitsuba 3's Hosek-Wilkie ``sunsky``.

``physrelight`` may not import Mitsuba (DESIGN.md), so the sky a sun target brings is shipped as a
small table that this module writes (``physrelight/data/sunsky_table.safetensors``) and
:func:`physrelight.sky_model.sunsky_radiance` reads. The table holds, for each sun elevation of
:data:`ELEVATIONS_DEG`, the sky's linear-sRGB radiance (no sun) on a grid of view elevation
(:data:`VIEW_ROWS` rows, 0 to 90 degrees above the horizon) by azimuth from the sun
(:data:`AZIMUTH_COLS` columns, 0 to 180 degrees; the sky is mirror-symmetric about the sun's vertical
plane), white-balanced to the zenith sun (divided per channel by the colour of Mitsuba's sun 90 degrees up,
luminance 1; it is warm in linear sRGB, red/green 1.18, blue/green 0.79), because the library's sun is white
at the zenith (:func:`physrelight.sky_model.sun_colour`), then divided by the luminance of the same model's
sun irradiance on a surface facing it, white-balanced the same way. So a sun of luminance 1 and this sky keep Mitsuba's sky-to-sun
ratio, which changes with the sun's elevation (horizontal sky irradiance 0.29 of the sun's at 5 degrees up,
0.19-0.22 from 15 degrees up, in luminance, turbidity 3), and their colours relative to each other.

Turbidity :data:`TURBIDITY` and ground albedo :data:`GROUND_ALBEDO` are the middles of the synthetic
data's ranges (:data:`synth.lighting.TURBIDITY_RANGE` 2-6, :data:`synth.lighting.GROUND_ALBEDO_RANGE`
0.1-0.4); the rounded 3 rather than 4 for a clear day.

Regenerate (deterministic, ~10 s)::

    .venv/bin/python -m synth.sunsky_table -o physrelight/data/sunsky_table.safetensors

The same sky at each turbidity of :data:`TURBIDITIES` (the synthetic data's range, for
:mod:`physrelight.sun_from_sky`, which fits the turbidity of a photo's sky) is a second file, each turbidity
normalised by its own sun and zenith sun as above; the turbidity-3 file is left as it is (~50 s, 1.3 MB)::

    .venv/bin/python -m synth.sunsky_table --turbidities -o physrelight/data/sunsky_turbidity_table.safetensors
"""

from __future__ import annotations

import argparse
import math
import sys

import numpy as np

from physrelight import colour
from physrelight.io import atomic_path, canonical_safetensors

__all__ = ["AZIMUTH_COLS", "ELEVATIONS_DEG", "GROUND_ALBEDO", "TURBIDITIES", "TURBIDITY", "VIEW_ROWS", "main",
           "table_directions", "sunsky_table", "zenith_sun_colour"]

ELEVATIONS_DEG = (2.0, 2.5, 3.0, 3.5, 4.0, 5.0, 6.0, 8.0, 10.0, 12.0, 15.0, 18.0, 22.0, 26.0, 30.0, 35.0, 40.0, 45.0,
                  50.0, 60.0, 70.0, 80.0, 90.0)
"""Sun elevations of the table (degrees): dense near the horizon, where the sky changes fastest. From 2 degrees:
below it Mitsuba's sun keeps its 2-degree irradiance (its solar data stop there) while its sky dims, so the
ratio of the two would rise towards the horizon (in luminance, before the white balance: 0.37 at 0.5 degree, 0.57 at
2, against 0.40 at 3)."""
VIEW_ROWS = 31
"""View elevations ``linspace(0, 90, VIEW_ROWS)`` (3 degrees apart)."""
AZIMUTH_COLS = 61
"""Azimuths from the sun ``linspace(0, 180, AZIMUTH_COLS)`` (3 degrees apart)."""
TURBIDITY = 3.0
GROUND_ALBEDO = 0.2
TURBIDITIES = (2.0, 3.0, 4.0, 5.0, 6.0)
"""Turbidities of the ``--turbidities`` table: :data:`synth.lighting.TURBIDITY_RANGE` (2-6) a unit apart."""


def table_directions(elevation_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """``(VIEW_ROWS, AZIMUTH_COLS, 3)`` world view directions of the table's nodes and the ``(3,)`` sun
    direction, for a sun at ``elevation_deg`` and azimuth 0 (:func:`physrelight.envmap.direction_from_angles`)."""
    from physrelight.envmap import direction_from_angles

    d = direction_from_angles(np.linspace(0.0, 90.0, VIEW_ROWS)[:, None], np.linspace(0.0, 180.0, AZIMUTH_COLS)[None, :])
    return d, direction_from_angles(elevation_deg, 0.0)


def sunsky_table(elevations_deg: tuple[float, ...] = ELEVATIONS_DEG, turbidity: float = TURBIDITY,
                 albedo: float = GROUND_ALBEDO) -> np.ndarray:
    """``(len(elevations_deg), VIEW_ROWS, AZIMUTH_COLS, 3)`` float64: Mitsuba's ``sunsky`` sky radiance at the
    table's nodes over the luminance of its sun's irradiance on a surface facing the sun, over the zenith
    sun's colour (:func:`zenith_sun_colour`)."""
    from synth.lighting import _mitsuba, _sun_disk_irradiance, _sunsky_dict, eval_emitter

    mi = _mitsuba()
    lum = np.asarray(colour.LUMINANCE, dtype=np.float64)
    out = np.empty((len(elevations_deg), VIEW_ROWS, AZIMUTH_COLS, 3))
    white = zenith_sun_colour(turbidity, albedo)
    for i, e in enumerate(elevations_deg):
        if not 0.0 < e <= 90.0:
            raise ValueError(f"sun elevations must lie in (0, 90] degrees, got {e}")
        d, s = table_directions(e)
        sky = mi.load_dict(_sunsky_dict(mi, s, turbidity, albedo, sky_scale=1.0, sun_scale=0.0))
        sun = mi.load_dict(_sunsky_dict(mi, s, turbidity, albedo, sky_scale=0.0, sun_scale=1.0))
        # the sun's luminance after the white balance: the library's sun has luminance 1 in that frame
        e_sun = float(np.clip(_sun_disk_irradiance(mi, sun, s), 0.0, None) / white @ lum)
        radiance = np.clip(eval_emitter(mi, sky, d.reshape(-1, 3)), 0.0, None).reshape(VIEW_ROWS, AZIMUTH_COLS, 3)
        out[i] = radiance / white / e_sun
    return out


def zenith_sun_colour(turbidity: float = TURBIDITY, albedo: float = GROUND_ALBEDO) -> np.ndarray:
    """``(3,)`` the colour (luminance 1, linear sRGB) of Mitsuba's ``sunsky`` sun 90 degrees up: the white
    balance of :func:`sunsky_table`."""
    from synth.lighting import _mitsuba, _sun_disk_irradiance, _sunsky_dict

    mi = _mitsuba()
    s = np.array([0.0, 1.0, 0.0])
    sun = mi.load_dict(_sunsky_dict(mi, s, turbidity, albedo, sky_scale=0.0, sun_scale=1.0))
    e = np.asarray(_sun_disk_irradiance(mi, sun, s), dtype=np.float64)
    return e / float(e @ np.asarray(colour.LUMINANCE, dtype=np.float64))


def main(argv: list[str] | None = None) -> int:
    """``python -m synth.sunsky_table``: write the clear-sky table (see the module's docstring)."""
    p = argparse.ArgumentParser(prog="python -m synth.sunsky_table", description=__doc__.split("\n\n")[0])
    p.add_argument("-o", "--out", required=True, help="the .safetensors file to write (atomically)")
    p.add_argument("--turbidities", action="store_true",
                   help=f"write the table at every turbidity of {TURBIDITIES} (a leading axis) instead of {TURBIDITY:g} alone")
    args = p.parse_args(argv)
    from safetensors.numpy import save

    if args.turbidities:
        stack = np.stack([sunsky_table(turbidity=t) for t in TURBIDITIES])
        tensors = {"radiance": stack.astype(np.float16), "turbidities": np.array(TURBIDITIES),
                   "elevations_deg": np.array(ELEVATIONS_DEG), "view_elevations_deg": np.linspace(0.0, 90.0, VIEW_ROWS),
                   "azimuths_deg": np.linspace(0.0, 180.0, AZIMUTH_COLS)}
        meta = {"model": "Mitsuba 3 sunsky (Hosek-Wilkie), sky only, per turbidity over its sun's irradiance luminance "
                         "and its zenith sun's colour", "ground_albedo": repr(GROUND_ALBEDO),
                "written_by": "synth.sunsky_table --turbidities"}
        with atomic_path(args.out) as tmp:
            tmp.write_bytes(canonical_safetensors(save(tensors, metadata=meta)))
        print(f"wrote {args.out}: {len(TURBIDITIES)} turbidities x {stack.shape[1]} sun elevations x {VIEW_ROWS} view "
              f"elevations x {AZIMUTH_COLS} azimuths", file=sys.stderr)
        return 0
    table = sunsky_table()

    tensors = {"radiance": table.astype(np.float16), "elevations_deg": np.array(ELEVATIONS_DEG),
               "view_elevations_deg": np.linspace(0.0, 90.0, VIEW_ROWS),
               "azimuths_deg": np.linspace(0.0, 180.0, AZIMUTH_COLS)}
    meta = {"model": "Mitsuba 3 sunsky (Hosek-Wilkie), sky only, over its sun's irradiance luminance and its zenith sun's colour",
            "turbidity": repr(TURBIDITY), "ground_albedo": repr(GROUND_ALBEDO), "written_by": "synth.sunsky_table"}
    with atomic_path(args.out) as tmp:
        tmp.write_bytes(canonical_safetensors(save(tensors, metadata=meta)))
    print(f"wrote {args.out}: {table.shape[0]} sun elevations ({ELEVATIONS_DEG[0]:g}-{ELEVATIONS_DEG[-1]:g} deg) x "
          f"{VIEW_ROWS} view elevations x {AZIMUTH_COLS} azimuths", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
