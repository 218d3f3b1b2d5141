"""Study 29 addendum: the shipped renderer's gain over ``quotient`` on the bench's cross pairs, split by the source
photo's response curve (filmic, gamma 2.2, sRGB), scene-bootstrap intervals.

    .venv/bin/python docs/experiments/scripts/29_renderer_by_curve.py data/val5
    .venv/bin/python docs/experiments/scripts/29_renderer_by_curve.py data/heldout
"""
import sys, numpy as np, torch
from learned import Relighter
from validation.bench.data import load_dataset
from validation.bench.methods import build_methods
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score
from physrelight.stats import paired_bootstrap
torch.set_num_threads(1)
views=load_dataset(sys.argv[1], with_physical=False); pairs=cross_pairs(views)
ms=build_methods(Relighter.load())
l1={}
for name in ("proposed","quotient"):
    P,T,M=[],[],[]
    for p in pairs:
        fg,tgt=p.foreground(),p.target_display()
        P.append(torch.where(fg,p.display(ms[name](p)),tgt)); T.append(tgt); M.append(fg)
    l1[name]=score(P,T,M,which=("l1",))["l1"]
curve=np.asarray([p.view.photo_params[p.source]["curve"] for p in pairs]); scene=np.asarray([p.view.scene for p in pairs])
for c in sorted(set(curve)):
    k=curve==c
    d=paired_bootstrap(l1["proposed"][k], l1["quotient"][k], groups=scene[k], seed=0)
    print(f"{c:>10} ({k.sum()} pairs): quotient {l1['quotient'][k].mean():.4f} proposed {l1['proposed'][k].mean():.4f}  diff {d.diff:+.4f} [{d.lo:+.4f}, {d.hi:+.4f}]")
