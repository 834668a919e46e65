#!/bin/bash
# Two gpustar binaries on the same independent sets, both backends: are the records the same
# byte for byte, less the timings? Used for "behaviour unchanged" (issue 23).
#   scripts/same_records.sh OLD_BIN NEW_BIN OUT FRAMES10 STREAKS SEQUENCES
# FRAMES10: scripts/sim_frames.py --out D (300 10-degree frames); STREAKS: scripts/sim_streaks.py
# --out D --defects; SEQUENCES: scripts/sim_sequence.py --out D. Each directory holds camera.toml.
set -u
OLD=$1 NEW=$2 OUT=$3 F10=$4 STR=$5 SEQ=$6
export XDG_RUNTIME_DIR=${XDG_RUNTIME_DIR:-$(mktemp -d)}
run() { # BIN DIR
  local bin=$1 d=$2
  mkdir -p "$d"
  for be in cpu gpu; do
    "$bin" batch "$F10" --camera "$F10/camera.toml" --backend $be -q -o "$d/frames10-$be.jsonl" --wcs-dir "$d/wcs-$be" 2>>"$d/log"
    "$bin" batch "$STR" --camera "$STR/camera.toml" --backend $be -q --streaks --tdm "$d/streaks-$be.tdm" \
      --iod "$d/streaks-$be.iod" --iod-station 9999 -o "$d/streaks-$be.jsonl" 2>>"$d/log"
    "$bin" batch "$SEQ" -r --sequence --camera "$SEQ/camera.toml" --backend $be -q -o "$d/seq-$be.jsonl" 2>>"$d/log"
  done
}
run "$OLD" "$OUT/old"
run "$NEW" "$OUT/new"
status=0
for f in frames10-cpu frames10-gpu streaks-cpu streaks-gpu seq-cpu seq-gpu; do
  a=$(sed 's/"timing_ms":{[^}]*}//' "$OUT/old/$f.jsonl" | md5sum)
  b=$(sed 's/"timing_ms":{[^}]*}//' "$OUT/new/$f.jsonl" | md5sum)
  n=$(wc -l < "$OUT/new/$f.jsonl")
  if [ "$a" = "$b" ]; then echo "$f: $n records, identical less timing_ms"; else echo "$f: DIFFER"; status=1; fi
done
for be in cpu gpu; do
  diff -rq "$OUT/old/wcs-$be" "$OUT/new/wcs-$be" >/dev/null && echo "wcs-$be: identical" || { echo "wcs-$be: DIFFER"; status=1; }
  cmp -s "$OUT/old/streaks-$be.iod" "$OUT/new/streaks-$be.iod" && echo "iod-$be: identical" || { echo "iod-$be: DIFFER"; status=1; }
  diff -q <(grep -v CREATION_DATE "$OUT/old/streaks-$be.tdm") <(grep -v CREATION_DATE "$OUT/new/streaks-$be.tdm") >/dev/null \
    && echo "tdm-$be: identical less CREATION_DATE" || { echo "tdm-$be: DIFFER"; status=1; }
done
exit $status
