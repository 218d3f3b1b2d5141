"""``physrelight lighting``: the sun and sky read from one outdoor photo, as JSON (issue 44).

Examples::

    physrelight lighting photo.jpg -o lighting.json
    physrelight lighting photo.jpg --fov 65 --pitch 10 --mask sky.png -o out/lighting.json

The photo's sky (``--mask``, white = sky, else the shipped segmenter's) is read through its camera (horizontal field
of view from ``--fov``, else the photo's EXIF, else 60 degrees; pitch from ``--pitch``, else from where the sky comes
down to) by :func:`physrelight.sun_from_sky.estimate_sun_from_sky`: a posterior over the sun's position from a
physical sky (Hosek-Wilkie at turbidity 2-6 mixed with the CIE overcast sky). When that posterior is informative
(a sun, and its 90 % credible region under :data:`MAX_INFORMATIVE_AREA_SR`) the JSON's ``source`` is ``"sky"``:
``sun`` is the MAP sun in ``relight --sun``'s convention (azimuth clockwise from straight ahead, elevation above
the horizon) and ``sh_camera`` the MAP sky and sun, over a ground that reflects them, as camera-frame order-2 radiance
SH (:func:`learned.sky_lighting.read_sky_lighting`, what ``RelightOptions(source_estimate="sky")`` divides by). Otherwise (no sky, night,
overcast, blown out, a sun whose place the sky does not tell) ``source`` is ``"fallback"`` with the ``reason``,
``sun`` is null and ``sh_camera`` is the library's own estimate (``Relighter.decompose_linear``'s lighting, what
``relight`` relights from). The schema is in docs/sun-from-sky.md (:data:`SCHEMA_VERSION`).

Next to ``NAME.json`` goes ``NAME_preview.png``: the estimated lighting as a 256 x 128 lat-long picture (column 0 =
straight ahead), tone-mapped, the MAP sun as a red ring, its 90 % credible region in cyan, the camera's frame in
yellow (:func:`physrelight.sun_from_sky.lighting_preview`).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from .sky_lighting import MAX_INFORMATIVE_AREA_SR

__all__ = ["MAX_INFORMATIVE_AREA_SR", "SCHEMA_VERSION", "add_parser", "estimate_lighting", "preview_path",
           "write_lighting"]

SCHEMA_VERSION = 2
"""The version of ``lighting.json``'s layout (docs/sun-from-sky.md): raised when a key changes meaning (2: the
``"sky"`` ``sh_camera`` has a ground that reflects the sky and sun, :func:`learned.sky_lighting.sky_sun_sh`; 1: a black
ground)."""


def preview_path(json_path: str | Path) -> Path:
    """``lighting.json`` -> ``lighting_preview.png`` (same folder)."""
    p = Path(json_path)
    return p.with_name(f"{p.stem}_preview.png")


def estimate_lighting(relighter: Any, image: np.ndarray, *, radiance: bool = False, sky_mask: np.ndarray | None = None,
                      fov_deg: float, fov_source: str, pitch_deg: float | None = None, reading: Any = None,
                      decomposition_lighting: np.ndarray | None = None) -> tuple[dict[str, Any], np.ndarray]:
    """The lighting of one photo as ``lighting.json``'s dict, and its preview ``(128, 256, 3)`` uint8.

    Args:
        relighter: a :class:`learned.Relighter` (its sky segmenter when ``sky_mask`` is None, and its
            decomposition for the fallback).
        image: ``(H, W, 3)`` display values in [0, 1], or with ``radiance`` linear radiance (any scale).
        sky_mask: ``(H, W)`` bool (True = sky), or None for the segmenter's.
        fov_deg: the horizontal field of view; ``fov_source`` where it came from (``"exif"``, ``"given"``,
            ``"default"``).
        pitch_deg: the camera's pitch (up positive), or None: estimated from the sky's horizon
            (:func:`physrelight.horizon.estimate_pitch`, as ``relight`` does).
        reading, decomposition_lighting: what a relighting of this very photo, mask and camera already has
            (:class:`learned.relighter.RelitLayers`): the sky's reading (:class:`learned.sky_lighting.SkyLighting`)
            and the decomposition's camera-frame lighting ``(9, 3)``; each None: made here.
    """
    import torch

    from physrelight import sh
    from physrelight.full_resolution import working_resolution
    from physrelight.horizon import estimate_pitch
    from physrelight.image_input import as_image, as_radiance
    from physrelight.panorama import level_camera, view_intrinsics
    from physrelight.sun_from_sky import lighting_preview

    from .sky_lighting import read_sky_lighting

    if fov_source not in ("exif", "given", "default"):
        raise ValueError(f"fov_source must be 'exif', 'given' or 'default', got {fov_source!r}")
    lin, _, _ = as_radiance(image) if radiance else (*as_image(image), 1.0)
    if lin.shape[0] != 1:
        raise ValueError(f"estimate_lighting takes one image, got a batch of {lin.shape[0]}")
    if not bool((lin > 0).any()):
        raise ValueError("the photo is black (every pixel 0): there is no light in it to read")
    h, w = lin.shape[-2:]
    sky, why = relighter.photo_sky(lin, sky_mask)  # (1, 1, H, W) bool
    K = view_intrinsics(float(fov_deg), w, h)
    pitch = float(pitch_deg) if pitch_deg is not None else estimate_pitch(sky[0, 0], K)
    R = level_camera(0.0, pitch)[:3, :3]
    # the sky is read as relight reads it (learned.sky_lighting): the same function, photo, mask and camera
    if reading is None:
        reading = read_sky_lighting(lin, sky, K, R, radiance=radiance)
    post = reading.posterior
    summary = post.summary()
    source = reading.source
    if source == "sky":
        reason = ""
        sh_world = reading.sh_world
        sh_camera = np.asarray(sh.rotation(R, order=2)) @ sh_world
    else:
        reason = reading.reason + (f" ({why})" if why and not post.has_sun else "")
        small, small_sky = working_resolution(lin, sky, relighter.res)
        if bool(small_sky.all()):
            raise ValueError(f"the whole photo is sky and it tells no sun ({reason}): there is no scene to estimate "
                             "the lighting from")
        if decomposition_lighting is None:
            with torch.no_grad():  # the library's own estimate, what relight relights from: (9, 3) camera frame
                decomposition_lighting = relighter.decompose_linear(small, small_sky)["lighting"][0].double().numpy()
        estimate = np.asarray(decomposition_lighting, dtype=np.float64)
        sh_camera = estimate
        sh_world = np.asarray(sh.rotation(R.T, order=2)) @ estimate
        summary["sun"] = None
    record = {
        "schema_version": SCHEMA_VERSION,
        "source": source,
        "reason": reason,
        "sun": summary["sun"],
        "sun_spread": summary["sun_spread"],
        "sun_probability": summary["sun_probability"],
        "sky_kind": summary["sky_kind"],
        "level": summary["level"],
        "turbidity": summary["turbidity"],
        "overcast_mix": summary["mix"],
        "exponent": summary["exponent"],
        "camera": {"fov_deg": round(float(fov_deg), 4), "fov_source": fov_source, "pitch_deg": round(pitch, 4),
                   "pitch_source": "given" if pitch_deg is not None else "horizon"},
        "sky_pixels": int(sky.sum()),
        "sh_camera": [[float(x) for x in row] for row in np.asarray(sh_camera, dtype=np.float64)],
        "image_size": [int(w), int(h)],
    }
    preview = lighting_preview(sh_world, post if source == "sky" else None, K, R, (h, w))
    return record, preview


def write_lighting(path: str | Path, record: dict[str, Any], preview: np.ndarray) -> None:
    """Write ``record`` as ``path`` (JSON) and ``preview`` as :func:`preview_path` ``(path)``, each atomically (the
    preview first: a JSON on disk means both are there)."""
    from physrelight import io

    io.write_png(preview_path(path), preview.astype(np.float32) / 255.0)
    io.write_json(path, record)


def _lighting(args: argparse.Namespace) -> int:
    import torch

    from physrelight import io
    from physrelight.cli_common import check_not_input, check_output_file

    torch.set_num_threads(args.threads)
    out = Path(args.output)
    if out.suffix.lower() != ".json":
        raise ValueError(f"output must be a .json file, got {str(out)!r}")
    check_output_file(preview_path(out), "preview")
    inputs = {"input photo": args.photo, "--mask": args.mask}
    check_not_input(out, inputs)
    check_not_input(preview_path(out), inputs)
    photo = io.read_photo(args.photo)  # one-line ValueError for missing, corrupt or palette files
    for note in photo.notes:
        print(f"physrelight: note: {args.photo}: {note}", file=sys.stderr)
    image = photo.image
    mask = None
    if args.mask is not None:
        mask = io.read_mask(args.mask, shape=image.shape[:2])
    from .relight_options import DEFAULT_FOV_DEG, RelightOptions
    from .relighter import Relighter

    if args.fov is not None:
        fov, fov_source = args.fov, "given"
    elif photo.fov_deg is not None:
        fov, fov_source = photo.fov_deg, "exif"
    else:
        fov, fov_source = DEFAULT_FOV_DEG, "default"
    relighter = Relighter.load(args.weights, options=RelightOptions())
    record, preview = estimate_lighting(relighter, image, radiance=photo.radiance, sky_mask=mask, fov_deg=fov,
                                        fov_source=fov_source, pitch_deg=args.pitch)
    write_lighting(out, record, preview)
    sun = record["sun"]
    said = (f"sun {sun['elevation_deg']:.1f} deg up, azimuth {sun['azimuth_deg']:.1f} deg" if sun is not None
            else f"no sun ({record['reason']})")
    print(f"{record['sky_kind']} sky, {said} -> {out}, {preview_path(out)}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``lighting``."""
    from physrelight.cli_common import number_in, positive_int

    p = sub.add_parser("lighting", help="read the sun and sky from one outdoor photo (JSON and a preview)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("photo", help="RGB photo (PNG or JPEG), or linear radiance (.exr or .hdr)")
    p.add_argument("--fov", type=number_in(1.0, 179.0, "a field of view in degrees"), default=None, metavar="DEG",
                   help="horizontal field of view in degrees (default: from EXIF, else 60)")
    p.add_argument("--pitch", type=number_in(-89.0, 89.0, "a pitch in degrees"), default=None, metavar="DEG",
                   help="camera pitch in degrees, up positive (default: estimated from the sky's horizon)")
    p.add_argument("--mask", default=None, help="sky mask PNG (white = sky), the photo's size "
                                                "(default: the shipped sky segmenter's)")
    p.add_argument("--weights", default=None, help="weights folder (default: the shipped ones)")
    p.add_argument("--threads", type=positive_int, default=2, help="torch CPU threads (default: 2)")
    p.add_argument("-o", "--output", required=True, help="output .json (the preview goes next to it as "
                                                         "NAME_preview.png)")
    p.set_defaults(handler=_lighting, output_files=("output",))
