"""Study 49 addendum (exploration): the sky's smoothness test on roughness in excess of the photo's noise floor
(``physrelight.denoise.noise_sigma`` of the log luminance), on the training crops as is and with 2 % noise, the
indoor photos and rocket.jpg at 640 and 160 px; the last part prints the figures of the 160-px noisy rocket.

    .venv/bin/python docs/experiments/scripts/49_noise_floor_roughness_probe.py
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
from physrelight.denoise import noise_sigma
torch.set_num_threads(2)
model=Relighter.load().sky_segmenter
_R=ss._roughness
def excess(lum):
    r=_R(lum)
    ly=torch.log(lum.clamp_min(1e-4))[None,None]
    s=float(noise_sigma(ly)[0,0])
    return (r*r - s*s*8/9).clamp_min(0).sqrt()
def masks(lin, variant_seed=0):
    out={}
    for name,f in (('today',_R),('excess',excess)):
        ss._roughness=f
        out[name]=ss.sky_mask_full_resolution(model, lin)[0][0,0].numpy()
    ss._roughness=_R
    return out
for v in ('as is','noise 2 %'):
    print('--',v)
    score_mask_variants(lambda lin: masks(lin if v=='as is' else camera_variant(lin, v, seed=7)), ('today','excess'), False, lattice.composite if v=='as is' else None)
import skimage.data as d
from PIL import Image
for n in ('astronaut','coffee','chelsea'):
    im=getattr(d,n)(); lin=colour.from_ldr(torch.from_numpy(im).permute(2,0,1)[None].float()/255)
    print(n, {k:float(m.mean()) for k,m in masks(lin).items()})
im=d.stereo_motorcycle()[0]; lin=colour.from_ldr(torch.from_numpy(np.ascontiguousarray(im)).permute(2,0,1)[None].float()/255); print('motorcycle', {k:float(m.mean()) for k,m in masks(lin).items()})
p=d.rocket()
for size in (640,160):
    im=np.asarray(Image.fromarray(p).resize((size,int(size*427/640)), Image.LANCZOS)).copy()
    lin=colour.from_ldr(torch.from_numpy(im).permute(2,0,1)[None].float()/255)
    for v in ('as is','noise 2 %'):
        x=lin if v=='as is' else camera_variant(lin,v,seed=0)
        print('rocket',size,v,{k:round(float(m.mean()),3) for k,m in masks(x).items()})
print('debug')
orig=ss.plausible_sky
def spy(mask,image):
    lum=(image*image.new_tensor(ss._LUMA)[:,None,None]).sum(0)
    r=_R(lum); ly=torch.log(lum.clamp_min(1e-4))[None,None]; s=float(noise_sigma(ly)[0,0])
    print('sigma_log floor %.4f'%s, 'median r sky %.4f fg %.4f'%(float(r[mask].median()), float(r[~mask].median())), 'shape', tuple(image.shape))
    return orig(mask,image)
ss.plausible_sky=spy
im=np.asarray(Image.fromarray(p).resize((160,107), Image.LANCZOS)).copy()
lin=colour.from_ldr(torch.from_numpy(im).permute(2,0,1)[None].float()/255)
ss.sky_mask_full_resolution(model, camera_variant(lin,'noise 2 %',seed=0))
