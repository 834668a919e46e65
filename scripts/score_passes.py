#!/usr/bin/env python3
"""Score gpustar's tracklets and --tle names against scripts/sim_passes.py truth.

    python3 scripts/score_passes.py RECORDS DIR [--json OUT]

A record's streak is the truth streak of its frame whose visible part it lies on (both ends
within 5 px of the truth segment's line, midpoints within half the truth's visible length);
anything else is a false streak. Reported:
* found: truth streaks >= 100 px visible with peak SNR >= 5 that a record streak matches, and
  all truth streaks;
* direction: of matched streaks with direction_known, those whose ends[0] -> ends[1] runs the
  way the object moved (truth p0 -> p1);
* names (--tle): of matched streaks of objects in the TLE file, those named with the right
  NORAD id (and how many of those are partial matches, `seen_fraction`); streaks named for a wrong object (in the file or not), and streaks of objects NOT
  in the file named for anything;
* tracklets: pure (every streak of a tracklet is one object) and whole (an object's matched
  streaks of one pass in one tracklet).
"""
import argparse
import json
import math
from collections import defaultdict


def seg_dist(p, a, b):
    ax, ay = a
    bx, by = b
    dx, dy = bx - ax, by - ay
    l2 = dx * dx + dy * dy or 1e-12
    t = max(0.0, min(1.0, ((p[0] - ax) * dx + (p[1] - ay) * dy) / l2))
    return math.hypot(p[0] - ax - t * dx, p[1] - ay - t * dy)


def line_dist(p, a, b):
    dx, dy = b[0] - a[0], b[1] - a[1]
    n = math.hypot(dx, dy) or 1e-12
    return abs((p[0] - a[0]) * dy - (p[1] - a[1]) * dx) / n


def clip(p0, p1, w=1024, h=1024):
    x0, y0 = p0
    dx, dy = p1[0] - x0, p1[1] - y0
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0 + 0.5), (dx, w - 0.5 - x0), (-dy, y0 + 0.5), (dy, h - 0.5 - y0)):
        if p == 0:
            if q < 0:
                return None
            continue
        r = q / p
        if p < 0:
            t0 = max(t0, r)
        else:
            t1 = min(t1, r)
        if t0 > t1:
            return None
    return (x0 + t0 * dx, y0 + t0 * dy), (x0 + t1 * dx, y0 + t1 * dy)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records")
    ap.add_argument("dir")
    ap.add_argument("--json")
    a = ap.parse_args()
    truth = {}
    for l in open(f"{a.dir}/truth.jsonl"):
        t = json.loads(l)
        truth[t["file"]] = t
    recs = [json.loads(l) for l in open(a.records) if l.startswith("{")]
    n_true = n_big = found = found_big = false = 0
    dir_known = dir_right = 0
    named_in = named_right = wrong_name = named_out = in_file = out_file = uncorrelated_in = 0
    partial = 0
    tracklet_objs = defaultdict(set)
    obj_tracklets = defaultdict(set)
    seen = set()
    examples = []
    for r in recs:
        t = truth.get(r["file"])
        if t is None:
            continue
        seen.add(r["file"])
        ts = t["streaks"]
        vis = [clip(s["p0"], s["p1"]) for s in ts]
        used = set()
        for s in r.get("streaks") or []:
            e0 = (s["ends"][0]["x"], s["ends"][0]["y"])
            e1 = (s["ends"][1]["x"], s["ends"][1]["y"])
            best = None
            for k, st in enumerate(ts):
                v = vis[k]
                if v is None or k in used:
                    continue
                ok = line_dist(e0, *v) < 5 and line_dist(e1, *v) < 5
                mid = ((e0[0] + e1[0]) / 2, (e0[1] + e1[1]) / 2)
                ok &= seg_dist(mid, *v) < 0.5 * math.dist(*v) + 5
                if ok:
                    d = seg_dist(mid, *v)
                    if best is None or d < best[0]:
                        best = (d, k)
            if best is None:
                false += 1
                examples.append(("false", r["file"], e0, e1))
                continue
            k = best[1]
            used.add(k)
            st = ts[k]
            if s["direction_known"]:
                dir_known += 1
                dx, dy = e1[0] - e0[0], e1[1] - e0[1]
                tx, ty = st["p1"][0] - st["p0"][0], st["p1"][1] - st["p0"][1]
                if dx * tx + dy * ty > 0:
                    dir_right += 1
                else:
                    examples.append(("direction", r["file"], st["norad"]))
            sat = s.get("satellite")
            if st["in_file"]:
                in_file += 1
                if sat and sat["norad"] == st["norad"]:
                    named_right += 1
                    partial += "seen_fraction" in sat
                elif sat:
                    wrong_name += 1
                    examples.append(("wrong name", r["file"], st["norad"], sat["norad"]))
                else:
                    uncorrelated_in += 1
                    examples.append(("not named", r["file"], st["norad"], s.get("uncorrelated")))
            else:
                out_file += 1
                if sat:
                    named_out += 1
                    examples.append(("named but not in file", r["file"], st["norad"], sat["norad"]))
            if s.get("tracklet"):
                tracklet_objs[s["tracklet"]].add((t["pass"], st["norad"]))
                obj_tracklets[(t["pass"], st["norad"])].add(s["tracklet"])
        for k, st in enumerate(ts):
            big = st["visible_length_px"] >= 100 and st["peak_snr"] >= 5
            n_true += 1
            n_big += big
            if k in used:
                found += 1
                found_big += big
            elif big:
                examples.append(("missed", r["file"], st["norad"], st["visible_length_px"]))
    pure = sum(1 for v in tracklet_objs.values() if len(v) == 1)
    whole = sum(1 for v in obj_tracklets.values() if len(v) == 1)
    multi = sum(1 for k, v in tracklet_objs.items() if len(v) == 1)
    res = {
        "frames": len(seen), "truth_streaks": n_true, "found": found,
        "big_streaks": n_big, "big_found": found_big, "false_streaks": false,
        "direction_known": dir_known, "direction_right": dir_right,
        "in_file_matched": in_file, "named_right": named_right, "named_wrong": wrong_name,
        "in_file_not_named": uncorrelated_in, "named_partial": partial,
        "not_in_file_matched": out_file, "not_in_file_named": named_out,
        "tracklets": len(tracklet_objs), "tracklets_pure": pure,
        "objects_passes": len(obj_tracklets), "objects_in_one_tracklet": whole,
    }
    pc = lambda a, b: f"{100.0 * a / b:.1f} %" if b else "n/a"  # noqa: E731
    print(f"frames {len(seen)}; truth streaks {n_true}, found {found}; >= 100 px & SNR >= 5: "
          f"{found_big}/{n_big} ({pc(found_big, n_big)}); false streaks {false}")
    print(f"direction known on {dir_known}/{found} found streaks, right {dir_right}/{dir_known} "
          f"({pc(dir_right, dir_known)})")
    print(f"objects in the file: {named_right}/{in_file} streaks named right ({pc(named_right, in_file)}), "
          f"{wrong_name} named wrong, {uncorrelated_in} not named; {partial} of the right ones partial "
          f"(seen_fraction: dark over part of the exposure)")
    print(f"objects not in the file: {named_out}/{out_file} streaks named for something")
    print(f"tracklets {len(tracklet_objs)}: {pure} pure ({pc(pure, len(tracklet_objs))}); "
          f"object-passes {len(obj_tracklets)}: {whole} in one tracklet ({pc(whole, len(obj_tracklets))})")
    for e in examples[:12]:
        print("  ", e)
    del multi
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)


if __name__ == "__main__":
    main()
