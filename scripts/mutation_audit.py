"""Mutation audit of the relight path (issue 41): plant each known plausible bug and check a test kills it.

Each record in :data:`MUTATIONS` is one bug: the file, the exact text it replaces (found exactly once,
else the audit stops with a message naming the record), the text it puts there, and the pytest selection
that must fail with it. The working tree is never touched: the tree (git's tracked files plus untracked
ones git does not ignore) is copied to a temporary directory, each mutation is written there, its selection
run, and the file's bytes put back in a ``finally``. Every selection is first run unmutated: a selection that
fails on clean code kills nothing and the audit says so.

When code moves, update the record's ``path`` / ``old``; the rest follows.

    python scripts/mutation_audit.py                 # all mutations, table on stdout, exit 1 if any survives
    python scripts/mutation_audit.py -k exposure     # the records whose name contains "exposure"
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

T_QSUN = "tests/physrelight/test_quotient_sun_shadow.py"
T_PHYS = "tests/physrelight/test_relight_physics.py"
T_SRC = "tests/learned/test_source_lighting.py"
T_PINS = "tests/learned/test_relight_pins.py"
T_REAL = "tests/learned/test_relight_real.py"
T_CLI = "tests/learned/test_relight_cli.py"
T_MASK = "tests/physrelight/test_sky_mask.py"
T_ENV = "tests/physrelight/test_envmap.py"
T_VIEW = "tests/physrelight/test_sky_view.py"
PINS_STORED = f"{T_PINS}::test_10_the_shipped_pipeline_reproduces_its_stored_output_on_a_fixed_photo"


@dataclass(frozen=True)
class Mutation:
    """One planted bug: ``old`` (matched exactly once in ``path``) becomes ``new``; ``tests`` must fail."""

    name: str
    path: str
    old: str
    new: str
    tests: tuple[str, ...]


MUTATIONS: tuple[Mutation, ...] = (
    Mutation("1 quotient: exact-sun-cosine path drops the sun term's shadow", "physrelight/quotient.py",
             "direct = shadow.clamp(0.0, 1.0) * direct", "direct = direct",
             (f"{T_QSUN}::test_06_with_the_exact_sun_cosine_the_shadow_dims_the_exact_sun_term_only",)),
    Mutation("2 source lighting: IRLS skips its first reweighting", "learned/source_lighting.py",
             "if cfg.robust and it > 0 and not sky_only:", "if cfg.robust and it > 1 and not sky_only:",
             (f"{T_SRC}::test_12_one_reweighting_already_pulls_the_solve_towards_the_truth",)),
    Mutation("3 relighter: auto exposure without the sky-clipping guard", "learned/relighter.py",
             "exposure_gain(req.exposure, relit, lin, ~sky, highlights=sky)", "exposure_gain(req.exposure, relit, lin, ~sky)",
             (f"{T_PINS}::test_11_auto_exposure_meters_the_source_photo_and_spares_the_sky", PINS_STORED)),
    Mutation("4 relighter: auto exposure metered on the relit image", "learned/relighter.py",
             "exposure_gain(req.exposure, relit, lin, ~sky, highlights=sky)",
             "exposure_gain(req.exposure, relit, relit, ~sky, highlights=sky)",
             (f"{T_PINS}::test_11_auto_exposure_meters_the_source_photo_and_spares_the_sky", PINS_STORED)),
    Mutation("5 sky view: the sun disc's colour in BGR order", "physrelight/sky_view.py",
             "torch.from_numpy(sun_rgb(d))).to(out.dtype)",
             "torch.from_numpy(sun_rgb(d)[::-1].copy())).to(out.dtype)",
             (f"{T_VIEW}::test_02_a_low_suns_disc_is_red_as_its_light",)),
    Mutation("6 envmap: split_sun's contrast to the ring doubled (was envmap_sun's share of peak)", "physrelight/envmap.py",
             "contrast: float = 4.0) -> SunSky:", "contrast: float = 8.0) -> SunSky:",
             (f"{T_ENV}::test_18_an_env_maps_sun_is_its_texels_over_four_times_the_ring_within_three_degrees",)),
    Mutation("6b envmap: split_sun's least energy share doubled", "physrelight/envmap.py",
             "min_fraction: float = 0.01,", "min_fraction: float = 0.02,",
             (f"{T_ENV}::test_18_an_env_maps_sun_is_its_texels_over_four_times_the_ring_within_three_degrees",)),
    Mutation("7 relighter: paint_sky ignores its seed", "learned/relighter.py",
             'working["target"], seed=seed)', 'working["target"], seed=0)',
             (f"{T_REAL}::test_10c_skygans_sky_is_the_seeds",)),
    Mutation("8 exposure: dark-key threshold doubled", "physrelight/exposure.py",
             "DARK_KEY = 0.045", "DARK_KEY = 0.09",
             (f"{T_PHYS}::test_07c_a_source_is_dark_below_two_stops_under_middle_grey",)),
    Mutation("9 exposure: sky highlight percentile 99 -> 90", "physrelight/exposure.py",
             "highlights[b]].float(), 0.99)", "highlights[b]].float(), 0.90)",
             (f"{T_PHYS}::test_07d_the_sky_guard_is_the_skys_99th_percentile",)),
    Mutation("10 exposure: gain clamp dropped", "physrelight/exposure.py",
             "return gain.clamp(2.0**-16, 2.0**16)", "return gain",
             (f"{T_PHYS}::test_07e_a_black_or_blinding_relighting_keeps_a_finite_gain_of_at_most_16_stops",)),
    Mutation("11 sky mask: minimum sky fraction doubled", "physrelight/sky_mask.py",
             "MIN_SKY_FRACTION = 0.01", "MIN_SKY_FRACTION = 0.02",
             (f"{T_MASK}::test_12_a_sky_of_one_percent_of_the_photo_is_enough",)),
    Mutation("12 sky mask: inner-sky brightness threshold halved", "physrelight/sky_mask.py",
             ">= 0.5 * ref_lum and", ">= 0.25 * ref_lum and",
             (f"{T_MASK}::test_13_sky_between_towers_is_kept_when_half_as_bright_and_as_blue",)),
    Mutation("13 relight CLI: --pitch ignored", "learned/relight_cli.py",
             "else DEFAULT_FOV_DEG, pitch_deg=args.pitch,", "else DEFAULT_FOV_DEG, pitch_deg=None,",
             (f"{T_CLI}::test_10_pitch_reaches_the_relighter",)),
    Mutation("14 relight CLI: EXIF focal length overrides --fov", "learned/relight_cli.py",
             "fov = args.fov if args.fov is not None else photo.fov_deg if photo.fov_deg is not None else None",
             "fov = photo.fov_deg if photo.fov_deg is not None else args.fov",
             (f"{T_CLI}::test_11_fov_overrides_the_exif_focal_length_and_exif_overrides_the_default",)),
    Mutation("15 relight CLI: --source-env A --env B passes the target as the source", "learned/relight_cli.py",
             "pitch_deg=args.pitch, source=source,", "pitch_deg=args.pitch, source=target,",
             (f"{T_CLI}::test_12_source_env_is_the_source_and_env_the_target",)),
)


def tree_files(root: Path) -> list[str]:
    """The tree as CI sees it: tracked files and untracked ones git does not ignore (so uncommitted tests count)."""
    out = subprocess.run(["git", "ls-files", "-z", "--cached", "--others", "--exclude-standard"], cwd=root,
                         check=True, capture_output=True).stdout
    return sorted({p for p in out.decode().split("\0") if p and (root / p).is_file()})


def copy_tree(root: Path, dest: Path) -> Path:
    """Copy the tree into ``dest/<name>`` (with ``dest/shared`` linked to the tree's ``../shared``, as CI has it)."""
    repo = dest / root.name
    for rel in tree_files(root):
        target = repo / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(root / rel, target)
    shared = root.parent / "shared"
    if shared.exists():
        (dest / "shared").symlink_to(shared.resolve())
    return repo


def check_record(m: Mutation, repo: Path) -> str:
    """The file's text; a ValueError naming the record when the file is missing or ``old`` is not there exactly once."""
    path = repo / m.path
    if not path.is_file():
        raise ValueError(f"mutation {m.name!r}: {m.path} does not exist (moved? update its record)")
    text = path.read_text()
    n = text.count(m.old)
    if n != 1:
        raise ValueError(f"mutation {m.name!r}: the old text is found {n} times in {m.path}, not once "
                         f"(code moved or changed? update its record): {m.old!r}")
    return text


def run_tests(repo: Path, tests: tuple[str, ...]) -> tuple[int, list[str], str]:
    """``(pytest's exit code, the failed test ids, its output's tail)`` for ``tests`` run in ``repo``."""
    env = {**os.environ, "PYTHONPATH": str(repo), "PYTHONDONTWRITEBYTECODE": "1"}
    proc = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rf", "-p", "no:cacheprovider", *tests],
                          cwd=repo, env=env, capture_output=True, text=True)
    failed = [ln.split()[1] for ln in proc.stdout.splitlines() if ln.startswith("FAILED ")]
    return proc.returncode, failed, proc.stdout[-2000:] + proc.stderr[-2000:]


def short(node: str) -> str:
    """``tests/learned/test_x.py::test_07c_long_name[p]`` -> ``test_x::test_07c[p]``."""
    file, _, test = node.partition("::")
    m = re.match(r"(test_[0-9]+[a-z]?)[^\[]*(\[.*\])?$", test)
    return f"{Path(file).stem}::{m.group(1) + (m.group(2) or '') if m else test}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("-k", default="", help="only the mutations whose name contains this text")
    ap.add_argument("-v", "--verbose", action="store_true", help="print pytest's output of each run")
    args = ap.parse_args(argv)
    chosen = [m for m in MUTATIONS if args.k.lower() in m.name.lower()]
    if not chosen:
        print(f"mutation_audit: no mutation's name contains {args.k!r}", file=sys.stderr)
        return 2
    with tempfile.TemporaryDirectory(prefix="mutation_audit_") as tmp:
        repo = copy_tree(ROOT, Path(tmp))
        try:
            for m in chosen:
                check_record(m, repo)
        except ValueError as err:
            print(f"mutation_audit: {err}", file=sys.stderr)
            return 2
        # Unmutated, every selection must pass: a test that fails on clean code kills nothing.
        for tests in dict.fromkeys(m.tests for m in chosen):
            code, _, tail = run_tests(repo, tests)
            if code != 0:
                print(f"mutation_audit: the selection fails on the unmutated tree: {' '.join(tests)}\n{tail}",
                      file=sys.stderr)
                return 2
        rows = []
        for m in chosen:
            path = repo / m.path
            original = path.read_bytes()
            try:
                path.write_text(check_record(m, repo).replace(m.old, m.new))
                code, failed, tail = run_tests(repo, m.tests)
            finally:
                path.write_bytes(original)
            if args.verbose:
                print(tail)
            killed = code == 1 and bool(failed)  # 1: tests failed; anything else (an import error, ...) is not a kill
            result = "killed" if killed else "SURVIVED" if code == 0 else f"error (pytest exit {code})"
            rows.append((m.name, ", ".join(short(f) for f in failed) or "-", result))
    width = [max(len(r[i]) for r in rows + [("mutation", "killed by", "result")]) for i in range(3)]
    for r in [("mutation", "killed by", "result"), tuple("-" * w for w in width), *rows]:
        print(" | ".join(c.ljust(w) for c, w in zip(r, width)))
    return 0 if all(r[2] == "killed" for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
