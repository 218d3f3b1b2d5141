import sys, numpy as np, torch, time
sys.path.insert(0,'docs/experiments/scripts')
from real_crop_scores import score_mask_variants
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
    for name,flag in (('round1',False),('own_size',True)):
        ss.SMOOTHNESS_NOISE_AT_OWN_SIZE=flag
        out[name]=ss.sky_mask_full_resolution(model, lin)[0][0,0].numpy()
    ss.SMOOTHNESS_NOISE_AT_OWN_SIZE=True
    return out
import skimage.data as d
from PIL import Image
def noisy(photo,sigma,seed):
    rng=np.random.default_rng(seed); x=photo/255.0+sigma*rng.standard_normal(photo.shape)
    return (np.clip(x,0,1)*255+0.5).astype(np.uint8)
def lin(im): return colour.from_ldr(torch.from_numpy(np.ascontiguousarray(im)).permute(2,0,1)[None].float()/255)
for n,im in {'astronaut':d.astronaut(),'coffee':d.coffee(),'chelsea':d.chelsea(),'motorcycle':d.stereo_motorcycle()[0],'camera':np.stack([d.camera()]*3,-1)}.items():
    for sig,seed in ((0,0),(0.02,0),(0.02,1)):
        print(n,sig,seed,{k:round(float(m.mean()),3) for k,m in masks(lin(noisy(im,sig,seed) if sig else im)).items()},flush=True)
p=d.rocket()
for size in (640,320,160,120):
    im=np.asarray(Image.fromarray(p).resize((size,int(size*427/640)), Image.LANCZOS)).copy()
    for sig,seed in ((0,0),(0.02,0),(0.02,1),(0.01,0)):
        print('rocket',size,sig,seed,{k:round(float(m.mean()),3) for k,m in masks(lin(noisy(im,sig,seed) if sig else im)).items()},flush=True)
for v in ('as is','noise 2 %','JPEG 50'):
    print('--',v, flush=True)
    score_mask_variants(lambda x: masks(x if v=='as is' else camera_variant(x, v, seed=7)), ('round1','own_size'), False, lattice.composite if v=='as is' else None)
