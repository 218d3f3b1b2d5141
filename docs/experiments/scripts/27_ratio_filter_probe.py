"""Study 27: the known-source quotient with its log ratio smoothed by a guided filter (guide: the photo's log luminance).

Run: ``.venv/bin/python docs/experiments/scripts/27_ratio_filter_probe.py data/val5`` (the grid; chosen there)
and ``... data/heldout confirm`` (only the chosen setting, radius 3, eps 1e-3, against none). 1 thread.
"""
import numpy as np, torch, sys, json
from learned import Relighter
from physrelight.quotient import quotient_ratio
from physrelight.guided_filter import guided_filter
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score
from physrelight.stats import paired_bootstrap
torch.set_num_threads(1)
R = Relighter.load()
views = load_dataset(sys.argv[1], with_physical=False)
pairs = cross_pairs(views)
settings = [(0, 0)] + [(r, e) for r in (1, 2, 3) for e in (1e-3, 1e-2, 1e-1)]
if sys.argv[2:] == ['confirm']:
    settings = [(0, 0), (3, 1e-3)]
preds = {s: [] for s in settings}; T, M, G = [], [], []
dec = {}
with torch.no_grad():
  for p in pairs:
    img, sky = p.image(), p.sky()
    k = (p.view.name, p.source)
    if k not in dec: dec[k] = R.decompose_linear(img, sky)["normals"]
    n = dec[k]
    ratio = quotient_ratio(n, p.source_lighting(), p.target_lighting(), mask=~sky,
                           source_sun=p.sun_lighting(p.source), target_sun=p.sun_lighting(p.target), sun_cosine=True)
    lr = torch.log(ratio)
    guide = torch.log((img * torch.tensor([0.2126, 0.7152, 0.0722]).view(1, 3, 1, 1)).sum(1, keepdim=True).clamp_min(1e-4))
    fg, tgt = p.foreground(), p.target_display()
    for (r, e) in settings:
        x = lr if r == 0 else guided_filter(guide, lr, r, e)
        relit = torch.where(sky, img, img * torch.exp(x))
        preds[(r, e)].append(torch.where(fg, p.display(relit), tgt))
    T.append(tgt); M.append(fg); G.append(p.view.scene)
l1 = {s: score(x, T, M, which=("l1",))["l1"] for s, x in preds.items()}
for s, x in l1.items():
    d = paired_bootstrap(x, l1[(0, 0)], groups=np.array(G), seed=0)
    print(s, round(float(x.mean()), 5), d)
