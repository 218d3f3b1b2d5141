"""Study 50 (exploration, training side): the smoothness test with each pixel's expected display-value noise
taken out of the log-luminance roughness (``SMOOTHNESS_NOISE_AWARE``), against the plain roughness, on the training crops (as is, 2 % noise, JPEG 50, the
lattice set), the indoor photos and rocket.jpg at 640, 320 and 160 px.

    .venv/bin/python docs/experiments/scripts/50_noise_aware_roughness_probe.py
"""
import sys, numpy as np, torch
sys.path.insert(0,'docs/experiments/scripts')
from real_crop_scores import bench_crops, crop_panoramas, score_mask_variants
import importlib
lattice=importlib.import_module('40_lattice_sky_probe')
from validation.bench.real_metrics import camera_variant
from learned import Relighter
import learned.sky_segmentation as ss
from physrelight import colour
torch.set_num_threads(2)
model=Relighter.load().sky_segmenter
def masks(lin):
    out={}
    for name,flag in (('today',False),('noise_aware',True)):
        ss.SMOOTHNESS_NOISE_AWARE=flag
        out[name]=ss.sky_mask_full_resolution(model, lin)[0][0,0].numpy()
    ss.SMOOTHNESS_NOISE_AWARE=True
    return out
for v in ('as is','noise 2 %','JPEG 50'):
    print('--',v, flush=True)
    score_mask_variants(lambda lin: masks(lin if v=='as is' else camera_variant(lin, v, seed=7)), ('today','noise_aware'), False, lattice.composite if v=='as is' else None)
import skimage.data as d
from PIL import Image
for n in ('astronaut','coffee','chelsea','camera'):
    im=getattr(d,n)();
    if im.ndim==2: im=np.stack([im]*3,-1)
    lin=colour.from_ldr(torch.from_numpy(im).permute(2,0,1)[None].float()/255)
    for v in ('as is','noise 2 %'):
        x=lin if v=='as is' else camera_variant(lin,v,seed=0)
        print(n, v, {k:round(float(m.mean()),3) for k,m in masks(x).items()})
im=d.stereo_motorcycle()[0]; lin=colour.from_ldr(torch.from_numpy(np.ascontiguousarray(im)).permute(2,0,1)[None].float()/255); print('motorcycle', {k:float(m.mean()) for k,m in masks(lin).items()})
p=d.rocket()
for size in (640,320,160):
    im=np.asarray(Image.fromarray(p).resize((size,int(size*427/640)), Image.LANCZOS)).copy()
    lin=colour.from_ldr(torch.from_numpy(im).permute(2,0,1)[None].float()/255)
    for v in ('as is','noise 2 %'):
        x=lin if v=='as is' else camera_variant(lin,v,seed=0)
        print('rocket',size,v,{k:round(float(m.mean()),3) for k,m in masks(x).items()})
