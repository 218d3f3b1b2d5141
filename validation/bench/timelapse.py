"""``physrelight bench --timelapse DIR``: the paper's Table 1 protocol on real time-lapse frames.

Yu et al. (ECCV 2020, Table 1) relight BigTime sequences (Li & Snavely 2018): every frame of one
fixed view relit to the lighting of every other frame, that lighting *estimated from the target frame*
(no ground-truth maps), scored against the real target frame on the foreground with l1, MSE, SSIM
and DSSIM. Their figures: l1 0.103, MSE 0.021, SSIM 0.760, DSSIM 0.120 (:data:`PAPER`).

Layout read (BigTime's release, as its training loader reads it)::

    DIR/<sequence>/data/<frame>.jpg        (.jpeg, .png too) frames of one fixed camera, one size
    DIR/<sequence>/data/<frame>_mask.png   optional, white = pixels to score (not sky, nothing moving)
    DIR/<sequence>/lighting.json           optional, not BigTime's: a synthetic day's ground truth
                                           (:mod:`synth.timelapse`)

``DIR`` may also be one sequence (``DIR/data`` exists).

Protocol, per sequence and ordered pair (source frame i, target frame j != i), or a seeded subset of
``--pairs`` of them per sequence:

* the sky is the shipped segmenter's on each frame at full resolution (as ``physrelight relight`` has it);
* the target lighting is estimated from frame j by the pipeline's own decomposition
  (:func:`estimate_lighting`: :meth:`learned.Relighter.decompose_linear` at the working resolution, as
  :meth:`~learned.Relighter.relight_full_resolution` runs it), in frame j's linear units;
* frame i is relit to it by the bench's *estimated-track* methods, unchanged (:class:`.methods.Learned`:
  ``proposed``, ``lambertian_sh``, ``shadownet_lambertian``, ``quotient``), handed frame i's own estimate as
  the source lighting: the target's level is the estimates' ratio, so a relit frame comes out at frame j's
  exposure when the decomposition's albedo is the same in both frames (the scene did not change);
* scored against frame j as it is (display values) on the foreground: the masks of i and j (both must show
  the static scene) or, without masks, neither frame's segmented sky (:func:`.scores.score`: l1, MSE, SSIM,
  DSSIM, PSNR, CIEDE2000, and the same after the output's best single gain, ``gain_*``).

Controls: ``identity`` (frame i unchanged); *self* pairs (i relit to its own estimate, scored against i);
with a ``lighting.json``, the *given* track: the same methods handed the true target and source lighting
(the synthetic bench's protocol), which bounds what a better lighting estimate would give.

Means per sequence and overall, with 95 % hierarchical bootstrap intervals over sequences then pairs
(:func:`physrelight.stats.hierarchical_bootstrap`), as ``bench --real`` and ``--full-resolution`` give
them, and each estimated-track method's per-pair l1 difference to ``identity`` bootstrapped the same way.
Writes ``OUT/timelapse.json`` and ``OUT/timelapse.md`` atomically.
"""

from __future__ import annotations

import datetime
import math
import os
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import torch

from physrelight import colour, io
from physrelight.stats import hierarchical_bootstrap

from .methods import ESTIMATED_TRACK, build_methods
from .protocols import display_at_best_gain
from .scores import METRICS, MethodRun

__all__ = ["FRAME_EXTENSIONS", "PAPER", "TimelapseFrame", "TimelapsePair", "TimelapseSequence", "choose_pairs",
           "estimate_lighting", "read_sequence", "read_timelapse", "run_timelapse_bench", "write_timelapse_report"]

FRAME_EXTENSIONS = (".jpg", ".jpeg", ".png")
MASK_SUFFIX = "_mask"
PAPER = {"l1": 0.103, "mse": 0.021, "ssim": 0.760, "dssim": 0.120}
"""Yu et al. 2020, Table 1, BigTime (their method): real frames, not ours."""
GIVEN_METHODS = ("proposed", "quotient", "quotient_known", "proposed_known")
"""The given track's methods (those :func:`.methods.build_methods` has): true source and target lighting."""
BOOTSTRAP_SAMPLES = 2000
INTERVAL_METRICS = ("l1", "mse", "ssim", "dssim", "psnr", "gain_l1")
TRACK_TITLES = {"estimated": "estimated (the paper's setting: target lighting estimated from the target frame)",
                "given": "given (true source and target lighting; synthetic days only)",
                "reference": "reference"}


# ----------------------------------------------------------------------------- reading


@dataclass
class TimelapseFrame:
    """One frame of a sequence; its pixels are read when first asked for and dropped by :meth:`release`
    (a BigTime folder does not fit in memory at once).

    Attributes:
        name: file stem (``"0630"``).
        path: the frame's file.
        size: ``(H, W)`` as stored (upright by its EXIF orientation).
        mask_path: its ``_mask.png`` (white = pixels to score), or None.
        truth: the frame's ground truth from ``lighting.json`` (``sh``, ``sun_sh`` ``(9, 3)`` camera frame,
            the frame's linear units), or None.
    """

    name: str
    path: Path
    size: tuple[int, int]
    mask_path: Path | None = None
    truth: dict[str, np.ndarray] | None = None
    _cache: dict[str, Any] = field(default_factory=dict, repr=False)

    def photo(self) -> np.ndarray:
        """``(H, W, 3)`` float32 display values in [0, 1]."""
        if "photo" not in self._cache:
            photo = io.read_photo(self.path)
            if photo.radiance:
                raise ValueError(f"{str(self.path)!r}: a time-lapse frame is an 8-bit photo, not radiance")
            img = np.clip(photo.image, 0.0, 1.0).astype(np.float32)
            if img.shape[:2] != self.size:  # the header said otherwise (a broken file)
                raise ValueError(f"{str(self.path)!r}: decoded as {_size(img)}, its header says "
                                 f"{self.size[1]}x{self.size[0]}")
            self._cache["photo"] = img
        return self._cache["photo"]

    def mask(self) -> np.ndarray | None:
        """``(H, W)`` bool, True on pixels to score, or None without a mask."""
        if self.mask_path is None:
            return None
        if "mask" not in self._cache:
            self._cache["mask"] = io.read_mask(self.mask_path)
        return self._cache["mask"]

    def linear(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the frame linearised with the sRGB curve (the true curve is unknown to methods)."""
        if "linear" not in self._cache:
            self._cache["linear"] = colour.from_ldr(self.display().clamp(0.0, 1.0))
        return self._cache["linear"]

    def display(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the frame's display values (what a relit frame is scored against)."""
        if "display" not in self._cache:
            self._cache["display"] = torch.from_numpy(np.ascontiguousarray(self.photo())).permute(2, 0, 1)[None]
        return self._cache["display"]

    def release(self) -> None:
        """Drop the pixels read so far."""
        self._cache.clear()


@dataclass
class TimelapseSequence:
    """A fixed view's frames (sorted by name), all one size."""

    name: str
    folder: Path
    frames: list[TimelapseFrame]

    @property
    def size(self) -> tuple[int, int]:
        """``(H, W)``."""
        return self.frames[0].size

    @property
    def has_truth(self) -> bool:
        return all(f.truth is not None for f in self.frames)

    @property
    def has_masks(self) -> bool:
        return all(f.mask_path is not None for f in self.frames)

    def release(self) -> None:
        for f in self.frames:
            f.release()


def _size(a: np.ndarray) -> str:
    return f"{a.shape[1]}x{a.shape[0]}"


def _stored_size(path: Path, what: str) -> tuple[int, int]:
    """``(H, W)`` of an image file from its header, upright by its EXIF orientation (pixels not decoded)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            w, h = im.size
            if im.getexif().get(0x0112, 1) in (5, 6, 7, 8):  # stored sideways: read_photo turns it upright
                w, h = h, w
    except (UnidentifiedImageError, OSError) as err:
        raise ValueError(f"cannot read {str(path)!r} as {what}: {err}") from None
    return h, w


def read_sequence(folder: str | Path) -> TimelapseSequence:
    """One sequence folder in BigTime's layout (``folder/data/<frame>.jpg`` and optional ``<frame>_mask.png``).

    Only the files' headers are read here (sizes); pixels are read when a frame is relit.

    Raises:
        ValueError: no ``data`` folder, fewer than 2 frames, frames of different sizes, a mask of another size
            than its frame, an unreadable frame, mask or ``lighting.json``.
    """
    folder = Path(folder)
    data = folder / "data"
    if not data.is_dir():
        raise ValueError(f"{str(folder)!r} is not a time-lapse sequence: it has no data/ folder of frames")
    files = sorted(p for p in data.iterdir() if p.is_file() and p.suffix.lower() in FRAME_EXTENSIONS
                   and not p.stem.endswith(MASK_SUFFIX) and not p.name.startswith("."))
    if len(files) < 2:
        raise ValueError(f"{str(data)!r} has {len(files)} frame{'s' if len(files) != 1 else ''}; "
                         "a time-lapse needs at least 2")
    if len({p.stem for p in files}) != len(files):
        raise ValueError(f"{str(data)!r} has two frames of one name with different extensions")
    truth = _read_truth(folder)
    frames: list[TimelapseFrame] = []
    for p in files:
        size = _stored_size(p, "a frame")
        if frames and size != frames[0].size:
            h0, w0 = frames[0].size
            raise ValueError(f"{str(data)!r}: frames differ in size: {frames[0].path.name} is {w0}x{h0}, "
                             f"{p.name} is {size[1]}x{size[0]}")
        mpath: Path | None = data / f"{p.stem}{MASK_SUFFIX}.png"
        if mpath.is_file():
            msize = _stored_size(mpath, "a mask")
            if msize != size:
                raise ValueError(f"{str(mpath)!r}: the mask is {msize[1]}x{msize[0]}, its frame {p.name} is "
                                 f"{size[1]}x{size[0]}")
        else:
            mpath = None
        t = None
        if truth is not None:
            if p.stem not in truth:
                raise ValueError(f"{str(folder / 'lighting.json')!r} has no frame {p.stem!r}")
            t = truth[p.stem]
        frames.append(TimelapseFrame(p.stem, p, size, mpath, t))
    return TimelapseSequence(folder.name, folder, frames)


def _read_truth(folder: Path) -> dict[str, dict[str, np.ndarray]] | None:
    """``lighting.json``'s frames as ``{stem: {"sh": (9, 3), "sun_sh": (9, 3)}}``, or None without the file."""
    path = folder / "lighting.json"
    if not path.is_file():
        return None
    from synth.timelapse import TRUTH_FORMAT

    rec = io.read_json(path)
    if not isinstance(rec, dict) or rec.get("format") != TRUTH_FORMAT:
        raise ValueError(f"{str(path)!r} is not a {TRUTH_FORMAT} file")
    out = {}
    for stem, f in rec.get("frames", {}).items():
        try:
            d = {k: np.asarray(f[k], dtype=np.float64) for k in ("sh", "sun_sh")}
        except (KeyError, TypeError, ValueError):
            raise ValueError(f"{str(path)!r}: frame {stem!r} lacks its sh / sun_sh") from None
        if any(v.shape != (9, 3) or not np.isfinite(v).all() for v in d.values()):
            raise ValueError(f"{str(path)!r}: frame {stem!r} has SH that are not finite (9, 3) arrays")
        out[stem] = d
    return out


def read_timelapse(root: str | Path) -> list[TimelapseSequence]:
    """Every sequence under ``root`` (its sub-folders with a ``data/`` folder, sorted), or ``root`` itself when
    it is one sequence. One parser, every error a one-line ``ValueError`` naming the folder."""
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"--timelapse {str(root)!r} is not a folder")
    if (root / "data").is_dir():
        return [read_sequence(root)]
    folders = sorted(p for p in root.iterdir() if p.is_dir() and not p.name.startswith(".") and (p / "data").is_dir())
    if not folders:
        raise ValueError(f"{str(root)!r} holds no time-lapse sequence (expected SEQUENCE/data/<frame>.jpg, "
                         "BigTime's layout)")
    return [read_sequence(p) for p in folders]


# ----------------------------------------------------------------------------- pairs


def choose_pairs(n: int, cap: int | None, seed: int, index: int) -> list[tuple[int, int]]:
    """The ordered pairs ``(i, j)``, ``i != j``, of ``n`` frames: all, or ``cap`` of them drawn without
    replacement by a generator seeded with ``(seed, index)`` (the sequence's index), in order."""
    if n < 2:
        raise ValueError(f"a time-lapse needs at least 2 frames, got {n}")
    pairs = [(i, j) for i in range(n) for j in range(n) if i != j]
    if cap is None or cap >= len(pairs):
        return pairs
    if cap < 1:
        raise ValueError(f"--pairs must be at least 1, got {cap}")
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, int(index)])
    return [pairs[k] for k in sorted(rng.choice(len(pairs), size=cap, replace=False).tolist())]


def estimate_lighting(relighter: Any, linear: torch.Tensor, sky: torch.Tensor) -> torch.Tensor:
    """``(1, 9, 3)`` camera-frame radiance SH of a photo's lighting, in its linear units, as the pipeline
    estimates it: :meth:`learned.Relighter.decompose_linear` of the (denoised, when set) photo at the working
    resolution, the decomposition :meth:`~learned.Relighter.relight_full_resolution` makes of it.

    ``linear (1, 3, H, W)`` the linearised photo, ``sky (1, 1, H, W)`` bool.
    """
    from physrelight.full_resolution import working_resolution

    small, small_sky = working_resolution(relighter.denoised(linear), sky, relighter.res)
    return relighter.decompose_linear(small.float(), small_sky.bool())["lighting"].float()


@dataclass
class TimelapsePair:
    """One relighting of a sequence: frame ``source`` relit to frame ``target``'s lighting, scored against it.

    The interface of :class:`.protocols.Pair` that :func:`.run.evaluate` and the methods read, for real frames:
    the lightings are the pipeline's estimates (``given=False``) or the sequence's ground truth (``given=True``).
    """

    sequence: TimelapseSequence
    source: int
    target: int
    given: bool
    lightings: dict[str, torch.Tensor]
    skies: list[torch.Tensor]
    _cache: dict[str, torch.Tensor] = field(default_factory=dict, repr=False)

    @property
    def key(self) -> str:
        f = self.sequence.frames
        return f"{self.sequence.name}:{f[self.source].name}->{f[self.target].name}"

    def image(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the source frame, linearised."""
        return self.sequence.frames[self.source].linear()

    def sky(self) -> torch.Tensor:
        """``(1, 1, H, W)`` bool: the segmenter's sky of the source frame."""
        return self.skies[self.source]

    def foreground(self) -> torch.Tensor:
        """``(1, 1, H, W)`` bool: both frames' masks, or neither frame's sky without masks."""
        if "fg" not in self._cache:
            fs = [self.sequence.frames[k] for k in (self.source, self.target)]
            if all(f.mask_path is not None for f in fs):
                fg = torch.from_numpy(fs[0].mask() & fs[1].mask())[None, None]
            else:
                fg = ~(self.skies[self.source] | self.skies[self.target])
            self._cache["fg"] = fg
        return self._cache["fg"]

    def lighting(self, index: int) -> torch.Tensor:
        """``(1, 9, 3)`` frame ``index``'s lighting in its linear units (estimated, or the truth when given)."""
        return self.lightings[f"{'given' if self.given else 'estimated'}:{index}"]

    def sun_lighting(self, index: int) -> torch.Tensor:
        """``(1, 9, 3)`` the sun alone within :meth:`lighting` (zeros without one): the truth's sun when given,
        else the sun of the sky model fitted to the estimate (:func:`physrelight.target_lighting.target_sun`, as
        ``relight`` takes an SH target's sun)."""
        return self.lightings[f"{'given' if self.given else 'estimated'}_sun:{index}"]

    def target_lighting(self) -> torch.Tensor:
        return self.lighting(self.target)

    def source_lighting(self) -> torch.Tensor:
        return self.lighting(self.source)

    def target_display(self) -> torch.Tensor:
        """``(1, 3, H, W)`` the target frame as it is (display values)."""
        return self.sequence.frames[self.target].display()

    def target_linear(self) -> torch.Tensor:
        return self.sequence.frames[self.target].linear()

    def display(self, relit: torch.Tensor) -> torch.Tensor:
        """``(1, 3, H, W)`` a method's linear output -> display values (sRGB, as the frames are read)."""
        return colour.to_ldr(relit.clamp_min(0.0))

    def display_at_best_gain(self, relit: torch.Tensor) -> torch.Tensor:
        """:meth:`display` of ``relit`` at its best single gain against the target
        (:func:`.protocols.display_at_best_gain`)."""
        return display_at_best_gain(relit, self.target_display(), self.target_linear(), self.foreground())

    def release(self) -> None:
        self._cache.clear()


def _sequence_inputs(relighter: Any, seq: TimelapseSequence) -> tuple[list[torch.Tensor], dict[str, torch.Tensor]]:
    """Per frame: the segmenter's sky and the lightings (estimated, and the truth when the sequence has it)."""
    from physrelight.target_lighting import target_sun

    skies, lights = [], {}
    for k, f in enumerate(seq.frames):
        sky = relighter.photo_sky(f.linear())[0].bool()
        skies.append(sky)
        est = estimate_lighting(relighter, f.linear(), sky)
        lights[f"estimated:{k}"] = est
        sun = target_sun(est[0].double())
        lights[f"estimated_sun:{k}"] = torch.zeros_like(est) if sun is None else sun.float()[None]
        if f.truth is not None:
            lights[f"given:{k}"] = torch.from_numpy(f.truth["sh"]).float()[None]
            lights[f"given_sun:{k}"] = torch.from_numpy(f.truth["sun_sh"]).float()[None]
    return skies, lights


# ----------------------------------------------------------------------------- the run


def _merge(name: str, parts: Sequence[MethodRun]) -> MethodRun:
    """One :class:`MethodRun` of several runs' pairs, in order."""
    keys = [k for r in parts for k in r.keys]
    values = {m: np.concatenate([r.values[m] for r in parts]) for m in parts[0].values} if parts else {}
    return MethodRun(name, keys, values, [s for r in parts for s in r.seconds], sum(r.nonfinite for r in parts),
                     [f for r in parts for f in r.failures])


def run_timelapse_bench(root: str | Path, out_dir: str | Path, command: str, pairs: int | None = None, seed: int = 0,
                        threads: int = 2, weights: str | Path | None = None,
                        progress: Callable[[str], None] = print, bar: bool = True) -> dict[str, Any]:
    """Run the time-lapse protocol (module doc) on the sequences under ``root``; write ``timelapse.json`` and
    ``timelapse.md`` into ``out_dir``.

    Args:
        root: a BigTime-layout folder (:func:`read_timelapse`).
        pairs: ordered pairs per sequence (a seeded subset, :func:`choose_pairs`); None: all of them.
        seed: the subset's seed.
        threads: torch threads during the run.
        weights: the learned methods' weights folder (None: the shipped ones).
        bar: show a progress bar (tqdm, on stderr).

    Returns:
        timelapse.json's content.
    """
    if threads < 1:
        raise ValueError(f"threads must be >= 1, got {threads}")
    if pairs is not None and pairs < 1:
        raise ValueError(f"--pairs must be at least 1, got {pairs}")
    from tqdm import tqdm

    from learned import Relighter
    from learned.relight_eval import informative_target

    from ..common import machine
    from .run import evaluate

    t_start = time.perf_counter()
    sequences = read_timelapse(root)  # every refusal before any work
    relighter = Relighter.load(weights)
    before = torch.get_num_threads()
    torch.set_num_threads(threads)
    load_before = os.getloadavg()
    try:
        methods = build_methods(relighter)
        tasks = [(track, m, methods[m]) for track in ("estimated", "self") for m in ESTIMATED_TRACK]
        tasks.append(("reference", "identity", methods["identity"]))
        tasks += [("given", m, methods[m]) for m in GIVEN_METHODS if m in methods]
        chosen = [choose_pairs(len(seq.frames), pairs, seed, s) for s, seq in enumerate(sequences)]

        def relightings(seq: TimelapseSequence, ps: list[tuple[int, int]]) -> int:  # what `tasks` run on ps
            n = {"estimated": len(ps), "reference": len(ps), "given": len(ps) if seq.has_truth else 0,
                 "self": len({i for i, _ in ps})}
            return sum(n[t] for t, _, _ in tasks)

        total = sum(relightings(seq, c) for seq, c in zip(sequences, chosen))
        progress(f"{len(sequences)} sequence(s), {sum(map(len, chosen))} pairs, {total} relightings")
        parts: dict[tuple[str, str], list[MethodRun]] = {}
        groups: dict[str, list[str]] = {"estimated": [], "given": [], "self": []}
        seq_info, left_out = [], []
        with tqdm(total=total, desc="bench --timelapse", disable=not bar, dynamic_ncols=True) as pbar:
            # one sequence at a time: only its frames are in memory
            for s, seq in enumerate(sequences):
                skies, lights = _sequence_inputs(relighter, seq)
                kept = []
                for i, j in chosen[s]:
                    p = TimelapsePair(seq, i, j, False, lights, skies)
                    if bool(p.foreground().any()) and informative_target(p.target_display()[0], p.foreground()[0]):
                        kept.append((i, j))
                    else:
                        left_out.append(p.key)
                pbar.total -= relightings(seq, chosen[s]) - relightings(seq, kept)
                track_pairs = {
                    "estimated": [TimelapsePair(seq, i, j, False, lights, skies) for i, j in kept],
                    "given": [TimelapsePair(seq, i, j, True, lights, skies) for i, j in kept] if seq.has_truth else [],
                    "self": [TimelapsePair(seq, i, i, False, lights, skies) for i in sorted({i for i, _ in kept})]}
                for track, ps in track_pairs.items():
                    groups[track] += [seq.name] * len(ps)
                for track, name, m in tasks:
                    ps = track_pairs["estimated" if track == "reference" else track]

                    def counted(p: TimelapsePair, m: Any = m) -> torch.Tensor:
                        out = m(p)
                        pbar.update(1)
                        return out

                    # chunks of 64 pairs: the scored images of a long sequence are never all in memory
                    parts.setdefault((track, name), []).extend(
                        evaluate(name, counted, ps[k:k + 64]) for k in range(0, len(ps), 64))
                seq_info.append({"name": seq.name, "folder": str(seq.folder), "frames": [f.name for f in seq.frames],
                                 "size": list(seq.size), "masks": seq.has_masks, "truth": seq.has_truth,
                                 "pairs": len(kept), "sky_fraction": [float(k.float().mean()) for k in skies]})
                seq.release()
            pbar.refresh()
        if not groups["estimated"]:
            raise ValueError(f"{str(root)!r}: no pair to score (every target frame is clipped or masked out)")
        runs: dict[str, dict[str, MethodRun]] = {}
        for (track, name), ps in parts.items():
            if ps:
                runs.setdefault(track, {})[name] = _merge(name, ps)
        report = {
            "format": "physrelight-bench-timelapse", "version": 1, "command": command, "seed": seed,
            "pairs_cap": pairs, "data": str(root), "sequences": seq_info, "left_out_pairs": left_out,
            "machine": {**machine(), "torch_threads": threads,
                        "load_average_before": [round(x, 2) for x in load_before],
                        "load_average_after": [round(x, 2) for x in os.getloadavg()],
                        "shared": "the machine is shared with other jobs: timings are medians and indicative"},
            "date": datetime.datetime.now().isoformat(timespec="seconds"),
            "weights": "learned/weights" if weights is None else str(weights), "paper": PAPER,
            "tracks": _summaries(runs, groups, seed),
        }
        report["seconds"] = round(time.perf_counter() - t_start, 1)
        return write_timelapse_report(out_dir, report)
    finally:
        torch.set_num_threads(before)


def _summaries(runs: dict[str, dict[str, MethodRun]], sequence_of: dict[str, list[str]],
               seed: int) -> dict[str, Any]:
    """Per track and method: overall means with intervals, per-sequence means, paired difference to identity."""
    out: dict[str, Any] = {}
    ident = runs["reference"]["identity"]
    for track, methods in runs.items():
        groups = np.asarray(sequence_of["estimated" if track == "reference" else track])
        out[track] = {}
        for name, run in methods.items():
            entry: dict[str, Any] = {"pairs": len(groups), "mean": run.mean(), "interval": {},
                                     "per_sequence": {}, "seconds_per_image": _median(run.seconds),
                                     "nonfinite": run.nonfinite, "failures": run.failures,
                                     "l1_per_pair": run.values["l1"].tolist()}
            for metric in INTERVAL_METRICS:
                v = run.values[metric]
                ok = np.isfinite(v)
                if ok.any():
                    mi = hierarchical_bootstrap(v[ok], groups[ok], samples=BOOTSTRAP_SAMPLES, seed=seed)
                    entry["interval"][metric] = {"lo": mi.lo, "hi": mi.hi, "sequences": mi.groups, "pairs": mi.cases}
            for g in dict.fromkeys(groups.tolist()):
                entry["per_sequence"][g] = run.mean(np.flatnonzero(groups == g).tolist())
            if track == "estimated" and run.keys == ident.keys:
                a, b = run.values["l1"], ident.values["l1"]
                ok = np.isfinite(a) & np.isfinite(b)
                # per-pair differences, bootstrapped like the means (sequences, then pairs): with one sequence
                # paired_bootstrap, which resamples sequences only, would give a zero-width interval
                d = hierarchical_bootstrap(a[ok] - b[ok], groups[ok], samples=BOOTSTRAP_SAMPLES, seed=seed)
                entry["l1_minus_identity"] = {"diff": d.mean, "lo": d.lo, "hi": d.hi, "sequences": d.groups}
            out[track][name] = entry
    return out


def _median(xs: Sequence[float]) -> float:
    return float(statistics.median(xs)) if xs else math.nan


# ----------------------------------------------------------------------------- the report


def _fmt(x: Any, metric: str = "l1") -> str:
    if x is None or not math.isfinite(x):
        return "n/a"
    if metric in ("psnr", "ciede2000"):
        return f"{x:.2f}"
    if metric == "ssim":
        return f"{x:.3f}"
    return f"{x:.4f}"


def _with_interval(entry: dict[str, Any], metric: str) -> str:
    s = _fmt(entry["mean"].get(metric), metric)
    iv = entry["interval"].get(metric)
    return f"{s} [{_fmt(iv['lo'], metric)}, {_fmt(iv['hi'], metric)}]" if iv else s


def markdown(report: dict[str, Any]) -> str:
    """``timelapse.md``: the Table 1 layout per track, the paper's row, per-sequence l1, the controls."""
    from ..common import machine_line

    tracks = report["tracks"]
    seqs = report["sequences"]
    n_pairs = sum(s["pairs"] for s in seqs)
    lines = ["# Time-lapse relighting (`bench --timelapse`, the paper's Table 1 protocol)", "",
             f"Command: `{report['command']}`", "",
             f"Data: `{report['data']}`: {len(seqs)} sequence(s), {n_pairs} ordered pairs (source frame relit to "
             f"the lighting estimated from the target frame, scored against the target frame on the foreground)"
             + (f", at most {report['pairs_cap']} per sequence (seed {report['seed']})" if report["pairs_cap"] else "")
             + f"; {len(report['left_out_pairs'])} pair(s) left out (target clipped or no foreground).", "",
             f"Machine: {machine_line(report['machine'])}; torch threads {report['machine']['torch_threads']}; "
             f"load average before {report['machine']['load_average_before']}, after "
             f"{report['machine']['load_average_after']} ({report['machine']['shared']}). "
             f"Run {report['seconds']:.0f} s, {report['date']}.", "",
             "Means over pairs with 95 % bootstrap intervals (sequences, then pairs within them); l1, MSE on display "
             "values in [0, 1]; `gain l1`: l1 after the output's best single gain (level removed).", ""]
    head = ("| method | l1 | MSE | SSIM | DSSIM | PSNR (dB) | CIEDE2000 | gain l1 | s / image |\n"
            "| --- | ---: | ---: | ---: | ---: | ---: | ---: | ---: | ---: |")

    def row(name: str, e: dict[str, Any]) -> str:
        return (f"| {name} | {_with_interval(e, 'l1')} | {_with_interval(e, 'mse')} | {_with_interval(e, 'ssim')} | "
                f"{_with_interval(e, 'dssim')} | {_fmt(e['mean']['psnr'], 'psnr')} | "
                f"{_fmt(e['mean']['ciede2000'], 'ciede2000')} | {_fmt(e['mean']['gain_l1'])} | "
                f"{_fmt(e['seconds_per_image'])} |")

    lines += ["## Estimated track (the paper's setting)", "", head]
    for name, e in tracks["estimated"].items():
        lines.append(row(name, e))
    lines.append(row("identity (frame unchanged)", tracks["reference"]["identity"]))
    p = report["paper"]
    lines += [f"| *paper, BigTime (real frames, not ours)* | {p['l1']:.3f} | {p['mse']:.3f} | {p['ssim']:.3f} | "
              f"{p['dssim']:.3f} | | | | |", ""]
    lines += ["Paired l1 difference to identity (negative: better than leaving the frame as it is):", ""]
    for name, e in tracks["estimated"].items():
        d = e.get("l1_minus_identity")
        if d:
            lines.append(f"- {name}: {d['diff']:+.4f} [{d['lo']:+.4f}, {d['hi']:+.4f}]")
    lines.append("")
    if "given" in tracks:
        lines += ["## Given track (true source and target lighting; synthetic days only)", "",
                  "The same methods handed the ground-truth lightings of `lighting.json` (the synthetic bench's "
                  "protocol): what a perfect lighting estimate would give.", "", head]
        for name, e in tracks["given"].items():
            lines.append(row(name, e))
        lines.append("")
    lines += ["## Control: each frame relit to its own estimated lighting", "",
              "Scored against itself (identity scores 0 here): what the pipeline loses when the lighting does not "
              "change.", "", head]
    for name, e in tracks["self"].items():
        lines.append(row(name, e))
    lines += ["", "## Per sequence (l1)", ""]
    names = list(tracks["estimated"]) + ["identity"]
    lines += ["| sequence | frames | pairs | " + " | ".join(names) + " |",
              "| --- | ---: | ---: | " + " | ".join("---:" for _ in names) + " |"]
    for s in seqs:
        vals = [tracks["estimated"][n]["per_sequence"].get(s["name"], {}).get("l1") for n in names[:-1]]
        vals.append(tracks["reference"]["identity"]["per_sequence"].get(s["name"], {}).get("l1"))
        lines.append(f"| {s['name']} | {len(s['frames'])} | {s['pairs']} | " + " | ".join(_fmt(v) for v in vals) + " |")
    failures = [f for t in tracks.values() for e in t.values() for f in e["failures"]]
    if failures:
        lines += ["", f"## Failures ({len(failures)}; scored as the input)", ""] + [f"- {f}" for f in failures[:20]]
    return "\n".join(lines) + "\n"


def write_timelapse_report(out_dir: str | Path, report: dict[str, Any]) -> dict[str, Any]:
    """Write ``timelapse.json`` and ``timelapse.md`` into ``out_dir`` atomically; return the JSON content."""
    from ..common import jsonable

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    report = jsonable(report)
    md = markdown(report)
    io.write_json(out / "timelapse.json", report)
    with io.atomic_path(out / "timelapse.md", ".md") as tmp:
        tmp.write_text(md)
    return report
