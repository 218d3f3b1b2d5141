"""Study 39 diagnosis: on ``bench --real --full``'s training-side crops with sky, the self-relit level error of the
estimated-track ``quotient`` (log2 of relit over photo foreground mean luminance, the crop's level given) beside
``log2 g``, the grey world's reading (``Relighter.grey_world_gain``): their spreads and correlation.

    .venv/bin/python docs/experiments/scripts/39_level_real_diagnosis.py
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from real_crop_scores import bench_crops, crop_panoramas
from learned import Relighter
from physrelight import colour
torch.set_num_threads(1)
r=Relighter.load(); L=torch.tensor(colour.LUMINANCE)
_,panos=crop_panoramas(False)
rows=[]
for pano,crop in bench_crops(panos):
    if crop.stratum=="no_sky" or crop.sky.all(): continue
    lin=crop.linear(); fg=~torch.from_numpy(crop.sky)
    seg,_=r.photo_sky(lin)
    src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float()
    res=r.relight_full_resolution(lin,seg,src,source_lighting=src,method="quotient")
    w=res["working"]; img=res["working_image"]; sky=res["working_sky"]
    from physrelight.exposure import exposure_scale
    scale=exposure_scale(src[None] if src.ndim==2 else src, w["lighting"], src[None] if src.ndim==2 else src)[:,None,None]
    g=float(r.grey_world_gain(img,sky,w,scale)[0,0,0])
    lum=lambda x:(x[0]*L[:,None,None]).sum(0)[fg].mean()
    e0=float(torch.log2(lum(res["relit"])/lum(lin)))
    rows.append((pano.name,e0,np.log2(g)))
    print(pano.name, crop.index, f"e0 {e0:+.2f}  log2g {np.log2(g):+.2f}", flush=True)
a=np.array([(x[1],x[2]) for x in rows])
print("mean e0 %.2f sd %.2f | mean log2g %.2f sd %.2f | corr %.2f"%(a[:,0].mean(),a[:,0].std(),a[:,1].mean(),a[:,1].std(),np.corrcoef(a.T)[0,1]))
for n in ("city","courtyard","forest"):
    b=np.array([(x[1],x[2]) for x in rows if x[0]==n]); print(n, "e0 %.2f log2g %.2f"%tuple(b.mean(0)))
