"""The ``physrelight`` command line: one entry point, one subcommand per job.

Every subcommand has ``--help``, shows progress on long work, and exits non-zero with a
one-line reason on bad input (``ValueError``/``FileNotFoundError`` become
``physrelight: error: ...``), never a traceback.
"""

from __future__ import annotations

import argparse
import sys
from typing import Callable, Sequence

Handler = Callable[[argparse.Namespace], int]


_DEMO_PART_2 = """
Part 2 (validation/relight_demo.py, needs the full install): a synthetic scene path traced
with Mitsuba under a clear sky is relit to three other lightings with the shipped weights and
compared with the path-traced targets (proposed, lambertian_sh, identity: l1, PSNR, SSIM);
scikit-image's rocket.jpg is relit too. Outputs: relight_demo.png, relight_metrics.json/.md.
"""


def _demo(args: argparse.Namespace) -> int:
    from physrelight import demo

    print("== part 1: the physics core (SH relighting of a sphere vs exact irradiance)")
    demo.run(args.output, source=args.source, targets=tuple(args.targets), size=args.size)
    if args.physics_only:
        return 0
    try:  # the pipeline part needs the synth (Mitsuba) and learned extras
        from validation import relight_demo
    except ImportError as err:
        raise ValueError(f"the pipeline demo needs the full install ({err}); use --physics-only") from None
    print("== part 2: the learned pipeline on a path-traced scene and a real photo")
    relight_demo.run(args.output, size=args.scene_size, seed=args.seed)
    return 0


def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job: SH relighting vs exact, then the learned pipeline vs path tracing",
                       description=__import__("physrelight.demo", fromlist=["x"]).__doc__ + _DEMO_PART_2,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--output", default="out/demo", help="output folder (default: out/demo)")
    p.add_argument("--source", default="city", help="shipped HDRI lighting the photo (default: city)")
    p.add_argument("--targets", nargs="+", default=["forest", "courtyard"], help="shipped HDRIs to relight to")
    p.add_argument("--size", type=positive_int, default=80, help="sphere image size in pixels (default: 80)")
    p.add_argument("--scene-size", type=positive_int, default=96, help="synthetic scene size in pixels (default: 96)")
    p.add_argument("--seed", type=int, default=7, help="synthetic scene seed (default: 7)")
    p.add_argument("--physics-only", action="store_true", help="only part 1 (no Mitsuba, no networks)")
    p.set_defaults(handler=_demo)


def positive_int(text: str) -> int:
    """argparse type: a positive integer, with a one-line error otherwise (shared by subcommands)."""
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def _synth(args: argparse.Namespace) -> int:
    from synth import writer  # imports Mitsuba: only for this subcommand

    config = writer.SynthConfig(
        scenes=args.scenes, views=args.views, lights=args.lights, res=args.res, spp=args.spp, seed=args.seed,
        max_depth=args.max_depth, gbuffer_spp=args.gbuffer_spp, shadow_spp=args.shadow_spp,
        env_resolution=args.env_res, kinds=tuple(args.kinds), hdri_dir=args.hdri_dir,
        glossy_fraction=args.glossy_fraction, trees=not args.no_trees, mvs_scale=args.mvs_scale)
    shard = writer.parse_shard(args.shard)
    summary = writer.write_dataset(args.output, config, shard, progress=not args.quiet)
    print(f"rendered {len(summary['rendered'])} scene(s), skipped {len(summary['skipped'])} finished, "
          f"in {summary['seconds']:.1f} s -> {args.output}")
    return 0


def _add_synth(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("synth", help="render a synthetic multi-view x multi-illumination dataset with Mitsuba",
                       description="Render procedural outdoor landmarks under several lightings from several "
                                   "tourist-like views, with ground truth (see synth/writer.py for the layout). "
                                   "Resumable: re-run the same command to finish an interrupted dataset.")
    p.add_argument("output", help="dataset folder")
    p.add_argument("--scenes", type=positive_int, default=4)
    p.add_argument("--views", type=positive_int, default=4)
    p.add_argument("--lights", type=positive_int, default=3)
    p.add_argument("--res", type=positive_int, default=128, help="image size in pixels (square)")
    p.add_argument("--spp", type=positive_int, default=64, help="path-tracing samples per pixel")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--shard", default="0/1", help="render scenes i, i+n, ... of the dataset (i/n)")
    p.add_argument("--hdri-dir", default=None, help="folder of .exr maps for the hdri lighting kind "
                                                    "(default: the maps shipped in the package)")
    p.add_argument("--max-depth", type=positive_int, default=8, help="path length (bounces + 1)")
    p.add_argument("--gbuffer-spp", type=positive_int, default=16)
    p.add_argument("--shadow-spp", type=positive_int, default=32,
                   help="shadow samples per pixel (x4 for lightings without a sun)")
    p.add_argument("--env-res", type=positive_int, default=128, help="sky map height for sun/sky lightings")
    p.add_argument("--kinds", nargs="+", default=["sunsky", "evening", "overcast", "hdri"],
                   help="lighting kinds to draw from")
    p.add_argument("--glossy-fraction", type=float, default=0.0, help="share of non-Lambertian materials")
    p.add_argument("--no-trees", action="store_true")
    p.add_argument("--mvs-scale", type=positive_int, default=1,
                   help="degrade the MVS depth from geometry at this many times the photo's resolution "
                        "(every other file is unchanged; at most 4)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(handler=_synth)


_SUBCOMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_demo, _add_synth]

# Subcommands owned by other packages: each module has ``add_parser(subparsers)`` and
# keeps its heavy imports (Mitsuba, training code) inside the handler.
_PACKAGE_SUBCOMMANDS = ("validation.cli", "learned.cli", "learned.relight_cli", "validation.bench.cli")


def build_parser() -> argparse.ArgumentParser:
    import importlib

    parser = argparse.ArgumentParser(prog="physrelight", description="Single-image outdoor relighting, physics-checked.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in _SUBCOMMANDS:
        add(sub)
    for name in _PACKAGE_SUBCOMMANDS:
        try:
            module = importlib.import_module(name)
        except ModuleNotFoundError as err:
            if err.name != name and not name.startswith(f"{err.name}."):
                raise  # a real missing dependency, not a package that is not there yet
            continue
        module.add_parser(sub)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return args.handler(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"physrelight: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("physrelight: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
