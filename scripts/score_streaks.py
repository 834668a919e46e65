#!/usr/bin/env python3
"""Score gpustar streak records against sim_streaks.py truth.

Usage:
    python3 scripts/score_streaks.py --truth DIR/truth.jsonl RECORDS.jsonl [--json OUT.json]

Association: a record streak can match a truth streak when, against the truth's *visible*
segment (the part inside the pixel-centre box [0, W-1] x [0, H-1]),
  * both record ends lie within --perp-tol (3 px) of the truth line,
  * the directions (as undirected lines) agree within --angle-tol (2 deg),
  * the overlap of the two segments along the truth line is >= --min-overlap (50%) of the
    shorter of the two.
Pairs are then taken one-to-one, greedily by overlap / length of the *longer* segment (so a
full-length detection beats a fragment of it, which also overlaps 100% of the shorter one).
Unmatched record streaks that lie along some truth streak (both ends within --perp-tol of its
line, the overlap as above, the direction not asked: a short piece's direction is the least
sure) are counted as "along a truth streak" (fragments/duplicates, or a piece measured a few
degrees off) within the false streaks; the rest are phantoms.

End order: a single frame cannot tell start from end, so each matched streak uses the order
(record end 0 <-> truth p0, or swapped) that minimises the summed distance over the truth ends
that are inside the frame; when both truth ends are off the frame, the visible (clipped) ends
decide. That order is used for the end errors, the edge flags, RA/Dec and time checks.

End errors are reported only for truth ends inside the frame (edge false): distance from
truth p0/p1; along-track (signed "outward" = the record end lies beyond the truth end, i.e.
the record streak is too long) and cross-track components.

Only the standard library and numpy are needed.
"""
import argparse
import json
import math
import sys
from collections import Counter, defaultdict
from datetime import datetime

import numpy as np

SNR_BINS = [(3.0, 5.0), (5.0, 10.0), (10.0, 25.0 + 1e-9)]
LEN_BINS = [(0.0, 100.0), (100.0, 300.0), (300.0, float("inf"))]
SNR_LABELS = ["3-5", "5-10", "10-25"]
LEN_LABELS = ["<100", "100-300", ">=300"]


def star_key(s):
    """A star's identity in records and truth files: its catalog_id ("HIP 27989", "Gaia DR3 ...")
    where written, else its HIP (truth files of the Python simulators, older records)."""
    return s.get("catalog_id") or f"HIP {s['hip']}"


def load_jsonl(path):
    out = []
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if not line:
                continue
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError as e:
                print(f"warning: {path}:{n}: {e}", file=sys.stderr)
    return out


def basename(p):
    return str(p).replace("\\", "/").rsplit("/", 1)[-1]


def parse_time(s):
    if not s:
        return None
    s = s.rstrip("Z")
    for fmt in ("%Y-%m-%dT%H:%M:%S.%f", "%Y-%m-%dT%H:%M:%S"):
        try:
            return datetime.strptime(s, fmt)
        except ValueError:
            pass
    return None


def ang_sep_arcsec(ra1, dec1, ra2, dec2):
    r1, d1, r2, d2 = map(math.radians, (ra1, dec1, ra2, dec2))
    # haversine: well-conditioned for the arcsecond-sized separations we care about
    h = math.sin((d2 - d1) / 2) ** 2 + math.cos(d1) * math.cos(d2) * math.sin((r2 - r1) / 2) ** 2
    return math.degrees(2 * math.asin(min(1.0, math.sqrt(h)))) * 3600.0


def stats(vals):
    v = np.asarray([x for x in vals if x is not None and math.isfinite(x)], float)
    if v.size == 0:
        return {"n": 0, "median": None, "p95": None, "max": None}
    return {"n": int(v.size), "median": float(np.median(v)), "p95": float(np.percentile(v, 95)),
            "max": float(v.max())}


def rec_ends(rs):
    """The two record ends as numpy points (None when the record lacks them)."""
    ends = rs.get("ends") or []
    if len(ends) != 2:
        return None
    try:
        return [np.array([float(e["x"]), float(e["y"])]) for e in ends]
    except (KeyError, TypeError, ValueError):
        return None


def match_score(ts, ends, perp_tol, angle_tol, min_overlap):
    """(overlap / longer length, overlap px) if the record segment lies along the truth's
    visible segment, else None."""
    a, b = np.array(ts["visible"][0], float), np.array(ts["visible"][1], float)
    lt = float(np.linalg.norm(b - a))
    if lt <= 0:
        return None
    u = (b - a) / lt
    n = np.array([-u[1], u[0]])
    e0, e1 = ends
    if abs((e0 - a) @ n) > perp_tol or abs((e1 - a) @ n) > perp_tol:
        return None
    lr = float(np.linalg.norm(e1 - e0))
    if lr <= 0:
        return None
    cosang = abs(float((e1 - e0) @ u)) / lr
    if math.degrees(math.acos(min(1.0, cosang))) > angle_tol:
        return None
    t0, t1 = sorted((float((e0 - a) @ u), float((e1 - a) @ u)))
    overlap = max(0.0, min(t1, lt) - max(t0, 0.0))
    if overlap < min_overlap * min(lt, lr):
        return None
    return overlap / max(lt, lr), overlap


def associate(truth_streaks, rec_streaks, args):
    """Greedy one-to-one association; returns ({truth index: record index}, set of unmatched
    record indices that lie along some truth streak)."""
    cands = []
    for i, ts in enumerate(truth_streaks):
        for j, rs in enumerate(rec_streaks):
            ends = rec_ends(rs)
            if ends is None:
                continue
            m = match_score(ts, ends, args.perp_tol, args.angle_tol, args.min_overlap)
            if m:
                cands.append((m[0], m[1], i, j))
    cands.sort(key=lambda c: (-c[0], -c[1]))
    t_used, r_used, pairs = set(), set(), {}
    for _, _, i, j in cands:
        if i in t_used or j in r_used:
            continue
        t_used.add(i)
        r_used.add(j)
        pairs[i] = j
    # unmatched records that lie along some truth streak: fragments/duplicates, not phantoms
    along = set()
    for ts in truth_streaks:
        for j, rs in enumerate(rec_streaks):
            ends = rec_ends(rs)
            if j in r_used or ends is None:
                continue
            if match_score(ts, ends, args.perp_tol, 90.0, args.min_overlap):
                along.add(j)
    return pairs, along


def end_order(ts, ends):
    """0: record end k <-> truth end k; 1: swapped. See the module docstring."""
    p = [np.array(ts["p0"], float), np.array(ts["p1"], float)]
    vis = [np.array(ts["visible"][0], float), np.array(ts["visible"][1], float)]
    inside = [not ts["edge0"], not ts["edge1"]]
    ref = [p[k] if inside[k] else vis[k] for k in range(2)]
    use = [k for k in range(2) if inside[k]] or [0, 1]
    cost = [sum(np.linalg.norm(ends[(k + o) % 2] - ref[k]) for k in use) for o in (0, 1)]
    return 0 if cost[0] <= cost[1] else 1


def bin_index(v, bins):
    for k, (lo, hi) in enumerate(bins):
        if lo <= v < hi:
            return k
    return None


def rotation_error_arcsec(r_rec, r_true):
    a = np.asarray(r_rec, float) @ np.asarray(r_true, float).T
    c = (np.trace(a) - 1.0) / 2.0
    return math.degrees(math.acos(max(-1.0, min(1.0, c)))) * 3600.0


def false_cause(ends, defects):
    """What a false record streak lies on: a chain of stars (two or more of its points within
    3 px of the segment), a defective column (both ends within 3 px of it), else None."""
    if ends is None:
        return None
    a, b = ends
    d = b - a
    l2 = max(float(d @ d), 1e-12)

    def dist(p):
        p = np.asarray(p, float)
        t = min(max(float((p - a) @ d) / l2, 0.0), 1.0)
        return float(np.linalg.norm(p - a - t * d))
    for df in defects:
        if df["type"] in ("star_chain", "false_chain"):
            if sum(dist(p) <= 3.0 for p in df["points"]) >= 2:
                return df["type"]
        elif "x" in df and df["type"] in ("hot_column", "cold_column", "warm_pair", "bleed"):
            if abs(a[0] - df["x"]) <= 3.0 and abs(b[0] - df["x"]) <= 3.0:
                return df["type"]
    return None


def score(truth, records, args):
    recs = {}
    for r in records:
        recs[basename(r.get("file", ""))] = r  # later lines win, like a re-run appended
    tnames = {t["file"] for t in truth}
    unknown = sorted(set(recs) - tnames)

    per_streak = []
    false_streaks = []  # (file, record index, frame has truth streaks, along a truth streak)
    comp_tab = [[[0, 0] for _ in LEN_BINS] for _ in SNR_BINS]  # [found, total]
    end_err, along_abs, along_out, cross_abs, radec_err = [], [], [], [], []
    edge_agree = edge_total = 0
    edge_conf = Counter()  # (truth edge, record edge) -> count
    time_any_ok = time_checked = time_null = 0
    time_pair_ok = time_pair_total = 0
    star_groups = {True: defaultdict(list), False: defaultdict(list)}
    missing = []

    for t in truth:
        name = t["file"]
        rec = recs.get(name)
        if rec is None:
            missing.append(name)
            rec = {"status": "missing", "streaks": [], "matches": []}
        rstreaks = rec.get("streaks") or []
        tstreaks = t["streaks"]
        pairs, along = associate(tstreaks, rstreaks, args)
        t_beg, t_end = parse_time(t["date_beg_utc"]), parse_time(t["date_end_utc"])

        for i, ts in enumerate(tstreaks):
            si, li = bin_index(ts["peak_snr"], SNR_BINS), bin_index(ts["visible_length_px"], LEN_BINS)
            found = i in pairs
            if si is not None and li is not None:
                comp_tab[si][li][1] += 1
                comp_tab[si][li][0] += int(found)
            row = {"file": name, "truth_index": i, "peak_snr": ts["peak_snr"],
                   "visible_length_px": ts["visible_length_px"], "edge": [ts["edge0"], ts["edge1"]],
                   "matched": found, "record_index": pairs.get(i),
                   "glint": (ts.get("glint") or {}).get("kind")}
            if found:
                rs = rstreaks[pairs[i]]
                ends = rec_ends(rs)
                o = end_order(ts, ends)
                rend = [rs["ends"][(k + o) % 2] for k in range(2)]
                rpts = [ends[(k + o) % 2] for k in range(2)]
                p = [np.array(ts["p0"], float), np.array(ts["p1"], float)]
                u = (p[1] - p[0]) / np.linalg.norm(p[1] - p[0])
                n = np.array([-u[1], u[0]])
                tedge = [ts["edge0"], ts["edge1"]]
                row["end_err_px"] = [None, None]
                for k in range(2):
                    redge = bool(rend[k].get("edge"))
                    edge_total += 1
                    edge_agree += int(redge == tedge[k])
                    edge_conf[(tedge[k], redge)] += 1
                    if tedge[k]:
                        continue
                    d = rpts[k] - p[k]
                    outward = -u if k == 0 else u
                    err = float(np.linalg.norm(d))
                    end_err.append(err)
                    along_abs.append(abs(float(d @ u)))
                    along_out.append(float(d @ outward))
                    cross_abs.append(abs(float(d @ n)))
                    row["end_err_px"][k] = round(err, 3)
                    ra, dec = rend[k].get("ra_deg"), rend[k].get("dec_deg")
                    if ra is not None and dec is not None:
                        radec_err.append(ang_sep_arcsec(ra, dec, ts[f"ra{k}_deg"], ts[f"dec{k}_deg"]))
                    tr = parse_time(rend[k].get("time_utc"))
                    if tr is None:
                        time_null += 1
                    else:
                        time_checked += 1
                        ok = min(abs((tr - t_beg).total_seconds()), abs((tr - t_end).total_seconds())) <= 0.002
                        time_any_ok += int(ok)
                if not tedge[0] and not tedge[1]:
                    times = [parse_time(rend[k].get("time_utc")) for k in range(2)]
                    if all(times):
                        time_pair_total += 1
                        a, b = sorted(times)
                        time_pair_ok += int(abs((a - t_beg).total_seconds()) <= 0.002
                                            and abs((b - t_end).total_seconds()) <= 0.002)
                row["order_swapped"] = bool(o)
            per_streak.append(row)

        n_false = 0
        for j in range(len(rstreaks)):
            if j not in pairs.values():
                n_false += 1
                false_streaks.append({"file": name, "record_index": j, "frame_has_streaks": bool(tstreaks),
                                      "along_truth_streak": j in along,
                                      "defects": [d["type"] for d in t.get("defects", [])],
                                      "length_px": rstreaks[j].get("length_px"), "snr": rstreaks[j].get("snr"),
                                      "lies_on": "truth streak" if j in along
                                      else false_cause(rec_ends(rstreaks[j]), t.get("defects", []))})

        # star identification: a match is right when a truth star of the same id lies within tol
        tstars = {star_key(s): (s["x"], s["y"]) for s in t.get("stars", [])}
        right = wrong = 0
        for m in rec.get("matches") or []:
            try:
                key, x, y = star_key(m), float(m["x"]), float(m["y"])
            except (KeyError, TypeError, ValueError):
                continue
            tp = tstars.get(key)
            if tp is not None and math.hypot(x - tp[0], y - tp[1]) <= args.star_tol:
                right += 1
            else:
                wrong += 1
        g = star_groups[bool(tstreaks)]
        g["frames"].append(name)
        g["solved"].append(rec.get("status") == "solved")
        g["right"].append(right)
        g["false"].append(wrong)
        g["detectable"].append(sum(1 for s in t.get("stars", []) if s["peak_snr"] >= 5))
        if rec.get("status") == "solved" and rec.get("rotation_matrix"):
            g["att_err"].append(rotation_error_arcsec(rec["rotation_matrix"], t["rotation_matrix"]))
        g["n_false_streaks"].append(n_false)
        g["defects"].append([d["type"] for d in t.get("defects", [])])

    # ---------------------------------------------------------------- summary
    def comp(sel):
        rows = [r for r in per_streak if sel(r)]
        return {"found": sum(r["matched"] for r in rows), "total": len(rows),
                "fraction": (sum(r["matched"] for r in rows) / len(rows)) if rows else None}

    table = {SNR_LABELS[a]: {LEN_LABELS[b]: {"found": comp_tab[a][b][0], "total": comp_tab[a][b][1]}
                             for b in range(len(LEN_BINS))} for a in range(len(SNR_BINS))}

    nostreak = star_groups[False]
    defect_tab = defaultdict(lambda: {"frames": 0, "frames_with_false": 0, "false_streaks": 0})
    for defs, nf in zip(nostreak["defects"], nostreak["n_false_streaks"]):
        for d in (defs or ["none"]):
            defect_tab[d]["frames"] += 1
            defect_tab[d]["frames_with_false"] += int(nf > 0)
            defect_tab[d]["false_streaks"] += nf
    false_by_defect_all = Counter()
    for f in false_streaks:
        for d in (f["defects"] or ["none"]):
            false_by_defect_all[d] += 1

    def star_summary(g):
        n = len(g["frames"])
        return {"frames": n, "solved": int(sum(g["solved"])),
                "right_ids": int(sum(g["right"])), "false_ids": int(sum(g["false"])),
                "frames_with_false_ids": int(sum(1 for x in g["false"] if x > 0)),
                "mean_right_per_frame": (sum(g["right"]) / n) if n else None,
                "mean_detectable_stars_per_frame": (sum(g["detectable"]) / n) if n else None,
                "attitude_error_arcsec": stats(g["att_err"])}

    summary = {
        "params": {"perp_tol_px": args.perp_tol, "angle_tol_deg": args.angle_tol,
                   "min_overlap": args.min_overlap, "star_tol_px": args.star_tol},
        "frames": len(truth), "records_missing": len(missing), "records_unknown": len(unknown),
        "truth_streaks": len(per_streak), "record_streaks": sum(len((recs.get(t["file"]) or {}).get("streaks") or [])
                                                                for t in truth),
        "completeness": comp(lambda r: True),
        "completeness_long_bright": comp(lambda r: r["visible_length_px"] >= 100 and r["peak_snr"] >= 5),
        "completeness_edge": comp(lambda r: r["edge"][0] or r["edge"][1]),
        "completeness_inside": comp(lambda r: not (r["edge"][0] or r["edge"][1])),
        "completeness_table": table,
        # --glints: by the object's light curve (steady, periodic, irregular, gaps, flashes)
        "completeness_by_glint": {k: {"all": comp(lambda r, k=k: r["glint"] == k),
                                      "long_bright": comp(lambda r, k=k: r["glint"] == k and r["visible_length_px"] >= 100
                                                          and r["peak_snr"] >= 5)}
                                  for k in sorted({r["glint"] for r in per_streak if r["glint"]})},
        "false_streaks": {
            "total": len(false_streaks),
            "along_truth_streak": sum(f["along_truth_streak"] for f in false_streaks),
            "on_frames_without_streaks": sum(1 for f in false_streaks if not f["frame_has_streaks"]),
            "frames_without_streaks": len(nostreak["frames"]),
            "frames_without_streaks_with_false": sum(1 for x in nostreak["n_false_streaks"] if x > 0),
            "by_defect_on_frames_without_streaks": dict(defect_tab),
            "by_defect_all_frames": dict(false_by_defect_all),
            "lies_on": dict(Counter(str(f["lies_on"]) for f in false_streaks)),
            "list": false_streaks,
        },
        "end_error_px": stats(end_err),
        "end_along_abs_px": stats(along_abs),
        "end_along_outward_median_px": float(np.median(along_out)) if along_out else None,
        "end_cross_abs_px": stats(cross_abs),
        "end_radec_error_arcsec": stats(radec_err),
        "edge_flags": {"agree": edge_agree, "total": edge_total,
                       "fraction": edge_agree / edge_total if edge_total else None,
                       "truth_edge_record_edge": edge_conf[(True, True)],
                       "truth_edge_record_inside": edge_conf[(True, False)],
                       "truth_inside_record_edge": edge_conf[(False, True)],
                       "truth_inside_record_inside": edge_conf[(False, False)]},
        "end_times": {"inside_ends_with_time": time_checked, "inside_ends_time_null": time_null,
                      "time_is_beg_or_end": time_any_ok,
                      "both_inside_streaks_with_times": time_pair_total,
                      "both_inside_times_are_beg_and_end": time_pair_ok},
        "stars": {"frames_with_streaks": star_summary(star_groups[True]),
                  "frames_without_streaks": star_summary(star_groups[False])},
        "missing_records": missing, "unknown_records": unknown,
        "per_streak": per_streak,
    }
    return summary


def fmt_stats(s, unit="px"):
    if not s["n"]:
        return "n=0"
    return f"median {s['median']:.3f} {unit}, p95 {s['p95']:.3f} {unit}, max {s['max']:.3f} {unit} (n={s['n']})"


def pct(c):
    return f"{c['found']}/{c['total']}" + (f" = {100 * c['found'] / c['total']:.1f}%" if c["total"] else "")


def print_summary(s):
    p = print
    p(f"frames {s['frames']}  (records missing {s['records_missing']}, unknown {s['records_unknown']}); "
      f"truth streaks {s['truth_streaks']}, record streaks {s['record_streaks']}")
    p(f"completeness: {pct(s['completeness'])};  visible >=100 px & SNR >=5: {pct(s['completeness_long_bright'])}")
    p(f"  with an edge end: {pct(s['completeness_edge'])};  both ends inside: {pct(s['completeness_inside'])}")
    p("  SNR \\ length " + "".join(f"{lab:>16}" for lab in LEN_LABELS))
    for a in SNR_LABELS:
        cells = []
        for b in LEN_LABELS:
            c = s["completeness_table"][a][b]
            cells.append(f"{c['found']}/{c['total']}" + (f" ({100 * c['found'] / c['total']:.0f}%)" if c["total"] else "     "))
        p(f"  {a:<13}" + "".join(f"{c:>16}" for c in cells))
    f = s["false_streaks"]
    p(f"false streaks: {f['total']} ({f['along_truth_streak']} lie along a truth streak: fragments/duplicates; "
      f"{f['total'] - f['along_truth_streak']} phantoms); "
      f"on frames without streaks: {f['on_frames_without_streaks']}, "
      f"{f['frames_without_streaks_with_false']}/{f['frames_without_streaks']} such frames have >= 1")
    if f["by_defect_on_frames_without_streaks"]:
        p("  frames without streaks, by defect: " + ", ".join(
            f"{k} {v['frames_with_false']}/{v['frames']} ({v['false_streaks']} false)"
            for k, v in sorted(f["by_defect_on_frames_without_streaks"].items())))
    if s["completeness_by_glint"]:
        p("  by light curve (all; >=100 px & SNR >=5): " + ", ".join(
            f"{k} {pct(v['all'])}; {pct(v['long_bright'])}" for k, v in s["completeness_by_glint"].items()))
    if f["lies_on"]:
        p("  false streaks lie on: " + ", ".join(f"{k} {v}" for k, v in sorted(f["lies_on"].items())))
    if f["by_defect_all_frames"]:
        p("  all false streaks by frame defect: " + ", ".join(f"{k} {v}" for k, v in sorted(f["by_defect_all_frames"].items())))
    p(f"end error (inside ends): {fmt_stats(s['end_error_px'])}")
    p(f"  along-track |d|: {fmt_stats(s['end_along_abs_px'])}; outward bias median "
      + (f"{s['end_along_outward_median_px']:+.3f} px" if s["end_along_outward_median_px"] is not None else "-"))
    p(f"  cross-track |d|: {fmt_stats(s['end_cross_abs_px'])}")
    p(f"  RA/Dec: {fmt_stats(s['end_radec_error_arcsec'], 'arcsec')}")
    e = s["edge_flags"]
    if e["total"]:
        p(f"edge flags agree: {e['agree']}/{e['total']} = {100 * e['fraction']:.1f}%  "
          f"(truth edge: rec edge {e['truth_edge_record_edge']}, rec inside {e['truth_edge_record_inside']}; "
          f"truth inside: rec edge {e['truth_inside_record_edge']}, rec inside {e['truth_inside_record_inside']})")
    t = s["end_times"]
    p(f"end times: {t['time_is_beg_or_end']}/{t['inside_ends_with_time']} inside ends at DATE-BEG or DATE-END (+-2 ms), "
      f"{t['inside_ends_time_null']} null; both-inside streaks with {{beg,end}}: "
      f"{t['both_inside_times_are_beg_and_end']}/{t['both_inside_streaks_with_times']}")
    p("stars:            frames solved  right IDs (mean/frame)  false IDs (frames)  detectable/frame  attitude err median")
    for k, lab in (("frames_with_streaks", "with streaks"), ("frames_without_streaks", "without streaks")):
        g = s["stars"][k]
        if not g["frames"]:
            p(f"  {lab:<15} 0")
            continue
        att = g["attitude_error_arcsec"]
        p(f"  {lab:<15} {g['frames']:>4} {g['solved']:>6}  {g['right_ids']:>7} ({g['mean_right_per_frame']:6.1f})"
          f"        {g['false_ids']:>5} ({g['frames_with_false_ids']:>3})"
          f"       {g['mean_detectable_stars_per_frame']:8.1f}"
          f"        " + (f"{att['median']:.1f}\"" if att["n"] else "-"))


def main(argv=None):
    ap = argparse.ArgumentParser(description="Score gpustar streak records against sim_streaks.py truth.")
    ap.add_argument("--truth", required=True, help="truth.jsonl from sim_streaks.py")
    ap.add_argument("records", help="gpustar records (JSON lines)")
    ap.add_argument("--json", help="write the full summary (with per-streak rows) here")
    ap.add_argument("--perp-tol", type=float, default=3.0, help="px (default 3)")
    ap.add_argument("--angle-tol", type=float, default=2.0, help="deg (default 2)")
    ap.add_argument("--min-overlap", type=float, default=0.5, help="fraction of the shorter segment (default 0.5)")
    ap.add_argument("--star-tol", type=float, default=3.0, help="px, star ID check (default 3)")
    args = ap.parse_args(argv)
    s = score(load_jsonl(args.truth), load_jsonl(args.records), args)
    print_summary(s)
    if args.json:
        with open(args.json, "w") as f:
            json.dump(s, f, indent=1)
    return s


if __name__ == "__main__":
    main()
