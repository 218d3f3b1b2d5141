"""Study 29: proposed minus quotient in bench --real's self-relighting, paired crop by crop.

Reads a ``bench --real`` output's ``real.json`` and prints, per group (held out, training side, indoor), the
mean PSNR and l1 difference with a 95 % bootstrap interval that resamples crops (the crops of one panorama
share its lighting, so the interval is narrower than a panorama bootstrap would give).

    .venv/bin/python docs/experiments/scripts/29_real_self_paired.py out/bench_real_now/real.json
"""

from __future__ import annotations

import json
import sys

import numpy as np

from physrelight.stats import paired_bootstrap


def main() -> None:
    crops = json.load(open(sys.argv[1]))["crops"]
    for group in ("heldout", "training", "indoor"):
        cs = [c for c in crops if c["group"] == group]
        for key in ("psnr", "l1"):
            a = np.array([c["self"]["proposed"][key] for c in cs])
            b = np.array([c["self"]["quotient"][key] for c in cs])
            ok = np.isfinite(a) & np.isfinite(b)
            d = paired_bootstrap(a[ok], b[ok], groups=np.arange(int(ok.sum())), seed=0)
            print(f"{group:>9} {key:>4}: proposed - quotient {d.diff:+.4f} [{d.lo:+.4f}, {d.hi:+.4f}] over {d.groups} crops")


if __name__ == "__main__":
    main()
