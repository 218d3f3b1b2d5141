"""``physrelight relight``: relight one outdoor photo to a new lighting.

Examples::

    physrelight relight photo.jpg --env physrelight/data/hdri/forest.exr -o relit.png
    physrelight relight photo.jpg --env sky.hdr --azimuth 90 --mask sky.png --layers layers/ -o relit.png
    physrelight relight photo.jpg --sun 25 120 --sky clear --sequence 24 -o day.gif
    physrelight relight photo.jpg --sh lighting.npy -o relit.png

The target lighting is given in the world frame (Y up) and the camera is assumed level,
looking along world -Z (a single photo does not tell its orientation): ``--azimuth`` turns
the target about the vertical axis, ``--sun ELEV AZIM`` puts the sun ELEV degrees above the
horizon and AZIM degrees clockwise (seen from above) from straight ahead of the camera
(0 = the sun behind the scene, facing the camera; 180 = the sun behind the camera).

Any input size: the networks run at their resolution and the result is brought back to full
resolution by ratio transfer (fine detail survives). The photo keeps its exposure; only
the lighting's shape and colour change. The sky is found by the shipped segmenter (or
``--mask``) and repainted by SkyGAN for the target lighting (``--keep-sky`` keeps it). ``--sequence N`` sweeps the azimuth over 360
degrees in N frames and writes an animated GIF.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

__all__ = ["add_parser", "sun_direction"]


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """World-frame unit vector towards the sun (Y up, camera looking along -Z).

    Azimuth 0 puts the sun straight ahead of the camera (-Z), 90 to its right (+X).
    """
    if not (math.isfinite(elevation_deg) and math.isfinite(azimuth_deg)) or not -90 <= elevation_deg <= 90:
        raise ValueError(f"sun elevation must lie in [-90, 90] degrees, got {elevation_deg}")
    e, a = math.radians(elevation_deg), math.radians(azimuth_deg)
    return np.array([math.sin(a) * math.cos(e), math.sin(e), -math.cos(a) * math.cos(e)])


def _read_sh(path: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"SH file {path!r} does not exist")
    try:
        if p.suffix == ".npy":
            arr = np.load(p, allow_pickle=False)
        elif p.suffix == ".json":
            from physrelight import io

            arr = np.asarray(io.read_json(p), dtype=np.float64)
        else:
            arr = np.loadtxt(p, dtype=np.float64, ndmin=2)
    except (OSError, ValueError) as err:
        raise ValueError(f"cannot read SH coefficients from {path!r}: {err}") from None
    if arr.shape != (9, 3):
        raise ValueError(f"{path!r} must hold order-2 radiance SH of shape (9, 3), got {arr.shape}")
    return arr


def _target(args: argparse.Namespace):
    if args.env is not None:
        p = Path(args.env)
        if not p.is_file():
            raise ValueError(f"environment map {args.env!r} does not exist")
        if p.suffix.lower() not in (".exr", ".hdr"):
            raise ValueError(f"environment map {args.env!r} must be an .exr or .hdr file")
        from physrelight import envmap

        env = envmap.read(p)
        if env.ndim != 3 or env.shape[1] != 2 * env.shape[0]:
            raise ValueError(f"environment map {args.env!r} must be lat-long (W = 2H), got {env.shape[:2]}")
        return env
    if args.sh is not None:
        return _read_sh(args.sh)
    return sun_direction(*args.sun)


def _write_gif(path: Path, frames: list[np.ndarray], fps: float) -> None:
    from PIL import Image

    from physrelight import io

    imgs = [Image.fromarray(np.clip(np.round(f * 255), 0, 255).astype(np.uint8)) for f in frames]
    with io.atomic_path(path) as tmp:
        imgs[0].save(tmp, format="GIF", save_all=True, append_images=imgs[1:], duration=round(1000 / fps), loop=0)


def _relight(args: argparse.Namespace) -> int:
    import torch

    from physrelight import io

    torch.set_num_threads(args.threads)
    out = Path(args.output)
    want = ".gif" if args.sequence else ".png"
    if out.suffix.lower() != want:
        raise ValueError(f"output must be a {want} file{' with --sequence' if args.sequence else ''}, got {str(out)!r}")
    photo = io.read_image(args.photo)  # one-line ValueError for missing, corrupt or grey-scale files
    mask = None
    if args.mask is not None:
        mask = io.read_mask(args.mask)
        if mask.shape != photo.shape[:2]:
            raise ValueError(f"mask {args.mask!r} is {mask.shape[1]}x{mask.shape[0]}, the photo "
                             f"{photo.shape[1]}x{photo.shape[0]}")
    target = _target(args)

    from .relighter import Relighter

    relighter = Relighter.load(args.weights)
    common = dict(sky_mask=mask, method=args.method, sky=args.sky, new_sky=not args.keep_sky, seed=args.seed)
    if args.sequence:
        azimuths = args.azimuth + 360.0 * np.arange(args.sequence) / args.sequence
        frames = relighter.relight_sequence(photo, target, azimuths, progress=not args.quiet, **common)
        _write_gif(out, frames, args.fps)
        print(f"{len(frames)} frames -> {out}")
        return 0
    layers = relighter.relight_layers(photo, target, azimuth_deg=args.azimuth, **common)
    io.write_png(out, layers["relit"])
    if args.layers is not None:
        d = Path(args.layers)
        for name, img in layers.items():
            io.write_png(d / f"{name}.png", img)
        print(f"layers ({', '.join(layers)}) -> {d}")
    print(f"relit {photo.shape[1]}x{photo.shape[0]} -> {out}")
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``relight``."""
    from physrelight.cli_common import positive_int, positive_number

    from .relighter import RELIGHT_METHODS, SKY_TYPES

    p = sub.add_parser("relight", help="relight one outdoor photo to a new lighting (shipped weights)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("photo", help="RGB photo (PNG or JPEG)")
    tgt = p.add_mutually_exclusive_group(required=True)
    tgt.add_argument("--env", help="target environment map (lat-long .exr or .hdr, world frame, Y up)")
    tgt.add_argument("--sh", help="target order-2 radiance SH, world frame: .npy, .json or text, shape (9, 3)")
    tgt.add_argument("--sun", nargs=2, type=float, metavar=("ELEV", "AZIM"),
                     help="target sun elevation and azimuth in degrees (see above), with --sky")
    p.add_argument("--sky", choices=SKY_TYPES, default="clear", help="sky type for --sun (default: clear)")
    p.add_argument("--azimuth", type=float, default=0.0, help="turn the target about the vertical (degrees)")
    p.add_argument("--mask", default=None, help="sky mask PNG (white = sky), the photo's size "
                                                "(default: the shipped sky segmenter's)")
    p.add_argument("--keep-sky", action="store_true", help="keep the photo's sky (default: SkyGAN paints a new one)")
    p.add_argument("--seed", type=int, default=0, help="SkyGAN noise seed (default: 0)")
    p.add_argument("--layers", default=None, help="also write albedo, normals, shadows, shading, sky mask here")
    p.add_argument("--sequence", type=positive_int, default=None, metavar="N",
                   help="sweep the azimuth over 360 degrees in N frames; write an animated GIF")
    p.add_argument("--fps", type=positive_number, default=12.0, help="GIF frame rate (default: 12)")
    p.add_argument("--method", choices=RELIGHT_METHODS, default="proposed",
                   help="relighting method (default: proposed, the full pipeline)")
    p.add_argument("--weights", default=None, help="weights folder (default: the shipped ones)")
    p.add_argument("--threads", type=positive_int, default=2, help="torch CPU threads (default: 2)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("-o", "--output", required=True, help="output .png (or .gif with --sequence)")
    p.set_defaults(handler=_relight)
