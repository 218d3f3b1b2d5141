"""The ``physrelight`` command: one entry point, one subcommand per job.

This is the one module of :mod:`physrelight` that reaches up into ``synth``, ``learned`` and
``validation``. Each subcommand's parser lives with its stage (``synth/cli.py``,
``learned/cli.py``, ``learned/relight_cli.py``, ``learned/lighting_cli.py``, ``validation/cli.py``,
``validation/bench/cli.py``; ``demo`` here) and is imported only when that subcommand is on
the command line: ``physrelight --help`` lists them from :data:`SUBCOMMANDS` without
importing any stage, or torch, and answers at once.

Before a handler runs, the optional extras it needs are checked
(:func:`physrelight.cli_common.require_extras`): a missing one is a one-line error naming
the ``pip install`` that adds it, before any work and with nothing written. Every
subcommand has ``--help``, shows progress on long work, and exits non-zero with a one-line
reason on bad input (``ValueError``/``FileNotFoundError`` become ``physrelight: error:
...``), never a traceback. Argument errors are one line too (``physrelight relight: error: ...``, exit 2; the
usage is in ``--help``). Every output path a subcommand declares (``output_files``/``output_folders``) is checked
before its handler runs (:func:`physrelight.cli_common.check_outputs`).
"""

from __future__ import annotations

import argparse
import importlib
import sys
from dataclasses import dataclass
from typing import Sequence

from physrelight.cli_common import MissingExtra, MissingSetup, check_outputs, positive_int, require_extras

__all__ = ["SUBCOMMANDS", "Subcommand", "build_parser", "main", "positive_int"]
# positive_int is re-exported for validation/bench/cli.py, which still imports it from here;
# new code imports it from physrelight.cli_common.


@dataclass(frozen=True)
class Subcommand:
    """Where a subcommand's parser lives and what its handler needs."""

    module: str  # has add_parser(subparsers), registering this subcommand with ``help``
    help: str  # listed by ``physrelight --help`` (the stage's own parser says the same: tested)
    extras: tuple[str, ...] = ()  # optional extras the handler needs (checked before it runs)


SUBCOMMANDS: dict[str, Subcommand] = {
    "demo": Subcommand(__name__, "the main job: SH relighting vs exact, then the learned pipeline vs path tracing"),
    "relight": Subcommand("learned.relight_cli", "relight one outdoor photo to a new lighting (shipped weights)"),
    "lighting": Subcommand("learned.lighting_cli", "read the sun and sky from one outdoor photo (JSON and a preview)"),
    "synth": Subcommand("synth.cli", "render a synthetic multi-view x multi-illumination dataset with Mitsuba",
                        ("synth",)),
    "export": Subcommand("synth.export", "write a synth set in a real collection's layout (COLMAP, MegaDepth)"),
    "train": Subcommand("learned.cli", "train, evaluate and export the networks (inverse, ShadowNet, renderer, "
                                       "SkyGAN, sky segmenter)"),
    "validate": Subcommand("validation.cli", "check the physics against path tracing and write a report",
                           ("validation",)),
    "bench": Subcommand("validation.bench.cli", "relighting benchmark: methods x protocols x strata, speed vs accuracy",
                        ("validation",)),
}


# ----------------------------------------------------------------------------- demo

_DEMO_DESCRIPTION = """\
Part 1 (physrelight/demo.py, the physics core alone): a textured Lambertian sphere is rendered
exactly under one shipped HDRI, its lighting solved from the photo at SH orders 2 and 4, its
albedo recovered and relit to other HDRIs, and compared with the exact render: the ceiling of any
SH relighting. Outputs: demo.png, metrics.json.

Part 2 (validation/relight_demo.py, needs the synth extra): a synthetic scene path traced with
Mitsuba under a clear sky is relit to three other lightings with the shipped weights and compared
with the path-traced targets (proposed, lambertian_sh, identity: l1, PSNR, SSIM); scikit-image's
rocket.jpg is relit too when scikit-image is installed. --source-estimate sky relights from the sun
and sky read from the photo's sky instead of the decomposition's lighting. Outputs: relight_demo.png,
relight_metrics.json/.md.
"""


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line on stderr (exit 2): the usage stays in ``--help``."""

    def error(self, message: str):  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _demo(args: argparse.Namespace) -> int:
    if not args.physics_only:  # part 2 renders with Mitsuba: say so before part 1 spends a minute
        require_extras("demo", ("synth",), "or run part 1 alone with --physics-only")
    from physrelight import demo

    print("== part 1: the physics core (SH relighting of a sphere vs exact irradiance)")
    demo.run(args.output, source=args.source, targets=tuple(args.targets), size=args.size)
    if args.physics_only:
        return 0
    from validation import relight_demo

    print("== part 2: the learned pipeline on a path-traced scene and a real photo")
    relight_demo.run(args.output, size=args.scene_size, seed=args.seed, source_estimate=args.source_estimate)
    return 0


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``demo``."""
    p = sub.add_parser("demo", help=SUBCOMMANDS["demo"].help, description=_DEMO_DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--output", default="out/demo", help="output folder (default: out/demo)")
    p.add_argument("--source", default="city", help="shipped HDRI lighting the photo (default: city)")
    p.add_argument("--targets", nargs="+", default=["forest", "courtyard"], help="shipped HDRIs to relight to")
    p.add_argument("--size", type=positive_int, default=80, help="sphere image size in pixels (default: 80)")
    p.add_argument("--scene-size", type=positive_int, default=96, help="synthetic scene size in pixels (default: 96)")
    p.add_argument("--seed", type=int, default=7, help="synthetic scene seed (default: 7)")
    # learned.relight_options.SOURCE_ESTIMATES, spelled out: --help must not import the learned package
    p.add_argument("--source-estimate", choices=("decomposition", "sky"), default="decomposition",
                   help="part 2: the photo's own lighting the relighter divides by: the decomposition's (default) or "
                        "the sun and sky read from the photo's sky (RelightOptions.source_estimate)")
    p.add_argument("--physics-only", action="store_true", help="only part 1 (no Mitsuba, no networks)")
    p.set_defaults(handler=_demo, output_folders=("output",))


# ----------------------------------------------------------------------------- dispatch


def _chosen(argv: Sequence[str]) -> str | None:
    """The subcommand named on the command line (the first word that is not an option), if any."""
    return next((a for a in argv if not a.startswith("-")), None)


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser with ``command``'s full subparser (its stage module imported) and the others listed only."""
    parser = _Parser(prog="physrelight", description="Single-image outdoor relighting, physics-checked.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, spec in SUBCOMMANDS.items():
        if name == command:
            importlib.import_module(spec.module).add_parser(sub)
        else:  # listed in --help; parsed only when named, with its own module loaded
            sub.add_parser(name, help=spec.help, add_help=False)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """The ``physrelight`` command: its exit status (0 done, 2 a one-line error, 130 interrupted)."""
    argv = list(sys.argv[1:] if argv is None else argv)
    command = _chosen(argv)
    parser = build_parser(command if command in SUBCOMMANDS else None)
    args = parser.parse_args(argv)
    try:
        require_extras(args.command, SUBCOMMANDS[args.command].extras)
        check_outputs(args)  # before any work: a bad output path is one line, not a traceback minutes later
        return args.handler(args)
    except (ValueError, FileNotFoundError, MissingExtra, MissingSetup) as err:
        print(f"physrelight: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("physrelight: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
