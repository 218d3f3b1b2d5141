"""Study 42 probe: depth from a ground plane with objects standing on it, for screen-space sun shadows.

Study 25 found the single-image depth (log depth integrated from the decomposition's normals) too poor at
occlusion boundaries for sun shadows: an object integrated together with the ground behind it casts its shadow
at the wrong depth. Outdoor scenes have a ground; this probe builds depth from that physical prior:

* the ground: foreground pixels whose normal is within ``acos(ground_cos)`` of the world's up and that lie
  below the horizon, in connected parts that touch the image's bottom row (roofs and treads are not ground);
  its depth is the plane's, ``z = 1 / -(ray . up)`` (the camera height is the free scale);
* everything else: log depth integrated from the normals (study 25's least squares), with the ground fixed,
  no edge between an object and the ground above or beside it (the object occludes that ground: a jump),
  and an edge where an object pixel stands directly on a ground pixel (the contact: continuous);
* a weak pull towards a "billboard" depth (each pixel at the depth of the first ground pixel below it in its
  column) anchors parts with no contact.

Scored as study 25 (``screen_space_shadow_study.py``): shadow AP against ``shadow.exr < 0.5`` over the
foreground pixels, and the relit l1 of the known-source quotient with sun-only shadows, on data/val5 here.

Run: ``.venv/bin/python docs/experiments/scripts/42_ground_depth_probe.py data/val5``
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from scipy import ndimage

sys.path.insert(0, str(Path(__file__).resolve().parent))
from screen_space_shadow_study import Photos, ap_table, relit_l1  # noqa: E402

from learned import Relighter  # noqa: E402
from physrelight.normal_integration import _cg, _edges, _rhs, log_depth_gradients  # noqa: E402


def pixel_rays(K: torch.Tensor, h: int, w: int, dtype=torch.float64) -> torch.Tensor:
    """``(1, 3, H, W)`` camera-frame rays with z-depth 1 (x right, y up, z towards the viewer)."""
    v, u = torch.meshgrid(torch.arange(h, dtype=dtype) + 0.5, torch.arange(w, dtype=dtype) + 0.5, indexing="ij")
    rx, ry = (u - K[0, 2]) / K[0, 0], (v - K[1, 2]) / K[1, 1]
    return torch.stack([rx, -ry, -torch.ones_like(rx)])[None]


def ground_mask(normals: torch.Tensor, rays: torch.Tensor, mask: torch.Tensor, up: torch.Tensor,
                ground_cos: float, min_share: float = 0.2) -> torch.Tensor:
    """``(1, 1, H, W)`` bool: the ground (see the module doc)."""
    n = F.normalize(normals, dim=1)
    upr = up.reshape(1, 3, 1, 1).to(n.dtype)
    flat = mask & ((n * upr).sum(1, keepdim=True) > ground_cos) & ((rays * upr).sum(1, keepdim=True) < -1e-3)
    lab, k = ndimage.label(flat[0, 0].numpy())
    if k == 0:
        return flat
    sizes = np.bincount(lab.ravel())[1:]
    bottom = set(np.unique(lab[-1])) - {0}
    keep = [i + 1 for i in range(k) if (i + 1) in bottom or sizes[i] >= min_share * sizes.sum()]
    return torch.from_numpy(np.isin(lab, keep))[None, None] & flat


def ground_depth(normals: torch.Tensor, K: torch.Tensor, mask: torch.Tensor, up: torch.Tensor, *,
                 ground_cos: float = 0.9, min_cos: float = 0.003, pull: float = 1e-3, contact: bool = True,
                 integrate: bool = True, iters: int = 3000, tol: float = 1e-8) -> torch.Tensor:
    """``(1, 1, H, W)`` z-depth up to scale (the camera's height above the ground = 1)."""
    normals = normals.double()
    h, w = normals.shape[-2:]
    rays = pixel_rays(K.double(), h, w)
    upr = (up / up.norm()).double()
    g = ground_mask(normals, rays, mask, upr, ground_cos)
    if not bool(g.any()):
        return torch.zeros(1, 1, h, w, dtype=torch.float64)
    dot = (rays * upr.reshape(1, 3, 1, 1)).sum(1, keepdim=True)
    zeta_plane = torch.where(g, torch.log(1.0 / (-dot).clamp_min(1e-6)), torch.zeros_like(dot))
    # Billboard: the first ground pixel at or below each pixel in its column.
    fallback = float(zeta_plane[g].median())
    bill = torch.full_like(zeta_plane, fallback)
    carry = torch.full((w,), fallback, dtype=torch.float64)
    seen = torch.zeros(w, dtype=torch.bool)
    for row in range(h - 1, -1, -1):
        gr = g[0, 0, row]
        carry = torch.where(gr, zeta_plane[0, 0, row], carry)
        seen |= gr
        bill[0, 0, row] = carry
    if not integrate:
        zeta = torch.where(g, zeta_plane, bill)
        return torch.where(mask, torch.exp(zeta), torch.zeros_like(zeta))
    p, q, conf = log_depth_gradients(normals, K.double()[None], min_cos)
    gx, wx, gy, wy = _edges(p, q, conf, mask)
    wx = wx * (g[..., 1:] == g[..., :-1])
    top, bot = g[..., :-1, :], g[..., 1:, :]
    keep_y = (top == bot) | ((~top & bot) if contact else torch.zeros_like(top))
    wy = wy * keep_y
    scale = torch.cat([wx.flatten(1), wy.flatten(1)], 1).mean().clamp_min(1e-12)
    rho = torch.where(g, 1e3 * scale, pull * scale) * mask + (~mask) * scale
    target = torch.where(g, zeta_plane, bill) * mask
    rhs = _rhs(gx, wx, gy, wy) + rho * target
    zeta = _cg(wx, wy, rhs, rho, target.clone(), iters, tol)
    return torch.where(mask, torch.exp(zeta), torch.zeros_like(zeta))


class GroundPhotos(Photos):
    """Study 25's cache with two more depth sources: ``ground_est`` (the decomposition's normals) and
    ``ground_true`` (the true normals; the model's ceiling). ``min_cos`` of a setting carries the variant."""

    variants: dict = {}

    def view(self, v) -> dict:
        vd = super().view(v)
        if "up" not in vd:
            d = self.ds.load(v.scene, v.view, None, keys=("world_to_camera",))
            vd["up"] = torch.from_numpy(d["world_to_camera"][:3, :3] @ np.array([0.0, 1.0, 0.0]))
        return vd

    def depth(self, v, source: str, min_cos, light: int):
        if not source.startswith("ground"):
            return super().depth(v, source, min_cos, light)
        vd = self.view(v)
        key = (v.name, source, min_cos, light if source == "ground_est" else -1)
        if source == "ground_true":
            normals, mask = vd["normal"], vd["fg"]
        else:
            ph = self.photo(v, light)
            normals, mask = ph["normals"], ~ph["sky"]
        if key not in self._depth:
            t0 = time.perf_counter()
            self._depth[key] = ground_depth(normals, vd["K"], mask, vd["up"], **self.variants[min_cos])
            self.seconds_integration.append(time.perf_counter() - t0)
        return self._depth[key], normals, mask

    def visibility(self, v, light, source, setting, photo_light):
        if not source.startswith("ground"):
            return super().visibility(v, light, source, setting, photo_light)
        return self._vis_ground(v, light, source, setting, photo_light if source == "ground_est" else -1)

    def _vis_ground(self, v, light, source, setting, photo_light):
        from physrelight.screen_space_shadow import sun_visibility
        steps, thickness, min_cos = setting
        sun = self.view(v)["suns"][light]
        if sun is None:
            return torch.ones_like(self.view(v)["depth"])
        key = (v.name, light, source, setting, photo_light)
        if key not in self._vis:
            depth, normals, mask = self.depth(v, source, min_cos, photo_light)
            self._vis[key] = sun_visibility(depth, self.view(v)["K"], sun, mask=mask, normals=normals, steps=steps,
                                            thickness=thickness)
        return self._vis[key]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("root", nargs="?", default="data/val5")
    ap.add_argument("--l1", action="store_true", help="also the relit l1 (slower)")
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    torch.set_num_threads(1)
    GroundPhotos.variants = {
        "g0.95": dict(ground_cos=0.95), "g0.9": dict(ground_cos=0.9), "g0.8": dict(ground_cos=0.8),
        "g0.9_nocontact": dict(ground_cos=0.9, contact=False), "g0.9_billboard": dict(ground_cos=0.9, integrate=False),
    }
    P = GroundPhotos(args.root, Relighter.load())
    out = {}
    t0 = time.time()
    with torch.no_grad():
        for th in (0.1, 0.2):
            settings = {"est_normals_depth": (64, th, 0.003)}
            for name in GroundPhotos.variants:
                settings[f"ground_est@{name}"] = (64, th, name)
            # Photos' ap_table keys sources by name: map them back for the cache.
            res = {}
            for key, (steps, t, mc) in settings.items():
                src = key.split("@")[0]
                res[key] = ap_table(P, {src: (steps, t, mc)})[src]["ap_all"]
            chance = ap_table(P, {})["positive_rate_all"]
            out[f"thickness {th}"] = {"chance": chance, **res}
            print(th, f"chance {chance:.3f}", {k: round(x, 3) for k, x in res.items()}, f"{time.time() - t0:.0f}s",
                  flush=True)
        for name in ("g0.9",):
            r = ap_table(P, {"ground_true": (64, 0.1, name)})["ground_true"]["ap_all"]
            out[f"ground_true@{name}"] = r
            print("ground_true", name, round(r, 3), flush=True)
        if args.l1:
            l1 = relit_l1(P, {"ground_est": (64, 0.1, "g0.9"), "est_normals_depth": (64, 0.1, 0.003)},
                          with_shadownet=False)
            out["l1"] = l1
            print(json.dumps(l1["mean_l1"], indent=1), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
