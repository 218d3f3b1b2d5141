"""Study 39: the true foreground median albedo (luminance) of every view of a synth folder: its median, geometric
mean and spread in stops (a property of the data, read before the rule).

    .venv/bin/python docs/experiments/scripts/39_albedo_medians.py data/val5
"""
import sys, numpy as np
from physrelight import io
from pathlib import Path
root=Path(sys.argv[1]); meds=[]
for sc in sorted(root.glob("scene_*")):
    for v in sorted(sc.glob("view_*")):
        a=io.read_exr(v/"albedo.exr"); sky=io.read_mask(v/"sky_mask.png")
        lum=a@np.array([0.2126,0.7152,0.0722])
        fg=~sky.astype(bool)
        meds.append(np.median(lum[fg]))
m=np.array(meds); print(len(m), "median of medians %.3f, geo-mean %.3f, sd log2 %.3f, q10/q90 %.3f %.3f"%(np.median(m), np.exp(np.log(m).mean()), np.log2(m).std(), *np.quantile(m,[.1,.9])))
