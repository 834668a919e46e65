#!/usr/bin/env bash
# Solve every real frame of ../shared/data/real the way a user would (each set with its
# camera, cedar-solve's mixed cameras with each frame's FOV), then score against truth.jsonl.
#   scripts/real_sets.sh OUTDIR [extra gpustar options, e.g. --backend gpu]
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
real="${GPUSTAR_REAL:-$here/../../shared/data/real}"
out="${1:?usage: real_sets.sh OUTDIR [gpustar options]}"; shift
gpustar="${GPUSTAR:-$here/../target/release/gpustar}"
mkdir -p "$out"

# The tetra3 frames' FOV is known to about 0.2 %: search the scale. openstartracker's
# fixed-pattern noise is as bright as its stars: subtract the median of its frames. Swarm's
# lens distortion is unknown: search the scale and fit k1.
"$gpustar" batch "$real/esa-tetra3" --camera "$here/cameras/esa-tetra3.toml" --epoch 2019.58 --fov-tolerance 0.01 -o "$out/esa-tetra3.jsonl" "$@" || true
"$gpustar" batch "$real/openstartracker" --camera "$here/cameras/openstartracker.toml" --epoch 2018.35 --dark-median -o "$out/openstartracker.jsonl" "$@" || true
"$gpustar" batch "$real/swarm-a" --camera "$here/cameras/swarm-a.toml" --epoch 2014.85 --fov-tolerance 0.01 --fit distortion -o "$out/swarm-a.jsonl" "$@" || true
# cedar-solve: several cameras; each frame with the FOV its user would give (truth.jsonl, 3 decimals).
: > "$out/cedar-solve.jsonl"
python3 -c '
import json, sys
for line in open(sys.argv[1]):
    t = json.loads(line)
    print(t["file"], round(t["fov_x_deg"], 3), t["epoch"])
' "$real/cedar-solve/truth.jsonl" | while read -r file fov epoch; do
  "$gpustar" solve "$real/cedar-solve/$file" --fov-deg "$fov" --fov-tolerance 0.01 --epoch "$epoch" -q "$@" >> "$out/cedar-solve.jsonl" || true
done
for set in esa-tetra3 cedar-solve openstartracker swarm-a; do
  echo "== $set"
  "$gpustar" evaluate --truth "$real/$set/truth.jsonl" "$out/$set.jsonl"
done
