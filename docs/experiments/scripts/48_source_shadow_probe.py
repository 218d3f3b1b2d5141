"""Study 48: the estimated track's `quotient` and `proposed` (the renderer on that quotient) with the decomposition's
source shadow divided out, floors and powers, on a synth folder's cross pairs.

    .venv/bin/python docs/experiments/scripts/48_source_shadow_probe.py data/val5
"""
import sys, numpy as np, torch
from learned import Relighter
from physrelight.exposure import exposure_scale
from learned.networks import repair_top_rows
from learned.neural_renderer import render_relit
from physrelight.quotient import SMOOTH_RADIUS, quotient_relight
from physrelight.stats import paired_bootstrap
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score
torch.set_num_threads(1); torch.set_grad_enabled(False)
r=Relighter.load()
views=load_dataset(sys.argv[1], with_physical=False); pairs=cross_pairs(views)
V={'none':None,'f0':(0.0,1.0),'f0.05':(0.05,1.0),'f0.2':(0.2,1.0),'f0_sqrt':(0.0,0.5),'f0.05_sqrt':(0.05,0.5)}
preds={(m,v):[] for m in ('quotient','proposed') for v in V}; tg=[]; ms=[]; sc=[]
cache={}
for p in pairs:
    image, sky = p.image(), p.sky()
    key=(p.view.name,p.source)
    if key not in cache: cache[key]=r.decompose_linear(image, sky)
    dec=cache[key]
    Ls,Lt=p.source_lighting(),p.target_lighting(); t_sun=p.sun_lighting(p.target)
    scale=exposure_scale(Lt,dec['lighting'],Ls,fallback=r.prior.mean.reshape(1,9,3))[:,None,None]
    tgt=Lt*scale
    s_t=repair_top_rows(r.shadow_net(dec['normals'], tgt))
    fg,t=p.foreground(),p.target_display()
    for v,par in V.items():
        sh=None if par is None else dec['shadow'].clamp(par[0],1.0)**par[1]
        q=quotient_relight(image,dec['normals'],dec['lighting'],tgt,mask=~sky,source_shadow=sh,target_sun=t_sun*scale,sun_cosine=True,smooth_radius=SMOOTH_RADIUS)
        pr=render_relit(r.renderer,image,sky,dec,tgt,s_t,quotient=q)
        for m,o in (('quotient',q),('proposed',pr)):
            preds[(m,v)].append(torch.where(fg,p.display(torch.where(sky,image,o.clamp_min(0)).float()),t))
    tg.append(t); ms.append(fg); sc.append(p.view.scene)
l1={k:np.asarray(score(x,tg,ms)['l1']) for k,x in preds.items()}
for m in ('quotient','proposed'):
    for v in V:
        d='' if v=='none' else ' %+.4f [%+.4f, %+.4f]'%tuple(paired_bootstrap(l1[(m,v)],l1[(m,'none')],groups=np.asarray(sc),seed=0)[:3])
        print(m, v, '%.4f'%l1[(m,v)].mean()+d, flush=True)
print('proposed none minus quotient f0:', paired_bootstrap(l1[('quotient','f0')],l1[('proposed','none')],groups=np.asarray(sc),seed=0))
