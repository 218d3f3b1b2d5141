"""Study 48: `bench --real` (d)'s self-relighting of the training crops with sky (`heldout`: sunrise's, not run),
`quotient` and `proposed` with and without the decomposition's source shadow divided out, through a replica of the
shipped path (working resolution, ratio transfer).

    .venv/bin/python docs/experiments/scripts/48_source_shadow_real.py
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from real_crop_scores import bench_crops, crop_panoramas
from learned import Relighter
from physrelight.exposure import exposure_scale
from physrelight.full_resolution import transfer_to_full_resolution, working_resolution
from learned.networks import repair_top_rows
from learned.neural_renderer import render_relit
from physrelight import colour
from physrelight.quotient import SMOOTH_RADIUS, quotient_relight
from validation.bench.methods import to_chw
from validation.bench.scores import score
torch.set_num_threads(1); torch.set_grad_enabled(False)
r=Relighter.load()
heldout = len(sys.argv)>1 and sys.argv[1]=='heldout'
_,panos=crop_panoramas(heldout)
crops=[(p,c) for p,c in bench_crops(panos) if c.stratum!="no_sky" and not c.sky.all()]
res={(m,v):[] for m in ('quotient','proposed') for v in ('none','src')}
for pano,crop in crops:
    lin=crop.linear(); fg=~torch.from_numpy(crop.sky)[None,None]
    seg,_=r.photo_sky(lin); src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float(); photo=to_chw(crop.display())
    clean=r.denoised(lin); small, small_sky = working_resolution(clean, seg, r.res)
    dec=r.decompose_linear(small, small_sky)
    scale=exposure_scale(src[None],dec['lighting'],src[None],fallback=r.prior.mean.reshape(1,9,3))[:,None,None]
    tgt=src[None]*scale; s_t=repair_top_rows(r.shadow_net(dec['normals'], tgt))
    for v in ('none','src'):
        sh=None if v=='none' else dec['shadow'].clamp(0,1)
        q=quotient_relight(small,dec['normals'],dec['lighting'],tgt,mask=~small_sky,source_shadow=sh,smooth_radius=SMOOTH_RADIUS)
        pr=render_relit(r.renderer,small,small_sky,dec,tgt,s_t,quotient=q)
        for m,o in (('quotient',q),('proposed',pr)):
            o=torch.where(small_sky, small, o.clamp_min(0))
            full=torch.where(seg, lin, transfer_to_full_resolution(clean, small, o))
            pred=torch.where(fg,colour.to_ldr(full.clamp_min(0)),photo)
            res[(m,v)].append(min(float(score([pred],[photo],[fg],which=("psnr",))["psnr"][0]),58.9))
for k,v in res.items(): print(k, round(float(np.mean(v)),3), len(v))
