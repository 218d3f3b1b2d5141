#!/usr/bin/env bash
# Render the small synth dataset that scripts/gpu_smoke.sh and scripts/device_check.sh train on
# (git-ignored, carried to the GPU machine by the lead). Needs Mitsuba (the synth extra): run it here,
# not on the GPU machine. Seeded: the same command writes the same bytes.
#
#   bash scripts/make_smoke_data.sh [OUT]        (default OUT: .smoke/data)
#
# 3 scenes x 4 views x 2 lightings at 256 px (sun/sky and overcast; no HDRI folder needed), about 33 MB:
# the lead carries it to the GPU machine (budget 40 MiB). The scenes are all in the 'train' split
# (synth.dataset.split_of), so the smoke validates on split 'all'. Reading it needs OpenEXR.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-.smoke/data}"
PY="${PYTHON:-python}"
if [ -e "$OUT/manifest.json" ]; then
    echo "$OUT already holds a dataset; remove it to render again" >&2
    exit 2
fi
mkdir -p "$(dirname "$OUT")"
# Rendered beside the target and moved into place at the end: no half-written dataset under OUT.
TMP="$(mktemp -d "$(dirname "$OUT")/.make_smoke_data.XXXXXX")"
trap 'rm -rf "$TMP"' EXIT
"$PY" -c "from physrelight.cli import main; raise SystemExit(main())" synth "$TMP/data" \
    --scenes 3 --views 4 --lights 2 --res 256 --spp 32 --gbuffer-spp 8 --shadow-spp 16 --env-res 64 \
    --kinds sunsky overcast --seed 0 --quiet
rm -rf "$OUT"
mv "$TMP/data" "$OUT"
du -sh "$OUT"
