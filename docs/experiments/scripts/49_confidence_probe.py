"""Study 49 addendum (exploration): the segmenter's mean probability over the top-touching sky at 128 px, on the
training crops under the strong warm cast and on scikit-image's indoor photos (a cue to relax the colour test?).

    .venv/bin/python docs/experiments/scripts/49_confidence_probe.py
"""
import sys, numpy as np, torch
sys.path.insert(0,'docs/experiments/scripts')
from real_crop_scores import bench_crops, crop_panoramas
import importlib; T=importlib.import_module('49_colour_threshold_probe')
from learned import Relighter
import learned.sky_segmentation as ss
from physrelight.full_resolution import resize_short_side
from physrelight import colour
import skimage.data as d
torch.set_num_threads(2)
model=Relighter.load().sky_segmenter
def conf(lin):
    small=resize_short_side(lin,128)
    with torch.no_grad(): p=torch.sigmoid(model(small))[0,0]
    m=p>0.5
    lab=ss.label_components(m); top=set(lab[0][lab[0]>0].tolist())
    if not top: return None
    tm=torch.isin(lab,torch.tensor(sorted(top)))
    ratio=small[0,2]/small[0,0].clamp_min(1e-4)
    return round(float(p[tm].mean()),3), round(float(tm.float().mean()),3), round(float(ratio[tm].median()),3)
_,panos=crop_panoramas(False)
vals=[]
for p_,c in bench_crops(panos):
    if c.sky.mean()<0.05: continue
    vals.append(conf(T.cast(c.linear(),(1.25,1.0,0.75))))
v=[x for x in vals if x]
print('warm training crops with sky>=5%: conf min/median', min(x[0] for x in v), np.median([x[0] for x in v]), 'n', len(v))
print(sorted(x[0] for x in v)[:8])
for n in ('astronaut','coffee','chelsea'):
    im=getattr(d,n)(); print(n, conf(colour.from_ldr(torch.from_numpy(im).permute(2,0,1)[None].float()/255)))
im=d.stereo_motorcycle()[0]; print('motorcycle', conf(colour.from_ldr(torch.from_numpy(np.ascontiguousarray(im)).permute(2,0,1)[None].float()/255)))
