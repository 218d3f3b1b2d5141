"""Study 43 probe: occluding-contour normals at full resolution for the quotient's shading.

Where the foreground meets the sky the surface turns away from the camera: at an occluding contour the
normal is perpendicular to the viewing ray and to the contour, so the image gives it exactly (pointing
from the object towards the sky across the boundary). The networks work at 64 px, where a rocket is three
pixels wide, and their normals are blobs. This probe keeps the relighting as shipped and multiplies it, at
full resolution, by the quotient ratio of normals corrected towards the contour normal over the ratio of the
working normals brought up bilinearly:

    relit' = relit * R(n_contour) / R(n_up),   R(n) = quotient_ratio(n; source, target)  (same guard)

``n_contour = normalize(beta c + (1 - beta) n_up)``: ``c`` the contour normals spread inwards by a normalised
Gaussian (opposite contours of a thin object cancel, leaving ``n_up``), ``beta = exp(-d / L)`` with ``d`` the
distance to the contour and ``L = length`` times the short side. Away from contours ``R(n_contour) = R(n_up)``
and the output is the shipped one.

Usage: ``python docs/experiments/scripts/43_contour_normals_probe.py rocket`` (pictures to /tmp) or ``real``
(self-relighting of the training-side crops of ``bench --real --full``) or ``synth DIR`` (a 256-px synth folder).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))

from learned import Relighter  # noqa: E402
from physrelight.quotient import quotient_ratio  # noqa: E402


def _gauss(x: torch.Tensor, sigma: float) -> torch.Tensor:
    """Separable Gaussian blur of ``(B, C, H, W)`` with zero padding (normalised convolution divides it out)."""
    r = max(1, int(3 * sigma))
    k = torch.exp(-0.5 * (torch.arange(-r, r + 1, dtype=x.dtype) / sigma) ** 2)
    k = k / k.sum()
    c = x.shape[1]
    x = F.conv2d(x, k.reshape(1, 1, 1, -1).expand(c, 1, 1, -1), padding=(0, r), groups=c)
    return F.conv2d(x, k.reshape(1, 1, -1, 1).expand(c, 1, -1, 1), padding=(r, 0), groups=c)


def contour_normals(sky: torch.Tensor, n_up: torch.Tensor, length: float, edge_sigma: float = 1.0,
                    iters: int = 3000) -> torch.Tensor:
    """``(1, 3, H, W)`` normals pulled towards the occluding contours of the foreground against ``sky``.

    The x and y components are interpolated harmonically inside the foreground from the contour normals
    (pinned at the boundary pixels), screened towards ``n_up``'s with decay length ``length`` times the short
    side; z is what makes the normal unit (Lumo's inflation): between two contours a strip becomes a cylinder.
    """
    from physrelight.normal_integration import _cg

    h, w = sky.shape[-2:]
    L = max(1.0, length * min(h, w))
    s = _gauss(sky.double(), edge_sigma)
    gv = F.pad(s[..., 2:, :] - s[..., :-2, :], (0, 0, 1, 1)) / 2
    gu = F.pad(s[..., :, 2:] - s[..., :, :-2], (1, 1, 0, 0)) / 2
    g = torch.cat([gu, -gv], 1)  # towards the sky, camera frame (y up)
    gn = g.norm(dim=1, keepdim=True)
    c = g / gn.clamp_min(1e-12)
    fg = ~sky
    near_sky = F.max_pool2d(sky.float(), 3, stride=1, padding=1) > 0
    boundary = fg & near_sky & (gn > 1e-3)
    if not bool(boundary.any()):
        return n_up
    nu = F.normalize(n_up.double(), dim=1)
    m = fg.double()
    wx = m[..., 1:] * m[..., :-1]
    wy = m[..., 1:, :] * m[..., :-1, :]
    rho = torch.where(boundary, torch.full_like(m, 1e4), torch.where(fg, torch.full_like(m, 1.0 / L ** 2),
                                                                      torch.ones_like(m)))
    target = torch.where(boundary, c, nu[:, :2])  # (1, 2, H, W)
    xy = torch.cat([_cg(wx, wy, rho * target[:, k: k + 1], rho, target[:, k: k + 1].clone(), iters, 1e-6)
                    for k in range(2)], 1)
    r2 = (xy ** 2).sum(1, keepdim=True)
    xy = xy / r2.sqrt().clamp_min(1.0)  # inside the unit disc
    z = (1.0 - (xy ** 2).sum(1, keepdim=True)).clamp_min(0.0).sqrt()
    n = torch.cat([xy, z], 1)
    return torch.where(fg, n, nu).to(n_up.dtype)


def patch(relighter: Relighter, length: float) -> None:
    """Make ``relighter.relight_full_resolution`` apply the contour correction (the probe's variant)."""
    original = Relighter.relight_full_resolution.__get__(relighter)

    def wrapped(image, sky, target, source_lighting=None, method="proposed", working_res=None, decomposition=None,
                known_source=False, denoised=None, **sun):
        out = original(image, sky, target, source_lighting=source_lighting, method=method, working_res=working_res,
                       decomposition=decomposition, known_source=known_source, denoised=denoised, **sun)
        if length <= 0:
            return out
        work = out["working"]
        tgt = work["target"]
        raw = torch.as_tensor(target, dtype=torch.float32).reshape(-1, 9, 3)
        lum = torch.tensor([0.2126, 0.7152, 0.0722])
        scale = ((tgt[:, 0] * lum).sum(-1) / (raw[:, 0] * lum).sum(-1).clamp_min(1e-12))[:, None, None]
        src = torch.as_tensor(source_lighting, dtype=torch.float32).reshape(-1, 9, 3) * scale if known_source \
            else work["lighting"]
        t_sun = sun.get("target_sun")
        s_sun = sun.get("source_sun") if known_source else None
        t_sun = None if t_sun is None else torch.as_tensor(t_sun, dtype=torch.float32).reshape(-1, 9, 3) * scale
        s_sun = None if s_sun is None else torch.as_tensor(s_sun, dtype=torch.float32).reshape(-1, 9, 3) * scale
        if t_sun is not None and known_source and s_sun is None:
            s_sun = torch.zeros_like(src)
        n_up = F.normalize(F.interpolate(work["normals"], size=image.shape[-2:], mode="bilinear",
                                         align_corners=False), dim=1)
        n_c = contour_normals(sky, n_up, length)
        kw = dict(mask=~sky, source_sun=s_sun, target_sun=t_sun, sun_cosine=t_sun is not None)
        corr = quotient_ratio(n_c, src, tgt, **kw) / quotient_ratio(n_up, src, tgt, **kw)
        out = dict(out)
        out["relit"] = torch.where(sky, image, out["relit"] * corr)
        out["normals_full"] = n_c
        return out

    relighter.relight_full_resolution = wrapped


def rocket(lengths: list[float]) -> None:
    import imageio.v3 as iio
    import skimage

    path = str(Path(skimage.__file__).parent / "data" / "rocket.jpg")
    rows = []
    for length in lengths:
        r = Relighter.load()
        patch(r, length)
        photo = iio.imread(path)
        row = [photo]
        for az in (90, -90):
            out = r.relight(photo.astype(np.float32) / 255.0, np.array([np.cos(np.radians(15)) * np.sin(np.radians(az)),
                                            np.sin(np.radians(15)),
                                            -np.cos(np.radians(15)) * np.cos(np.radians(az))]),
                            exposure="auto")
            row.append((np.clip(np.asarray(out), 0, 1) * 255 + 0.5).astype(np.uint8))
        rows.append(np.concatenate(row, 1))
    iio.imwrite("/tmp/43_rocket.png", np.concatenate(rows, 0)[::2, ::2])


def real(lengths: list[float]) -> None:
    from real_crop_scores import bench_crops, crop_panoramas
    from physrelight import colour
    from validation.bench.methods import to_chw
    from validation.bench.scores import score

    _, panos = crop_panoramas(False)
    crops = [(p, c) for p, c in bench_crops(panos) if c.stratum != "no_sky" and not c.sky.all()]
    for length in lengths:
        r = Relighter.load()
        patch(r, length)
        res = {m: [] for m in ("quotient", "proposed")}
        for pano, crop in crops:
            lin = crop.linear()
            fg = ~torch.from_numpy(crop.sky)[None, None]
            seg, _ = r.photo_sky(lin)
            src = torch.from_numpy(crop.lighting_sh(2) * crop.gain[None, :]).float()
            photo = to_chw(crop.display())
            for m in res:
                relit = r.relight_full_resolution(lin, seg, src, source_lighting=src, method=m)["relit"]
                pred = torch.where(fg, colour.to_ldr(relit.clamp_min(0)), photo)
                res[m].append(min(float(score([pred], [photo], [fg], which=("psnr",))["psnr"][0]), 58.9))
        print(f"length {length}: " + ", ".join(f"{m} {np.mean(v):.3f} dB" for m, v in res.items())
              + f" (n={len(crops)})", flush=True)


def synth(root: str, lengths: list[float], methods=("quotient", "proposed")) -> None:
    """Full-resolution relit l1 on the bench's cross pairs of a 256-px synth folder (working resolution 64)."""
    from physrelight.stats import paired_bootstrap
    from validation.bench.data import load_dataset
    from validation.bench.protocols import cross_pairs
    from validation.bench.scores import score

    views = load_dataset(root, with_physical=False)
    pairs = cross_pairs(views)
    l1 = {}
    for length in lengths:
        r = Relighter.load()
        patch(r, length)
        for m in methods:
            preds, targets, masks, scenes = [], [], [], []
            for p in pairs:
                suns = {"target_sun": p.sun_lighting(p.target)}
                relit = r.relight_full_resolution(p.image(), p.sky(), p.target_lighting(),
                                                  source_lighting=p.source_lighting(), method=m, working_res=64,
                                                  **suns)["relit"]
                fg, tgt = p.foreground(), p.target_display()
                preds.append(torch.where(fg, p.display(relit.float()), tgt))
                targets.append(tgt)
                masks.append(fg)
                scenes.append(p.view.scene)
            l1[(length, m)] = np.asarray(score(preds, targets, masks)["l1"])
            line = f"length {length} {m}: l1 {l1[(length, m)].mean():.4f}"
            if (lengths[0], m) in l1 and length != lengths[0]:
                d = paired_bootstrap(l1[(length, m)], l1[(lengths[0], m)], groups=np.asarray(scenes), seed=0)
                line += f"  {d.diff:+.4f} [{d.lo:+.4f}, {d.hi:+.4f}]"
            print(line + f" ({len(pairs)} pairs)", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("what", choices=("rocket", "real", "synth"))
    ap.add_argument("root", nargs="?", default="data/val5_256")
    ap.add_argument("--length", type=float, nargs="+", default=[0.0, 0.02, 0.05])
    args = ap.parse_args()
    torch.set_num_threads(1)
    with torch.no_grad():
        if args.what == "synth":
            synth(args.root, args.length)
        else:
            {"rocket": rocket, "real": real}[args.what](args.length)


if __name__ == "__main__":
    main()
