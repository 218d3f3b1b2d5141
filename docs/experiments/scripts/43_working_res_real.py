"""Study 43 side probe: the real training crops' self-relighting (``bench --real`` (d), PSNR dB) with the
decomposition run at a working short side of 64 (shipped), 96 or 128 px.

    .venv/bin/python docs/experiments/scripts/43_working_res_real.py
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from real_crop_scores import bench_crops, crop_panoramas
from learned import Relighter
from physrelight import colour
from validation.bench.methods import to_chw
from validation.bench.scores import score
torch.set_num_threads(1)
r=Relighter.load()
_,panos=crop_panoramas(False)
crops=[(p,c) for p,c in bench_crops(panos) if c.stratum!="no_sky" and not c.sky.all()]
for res in (64, 96, 128):
    out={m:[] for m in ("quotient","proposed")}
    for pano,crop in crops:
        lin=crop.linear(); fg=~torch.from_numpy(crop.sky)[None,None]
        seg,_=r.photo_sky(lin)
        src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float()
        photo=to_chw(crop.display())
        for m in out:
            relit=r.relight_full_resolution(lin,seg,src,source_lighting=src,method=m,working_res=res)["relit"]
            pred=torch.where(fg,colour.to_ldr(relit.clamp_min(0)),photo)
            out[m].append(min(float(score([pred],[photo],[fg],which=("psnr",))["psnr"][0]),58.9))
    print(res, {m:round(float(np.mean(v)),3) for m,v in out.items()}, flush=True)
