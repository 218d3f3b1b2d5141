"""Study 27: the known-source quotient with each shading replaced by its expectation under a von Mises-Fisher
spread of the normal around the decomposition's (concentration kappa): SH bands attenuated by
A1 = coth k - 1/k, A2 = 1 - 3 A1 / k, and the sun's clamped cosine by its Gaussian-smoothed expectation.

Run: ``.venv/bin/python docs/experiments/scripts/27_normal_uncertainty_probe.py data/val5`` (1 thread).
"""
import numpy as np, torch, sys, math
from learned import Relighter
from physrelight import image_model, sh
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score
from physrelight.stats import paired_bootstrap
torch.set_num_threads(1)
R = Relighter.load()
views = load_dataset(sys.argv[1], with_physical=False)
pairs = cross_pairs(views)
KAPPAS = [math.inf, 64, 32, 16, 8, 4]
def atten(k):
    if k == math.inf: return 1.0, 1.0
    a1 = 1 / math.tanh(k) - 1 / k
    return a1, 1 - 3 * a1 / k
def shaded(n, L, sun, k):
    a1, a2 = atten(k)
    w = torch.tensor([1] + [a1] * 3 + [a2] * 5, dtype=L.dtype).view(1, 9, 1)
    sky = image_model.shading(n, (L - sun) * w)
    d, e = sh.sun_of(sun)
    x = torch.einsum("bchw,bc->bhw", n, d)[:, None]
    if k == math.inf:
        c = x.clamp_min(0)
    else:
        m = a1 * x; s = ((1 - x * x).clamp_min(0) / k).sqrt().clamp_min(1e-4)
        z = m / s
        c = s * torch.exp(-0.5 * z * z) / math.sqrt(2 * math.pi) + m * 0.5 * (1 + torch.erf(z / math.sqrt(2)))
    valid = (n.norm(dim=1, keepdim=True) > 0.5).to(n.dtype)
    return (sky + c * e[:, :, None, None] / math.pi * valid).clamp_min(0)
preds = {k: [] for k in KAPPAS}; T, M, G = [], [], []
dec = {}
with torch.no_grad():
  for p in pairs:
    img, sky = p.image(), p.sky()
    key = (p.view.name, p.source)
    if key not in dec: dec[key] = R.decompose_linear(img, sky)["normals"]
    n = dec[key]
    fg, tgt = p.foreground(), p.target_display()
    m = (~sky).float()
    for k in KAPPAS:
        ss = shaded(n, p.source_lighting(), p.sun_lighting(p.source), k)
        st = shaded(n, p.target_lighting(), p.sun_lighting(p.target), k)
        g = 0.05 * (ss * m).sum((2, 3), keepdim=True) / m.sum().clamp_min(1)
        relit = torch.where(sky, img, img * (st + g) / (ss + g))
        preds[k].append(torch.where(fg, p.display(relit), tgt))
    T.append(tgt); M.append(fg); G.append(p.view.scene)
l1 = {s: score(x, T, M, which=("l1",))["l1"] for s, x in preds.items()}
for s, x in l1.items():
    d = paired_bootstrap(x, l1[math.inf], groups=np.array(G), seed=0)
    print(s, round(float(x.mean()), 5), round(d.diff, 5), round(d.lo, 5), round(d.hi, 5))
