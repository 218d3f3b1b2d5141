"""Study 61, follow-up: the sun's direction and the sky's shape read from the photo's sky, their two weights (sun, sky)
solved from the photo's shading instead of taken from the sky table (docs/experiments/61-sun-in-relighter.md,
"The sun's weight from the shading").

Per source photo the sky is read as ``sun_in_relighter_synthetic.py`` reads it; the decomposition gives albedo A,
normals n and the shadow map v; the luminance I of the photo's foreground is fitted by non-negative least squares as
``a * A max(0, n.s) v + b * A S(n; sky)`` and the read lighting becomes ``(a / b) * sun + sky`` (its level is set
downstream, as for the plain reading). bench --quick's cross pairs, proposed, one thread.

    PYTHONPATH=. .venv/bin/python docs/experiments/scripts/61_sun_weight_from_shading.py            # 60 s
"""
import sys, time, runpy
import numpy as np, torch
from scipy.optimize import nnls
sys.argv = [sys.argv[0]] + sys.argv[1:]
from pathlib import Path
mod = runpy.run_path(str(Path(__file__).with_name('sun_in_relighter_synthetic.py')), run_name='not_main')
SkyRead, sun_direction = mod['SkyRead'], mod['sun_direction']
from physrelight.image_model import shading
LUM = torch.tensor([0.2126, 0.7152, 0.0722])

class SkyReadFit(SkyRead):
    stats = []
    def __init__(self, relighter, method, readings=None):
        super().__init__(relighter, method, readings)
        self.name = f"{method}_skyfit"
    def __call__(self, pair):
        _, cam = self.reading(pair)
        if cam is None:
            return super(SkyRead, self).__call__(pair)
        image, sky = pair.image(), pair.sky()
        with torch.no_grad():
            dec = self.relighter.decompose_linear(image.float(), sky.bool())
        sun = torch.from_numpy(cam[1]).float(); skysh = torch.from_numpy(cam[0]).float() - sun
        d = sun_direction(cam[1])
        fg = (~sky.bool())[0, 0]
        n = dec['normals'][0]
        A = dec['albedo'][0]
        alb = (A * LUM[:, None, None]).sum(0)
        y = ((image[0].float()) * LUM[:, None, None]).sum(0)
        x2 = (A * shading(dec['normals'], skysh)[0] * LUM[:, None, None]).sum(0)
        if d is not None:
            cos = (n * torch.tensor(d, dtype=n.dtype)[:, None, None]).sum(0).clamp_min(0)
            x1 = alb * cos * dec['shadow'][0, 0]
        else:
            x1 = torch.zeros_like(x2)
        M = torch.stack([x1[fg], x2[fg]], 1).double().numpy(); t = y[fg].double().numpy()
        (a, b), _ = nnls(M, t)
        # the table's own weights are (1, 1) for (sun SH scaled to its irradiance, sky): keep the ratio a/b
        if b <= 0:
            return super().__call__(pair)
        ratio = a / b
        SkyReadFit.stats.append((pair.view.lights[pair.source].kind if hasattr(pair, 'source') else '?', ratio))
        new = ratio * sun + skysh
        return self.relighter.relight_full_resolution(
            image, sky, pair.target_lighting(), source_lighting=pair.source_lighting(), method=self.method,
            working_res=min(image.shape[-2:]), read_source=new, read_source_sun=ratio * sun)["relit"]

def main():
    from learned import Relighter
    from validation.bench.protocols import VARIANTS, cross_pairs, informative_pairs, timelapse_pairs
    from validation.bench.run import LEVELS, evaluate, gather_views
    from validation.bench.methods import Learned
    torch.set_num_threads(1)
    data = sys.argv[1] if len(sys.argv) > 1 else None
    level = LEVELS['full' if data else 'quick']
    views, _ = gather_views(level, data, lambda m: None)
    variant_views = [v.name for v in views if v.view == 0 and v.group != "timelapse"][: level.variant_views]
    cross, _ = informative_pairs(cross_pairs(views, VARIANTS, variant_views))
    pairs = cross
    rl = Relighter.load()
    readings = {}
    for method in ("proposed",):
        base = evaluate(method, Learned(rl, method), pairs)
        sky = SkyRead(rl, method, readings); r1 = evaluate(sky.name, sky, pairs)
        fit = SkyReadFit(rl, method, readings); r2 = evaluate(fit.name, fit, pairs)
        used = [i for i, p in enumerate(pairs) if sky.reading(p)[1] is not None]
        for title, idx in (("cross", None), ("read", used)):
            print(method, title, 'today %.4f sky %.4f skyfit %.4f | at best gain %.4f %.4f %.4f' % (
                base.mean(idx)['l1'], r1.mean(idx)['l1'], r2.mean(idx)['l1'], base.mean(idx)['gain_l1'], r1.mean(idx)['gain_l1'], r2.mean(idx)['gain_l1']))
    import collections
    by = collections.defaultdict(list)
    for k, r in SkyReadFit.stats: by[k].append(r)
    print({k: (len(v), float(np.median(v))) for k, v in by.items()})
main()
