"""``physrelight relight``: relight one outdoor photo to a new lighting.

Examples::

    physrelight relight photo.jpg --env physrelight/data/hdri/forest.exr -o relit.png
    physrelight relight photo.jpg --env sky.hdr --azimuth 90 --mask sky.png --layers layers/ -o relit.png
    physrelight relight photo.jpg --sun 25 120 --sky overcast -o overcast.png
    physrelight relight photo.jpg --sun 25 120 --sequence 24 -o day.gif
    physrelight relight photo.jpg --sh lighting.npy -o relit.png
    physrelight relight photo.jpg --source-env on_set.exr --env target.exr -o relit.png
    physrelight relight photo.jpg --env target.exr --exposure keep -o relit.exr

``-o NAME.exr`` writes the relit photo as linear radiance (float32): the photo's sRGB-decoded units times the
exposure's gain, nothing clipped. A photo given as ``.exr`` or ``.hdr`` (a render, an HDR photo) is read as linear
radiance and relit at a display-like level (its 99.9th-percentile luminance to 1); an ``.exr`` output is given
back in its own units.

The target lighting is given in the world frame (Y up); the camera is level and looks along
world -Z. ``--sun ELEV AZIM`` puts the sun ELEV degrees above the horizon and AZIM degrees
clockwise (seen from above) from straight ahead of the camera (0 = the sun behind the scene, facing
the camera; 90 = to its right; 180 = behind the camera); ``--azimuth T`` turns the target about the
vertical by T degrees the same way (``--sun E A --azimuth T`` is ``--sun E A+T``; an env map's column
j moves to j + T W / 360), as ``Relighter.relight(..., azimuth_deg=T)`` does.
A clear sky (``--sky clear``, the default) is Mitsuba 3's Hosek-Wilkie sky for that sun (tabulated, turbidity
3; a sun under 2 degrees gets the sky of 2 degrees) and needs ELEV > 0; ``--sky overcast`` has no sun.
The camera's horizontal field of view comes from the photo's EXIF focal length, else ``--fov``
(default 60); its pitch from ``--pitch``, else from where the sky comes down to (the horizon).

The photo is relit at the networks' working resolution and brought back to full resolution
along its own edges (fine detail survives). The physical core, ``quotient``, multiplies the
photo by the ratio of the target's shading to the photo's own: its albedo is never repainted.
The default method, ``proposed``, is the shipped neural renderer on top of it: a learned gain on
that quotient image, given ShadowNet's shadow for the target. Without ``--source-env``/``--source-sh``
the photo's lighting is the decomposition's estimate; with them (the photo's own lighting,
captured on set) the quotient divides by that lighting (``--method quotient``: relighting to it
gives the photo back exactly).

The sky (white = sky in ``--mask``) is found by the shipped segmenter, kept only where it is a
plausible sky; when there is none a one-line warning says why and only the foreground is
relit. It is replaced by ``--sky-source``: ``target`` renders the target's own sky (an env map
seen through the camera, or the sun's clear or overcast sky) in the foreground's exposure,
``fit`` renders the outdoor sky model fitted to the target's SH (any target), ``gan`` paints one
with SkyGAN, ``keep`` keeps the photo's. ``--exposure auto`` (default)
meters the relit photo as a camera would (the foreground to the photo's key, middle grey for
a dark photo, never clipping the sky); ``keep`` keeps the camera's settings; a number adds
stops to ``keep``. ``--sequence N`` sweeps the azimuth clockwise over 360 degrees in N frames (GIF).

``--layers DIR`` writes ``relit``, ``sky_mask`` (white = sky), the decomposition's layers and the sun and sky read
from the photo (``lighting.json`` and ``lighting_preview.png``, as ``physrelight lighting`` writes them). Those
(:data:`DECOMPOSITION_LAYERS`) are computed over the whole photo but describe surfaces, so on the sky they
mean nothing: they are written as RGBA, transparent on the sky (their colour values kept), so that a viewer
shows the foreground's albedo, normals, shadows and shading alone.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["DECOMPOSITION_LAYERS", "LAYER_FILES", "MAX_SEQUENCE", "PROGRESS_PIXELS", "SUN_AZIMUTH_LIMIT", "add_parser",
           "layer_with_alpha", "sequence_bytes", "sun_direction"]

MAX_SEQUENCE = 720
"""The most frames ``--sequence`` takes: one every half degree of the 360-degree sweep (a 12 fps GIF of a minute),
and the frames are all held in memory until the GIF is written (:func:`sequence_bytes` bounds them too)."""
SUN_AZIMUTH_LIMIT = 360.0
"""``--sun``'s and ``--azimuth``'s angles lie in [-360, 360] degrees: refused beyond, not wrapped, since a larger
number is far likelier a slip (swapped or mistyped arguments) than a meant turn."""
PROGRESS_PIXELS = 1_000_000
"""A single relighting of a photo this large (pixels) or larger shows its stages on stderr unless ``--quiet``:
about 9 s at one thread for 2000 x 1334, 31 s for 4000 x 2669 (docs/bench.md)."""
DECOMPOSITION_LAYERS = ("albedo", "normals", "shadow", "target_shadow", "shading")
"""The layers of ``--layers`` that describe surfaces: written transparent on the sky (:func:`layer_with_alpha`)."""
LAYER_FILES = ("relit", *DECOMPOSITION_LAYERS, "sky_mask")
"""The files ``--layers DIR`` writes, as ``DIR/NAME.png`` (checked before any work not to be an input)."""


@contextlib.contextmanager
def _stage_bar(relighter: Any, enabled: bool, layers: bool = True) -> Iterator[None]:
    """While open, a progress bar on stderr that advances with ``relighter``'s stages (``Relighter.on_stage``):
    ``RELIGHT_STAGES``, less the last (``"layers"``) when the layers are not made."""
    if not enabled:
        yield
        return
    from tqdm import tqdm

    from .relighter import RELIGHT_STAGES

    stages = RELIGHT_STAGES if layers else RELIGHT_STAGES[:-1]
    bar = tqdm(total=len(stages), desc="relight", unit="stage", dynamic_ncols=True, file=sys.stderr)
    seen: list[str] = []

    def on_stage(name: str) -> None:
        if seen:
            bar.update(1)
        seen.append(name)
        bar.set_postfix_str(name)

    relighter.on_stage = on_stage
    try:
        yield
        bar.update(len(stages) - bar.n)
    finally:
        relighter.on_stage = None
        bar.close()


def layer_with_alpha(layer: np.ndarray, sky: np.ndarray) -> np.ndarray:
    """A surface layer ``(H, W, C)`` in [0, 1] (C = 3, or 1 for a shadow) with an alpha channel, 0 on the sky
    ``(H, W)`` bool and 1 elsewhere: ``(H, W, C + 1)``, its values unchanged. Without sky it is returned as it is."""
    if layer.ndim != 3 or layer.shape[-1] not in (1, 3):
        raise ValueError(f"layer must have shape (H, W, 1) or (H, W, 3), got {layer.shape}")
    if sky.shape != layer.shape[:2]:
        raise ValueError(f"sky must have shape {layer.shape[:2]}, got {sky.shape}")
    if not sky.any():
        return layer
    return np.concatenate([layer, (~sky)[..., None].astype(layer.dtype)], axis=-1)


def sun_direction(elevation_deg: float, azimuth_deg: float) -> np.ndarray:
    """World-frame unit vector towards the sun (Y up, camera looking along -Z).

    Azimuth 0 puts the sun straight ahead of the camera (-Z), 90 to its right (+X).
    """
    if not (math.isfinite(elevation_deg) and math.isfinite(azimuth_deg)) or not -90 <= elevation_deg <= 90:
        raise ValueError(f"sun elevation must lie in [-90, 90] degrees, got {elevation_deg}")
    from physrelight.envmap import direction_from_angles

    return direction_from_angles(elevation_deg, azimuth_deg)


def _read_sh(path: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise ValueError(f"SH file {path!r} {'is not a regular file' if p.exists() else 'does not exist'}")
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


def _target(env: str | None, sh_path: str | None, sun: list[float] | None, what: str = "target"):
    """The lighting named by one of ``--env`` / ``--sh`` / ``--sun`` (or their ``--source-`` twins)."""
    if env is not None:
        p = Path(env)
        if not p.is_file():
            raise ValueError(f"{what} environment map {env!r} "
                             f"{'is not a regular file' if p.exists() else 'does not exist'}")
        if p.suffix.lower() not in (".exr", ".hdr"):
            raise ValueError(f"{what} environment map {env!r} must be an .exr or .hdr file")
        import torch

        from physrelight import envmap

        try:
            image = envmap.read(p)
            envmap.check_envmap(torch.from_numpy(np.asarray(image, dtype=np.float32)), f"{what} environment map {env!r}")
        except (OSError, RuntimeError) as err:
            raise ValueError(f"cannot read {what} environment map {env!r}: {err}") from None
        return image
    if sh_path is not None:
        return _read_sh(sh_path)
    from physrelight.target_lighting import Sun

    return Sun(*sun)  # the Python API's sun target: --sun ELEV AZIM is Sun(ELEV, AZIM)


def _write_gif(path: Path, frames: list[np.ndarray], fps: float) -> None:
    from PIL import Image

    from physrelight import io

    imgs = [Image.fromarray(np.clip(np.round(f * 255), 0, 255).astype(np.uint8)) for f in frames]
    with io.atomic_path(path) as tmp:
        imgs[0].save(tmp, format="GIF", save_all=True, append_images=imgs[1:], duration=round(1000 / fps), loop=0)


def _check_sequence(frames: int, height: int, width: int) -> None:
    """Refuse, before any work, a ``--sequence`` that cannot be held: more than :data:`MAX_SEQUENCE` frames, or
    frames that need more memory than there is (:func:`sequence_bytes` against
    :func:`physrelight.cli_common.check_fits_in_memory`)."""
    from physrelight.cli_common import check_fits_in_memory

    if frames > MAX_SEQUENCE:
        raise ValueError(f"--sequence {frames}: at most {MAX_SEQUENCE} frames (one every "
                         f"{360 / MAX_SEQUENCE:g} degrees; the frames are held in memory until the GIF is written)")
    check_fits_in_memory(sequence_bytes(frames, height, width),
                         f"--sequence {frames} of a {width}x{height} photo (the frames are held in memory until "
                         f"the GIF is written)")


def sequence_bytes(frames: int, height: int, width: int) -> int:
    """Bytes that ``--sequence frames`` of a ``height x width`` photo holds before the GIF is written: every
    frame as float32 RGB (what :meth:`Relighter.relight_sequence` returns) and its 8-bit copy for the GIF."""
    return frames * height * width * 3 * (4 + 1)


def _denoise_note(image: np.ndarray) -> str | None:
    """Why ``--denoise`` will leave the photo ``(H, W, 3)`` (display values, or radiance) as it is, or None when
    it acts: the denoise is set by the noise floor measured in the photo's flattest tiles
    (:func:`physrelight.denoise.noise_sigma`), and a floor of 0 in every channel means there is nothing to remove."""
    import torch

    from physrelight import colour
    from physrelight.denoise import FLOOR_BLOCK, noise_sigma

    t = torch.from_numpy(np.ascontiguousarray(image, dtype=np.float32)).permute(2, 0, 1)[None]
    lin = t if image.dtype != np.uint8 and float(t.max()) > 1.0 else colour.from_ldr(t.clamp(0.0, 1.0))
    if bool((noise_sigma(lin) > 0).any()):
        return None
    return (f"--denoise changes nothing here: no noise was measured in the photo's flattest {FLOOR_BLOCK} x "
            f"{FLOOR_BLOCK} tiles (a clean photo, or JPEG compression removed the noise there), so it is relit "
            "as it is")


@contextlib.contextmanager
def _notes_from(logger_name: str) -> Iterator[None]:
    """Print the INFO records of ``logger_name`` (the relighter's: where the photo's own lighting came from) on
    stderr as ``physrelight: note: ...`` lines while the block runs."""
    import logging

    class _Note(logging.Handler):
        def emit(self, record: logging.LogRecord) -> None:
            print(f"physrelight: note: {record.getMessage()}", file=sys.stderr)

    logger, handler = logging.getLogger(logger_name), _Note(logging.INFO)
    level = logger.level
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)
    try:
        yield
    finally:
        logger.removeHandler(handler)
        logger.setLevel(level)


def _relight(args: argparse.Namespace) -> int:
    import warnings

    import torch

    from physrelight import io
    from physrelight.cli_common import keep_freed_memory
    from physrelight.exposure import parse_exposure

    torch.set_num_threads(args.threads)
    keep_freed_memory()  # full-size temporaries reused, not page-faulted in anew: half the CPU time on 12 MP
    out = Path(args.output)
    if args.sequence and args.layers is not None:
        raise ValueError("--layers writes the layers of one relit photo; it does not go with --sequence")
    if args.sequence and out.suffix.lower() != ".gif":
        raise ValueError(f"output must be a .gif file with --sequence, got {str(out)!r}")
    if not args.sequence and out.suffix.lower() not in (".png", ".exr"):
        raise ValueError(f"output must be a .png (display) or .exr (linear radiance) file, got {str(out)!r}")
    linear = out.suffix.lower() == ".exr"
    if args.sky is not None and args.sun is None:
        raise ValueError("--sky chooses the sky of a --sun target; an --env or --sh target brings its own")
    if args.sun is not None:
        elev, azim = args.sun
        if not abs(azim) <= SUN_AZIMUTH_LIMIT:
            raise ValueError(f"--sun {elev:g} {azim:g}: the azimuth AZIM must lie in [-{SUN_AZIMUTH_LIMIT:g}, "
                             f"{SUN_AZIMUTH_LIMIT:g}] degrees")
        if not elev <= 90:
            raise ValueError(f"--sun {elev:g} {azim:g}: the sun elevation ELEV must lie in (0, 90] degrees")
        if (args.sky or "clear") == "clear" and not elev > 0:
            raise ValueError(f"--sun {elev:g} {azim:g}: a clear sky's sun must be above the horizon "
                             f"(ELEV in (0, 90]); --sky overcast gives a sunless sky")
        if not elev >= -90:
            raise ValueError(f"--sun {elev:g} {azim:g}: the sun elevation ELEV must lie in [-90, 90] degrees")
    if args.source_env is not None or args.source_sh is not None:
        # The known-source track: the quotient divides by the given lighting (bench: quotient_known, and
        # proposed_known for the shipped renderer on top of it, study 29); resynthesis methods cannot use it.
        if args.method is not None and not (args.method.startswith("quotient") or args.method == "proposed"):
            raise ValueError("--source-env/--source-sh need --method proposed or a quotient method")
    if args.method is None:
        from .relight_options import DEFAULT_METHOD

        args.method = DEFAULT_METHOD
    exposure = parse_exposure(args.exposure)
    from physrelight.cli_common import check_not_input

    inputs = {"input photo": args.photo, "--mask": args.mask, "--env": args.env, "--sh": args.sh,
              "--source-env": args.source_env, "--source-sh": args.source_sh}
    check_not_input(out, inputs)
    for name in LAYER_FILES if args.layers is not None else ():  # the folder may hold the photo, not a layer's name
        check_not_input(Path(args.layers) / f"{name}.png", inputs)
    for name in ("lighting.json", "lighting_preview.png") if args.layers is not None else ():
        check_not_input(Path(args.layers) / name, inputs)
    if args.sequence:
        _check_sequence(args.sequence, 1, 1)  # the frame cap, before the photo is read
    photo = io.read_photo(args.photo)  # one-line ValueError for missing, corrupt or palette files
    for note in photo.notes:
        print(f"physrelight: note: {args.photo}: {note}", file=sys.stderr)
    image = photo.image
    if args.sequence:
        _check_sequence(args.sequence, *image.shape[:2])
    mask = None
    if args.mask is not None:
        mask = io.read_mask(args.mask, shape=image.shape[:2])
        if mask.all() or not mask.any():
            raise ValueError(f"mask {args.mask!r} marks {'every' if mask.all() else 'no'} pixel as sky "
                             f"(white = sky, black = the scene)")
    target = _target(args.env, args.sh, args.sun)
    source = None
    if args.source_env is not None or args.source_sh is not None:
        source = _target(args.source_env, args.source_sh, None, what="source")
    fov = args.fov if args.fov is not None else photo.fov_deg if photo.fov_deg is not None else None

    from .relight_options import DEFAULT_FOV_DEG, DENOISE, RelightOptions
    from .relighter import Relighter

    relighter = Relighter.load(args.weights, options=RelightOptions(sky_grow=args.sky_grow,
                                                                     denoise=DENOISE if args.denoise else None,
                                                                     source_estimate=args.source_estimate))
    if args.denoise:
        note = _denoise_note(image)
        if note is not None:
            print(f"physrelight: note: {note}", file=sys.stderr)
    common = dict(sky_mask=mask, method=args.method, sky=args.sky or "clear", new_sky=not args.keep_sky,
                  seed=args.seed, sky_source=args.sky_source, exposure=exposure,
                  fov_deg=fov if fov is not None else DEFAULT_FOV_DEG, pitch_deg=args.pitch, source=source,
                  radiance=photo.radiance)
    with warnings.catch_warnings(record=True) as caught, _notes_from("learned.relighter"):
        warnings.simplefilter("always", UserWarning)
        if args.sequence:
            azimuths = args.azimuth + 360.0 * np.arange(args.sequence) / args.sequence
            frames = relighter.relight_sequence(image, target, azimuths, progress=not args.quiet, **common)
        else:
            with _stage_bar(relighter, enabled=not args.quiet and image.shape[0] * image.shape[1] >= PROGRESS_PIXELS,
                            layers=args.layers is not None):
                if args.layers is None:  # the relit photo alone: the full-size layers cost 4 box passes on 12 MP
                    layers = {"relit": relighter.relight(image, target, azimuth_deg=args.azimuth, linear=linear,
                                                         **common)}
                else:
                    layers = relighter.relight_layers(image, target, azimuth_deg=args.azimuth, linear=linear,
                                                      **common)
    for w in {str(w.message) for w in caught if issubclass(w.category, UserWarning) and "NumPy array" not in str(w.message)}:
        print(f"physrelight: warning: {w}", file=sys.stderr)
    if args.layers is not None:  # the sun and sky read from the photo (physrelight lighting), before any write
        from .lighting_cli import estimate_lighting, write_lighting

        # the reading and the decomposition the relighting made, not made again
        lighting = estimate_lighting(
            relighter, image, radiance=photo.radiance, sky_mask=layers["sky_mask"][..., 0] > 0.5,
            fov_deg=common["fov_deg"], pitch_deg=args.pitch,
            fov_source="given" if args.fov is not None else "exif" if photo.fov_deg is not None else "default",
            reading=layers.sky_lighting, decomposition_lighting=layers.decomposition_lighting)
    if args.sequence:
        _write_gif(out, frames, args.fps)
        print(f"{len(frames)} frames -> {out}")
        return 0
    if linear:  # the relit radiance as it is, and its display values for the layers
        from physrelight import colour, envmap

        envmap.write(out, layers["relit"])
        layers["relit"] = colour.to_ldr(layers["relit"])
    else:
        io.write_png(out, layers["relit"])
    if args.layers is not None:
        d = Path(args.layers)
        d.mkdir(parents=True, exist_ok=True)  # checked before any work (physrelight.cli_common.check_outputs)
        sky = layers["sky_mask"][..., 0] > 0.5
        for name, img in layers.items():
            if name not in LAYER_FILES:  # a layer the early check did not know of: never over an input either
                check_not_input(d / f"{name}.png", inputs)
            io.write_png(d / f"{name}.png", layer_with_alpha(img, sky) if name in DECOMPOSITION_LAYERS else img)
        write_lighting(d / "lighting.json", *lighting)
        print(f"layers ({', '.join(layers)}, lighting.json, lighting_preview.png) -> {d}")
    print(f"relit {image.shape[1]}x{image.shape[0]} -> {out}")
    return 0


def _exposure(text: str) -> str | float:
    from physrelight.exposure import parse_exposure

    try:
        return parse_exposure(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``relight``."""
    from physrelight.cli_common import finite_number, number_in, positive_int, positive_number
    from physrelight.sky_mask import GROW_REACH
    from physrelight.target_lighting import SKY_TYPES

    from .relight_options import RELIGHT_METHODS, SKY_SOURCES, SOURCE_ESTIMATES, RelightOptions

    p = sub.add_parser("relight", help="relight one outdoor photo to a new lighting (shipped weights)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("photo", help="RGB photo (PNG or JPEG), or linear radiance (.exr or .hdr)")
    tgt = p.add_mutually_exclusive_group(required=True)
    tgt.add_argument("--env", help="target environment map (lat-long .exr or .hdr, world frame, Y up)")
    tgt.add_argument("--sh", help="target order-2 radiance SH, world frame: .npy, .json or text, shape (9, 3)")
    tgt.add_argument("--sun", nargs=2, type=finite_number("an angle in degrees"), metavar=("ELEV", "AZIM"),
                     help="target sun elevation in (0, 90] for a clear sky and azimuth in [-360, 360], in degrees "
                          "(see above), with --sky")
    p.add_argument("--sky", choices=SKY_TYPES, default=None, help="sky type for --sun (default: clear)")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--source-env", default=None, metavar="MAP",
                     help="the photo's own environment map (known-source track: relighting to it gives the photo)")
    src.add_argument("--source-sh", default=None, metavar="F", help="the photo's own order-2 radiance SH, world frame")
    p.add_argument("--fov", type=number_in(1.0, 179.0, "a field of view in degrees"), default=None, metavar="DEG",
                   help="horizontal field of view in degrees (default: from EXIF, else 60)")
    p.add_argument("--pitch", type=number_in(-89.0, 89.0, "a pitch in degrees"), default=None, metavar="DEG",
                   help="camera pitch in degrees, up positive (default: estimated from the sky's horizon)")
    p.add_argument("--sky-source", choices=SKY_SOURCES, default=None,
                   help="the relit sky: target (render the target's sky; default for --env/--sun), fit (a sky "
                        "model fitted to the target's SH), gan (SkyGAN; default for --sh), keep (the photo's)")
    p.add_argument("--exposure", type=_exposure, default="auto",
                   help="auto (meter like a camera; default), keep (same camera settings) or stops (e.g. -1)")
    p.add_argument("--azimuth", type=number_in(-SUN_AZIMUTH_LIMIT, SUN_AZIMUTH_LIMIT, "an azimuth in degrees"),
                   default=0.0, help="turn the target about the vertical, clockwise seen from above as --sun's "
                                     "azimuth counts (degrees, in [-360, 360])")
    p.add_argument("--mask", default=None, help="sky mask PNG (white = sky), the photo's size "
                                                "(default: the shipped sky segmenter's)")
    p.add_argument("--sky-grow", type=number_in(0.0, 1.0, "a fraction of the photo's short side"), default=GROW_REACH,
                   metavar="FRAC", help="also call sky the sky-coloured pixels within FRAC of the short side of the "
                                        f"found sky: lattices, bare branches (default: {GROW_REACH}; 0: off; "
                                        "docs/experiments/40)")
    p.add_argument("--denoise", action="store_true",
                   help="smooth the photo's noise before relighting, at a level estimated from the photo (off by "
                        "default: it also smooths fine texture such as foliage; for dark, noisy photos; "
                        "docs/experiments/37)")
    p.add_argument("--source-estimate", choices=SOURCE_ESTIMATES, default=RelightOptions().source_estimate,
                   help="the photo's own lighting when no --source-env/--source-sh is given: the decomposition's "
                        "estimate, or the sun and sky read from the photo's sky (falling back to the decomposition's "
                        "where the sky says nothing; a note says which) (default: %(default)s; "
                        "docs/experiments/61-sun-in-relighter.md)")
    p.add_argument("--keep-sky", action="store_true", help="keep the photo's sky (same as --sky-source keep)")
    p.add_argument("--seed", type=int, default=0, help="SkyGAN noise seed (default: 0)")
    p.add_argument("--layers", default=None,
                   help="also write albedo, normals, shadows, shading (RGBA: transparent on the sky, where they "
                        "describe nothing) and the sky mask (white = sky) into this folder")
    p.add_argument("--sequence", type=positive_int, default=None, metavar="N",
                   help=f"sweep the azimuth over 360 degrees in N frames (at most {MAX_SEQUENCE}, and what fits in "
                        "memory); write an animated GIF")
    p.add_argument("--fps", type=positive_number, default=12.0, help="GIF frame rate (default: 12)")
    p.add_argument("--method", choices=RELIGHT_METHODS, default=None,
                   help="relighting method (default: proposed, the neural renderer on top of the quotient image; "
                        "quotient is the physical method alone)")
    p.add_argument("--weights", default=None, help="weights folder (default: the shipped ones)")
    p.add_argument("--threads", type=positive_int, default=2, help="torch CPU threads (default: 2)")
    p.add_argument("--quiet", action="store_true",
                   help="no progress bar (shown for --sequence and for photos of a megapixel or more)")
    p.add_argument("-o", "--output", required=True, help="output .png, .exr (linear radiance, float32) or .gif with --sequence")
    p.set_defaults(handler=_relight, output_files=("output",), output_folders=("layers",))
