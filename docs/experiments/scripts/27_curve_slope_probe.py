"""Study 27: can a photo's response curve be told from the photo and its shading? The robust (Cauchy) slope of
log luminance linearised by each candidate curve against log shading (known source SH, or the decomposition's
estimate, on the decomposition's normals): the right curve should give slope 1 if albedo is independent of shading.

Run: ``.venv/bin/python docs/experiments/scripts/27_curve_slope_probe.py data/val5`` (1 thread).
"""
import numpy as np, torch, sys
from learned import Relighter
from physrelight import colour, image_model
from validation.bench.data import load_dataset
from validation.bench.methods import to_chw
from synth.photo import photo_gain
torch.set_num_threads(1)
R = Relighter.load()
views = load_dataset(sys.argv[1], with_physical=False)
rows = []
with torch.no_grad():
  for v in views:
    sky = torch.from_numpy(v.sky)[None, None]
    for a in range(v.num_lights):
        disp = to_chw(v.photo[a]).clamp(0, 1)
        img = colour.from_ldr(disp)
        out = R.decompose_linear(img, sky)
        g = photo_gain(v.photo_params[a])
        L = torch.from_numpy((v.sh[a] * g).astype(np.float32))[None]
        Ls = torch.from_numpy((v.sun_sh[a] * g).astype(np.float32))[None]
        for track, n, Lx, sun in (("known", out["normals"], L, Ls), ("est", out["normals"], out["lighting"], None)):
            if sun is not None:
                S = image_model.shading(n, Lx - sun) + image_model.sun_shading(n, sun)
            else:
                S = image_model.shading(n, Lx)
            S = S.clamp_min(0)
            Y = lambda x: (x * torch.tensor([0.2126, 0.7152, 0.0722]).view(1, 3, 1, 1)).sum(1)
            fg = (~sky[:, 0]) & (disp.max(1).values < 0.98) & (disp.max(1).values > 0.02)
            sy = Y(S)
            fg &= sy > 0.05 * sy[~sky[:, 0]].mean()
            x = torch.log(sy[fg]).double().numpy()
            res = {}
            for c in ("srgb", "gamma2.2", "filmic"):
                lin = colour.from_ldr(disp.clamp_max(1.0), c)
                y = torch.log(Y(lin)[fg].clamp_min(1e-6)).double().numpy()
                w = np.ones_like(x)
                for _ in range(5):
                    A = np.stack([x, np.ones_like(x)], 1)
                    coef = np.linalg.lstsq(A * w[:, None] ** .5, y * w ** .5, rcond=None)[0]
                    r = y - A @ coef
                    s = 1.4826 * np.median(np.abs(r - np.median(r))) + 1e-9
                    w = 1.0 / (1.0 + (r / (2 * s)) ** 2)
                res[c] = coef[0]
            rows.append((v.photo_params[a]["curve"], track, res["srgb"], res["gamma2.2"], res["filmic"], x.std()))
import collections
for track in ("known", "est"):
    for c in ("srgb", "gamma2.2", "filmic"):
        r = np.array([x[2:] for x in rows if x[0] == c and x[1] == track])
        print(track, c, len(r), "slopes srgb/g22/filmic median", np.median(r[:, :3], 0).round(3), "q25", np.quantile(r[:, 0], .25).round(3), "q75", np.quantile(r[:, 0], .75).round(3))
    # classify: pick curve with slope closest to 1
    acc = collections.Counter()
    for x in rows:
        if x[1] != track: continue
        s = dict(zip(("srgb", "gamma2.2", "filmic"), x[2:5]))
        pick = min(("srgb", "filmic"), key=lambda c: abs(s[c] - 1))
        acc[(x[0], pick)] += 1
    print(track, dict(acc))
