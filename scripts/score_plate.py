#!/usr/bin/env python3
"""Plate-fit residuals against centroid noise (issue 24, item 4): for each solved frame of a
set made by scripts/sim_narrow.py, the matched stars' fit residuals (pixels) against the
truth's Cramér–Rao bound of each centroid (`crb_px`, per axis) and against the centroids'
actual errors (record x, y against the truth's x, y).

Usage: python3 scripts/score_plate.py TRUTH_DIR RECORDS.jsonl

Prints, over all matched stars: rms residual (2-D, px), rms actual centroid error (2-D, px),
rms expected centroid noise sqrt(2)·crb (2-D, px), and the ratio residual / expected noise
(the issue's goal: within 1.2)."""
import json
import math
import sys
from pathlib import Path


def norm_id(s):
    s = str(s)
    for p in ("Gaia DR3 ", "GAIA-"):
        if s.startswith(p):
            return "G" + s[len(p):]
    for p in ("HIP ", "HIP-"):
        if s.startswith(p):
            return "H" + s[len(p):]
    return s


def main(argv):
    truth_dir, records = Path(argv[1]), argv[2]
    truth = {}
    for line in open(truth_dir / "truth.jsonl"):
        if line.strip():
            t = json.loads(line)
            truth[t["file"]] = t
    res2, err2, noise2, n, frames = 0.0, 0.0, 0.0, 0, 0
    per_frame = []
    for line in open(records):
        r = json.loads(line)
        t = truth.get(Path(r["file"]).name)
        if t is None or r.get("status") != "solved":
            continue
        scale = 3600.0 * math.degrees(math.atan(1.0 / t["fx_px"]))  # arcsec per px at the centre
        stars = {norm_id(s["catalog_id"]): s for s in t["stars"]}
        fr, fn = 0.0, 0.0
        frames += 1
        for m in r.get("matches") or []:
            s = stars.get(norm_id(m["catalog_id"]))
            if s is None or s.get("saturated"):
                continue
            rp = m["residual_arcsec"] / scale
            e = math.hypot(m["x"] - s["x"], m["y"] - s["y"])
            c2 = 2.0 * s["crb_px"] ** 2
            res2 += rp * rp
            err2 += e * e
            noise2 += c2
            fr += rp * rp
            fn += c2
            n += 1
        if fn > 0:
            per_frame.append(math.sqrt(fr / fn))
    if n == 0:
        print("no matched stars")
        return 1
    per_frame.sort()
    rms = lambda x: math.sqrt(x / n)
    print(f"{frames} frames, {n} matched stars (unsaturated)")
    print(f"  rms fit residual        {rms(res2):.4f} px")
    print(f"  rms centroid error      {rms(err2):.4f} px (against the truth)")
    print(f"  rms expected noise      {rms(noise2):.4f} px (sqrt(2)·CRB)")
    print(f"  residual / noise        {math.sqrt(res2 / noise2):.3f} (all stars); "
          f"per frame median {per_frame[len(per_frame) // 2]:.3f}, max {per_frame[-1]:.3f}")
    print(f"  centroid error / noise  {math.sqrt(err2 / noise2):.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
