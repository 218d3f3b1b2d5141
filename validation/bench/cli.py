"""``physrelight bench``: the relighting benchmark and its report.

Registered by :mod:`physrelight.cli` through :func:`add_parser`; torch, Mitsuba and the
benchmark load inside the handler, so ``physrelight --help`` stays light.
"""

from __future__ import annotations

import argparse
import shlex

DESCRIPTION = """\
Relight synthetic photos with every method and score them against path tracing; write
OUT/bench.md (tables in the paper's layouts, verdicts, strata, charts inline), OUT/bench.json
(every figure; methods under "methods") and OUT/charts/*.png.

Protocols: cross-relighting (every view under every lighting relit to the other lightings of its
scene) and time-lapse (one view, the sun moving through a day). Methods: proposed, lambertian_sh,
shadownet_lambertian, oracle_sh, oracle_sh_shadow, identity, and mitsuba_analysis_by_synthesis on a
few photos. Strata: dark input, low sun, overcast, night-like, noise + JPEG, large azimuth change,
glossy, very bright / very dark albedo.

--quick (default) renders its own small held-out set when --data is not given (a few minutes on 2
cores, CI); --full uses --data (default data/heldout) plus generated strata and time-lapse scenes.
"""


def _handler(args: argparse.Namespace) -> int:
    from .run import LEVELS, run_bench

    level = LEVELS["full" if args.full else "quick"]
    words = ["physrelight", "bench", "--full" if args.full else "--quick"]
    if args.data:
        words += ["--data", args.data]
    words += ["-o", args.output]
    if args.threads != 2:
        words += ["--threads", str(args.threads)]
    if args.no_abs:
        words.append("--no-abs")
    if args.weights is not None:
        words += ["--weights", args.weights]
    command = " ".join(shlex.quote(w) for w in words)
    progress = (lambda msg: None) if args.quiet else (lambda msg: print(msg, flush=True))
    report = run_bench(level, args.data, args.output, command, threads=args.threads, runs_dir=args.runs,
                       with_abs=not args.no_abs, progress=progress, weights=args.weights)
    v = report["verdicts"]
    words = ", ".join(f"{k} {'PASS' if x['passed'] else 'FAIL'}" for k, x in v.items())
    print(f"bench done in {report['seconds']:.0f} s ({words}) -> {args.output}/bench.md")
    return 0 if v["finite"]["passed"] else 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``bench`` on the ``physrelight`` subcommand parser."""
    from physrelight.cli import positive_int

    p = sub.add_parser("bench", help="relighting benchmark: methods x protocols x strata, speed vs accuracy",
                       description=DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="small run for CI, a few minutes on 2 cores (default)")
    g.add_argument("--full", action="store_true", help="the run the docs quote (data/heldout + generated scenes)")
    p.add_argument("--data", default=None, metavar="DIR",
                   help="a synth dataset folder (physrelight synth); --quick uses its first 2 scenes, --full all "
                        "(default: --quick renders its own, --full reads data/heldout)")
    p.add_argument("-o", "--output", default="out/bench", help="report folder (default: out/bench)")
    p.add_argument("--threads", type=positive_int, default=2, help="torch threads while timing (default 2)")
    p.add_argument("--runs", default="runs", metavar="DIR",
                   help="where the width sweep finds runs/width_4, width_8, width_16 (default: runs)")
    p.add_argument("--no-abs", action="store_true", help="skip the (slow) analysis-by-synthesis baseline")
    p.add_argument("--weights", default=None, metavar="DIR",
                   help="weights folder of the learned methods (default: the shipped learned/weights)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler=_handler)
