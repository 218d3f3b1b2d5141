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


REAL_DESCRIPTION = """
--real: the pipeline on real photos whose lighting is known exactly. Pinhole crops of real HDR
panoramas (45-75 deg, level, pitch -5..20 deg, made into 8-bit photos) are scored for (a) sky
segmentation, (b) lighting from the photo, (c) the relit sky against the target panorama seen
through the same camera, (d) self-relighting, with (e) panels; writes OUT/real.md, OUT/real.json,
OUT/charts/real_summary.png and OUT/panels/. Default panoramas: the shipped ones (city, courtyard,
forest: seen in training; studio: indoor, apart; sunrise: held out) and physrelight/data/hdri_more's
five masked outdoor maps (training side) and eight rooms (indoor); --hdri-dir scores a folder of
your own lat-long .exr/.hdr maps. --quick: 4 crops per panorama, 2 targets; --full: 16 and 3.
"""


TIMELAPSE_DESCRIPTION = """
--timelapse DIR: the paper's Table 1 protocol on time-lapse frames in BigTime's layout
(DIR/SEQUENCE/data/FRAME.jpg, optional FRAME_mask.png, white = scored). Every frame relit to the
lighting estimated from every other frame of its sequence, scored against that frame on the
foreground; --pairs N relights a seeded subset of N ordered pairs per sequence (--seed). Writes
OUT/timelapse.md and OUT/timelapse.json. A synthetic day in that layout: synth.timelapse.write_day.
"""


def _timelapse(args: argparse.Namespace, progress) -> int:
    from pathlib import Path

    from .timelapse import read_timelapse, run_timelapse_bench

    clash = [flag for flag, on in (("--real", args.real), ("--full-resolution", args.full_resolution),
                                   ("--data", args.data is not None), ("--hdri-dir", args.hdri_dir is not None),
                                   ("--full", args.full), ("--native-data", args.native_data is not None),
                                   ("--fov", tuple(args.fov) != (45.0, 75.0))) if on]
    if clash:
        raise ValueError(f"--timelapse reads its own frames: it does not go with {', '.join(clash)}")
    if Path(args.output).exists() and not Path(args.output).is_dir():
        raise ValueError(f"-o {args.output!r} is a file; the report goes into a folder")
    read_timelapse(args.timelapse)  # a bad folder fails here, before the networks load
    words = ["physrelight", "bench", "--timelapse", args.timelapse, "-o", args.output]
    if args.pairs is not None:
        words += ["--pairs", str(args.pairs)]
    if args.seed != 0:
        words += ["--seed", str(args.seed)]
    if args.threads != 2:
        words += ["--threads", str(args.threads)]
    if args.weights is not None:
        words += ["--weights", args.weights]
    report = run_timelapse_bench(args.timelapse, args.output, " ".join(shlex.quote(w) for w in words),
                                 pairs=args.pairs, seed=args.seed, threads=args.threads, weights=args.weights,
                                 progress=progress, bar=not args.quiet)
    n = sum(s["pairs"] for s in report["sequences"])
    print(f"bench --timelapse done in {report['seconds']:.0f} s ({len(report['sequences'])} sequence(s), {n} pairs) "
          f"-> {args.output}/timelapse.md")
    return 0


def _real(args: argparse.Namespace, command: str, progress) -> int:
    from synth.panorama_crops import crop_cameras, folder_panoramas

    from .real import REAL_LEVELS, run_real_bench

    crop_cameras(1, 0, tuple(args.fov))  # a bad --fov fails here, before any work
    if args.hdri_dir is not None:
        folder_panoramas(args.hdri_dir)  # an empty or broken folder fails here too
    level = REAL_LEVELS["full" if args.full else "quick"]
    report = run_real_bench(level, args.hdri_dir, args.output, command, threads=args.threads, progress=progress,
                            weights=args.weights, seed=args.seed, fov_range=tuple(args.fov))
    print(f"bench --real done in {report['seconds']:.0f} s ({len(report['crops'])} crops) -> {args.output}/real.md")
    return 0


# Which options each mode reads (dest -> the flag as typed); any other given option would be ignored: refused.
_MODE_OPTIONS = {
    "synthetic": ("quick", "full", "data", "runs", "no_abs"),
    "real": ("quick", "full", "hdri_dir", "fov", "seed"),
    "full_resolution": ("data", "native_data"),
}
_DEFAULT_FOV = (45.0, 75.0)
ABS_LABEL = "mitsuba_analysis_by_synthesis"


def _given(args: argparse.Namespace, dest: str) -> bool:
    """Whether option ``dest`` was on the command line (its parser default is None or False)."""
    return getattr(args, dest) not in (None, False)


def check_mode_options(args: argparse.Namespace) -> str:
    """The mode (``synthetic``, ``real``, ``full_resolution``) after refusing, before any work, an option that
    mode does not read (e.g. ``--fov`` without ``--real``, which a 5-minute synthetic bench would ignore)."""
    if args.real and args.full_resolution:
        raise ValueError("--real and --full-resolution are two different benches: give one")
    mode = "real" if args.real else "full_resolution" if args.full_resolution else "synthetic"
    flags = {d: "--" + d.replace("_", "-") for ds in _MODE_OPTIONS.values() for d in ds}
    for dest, flag in flags.items():
        if dest not in _MODE_OPTIONS[mode] and _given(args, dest):
            owners = [m for m, ds in _MODE_OPTIONS.items() if dest in ds]
            goes = " or ".join({"synthetic": "the synthetic bench (no --real)", "real": "--real",
                                "full_resolution": "--full-resolution"}[m] for m in owners)
            here = {"synthetic": "the synthetic bench", "real": "--real",
                    "full_resolution": "--full-resolution"}[mode]
            raise ValueError(f"{flag} goes with {goes}; {here} does not read it")
    return mode


def check_llvm(with_abs: bool) -> None:
    """Refuse, before any work, a synthetic bench with the analysis-by-synthesis baseline on a machine without
    an LLVM >= 16 library (Mitsuba's differentiable variant needs one; :func:`synth.backend.find_llvm`)."""
    if not with_abs:
        return
    from physrelight.cli_common import SETUP_COMMAND, MissingSetup
    from synth import backend

    if backend.find_llvm() is None:
        raise MissingSetup(f"the bench's {ABS_LABEL} baseline needs Mitsuba's {backend.DIFFERENTIABLE_VARIANT} and "
                           f"no LLVM >= {backend.MIN_LLVM} library was found: run `{SETUP_COMMAND}` (it installs "
                           "libllvm19) or set DRJIT_LIBLLVM_PATH to a libLLVM >= 16; or skip that baseline with "
                           "--no-abs")


def _handler(args: argparse.Namespace) -> int:
    from .run import LEVELS, run_bench

    mode = check_mode_options(args)
    if args.fov is None:
        args.fov = list(_DEFAULT_FOV)
    if args.seed is None:
        args.seed = 0
    if args.runs is None:
        args.runs = "runs"
    if mode == "synthetic":
        check_llvm(not args.no_abs)

    words = ["physrelight", "bench", "--full" if args.full else "--quick"]
    progress = (lambda msg: None) if args.quiet else (lambda msg: print(msg, flush=True))
    if args.timelapse is not None:
        return _timelapse(args, progress)
    if args.pairs is not None:
        raise ValueError("--pairs goes with --timelapse")
    if args.full_resolution:
        from .full_resolution import main

        return main(args, progress)
    if args.real:
        words.insert(2, "--real")
        if args.hdri_dir is not None:
            words += ["--hdri-dir", args.hdri_dir]
        if tuple(args.fov) != _DEFAULT_FOV:
            words += ["--fov", f"{args.fov[0]:g}", f"{args.fov[1]:g}"]
        if args.seed != 0:
            words += ["--seed", str(args.seed)]
        words += ["-o", args.output]
        if args.weights is not None:
            words += ["--weights", args.weights]
        return _real(args, " ".join(shlex.quote(w) for w in words), progress)
    level = LEVELS["full" if args.full else "quick"]
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
    report = run_bench(level, args.data, args.output, command, threads=args.threads, runs_dir=args.runs,
                       with_abs=not args.no_abs, progress=progress, weights=args.weights)
    v = report["verdicts"]
    words = ", ".join(f"{k} {'PASS' if x['passed'] else 'FAIL'}" for k, x in v.items())
    print(f"bench done in {report['seconds']:.0f} s ({words}) -> {args.output}/bench.md")
    return 0 if v["finite"]["passed"] else 1


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``bench`` on the ``physrelight`` subcommand parser."""
    from physrelight.cli_common import positive_int

    p = sub.add_parser("bench", help="relighting benchmark: methods x protocols x strata, speed vs accuracy",
                       description=DESCRIPTION + REAL_DESCRIPTION + TIMELAPSE_DESCRIPTION,
                       formatter_class=argparse.RawDescriptionHelpFormatter)
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", action="store_true", help="small run for CI, a few minutes on 2 cores (default)")
    g.add_argument("--full", action="store_true", help="the run the docs quote (data/heldout + generated scenes)")
    p.add_argument("--data", default=None, metavar="DIR",
                   help="a synth dataset folder (physrelight synth); --quick uses its first 2 scenes, --full all "
                        "(default: --quick renders its own, --full reads data/heldout)")
    p.add_argument("-o", "--output", default="out/bench", help="report folder (default: out/bench)")
    p.add_argument("--threads", type=positive_int, default=2, help="torch threads while timing (default 2)")
    p.add_argument("--runs", default=None, metavar="DIR",  # None: not given (check_mode_options), then "runs"
                   help="where the width sweep finds runs/width_4, width_8, width_16 (default: runs)")
    p.add_argument("--no-abs", action="store_true", help="skip the (slow) analysis-by-synthesis baseline")
    p.add_argument("--weights", default=None, metavar="DIR",
                   help="weights folder of the learned methods (default: the shipped learned/weights)")
    p.add_argument("--real", action="store_true", help="real photos: crops of real HDR panoramas (see above)")
    p.add_argument("--hdri-dir", default=None, metavar="DIR",
                   help="with --real: a folder of lat-long .exr/.hdr panoramas to score (default: the shipped ones)")
    p.add_argument("--fov", nargs=2, type=float, default=None, metavar=("LO", "HI"),
                   help="with --real: the crops' horizontal field of view range in degrees (default: 45 75)")
    p.add_argument("--seed", type=int, default=None,
                   help="with --real: crops, photo noise and SkyGAN noise (default 0)")
    p.add_argument("--full-resolution", action="store_true",
                   help="relit l1 and halo error at depth edges of a synth folder rendered at 256 px (--data, default "
                        "data/heldout256): working at 64 px with bilinear or guided transfer, or at 256 px "
                        "(validation/bench/full_resolution.py); writes OUT/full_resolution.md and .json")
    p.add_argument("--native-data", default=None, metavar="DIR",
                   help="with --full-resolution: the same scenes rendered at 64 px (e.g. data/heldout), scored too")
    p.add_argument("--timelapse", default=None, metavar="DIR",
                   help="time-lapse frames in BigTime's layout (DIR/SEQUENCE/data/*.jpg): the paper's Table 1 "
                        "protocol (see above); writes OUT/timelapse.md and .json")
    p.add_argument("--pairs", type=positive_int, default=None, metavar="N",
                   help="with --timelapse: a seeded subset (--seed) of N ordered frame pairs per sequence "
                        "(default: all)")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(handler=_handler, output_folders=("output",))
