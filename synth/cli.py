"""``physrelight synth``: render a synthetic multi-view x multi-illumination dataset.

Registered by :mod:`physrelight.cli` through :func:`add_parser`. Mitsuba loads inside the
handler, after the entry module has checked that the ``synth`` extra is installed, so a
missing extra is one line and no folder is made.
"""

from __future__ import annotations

import argparse

from physrelight.cli_common import positive_int

HELP = "render a synthetic multi-view x multi-illumination dataset with Mitsuba"


def _handler(args: argparse.Namespace) -> int:
    from . import writer  # imports Mitsuba's helpers lazily itself; the extra was checked before

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


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``synth`` on the ``physrelight`` subcommand parser."""
    p = sub.add_parser("synth", help=HELP,
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
    p.set_defaults(handler=_handler, output_folders=("output",))
