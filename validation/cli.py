"""``physrelight validate``: the physics checks and their report.

Registered by :mod:`physrelight.cli` through :func:`add_parser`. Mitsuba and the checks
are imported inside the handler, so ``validate --help`` loads nothing but :mod:`validation.checks`.
"""

from __future__ import annotations

import argparse
import shlex
import textwrap

from .checks import CHECKS

_CHECKS_LINE = textwrap.fill(
    "Checks: " + ", ".join(f"{i} {what}" for i, (_, _, what) in enumerate(CHECKS, start=1)) + ". Each verdict's "
    "tolerance comes from Monte Carlo noise or from theory. Exits 1 if any verdict fails.", 95)

DESCRIPTION = f"""\
Check physrelight's physics against Mitsuba 3 path tracing and write DIR/report.md (readable on
its own), DIR/report.json (every figure) and DIR/charts/*.png.

{_CHECKS_LINE}

--quick (default) takes a few minutes on 2 cores and runs in CI; --full is what the docs quote.
"""


def _handler(args: argparse.Namespace) -> int:
    from .checks import check_keys
    from .common import LEVELS
    from .report import run_checks

    level = LEVELS["full" if args.full else "quick"]
    keys = check_keys(args.checks)  # ValueError -> one-line error
    words = ["physrelight", "validate", "--full" if args.full else "--quick", "-o", args.output]
    if args.checks:
        words += ["--checks", *args.checks]
    command = " ".join(shlex.quote(w) for w in words)
    progress = (lambda msg: None) if args.quiet else (lambda msg: print(msg, flush=True))
    report = run_checks(level, args.output, command, keys, progress)
    status = "PASS" if report["passed"] else "FAIL"
    print(f"validation {status} in {report['seconds']:.0f} s -> {args.output}/report.md")
    return 0 if report["passed"] else 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``validate`` on the ``physrelight`` subcommand parser."""
    p = sub.add_parser("validate", help="check the physics against path tracing and write a report",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="small run for CI, a few minutes on 2 cores (default)")
    g.add_argument("--full", action="store_true", help="the run the docs quote (about 20 minutes on 2 cores)")
    p.add_argument("-o", "--output", default="out/validation", help="report folder (default: out/validation)")
    p.add_argument("--checks", nargs="+", metavar="CHECK",
                   help=f"run only these checks (numbers 1-{len(CHECKS)} or names such as sh_model)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler=_handler, output_folders=("output",))
