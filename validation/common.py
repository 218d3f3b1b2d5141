"""What every check shares: run levels, results with verdicts, statistics, the machine.

No Mitsuba here: the command line imports this module to parse its arguments.

A check returns a :class:`CheckResult`: a dict of figures (JSON-ready), a list of
:class:`Verdict` s (each with its value, its tolerance and where the tolerance comes
from) and the charts it drew. Figures that attribute residuals are *diagnostic*: they
are reported without a verdict, and the result says so in ``notes``.
"""

from __future__ import annotations

import math
import os
import platform
import time
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from physrelight import colour

LUMINANCE = np.asarray(colour.LUMINANCE)
"""Rec. 709 luminance weights (z-tests run on luminance: R, G, B of a pixel share their paths)."""


# ----------------------------------------------------------------------------- levels


@dataclass(frozen=True)
class Level:
    """Everything that sets a run's size. ``quick`` is CI's; ``full`` is what the docs quote.

    Attributes:
        name: ``"quick"`` or ``"full"``.
        env_res: sky map height of every lighting (width ``2 env_res``).
        lightings: names from :data:`validation.scenes.LIGHTINGS` used by checks 1, 2.
        shapes: convex shapes of check 1 (:data:`validation.scenes.CONVEX_SHAPES`).
        convex_res, convex_spp, convex_seeds: image size, samples per pixel per render
            and independent renders (seeds) of check 1.
        scene_seeds: seeds of the generated scenes of checks 2-5.
        scene_views: views per scene.
        scene_lightings: lightings of the scene bank.
        scene_res, scene_spp, scene_renders: image size, spp per render and
            independent renders of the scene bank.
        gbuffer_spp: samples per pixel of each of the two albedo (G-buffer) renders: the
            albedo is a footprint average of a texture, itself a Monte Carlo estimate.
        shadow_spp: samples per pixel of each of the two shadow renders.
        glossy_fraction: share of non-Lambertian materials in the glossy variant.
        spp_ladder, res_ladder: the sweeps of the speed check.
        timing_repeats: repeats per timing (the median is reported).
    """

    name: str
    env_res: int
    lightings: tuple[str, ...]
    shapes: tuple[str, ...]
    convex_res: int
    convex_spp: int
    convex_seeds: int
    scene_seeds: tuple[int, ...]
    scene_views: int
    scene_lightings: tuple[str, ...]
    scene_res: int
    scene_spp: int
    scene_renders: int
    gbuffer_spp: int
    shadow_spp: int
    glossy_fraction: float
    spp_ladder: tuple[int, ...]
    res_ladder: tuple[int, ...]
    timing_repeats: int

    def to_json(self) -> dict[str, Any]:
        return asdict(self)


QUICK = Level(
    name="quick", env_res=64,
    lightings=("sunsky", "evening", "overcast", "city", "courtyard", "forest"),
    shapes=("sphere", "box", "ellipsoid"), convex_res=48, convex_spp=64, convex_seeds=8,
    scene_seeds=(2, 7), scene_views=2, scene_lightings=("sunsky", "overcast", "city"),
    scene_res=64, scene_spp=32, scene_renders=4, gbuffer_spp=1024, shadow_spp=256, glossy_fraction=0.6,
    spp_ladder=(4, 16, 64, 256), res_ladder=(32, 64, 128), timing_repeats=2,
)

FULL = Level(
    name="full", env_res=128,
    lightings=("sunsky", "sunsky_high", "evening", "overcast", "city", "courtyard", "forest", "studio"),
    shapes=("sphere", "box", "ellipsoid"), convex_res=96, convex_spp=64, convex_seeds=16,
    scene_seeds=(2, 7, 11, 19), scene_views=3, scene_lightings=("sunsky", "evening", "overcast", "city", "forest"),
    scene_res=96, scene_spp=64, scene_renders=6, gbuffer_spp=2048, shadow_spp=256, glossy_fraction=0.6,
    spp_ladder=(4, 8, 16, 32, 64, 128, 256, 512), res_ladder=(32, 64, 128, 256, 512), timing_repeats=5,
)

LEVELS = {"quick": QUICK, "full": FULL}


# ----------------------------------------------------------------------------- results


@dataclass
class Verdict:
    """One pass/fail decision.

    Attributes:
        name: what is decided, in words (e.g. ``"sphere / sunsky: mean ratio"``).
        passed: the decision.
        value: the measured figure.
        tolerance: the bound it is held to, as text (e.g. ``"|r - 1| <= 0.0061"``).
        source: where the tolerance comes from (Monte Carlo noise, a theorem, float round-off).
    """

    name: str
    passed: bool
    value: float
    tolerance: str
    source: str

    def to_json(self) -> dict[str, Any]:
        return {"name": self.name, "passed": bool(self.passed), "value": _finite(self.value),
                "tolerance": self.tolerance, "source": self.source}


@dataclass
class CheckResult:
    """The outcome of one check.

    Attributes:
        key: short id (``"renderer_irradiance"``).
        title: heading for the report.
        summary: what was checked, for a reader who has not seen the code (markdown).
        figures: JSON-ready numbers (the report.json payload of the check).
        verdicts: pass/fail decisions; an empty list means the check is diagnostic only.
        tables: markdown tables for the report, in order.
        charts: ``(relative path, caption)`` of PNG charts.
        notes: extra markdown paragraphs (findings, what is diagnostic and why).
        seconds: wall time of the check.
    """

    key: str
    title: str
    summary: str
    figures: dict[str, Any] = field(default_factory=dict)
    verdicts: list[Verdict] = field(default_factory=list)
    tables: list[str] = field(default_factory=list)
    charts: list[tuple[str, str]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    seconds: float = 0.0

    @property
    def passed(self) -> bool:
        return all(v.passed for v in self.verdicts)

    @property
    def status(self) -> str:
        if not self.verdicts:
            return "diagnostic"
        return "pass" if self.passed else "FAIL"

    def check(self, name: str, value: float, ok: bool, tolerance: str, source: str) -> bool:
        """Record a verdict and return it."""
        self.verdicts.append(Verdict(name, bool(ok), float(value), tolerance, source))
        return bool(ok)

    def to_json(self) -> dict[str, Any]:
        return {"key": self.key, "title": self.title, "status": self.status, "seconds": round(self.seconds, 2),
                "figures": jsonable(self.figures), "verdicts": [v.to_json() for v in self.verdicts],
                "charts": [p for p, _ in self.charts]}


def _finite(x: float) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


def md_cell(text: str) -> str:
    """``text`` safe inside a markdown table cell: a bare ``|`` (as in ``|z| > 4``) would end the cell."""
    return str(text).replace("|", "\\|")


def jsonable(obj: Any) -> Any:
    """Numbers, arrays and nested containers -> plain JSON types (NaN/inf -> None)."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        return _finite(float(obj))
    return obj


class Stopwatch:
    """``with Stopwatch() as t: ...; t.seconds``."""

    def __enter__(self) -> "Stopwatch":
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc: Any) -> None:
        self.seconds = time.perf_counter() - self.t0


# ----------------------------------------------------------------------------- statistics


def t_tail(z: float, dof: int) -> float:
    """Two-sided tail ``P(|T| > z)`` of Student's t with ``dof`` degrees of freedom.

    The null distribution of a per-pixel z built from the sample standard deviation of
    ``dof + 1`` independent renders.
    """
    from scipy import stats

    return float(2.0 * stats.t.sf(abs(z), dof))


def binomial_upper(p: float, n: int, sigmas: float = 4.0) -> float:
    """Largest fraction of ``n`` independent tests with probability ``p`` each that is
    still within ``sigmas`` standard deviations of the expected count (plus one test for
    the discreteness of a count)."""
    if n <= 0:
        return 1.0
    return (n * p + sigmas * math.sqrt(n * p * (1 - p)) + 1.0) / n


def per_pixel_stats(runs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mean and standard error of the mean over independent renders.

    Args:
        runs: ``(K, ...)`` K >= 2 independent renders (different seeds).

    Returns:
        ``(mean, sem)`` of shape ``(...)``: ``sem = std(ddof=1) / sqrt(K)``.
    """
    if runs.shape[0] < 2:
        raise ValueError(f"need at least 2 independent renders for a sample variance, got {runs.shape[0]}")
    k = runs.shape[0]
    return runs.mean(axis=0), runs.std(axis=0, ddof=1) / math.sqrt(k)


# ----------------------------------------------------------------------------- machine


def machine() -> dict[str, Any]:
    """CPU model and vector unit, cores, memory, Python/torch/Mitsuba versions: stated beside every figure.

    ``vector_unit`` (``"avx512"``, ``"avx2"`` or None) is recorded because Mitsuba's LLVM backend compiles for it,
    and renders from the same seed differ in their last bits between the two (docs/dataset.md)."""
    model: str | None = None
    flags: set[str] = set()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:  # the first processor's model name, then its flags
                if model is None and line.startswith("model name"):
                    model = line.split(":", 1)[1].strip()
                elif line.startswith("flags"):
                    flags = set(line.split(":", 1)[1].split())
                    break
    except OSError:
        pass
    cpu = model or platform.processor() or platform.machine()
    vector_unit = "avx512" if "avx512f" in flags else "avx2" if "avx2" in flags else None
    mem_gib = None
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemTotal"):
                    mem_gib = round(int(line.split()[1]) / 2**20, 1)
                    break
    except OSError:
        pass
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    info: dict[str, Any] = {"cpu": cpu, "vector_unit": vector_unit, "cores": cores, "memory_gib": mem_gib,
                            "python": platform.python_version(), "os": platform.platform(terse=True)}
    try:
        import torch

        info["torch"] = torch.__version__
        info["torch_threads"] = torch.get_num_threads()
    except ImportError:  # pragma: no cover - torch is a core dependency
        pass
    import sys

    if "mitsuba" in sys.modules:
        mi = sys.modules["mitsuba"]
        info["mitsuba"] = getattr(mi, "__version__", "?")
        info["mitsuba_variant"] = mi.variant()
    return info


def machine_line(info: dict[str, Any]) -> str:
    """One line for chart footnotes: ``2-core AMD EPYC 7B13, 23.5 GiB, Mitsuba 3.9.1 llvm_ad_rgb``."""
    parts = [f"{info.get('cores')}-core {info.get('cpu')}"]
    if info.get("memory_gib"):
        parts.append(f"{info['memory_gib']} GiB")
    if info.get("mitsuba"):
        parts.append(f"Mitsuba {info['mitsuba']} {info.get('mitsuba_variant', '')}".strip())
    return ", ".join(parts)


# ----------------------------------------------------------------------------- run context


@dataclass
class Context:
    """What a check needs besides its level: where to write, what to say on charts.

    Attributes:
        level: the run level.
        out_dir: the report folder (charts go to ``out_dir / "charts"``).
        command: the command line that produced the run (stated on every chart).
        machine: :func:`machine` of this run.
        progress: ``progress(message)`` prints a line (or nothing).
        shared: objects checks share (the scene bank: :func:`validation.scenes.bank`), made on first use.
    """

    level: Level
    out_dir: Any
    command: str
    machine: dict[str, Any]
    progress: Any = print
    shared: dict[str, Any] = field(default_factory=dict)

    @property
    def chart_dir(self) -> Any:
        from pathlib import Path

        d = Path(self.out_dir) / "charts"
        d.mkdir(parents=True, exist_ok=True)
        return d
