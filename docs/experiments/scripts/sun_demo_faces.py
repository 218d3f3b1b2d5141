"""Do the colonnade's sunlit faces even out when the source's sun is read from the photo's sky? (issue 44, the
demo's part 2; docs/experiments/61-sun-in-relighter.md, "The demo's part 2").

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/sun_demo_faces.py [OUT.json]   # ~1 min, one torch thread

The demo's scene (``validation.relight_demo._scene``: seed 7, 96 px, 64 spp, the same renders as ``physrelight
demo``), its photo and protocol, relit to each target with ``quotient`` and ``proposed`` taking the photo's own
lighting four ways: ``decomposition`` (the default), ``sky`` (read from the photo's sky, as ``--source-estimate sky``),
``true shape`` (the path-traced source's own SH passed where the reading goes: a perfect reading, at the
decomposition's level) and, for ``quotient`` alone, ``known`` (the true source lighting at its true level: the
quotient's ceiling). Per relit photo: l1 on the foreground (display values, the demo's figure) and the *sun-facing
contrast*: the median linear luminance of the foreground pixels facing the source's sun (n . s > 0.5, camera frame,
the scene's true normals) over that of the pixels facing away from it (n . s < 0). The source photo's contrast is its
sunlit faces; a relit photo has evened them out when its contrast is the target's. Also the foreground's mean
linear luminance over the target's (``level``) and its red/blue ratio over the target's (``tint``, > 1 warmer).
"""

from __future__ import annotations

import sys

import numpy as np
import torch


def main() -> int:
    torch.set_num_threads(1)
    from learned import Relighter
    from physrelight import colour, io, metrics
    from validation.relight_demo import _chw, _scene, _sky_reading

    sc = _scene(7, 96, 64, lambda m: None)
    gain = 2.0 ** sc["ev"]
    names = list(sc["lights"])
    src = sc["lights"][names[0]]
    photo = colour.to_ldr(_chw(src["radiance"] * gain))
    lin = colour.from_ldr(photo)
    sky = torch.from_numpy(sc["sky"])[None, None]
    fg = torch.from_numpy(sc["foreground"])[None, None].float()
    w2c = sc["camera"]
    s_cam = w2c[:3, :3] @ np.asarray(src["sun_direction"])
    ndots = sc["normals"] @ s_cam
    facing, away = sc["foreground"] & (ndots > 0.5), sc["foreground"] & (ndots < 0.0)
    lum = np.asarray(colour.LUMINANCE)

    def contrast(display: torch.Tensor) -> float:
        y = colour.from_ldr(display.clamp(0, 1))[0].permute(1, 2, 0).numpy() @ lum
        return float(np.median(y[facing]) / np.median(y[away]))

    def level_and_tint(display: torch.Tensor, target: torch.Tensor) -> tuple[float, float]:
        """The foreground's mean linear luminance over the target's, and its mean red over mean blue over the
        target's (> 1: warmer than the target)."""
        a, b = (colour.from_ldr(x.clamp(0, 1))[0].permute(1, 2, 0).numpy()[sc["foreground"]] for x in (display, target))
        return float((a @ lum).mean() / (b @ lum).mean()), float((a[:, 0].mean() / a[:, 2].mean())
                                                                 / (b[:, 0].mean() / b[:, 2].mean()))

    def figures(display: torch.Tensor, target: torch.Tensor) -> dict:
        level, tint = level_and_tint(display, target)
        return {"l1": float(metrics.l1(display, target, fg)), "contrast": contrast(display), "level": level,
                "tint": tint}

    relighter = Relighter.load()
    read, info = _sky_reading(lin, sc["sky"], sc["K"], w2c, src["sun_direction"])
    true_sh = torch.from_numpy(src["sh"] * gain).float()
    ways = {"decomposition": {}, "sky": read, "true shape": {"read_source": true_sh}}
    out = {"pixels": {"facing": int(facing.sum()), "away": int(away.sum())}, "reading": info,
           "source_photo_contrast": contrast(photo), "targets": {}}
    print(f"reading: {info}\nfacing the source's sun {int(facing.sum())} px, away {int(away.sum())} px; "
          f"the photo's contrast {out['source_photo_contrast']:.2f}")
    for name in names[1:]:
        target = colour.to_ldr(_chw(sc["lights"][name]["radiance"] * gain))
        row = {"target_contrast": contrast(target)}
        tgt = torch.from_numpy(sc["lights"][name]["sh"] * gain).float()
        for method in ("quotient", "proposed"):
            for way, kw in ways.items():
                relit = relighter.relight_full_resolution(lin, sky, tgt, source_lighting=true_sh, method=method,
                                                          **kw)["relit"]
                d = colour.to_ldr(relit.clamp_min(0))
                row[f"{method} / {way}"] = figures(d, target)
        relit = relighter.relight_full_resolution(lin, sky, tgt, source_lighting=true_sh, method="quotient",
                                                  known_source=True)["relit"]
        d = colour.to_ldr(relit.clamp_min(0))
        row["quotient / known"] = figures(d, target)
        out["targets"][name] = row
        print(f"\n{name}: the target's contrast {row['target_contrast']:.2f}")
        for k, v in row.items():
            if k != "target_contrast":
                print(f"  {k:26s} l1 {v['l1']:.4f}  contrast {v['contrast']:.2f}  level {v['level']:.2f}  "
                      f"tint {v['tint']:.2f}")
    if len(sys.argv) > 1:  # the figures as JSON, atomically
        io.write_json(sys.argv[1], out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
