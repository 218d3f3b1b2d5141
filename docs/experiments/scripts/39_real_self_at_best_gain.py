"""Study 39 addendum: self-relighting of ``bench --real --full``'s training-side crops (with sky) on the estimated
track, PSNR as ``bench --real`` (d) computes it and after the output's best single gain (least squares in linear,
then a 0.05-stop search of +-2 stops): how much of the error is the relit level.

    .venv/bin/python docs/experiments/scripts/39_real_self_at_best_gain.py
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from real_crop_scores import bench_crops, crop_panoramas
from learned import Relighter
from physrelight import colour, metrics
from validation.bench.methods import to_chw
from validation.bench.scores import score
torch.set_num_threads(1)
r=Relighter.load()
_,panos=crop_panoramas(False)
res={m:{"abs":[], "gain":[]} for m in ("quotient","proposed")}
for pano,crop in bench_crops(panos):
    if crop.stratum=="no_sky" or crop.sky.all(): continue
    lin=crop.linear(); fg=~torch.from_numpy(crop.sky)[None,None]
    seg,_=r.photo_sky(lin)
    src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float()
    photo=to_chw(crop.display())
    for m in res:
        relit=r.relight_full_resolution(lin,seg,src,source_lighting=src,method=m)["relit"]
        pred=torch.where(fg,colour.to_ldr(relit.clamp_min(0)),photo)
        res[m]["abs"].append(min(float(score([pred],[photo],[fg],which=("psnr",))["psnr"][0]),58.9))
        # best single gain in linear (least squares on fg), then display
        x=relit[fg.expand_as(relit)]; y=lin[fg.expand_as(lin)]
        g=float((x*y).sum()/(x*x).sum())
        best=None
        for t in np.linspace(-2,2,81):
            pr=torch.where(fg,colour.to_ldr((relit*g*2**t).clamp_min(0)),photo)
            p=float(score([pr],[photo],[fg],which=("psnr",))["psnr"][0])
            best=p if best is None or p>best else best
        res[m]["gain"].append(min(best,58.9))
for m,v in res.items(): print(m, "PSNR %.2f, at best gain %.2f (n=%d)"%(np.mean(v["abs"]),np.mean(v["gain"]),len(v["abs"])))
