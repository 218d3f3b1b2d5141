"""Speed of the physics core (not a test: shared machines are noisy, so it reports medians).

    .venv/bin/python scripts/bench_core.py [--repeats 7] [--json out/bench_core.json]

Measures: SH projection of a 1024 x 512 map (cold = first call builds the cached
separable factors; warm = cached), SH irradiance for 512 x 512 normals, the lighting
solve for a 256 x 256 image, and the brute-force irradiance yardstick per normal.
"""

from __future__ import annotations

import argparse
import platform
import statistics
import time
from pathlib import Path
from typing import Callable

import numpy as np
import torch

from physrelight import envmap, image_model, io, sh
from physrelight.sh import _projection_factors

HDRI = Path(__file__).resolve().parents[1] / "physrelight" / "data" / "hdri" / "city.exr"


def median_seconds(fn: Callable[[], object], repeats: int) -> float:
    fn()  # warm-up (allocations, caches of the function itself are *not* cleared)
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return statistics.median(times)


def cpu_name() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--json", type=Path, default=None, help="also write the figures here")
    args = parser.parse_args()

    env = envmap.read(HDRI)
    rng = np.random.default_rng(0)
    results: dict[str, float] = {}

    for order in (2, 4):
        _projection_factors.cache_clear()
        t = time.perf_counter()
        sh.project_envmap(env, order)
        results[f"project_envmap_1024x512_order{order}_cold_s"] = time.perf_counter() - t
        results[f"project_envmap_1024x512_order{order}_warm_s"] = median_seconds(
            lambda: sh.project_envmap(env, order), args.repeats)

    n = rng.normal(size=(512 * 512, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    for order in (2, 4):
        c = sh.project_envmap(env, order)
        results[f"irradiance_512x512_order{order}_numpy_f64_s"] = median_seconds(lambda: sh.irradiance(c, n), args.repeats)
        ct, nt = torch.from_numpy(c).float(), torch.from_numpy(n).float()
        results[f"irradiance_512x512_order{order}_torch_f32_s"] = median_seconds(lambda: sh.irradiance(ct, nt), args.repeats)
        img_n = nt.reshape(1, 512, 512, 3).permute(0, 3, 1, 2).contiguous()
        results[f"image_shading_512x512_order{order}_torch_f32_s"] = median_seconds(
            lambda: image_model.shading(img_n, ct), args.repeats)

    h = w = 256
    g = torch.Generator().manual_seed(0)
    nn = torch.randn(1, 3, h, w, generator=g)
    nn = nn / nn.norm(dim=1, keepdim=True)
    alb = 0.1 + 0.7 * torch.rand(1, 3, h, w, generator=g)
    shadow = 0.2 + 0.8 * torch.rand(1, 1, h, w, generator=g)
    mask = torch.ones(1, 1, h, w)
    light = torch.from_numpy(sh.project_envmap(env, 2)).float()
    img = image_model.render(alb, nn, light, shadow)
    for order in (2, 4):
        results[f"solve_lighting_256x256_order{order}_torch_f32_s"] = median_seconds(
            lambda: image_model.solve_lighting(img, alb, nn, mask, shadow, order=order), args.repeats)

    normals = sh.fibonacci_sphere(256)
    results["irradiance_reference_1024x512_per_normal_s"] = median_seconds(
        lambda: envmap.irradiance_reference(env, normals), max(1, args.repeats // 3)) / len(normals)

    machine = f"{cpu_name()}, {torch.get_num_threads()} torch threads, torch {torch.__version__}"
    print(f"machine: {machine}")
    for k, v in results.items():
        print(f"{k:<52} {v * 1e3:10.2f} ms")
    if args.json:
        io.write_json(args.json, {"machine": machine, "repeats": args.repeats, "seconds": results})


if __name__ == "__main__":
    main()
