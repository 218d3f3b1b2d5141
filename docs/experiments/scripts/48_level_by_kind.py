"""Study 48: on data/val5's cross pairs, the robust log2 gain (median log ratio over the foreground) that would
bring each `quotient` / `quotient_known` output to its target, by source and target lighting kind.

    .venv/bin/python docs/experiments/scripts/48_level_by_kind.py
"""
import sys, numpy as np, torch
from collections import defaultdict
from learned import Relighter
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.methods import build_methods
torch.set_num_threads(1)
r=Relighter.load(); M=build_methods(r)
views=load_dataset('data/val5', with_physical=False); pairs=cross_pairs(views)
rows=[]
for p in pairs:
    fg=p.foreground().expand(1,3,-1,-1)
    for m in ('quotient','quotient_known'):
        out=M[m](p); t=p.target_linear()
        x=out[fg]; y=t[fg]
        g=float(torch.exp(torch.median(torch.log(y.clamp_min(1e-6))-torch.log(x.clamp_min(1e-6)))))  # robust log gain
        rows.append((m, p.view.lights[p.source].kind, p.view.lights[p.target].kind, np.log2(g), p.view.scene))
for m in ('quotient','quotient_known'):
    R=[x for x in rows if x[0]==m]; v=np.array([x[3] for x in R])
    print(m, 'mean log2 gain needed %.2f, sd %.2f, mean abs %.2f'%(v.mean(), v.std(), np.abs(v).mean()))
    d=defaultdict(list)
    for _,s,t,l,_ in R: d[(s,t)].append(l)
    for k in sorted(d): print('  ', k, 'n=%d mean %.2f sd %.2f'%(len(d[k]), np.mean(d[k]), np.std(d[k])))
