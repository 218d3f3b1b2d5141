"""Study 39 addendum (exploration, a lead, nothing chosen): the estimated track's relit level error beside cheap
features of the decomposition, on a synth folder's cross pairs (every other one; the error against the path-traced
target) or on ``bench --real``'s training-side crops (``real``: self-relighting, the error against the photo).
Features: log2 of the grey world's reading, the estimate's directionality |L1| / L0 (luminance), the mean of the
decomposition's source shadow on the foreground, the shading's coefficient of variation, the photo's log-luminance
spread.

    .venv/bin/python docs/experiments/scripts/39_level_features.py data/val5
    .venv/bin/python docs/experiments/scripts/39_level_features.py real
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from learned import Relighter
from physrelight.exposure import exposure_scale
from physrelight import colour, image_model
torch.set_num_threads(1)
r=Relighter.load(); L=torch.tensor(colour.LUMINANCE)
lum=lambda x,m:(x[0]*L[:,None,None]).sum(0)[m].mean()
def feats(small, ssky, dec, src):
    fg=~ssky[0,0]
    scale=exposure_scale(src[None], dec["lighting"], src[None])[:,None,None]
    g=float(r.grey_world_gain(small, ssky, dec, scale)[0,0,0])
    Ls=dec["lighting"][0]
    dirn=float((Ls[1:4]*L[None,:]).sum(1).norm()/ (Ls[0]*L).sum())
    shadow=float(dec["shadow"][0,0][fg].mean())
    S=image_model.shading(dec["normals"], dec["lighting"])
    Sl=(S[0]*L[:,None,None]).sum(0)[fg]
    contrast=float(Sl.std()/Sl.mean())
    y=(small[0]*L[:,None,None]).sum(0)[fg].clamp_min(1e-4)
    pc=float(torch.log(y).std())
    return [np.log2(g), dirn, shadow, contrast, pc]
names=["log2g","dirn","shadow_mean","shading_cv","photo_logstd"]
mode=sys.argv[1]
E,X=[],[]
if mode=="real":
    from real_crop_scores import bench_crops, crop_panoramas
    from physrelight.full_resolution import working_resolution
    _,panos=crop_panoramas(False)
    for pano,crop in bench_crops(panos):
        if crop.stratum=="no_sky" or crop.sky.all(): continue
        lin=crop.linear(); seg,_=r.photo_sky(lin); fg=~torch.from_numpy(crop.sky)
        src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float()
        res=r.relight_full_resolution(lin,seg,src,source_lighting=src,method="quotient")
        E.append(float(torch.log2(lum(res["relit"],fg)/lum(lin,fg))))
        X.append(feats(res["working_image"],res["working_sky"],res["working"],src))
else:
    from validation.bench.data import load_dataset
    from validation.bench.protocols import cross_pairs
    views=load_dataset(mode, with_physical=False); pairs=cross_pairs(views)
    for p in pairs[::2]:
        img=p.image(); fg=p.foreground()[0,0]
        res=r.relight_full_resolution(img,p.sky(),p.target_lighting(),source_lighting=p.source_lighting(),method="quotient",working_res=min(img.shape[-2:]))
        E.append(float(torch.log2(lum(res["relit"]*2**p.eval_stops,fg)/lum(p.target_linear(),fg))))
        X.append(feats(res["working_image"],res["working_sky"],res["working"],p.source_lighting()[0]))
E=np.array(E); X=np.array(X)
print(mode, "n", len(E), "level error mean %.2f sd %.2f"%(E.mean(),E.std()))
for i,n in enumerate(names): print(f"  corr(e, {n}) = {np.corrcoef(E,X[:,i])[0,1]:+.2f}")
