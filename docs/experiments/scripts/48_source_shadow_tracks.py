"""Study 48: `quotient` on both tracks with the decomposition's source shadow divided out (whole shading on the
estimated track, the sun's part on the known one), against none, on a synth folder's cross pairs.

    .venv/bin/python docs/experiments/scripts/48_source_shadow_tracks.py data/val5
"""
import sys, numpy as np, torch
from learned import Relighter
from physrelight.exposure import exposure_scale
from physrelight.quotient import SMOOTH_RADIUS, quotient_relight
from physrelight.stats import paired_bootstrap
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.scores import score
torch.set_num_threads(1)
r=Relighter.load()
views=load_dataset(sys.argv[1], with_physical=False); pairs=cross_pairs(views)
V=('none','src_shadow','src_shadow_sqrt')
preds={(t,v):[] for t in ('est','known') for v in V}; tg=[]; ms=[]; sc=[]
cache={}
for p in pairs:
    image, sky = p.image(), p.sky()
    key=(p.view.name,p.source)
    if key not in cache: cache[key]=r.decompose_linear(image, sky)
    dec=cache[key]
    Ls,Lt=p.source_lighting(),p.target_lighting(); s_sun,t_sun=p.sun_lighting(p.source),p.sun_lighting(p.target)
    scale=exposure_scale(Lt,dec['lighting'],Ls,fallback=r.prior.mean.reshape(1,9,3))[:,None,None]
    fg,t=p.foreground(),p.target_display()
    for v in V:
        sh=None if v=='none' else dec['shadow'].clamp(0.05,1.0)
        if v=='src_shadow_sqrt': sh=sh.sqrt()
        # estimated: the source shading is the decomposition's SH (no sun part): the shadow dims all of it
        out=quotient_relight(image,dec['normals'],dec['lighting'],Lt*scale,mask=~sky,source_shadow=sh,target_sun=t_sun*scale,sun_cosine=True,smooth_radius=SMOOTH_RADIUS)
        preds[('est',v)].append(torch.where(fg,p.display(torch.where(sky,image,out.clamp_min(0)).float()),t))
        out=quotient_relight(image,dec['normals'],Ls*scale,Lt*scale,mask=~sky,source_shadow=sh,source_sun=s_sun*scale,target_sun=t_sun*scale,sun_cosine=True,smooth_radius=SMOOTH_RADIUS)
        preds[('known',v)].append(torch.where(fg,p.display(torch.where(sky,image,out.clamp_min(0)).float()),t))
    tg.append(t); ms.append(fg); sc.append(p.view.scene)
l1={k:np.asarray(score(x,tg,ms)['l1']) for k,x in preds.items()}
for tr in ('est','known'):
    for v in V:
        d='' if v=='none' else ' %+.4f [%+.4f, %+.4f]'%tuple(paired_bootstrap(l1[(tr,v)],l1[(tr,'none')],groups=np.asarray(sc),seed=0)[:3])
        print(tr, v, '%.4f'%l1[(tr,v)].mean()+d, flush=True)
