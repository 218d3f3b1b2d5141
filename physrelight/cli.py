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


def _demo(args: argparse.Namespace) -> int:
    from physrelight import demo

    demo.run(args.output, source=args.source, targets=tuple(args.targets), size=args.size)
    return 0


def _add_demo(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="the main job: relight a sphere between shipped HDRIs and compare with exact",
                       description=__import__("physrelight.demo", fromlist=["x"]).__doc__,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("-o", "--output", default="out/demo", help="output folder (default: out/demo)")
    p.add_argument("--source", default="city", help="shipped HDRI lighting the photo (default: city)")
    p.add_argument("--targets", nargs="+", default=["forest", "courtyard"], help="shipped HDRIs to relight to")
    p.add_argument("--size", type=_positive_int, default=80, help="sphere image size in pixels (default: 80)")
    p.set_defaults(handler=_demo)


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v <= 0:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


_SUBCOMMANDS: list[Callable[[argparse._SubParsersAction], None]] = [_add_demo]


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="physrelight", description="Single-image outdoor relighting, physics-checked.")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for add in _SUBCOMMANDS:
        add(sub)
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
