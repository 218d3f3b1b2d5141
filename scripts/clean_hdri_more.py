"""Clean the fifteen packaged Poly Haven panoramas (DWAB-compressed) into ``physrelight/data/hdri_more/``.

Each ``pm_NAME.exr`` of the shared folder is read as decoded (negatives kept), cleaned by
:func:`physrelight.panorama_repair.repair_panorama` (clamp the negatives, repair the damaged blocks at bright
sources) and written losslessly (PIZ; half floats, as the source, unless a value exceeds half's range, then
float32). Beside the maps: ``LICENSE`` (CC0, copied), ``kinds.json`` (outdoor / indoor / walkway per map),
``cleaning.json`` (what the cleaning changed, per map) and ``README.md`` (provenance, the cleaning, the table).
Every file is written atomically; the same input gives the same bytes.

    python scripts/clean_hdri_more.py                      # all fifteen, shared folder -> package folder
    python scripts/clean_hdri_more.py --only pm_sky --dst /tmp/out
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT.parent / "shared" / "data" / "hdri_more"
DEST = ROOT / "physrelight" / "data" / "hdri_more"
HALF_MAX = 65504.0

KINDS = {
    "pm_city": "outdoor", "pm_dawn": "outdoor", "pm_forest": "outdoor", "pm_night": "outdoor",
    "pm_sky": "outdoor", "pm_venice": "outdoor",
    "pm_apartment": "indoor", "pm_esplanade": "indoor", "pm_hall": "indoor", "pm_lab": "indoor",
    "pm_lobby": "indoor", "pm_studio": "indoor", "pm_warehouse": "indoor", "pm_workshop": "indoor",
    "pm_bridge": "walkway",
}
"""Kind of each map (the shared README's table): ``outdoor`` maps are training candidates, ``indoor`` ones
controls, ``walkway`` (a covered glass bridge) neither without a look at its windows."""


def write_exr_lossless(path: Path, env: np.ndarray) -> str:
    """Write ``(H, W, 3)`` radiance as a PIZ-compressed EXR, atomically; half floats when every value fits
    half's range (the source's type), else float32. Returns ``"half"`` or ``"float"``."""
    import OpenEXR

    from physrelight.io import atomic_path

    dtype, kind = (np.float16, "half") if float(env.max()) <= HALF_MAX else (np.float32, "float")
    channels = {c: np.ascontiguousarray(env[..., k].astype(dtype)) for k, c in enumerate("RGB")}
    header = {"compression": OpenEXR.PIZ_COMPRESSION, "type": OpenEXR.scanlineimage}
    with atomic_path(path, ".exr") as tmp:
        with OpenEXR.File(header, channels) as f:
            f.write(str(tmp))
    return kind


def clean_map(src: Path, dst: Path) -> dict:
    """Clean one decoded panorama ``src`` into ``dst``; return what changed (see ``repair_report``) plus
    ``negative_texels`` (share with a channel < 0), ``windows`` (repaired), ``broken_windows`` (with a lost
    channel), ``storage`` and ``bytes``."""
    from physrelight import io, panorama_repair

    decoded = io.read_exr(src)
    if decoded.ndim != 3:
        raise ValueError(f"{str(src)!r} must have R, G, B channels")
    repair = panorama_repair.repair_panorama(decoded)
    storage = write_exr_lossless(dst, repair.env)
    stored = io.read_exr(dst).astype(np.float64)  # report what the file holds (half rounding included)
    report = panorama_repair.repair_report(decoded, stored)
    report.update({
        "negative_texels": float((decoded < 0).any(axis=-1).mean()),
        "windows": len(repair.repairs),
        "broken_windows": int(sum(bool(r.broken.any()) for r in repair.repairs)),
        "storage": storage,
        "bytes": dst.stat().st_size,
    })
    return report


def _write_text(path: Path, text: str) -> None:
    from physrelight.io import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_text(text)


def _readme(reports: dict[str, dict]) -> str:
    rows = []
    for name, r in reports.items():
        rows.append(
            f"| {name} | {KINDS[name]} | {100 * r['negative_texels']:.2f} | {r['windows']} | "
            f"{r['luminance_before']:.4g} | {r['luminance_after']:.4g} | {100 * r['luminance_change']:+.2f} | "
            f"{100 * r['luminance_change_repair']:+.3f} | "
            f"{r['l1_over_l00_before']:.3f} -> {r['l1_over_l00_after']:.3f} | "
            f"{r['l2_over_l00_before']:.3f} -> {r['l2_over_l00_after']:.3f} | {100 * r['sh_change']:.2f} | "
            f"{100 * r['sh_change_repair']:.2f} |")
    total = sum(r["bytes"] for r in reports.values())
    floats = ", ".join(n for n, r in reports.items() if r["storage"] == "float") or "none"
    broken = {n: r["broken_windows"] for n, r in reports.items() if r["broken_windows"]}
    lost = ("no window here lost a channel" if not broken else "windows with a lost channel, coloured from "
            "their ring: " + ", ".join(f"{n} {k}" for n, k in broken.items()))
    return f"""# More real HDR panoramas, cleaned (CC0)

Fifteen Poly Haven panoramas (CC0-1.0, `LICENSE`) as packaged, 512 x 256 and DWAB-compressed, in the npm
package `@pmndrs/assets` 1.7.0; the shared folder `data/hdri_more` reproduces them byte for byte
(its `decode.py`). Written here by `scripts/clean_hdri_more.py` (do not edit by hand: rerun it).

- Layout: lat-long, the library's (DESIGN.md), as the shipped `data/hdri` maps: row 0 the zenith, the
  horizon on the middle row. Checked by eye on tone-mapped views of pm_city, pm_forest, pm_venice, pm_dawn,
  pm_sky beside the shipped city and forest (sky on top, horizon on rows 127-128 in all), and by the sun:
  pm_sky's visible disc peaks at row 59, column 304 (elevation 48.4 deg, azimuth -145.9 deg in
  `envmap.direction_from_angles` terms); the repaired disc sits at elevation 48.1 deg, azimuth -145.7 deg,
  0.3 deg (under half a texel) away; the package's README says about 48 deg. East-west (a mirror) cannot
  be checked against the shipped maps (no panorama is in both sets; log-luminance cross-correlation over
  all shifts, mirrored or not, stays below 0.8); both sets are Poly Haven's own equirectangular images
  passed on unchanged (Blender's data files; the npm package's base64), so the same column convention
  holds, and pm_esplanade's lit sign appears to read left to right (at 512 px, weak evidence).
- Kinds: `kinds.json` (`outdoor`: city, dawn, forest, night, sky, venice; `indoor`: eight rooms, controls
  with no sky; `walkway`: bridge, a covered glass walkway).
- Storage: PIZ (lossless), half floats as the source (float32 only where a value exceeds 65504:
  {floats}): {total / 1e6:.1f} MB in all. Half rounding of the repaired texels moves a map's energy by
  at most 1e-4 (the table is measured on the stored files).
- Sky masks: `NAME_sky.png` beside the maps (white = sky, as `data/hdri`'s), written by
  `scripts/hdri_more_sky_masks.py` after a review (docs/experiments/58-prior-on-more-panoramas.md): the five
  outdoor maps city, dawn, night, sky, venice; the eight rooms' are empty (no sky: negatives). None for
  pm_forest (sky through a canopy at 512 px is texel-scale speckle) nor the walkway pm_bridge.

## The cleaning (`physrelight.panorama_repair.repair_panorama`)

1. Negative texels (DCT ringing round sharp edges) are clamped to zero.
2. Damaged windows are found on DWA's 8 x 8 blocks: a *source* block has a peak luminance at least 50 x
   the median of its ring (texels two blocks away) and of the map; its block and its 3 x 3 neighbours are
   *damaged* where a channel dips below -0.1 x the source's peak in that channel, or where, at the
   brightest texel, a channel is at most 1 % of the largest while the ring holds more of it (a lost
   channel: OpenEXR decodes a half overflow as 0). Windows are the source plus its damaged neighbours,
   brightest source first.
3. Each window is replaced by a smooth fill (the Laplace interpolation of the texels round it, capped at
   the 75th percentile of its 4-texel ring so a neighbouring lamp does not flood it) plus a disc of 1 deg
   radius at the energy centroid holding the rest of the window's solid-angle weighted energy, per channel
   (exactly); a lost channel takes the ring's colour (its median). Weaker ringing is only clamped.

Tested (`tests/physrelight/test_panorama_repair.py`) on a synthetic sun written as DWAB by OpenEXR 3.5.3
itself: direction within 0.2 texel, irradiance on a surface facing the sun within 1 % (blue, intact) and
2 % (red, green, luminance, from the ring's colour).

## What the cleaning changed

Energy: `sum L dOmega` of the luminance (texel solid angles of DESIGN.md's layout), as decoded (signed,
negatives included) and as stored. SH: order 2 of the luminance, band norms over the DC, before (the
signed decoded map) and after; the last column is `||c_after - c_before|| / ||c_before||` over the 27
RGB coefficients. The `repair` columns compare the stored map with the decoded one clamped at zero: the
repair (step 3) alone. Clamping adds energy wherever ringing was deep (pm_sky: +13 %, nearly all in its
sun's block); the repair itself moves energy only through half rounding ({lost}) and the SH by the discs'
displacement. DWA quantises in a log-like space, so neither the signed nor the
clamped sum is the true energy of a wrecked block: the clamped one is kept (no texel is negative).

| map | kind | negative texels % | windows | energy decoded | energy cleaned | change % | repair % | L1/L00 | L2/L00 | SH change % | repair SH % |
| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |
""" + "\n".join(rows) + "\n"


def clean_folder(src: Path = SOURCE, dst: Path = DEST, only: list[str] | None = None) -> dict[str, dict]:
    """Clean the maps of ``src`` (all of :data:`KINDS`, or ``only``) into ``dst`` with LICENSE, kinds.json,
    cleaning.json and README.md; return the per-map reports. The side files are written only for a full run."""
    names = list(KINDS) if not only else only
    unknown = [n for n in names if n not in KINDS]
    if unknown:
        raise ValueError(f"unknown map(s) {unknown}; known: {sorted(KINDS)}")
    if not src.is_dir():
        raise ValueError(f"{str(src)!r} is not a folder")
    missing = [n for n in names if not (src / f"{n}.exr").is_file()]
    if missing:
        raise ValueError(f"{str(src)!r} lacks {', '.join(f'{n}.exr' for n in missing)}")
    if not (src / "LICENSE").is_file():
        raise ValueError(f"{str(src)!r} has no LICENSE to copy")
    dst.mkdir(parents=True, exist_ok=True)
    reports = {n: clean_map(src / f"{n}.exr", dst / f"{n}.exr") for n in names}
    if only:
        return reports
    from physrelight.io import atomic_path

    with atomic_path(dst / "LICENSE") as tmp:
        shutil.copyfile(src / "LICENSE", tmp)
    _write_text(dst / "kinds.json", json.dumps(KINDS, indent=2, sort_keys=True) + "\n")
    _write_text(dst / "cleaning.json", json.dumps(reports, indent=2, sort_keys=True) + "\n")
    _write_text(dst / "README.md", _readme(reports))
    return reports


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--src", type=Path, default=SOURCE, help="folder of the decoded pm_*.exr (shared data)")
    parser.add_argument("--dst", type=Path, default=DEST, help="output folder (the package's data/hdri_more)")
    parser.add_argument("--only", nargs="+", metavar="NAME", help="clean these maps only (no side files)")
    args = parser.parse_args(argv)
    try:
        reports = clean_folder(args.src, args.dst, args.only)
    except ValueError as err:
        print(f"clean_hdri_more: {err}", file=sys.stderr)
        return 2
    for name, r in reports.items():
        print(f"{name:14s} windows {r['windows']:3d}  energy {100 * r['luminance_change']:+6.2f} %  "
              f"SH {100 * r['sh_change']:5.2f} %  {r['bytes'] / 1e3:6.0f} kB")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    sys.exit(main())
