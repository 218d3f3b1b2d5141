"""Study 39 addendum (exploration): a sun added to the source lighting estimate, its direction searched over 256
directions and its intensity (with the estimate's own weight) fitted by least squares to the photo's luminance,
the decomposition's shadow layer gating only the sun's light (or not); scale-invariant shading error against the
truth, beside the shipped estimate. ``real``: bench --real's training-side crops; a synth folder: one photo per
(view, source lighting) of its cross pairs.

    .venv/bin/python docs/experiments/scripts/39_sun_fit_probe.py real
    .venv/bin/python docs/experiments/scripts/39_sun_fit_probe.py data/val5
"""
import sys, numpy as np, torch
sys.path.insert(0,"docs/experiments/scripts")
from learned import Relighter
from physrelight import colour, image_model, sh
from validation.bench.real import shading_error
torch.set_num_threads(1)
r=Relighter.load(); LUM=torch.tensor(colour.LUMINANCE,dtype=torch.float64)
D=torch.as_tensor(np.asarray(sh.fibonacci_sphere(256)),dtype=torch.float64)  # (256,3)
SPH=np.asarray(sh.fibonacci_sphere(256))
def sunfit(img, sky, dec, use_shadow=True):
    fg=(~sky[0,0]).flatten()
    n=dec["normals"][0].double().reshape(3,-1)[:,fg]            # (3,N)
    a=dec["albedo"][0].double().reshape(3,-1)[:,fg]
    s=dec["shadow"][0,0].double().flatten()[fg] if use_shadow else torch.ones(int(fg.sum()),dtype=torch.float64)
    y=(img[0].double().reshape(3,-1)[:,fg]*LUM[:,None]).sum(0)
    Lh=dec["lighting"][0].double()
    S=image_model.shading(dec["normals"].double(), Lh)[0].reshape(3,-1)[:,fg]
    f1=((a*S)*LUM[:,None]).sum(0)
    al=(a*LUM[:,None]).sum(0)
    cos=(D@n).clamp_min(0)/np.pi                                # (256,N)
    f2=al[None]*s[None]*cos                                     # (256,N)
    best=None
    for k in range(D.shape[0]):
        A=torch.stack([f1,f2[k]],1)
        x=torch.linalg.lstsq(A,y[:,None]).solution[:,0]
        if x[1]<0 or x[0]<0:
            b=float((f1@y)/(f1@f1)); x=torch.tensor([max(b,0.0),0.0],dtype=torch.float64)
        res=float(((A@x-y)**2).mean())
        if best is None or res<best[0]: best=(res,k,x)
    res0=float((( (f1*float((f1@y)/(f1@f1)))-y)**2).mean())
    _,k,x=best
    col=(Lh[0]/ (Lh[0]@LUM)).clamp_min(0)
    Lnew=x[0]*Lh+torch.as_tensor(np.asarray(sh.project_sun(D[k].numpy(), (float(x[1])*col).numpy())))
    return Lnew.numpy(), best[0]/max(res0,1e-30)
mode=sys.argv[1]; out={"cur":[], "sun":[], "sun_noshadow":[]}
def score(Lest, Ltrue, R=None):
    Et=np.asarray(sh.irradiance(Ltrue, SPH)); Ee=np.asarray(sh.irradiance(Lest, SPH)); return shading_error(Ee,Et)
if mode=="real":
    from real_crop_scores import bench_crops, crop_panoramas
    _,panos=crop_panoramas(False)
    for pano,crop in bench_crops(panos):
        if crop.stratum=="no_sky" or crop.sky.all(): continue
        lin=crop.linear(); seg,_=r.photo_sky(lin)
        src=torch.from_numpy(crop.lighting_sh(2)*crop.gain[None,:]).float()
        res=r.relight_full_resolution(lin,seg,src,source_lighting=src,method="quotient")
        dec=res["working"]; img=res["working_image"]; sky=res["working_sky"]
        Lt=crop.lighting_sh(2)
        out["cur"].append(score(dec["lighting"][0].double().numpy(), Lt))
        out["sun"].append(score(sunfit(img,sky,dec)[0], Lt))
        out["sun_noshadow"].append(score(sunfit(img,sky,dec,False)[0], Lt))
else:
    from validation.bench.data import load_dataset
    views=load_dataset(mode, with_physical=False)
    from validation.bench.protocols import cross_pairs
    seen=set()
    for p in cross_pairs(views):
        key=(p.view.name,p.source)
        if key in seen: continue
        seen.add(key)
        img=p.image()
        res=r.relight_full_resolution(img,p.sky(),p.target_lighting(),source_lighting=p.source_lighting(),method="quotient",working_res=min(img.shape[-2:]))
        dec=res["working"]; wi=res["working_image"]; sky=res["working_sky"]
        Lt=p.source_lighting()[0].double().numpy()
        out["cur"].append(score(dec["lighting"][0].double().numpy(), Lt))
        out["sun"].append(score(sunfit(wi,sky,dec)[0], Lt))
        out["sun_noshadow"].append(score(sunfit(wi,sky,dec,False)[0], Lt))
for k,v in out.items(): print(mode, k, "shading error %.3f (n=%d)"%(np.mean(v),len(v)))
