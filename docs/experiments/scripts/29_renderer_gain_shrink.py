"""Study 29 addendum: the renderer's gain shrunk, ``relit = quotient * (proposed / quotient) ** beta``, on the bench's
cross pairs of a synth folder (l1) and on the real training crops' self-relighting (PSNR dB, ``bench --real`` (d)).

    .venv/bin/python docs/experiments/scripts/29_renderer_gain_shrink.py synth data/val5
    .venv/bin/python docs/experiments/scripts/29_renderer_gain_shrink.py real
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from learned import Relighter
from validation.bench.data import load_dataset
from validation.bench.protocols import cross_pairs
from validation.bench.methods import build_methods, to_chw
from validation.bench.scores import score
from physrelight import colour
torch.set_num_threads(1)
r=Relighter.load()
B=(0.0,0.25,0.5,0.75,1.0)
def mix(q,p,b):
    g=(p.clamp_min(1e-8)/q.clamp_min(1e-8))
    return torch.where(q>0, q*g**b, p)
if sys.argv[1]=='synth':
    views=load_dataset(sys.argv[2], with_physical=False); pairs=cross_pairs(views); M=build_methods(r)
    preds={b:[] for b in B}; tg=[]; ms=[]
    for p in pairs:
        q=M['quotient'](p); pr=M['proposed'](p); fg,t=p.foreground(),p.target_display()
        for b in B: preds[b].append(torch.where(fg,p.display(mix(q,pr,b).float()),t))
        tg.append(t); ms.append(fg)
    for b in B: print('synth beta',b, round(float(np.mean(score(preds[b],tg,ms)['l1'])),4), flush=True)
else:
    from real_crop_scores import bench_crops, crop_panoramas
    _,panos=crop_panoramas(False)
    crops=[(p,c) for p,c in bench_crops(panos) if c.stratum!="no_sky" and not c.sky.all()]
    out={b:[] for b in B}
    for pano,crop in crops:
        lin=crop.linear(); fg=~torch.from_numpy(crop.sky)[None,None]
        seg,_=r.photo_sky(lin); src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float(); photo=to_chw(crop.display())
        q=r.relight_full_resolution(lin,seg,src,source_lighting=src,method='quotient')['relit']
        pr=r.relight_full_resolution(lin,seg,src,source_lighting=src,method='proposed')['relit']
        for b in B:
            pred=torch.where(fg,colour.to_ldr(mix(q,pr,b).clamp_min(0)),photo)
            out[b].append(min(float(score([pred],[photo],[fg],which=("psnr",))["psnr"][0]),58.9))
    for b in B: print('real beta',b, round(float(np.mean(out[b])),3), flush=True)
