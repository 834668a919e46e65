#!/usr/bin/env python3
"""Score gpustar --sequence records against scripts/sim_sequence.py truth.

Usage:
    python3 scripts/score_sequence.py --truth DIR/truth.jsonl --records REC.jsonl
            [--baseline BASE.jsonl] [--from-index 9] [--json OUT.json]

Definitions (every count is over the truth's frames; a frame without a record is "missing"
and counts as unsolved):
  * solved: status "solved" with a rotation_matrix; attitude error = angle of R_rec R_true^T
    (arcsec); wrong = solved with error > 60"; correct = solved and not wrong. "late" = frames
    with index >= --from-index (default 9: the 10th frame on), where tracking has settled.
  * particles: a record particle is a true positive when within 3.0 px of a truth particle of
    that frame, one-to-one, nearest pairs first. Precision = TP / reported. Recall is over the
    "detectable" truth particles (centre >= 3 px inside the border, i.e. in [3, W-4] x
    [3, H-4], and peak_snr >= 5): detectable ones matched / detectable. Unmatched reported
    particles within 3 px of a truth star are "stars flagged as particles"; within 1.5 px of a
    hot pixel, "hot pixels flagged". "Precision (>= 3 px inside)" counts only the reports in
    that same area: the truth lists particles whose centre is in the frame, while the simulator
    still renders a departed one whose light touches it, so a report on the border row may be a
    true particle the truth does not hold.
  * stars identified on particles: matches within 2.0 px of a truth particle and not within
    2.0 px of the truth star of that HIP (must be 0).
  * star IDs: a match whose HIP is in the frame's truth stars is correct within 2 px of that
    star's truth position, wrong beyond; a HIP not in the truth list is "unverified" (the truth
    lists only stars with centre in the frame, Hp <= 6; no catalog is read here).
  * with --baseline (records of the same files without --sequence): "worse" = baseline
    correct and the record unsolved, wrong, or with fewer stars_matched than the baseline.

Exit code 0 (a report) unless an input cannot be read. Needs only numpy.
"""
import argparse
import json
import math
import sys
from collections import defaultdict

import numpy as np

WRONG_ARCSEC = 60.0
PARTICLE_TOL_PX = 3.0
BORDER_PX = 3.0
DETECTABLE_SNR = 5.0
STAR_TOL_PX = 2.0
HOT_TOL_PX = 1.5
MODES = ("tracking", "lost_in_space", "missing")


# ----------------------------------------------------------------------------- input

def star_key(s):
    """A star's identity in records and truth files: its catalog_id ("HIP 27989", "Gaia DR3 ...")
    where written, else its HIP (truth files of the Python simulators, older records)."""
    return s.get("catalog_id") or f"HIP {s['hip']}"


def load_jsonl(path):
    """JSON objects of a JSON Lines file; bad lines are skipped with a warning."""
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


def key(name):
    """seq_NNN/frame_NNN.fits from whatever prefix a record's path carries."""
    parts = str(name).replace("\\", "/").split("/")
    return "/".join(parts[-2:])


def index_records(records):
    out = {}
    for r in records:
        out[key(r.get("file", ""))] = r  # later lines win, like a re-run appended
    return out


# ----------------------------------------------------------------------------- helpers

def rotation_angle_arcsec(a, b):
    """Angle of the rotation a b^T (arcsec), from both its sine and cosine (accurate when small)."""
    m = np.asarray(a, float) @ np.asarray(b, float).T
    s = 0.5 * math.sqrt((m[2, 1] - m[1, 2]) ** 2 + (m[0, 2] - m[2, 0]) ** 2 + (m[1, 0] - m[0, 1]) ** 2)
    c = 0.5 * (np.trace(m) - 1.0)
    return math.degrees(math.atan2(s, c)) * 3600.0


def stats(vals, pct=95):
    v = np.asarray([x for x in vals if x is not None and math.isfinite(x)], float)
    if v.size == 0:
        return {"n": 0, "median": None, f"p{pct}": None, "max": None}
    return {"n": int(v.size), "median": float(np.median(v)), f"p{pct}": float(np.percentile(v, pct)),
            "max": float(v.max())}


def median(vals):
    v = [x for x in vals if x is not None]
    return float(np.median(v)) if v else None


def ratio(a, b):
    return a / b if b else None


def is_solved(rec):
    return rec is not None and rec.get("status") == "solved" and rec.get("rotation_matrix") is not None


def attitude_error(rec, truth):
    return rotation_angle_arcsec(rec["rotation_matrix"], truth["rotation_matrix"]) if is_solved(rec) else None


def identify_ms(rec):
    t = (rec or {}).get("timing_ms") or {}
    v = t.get("identify")
    return float(v) if v is not None else None


def near(x, y, pts, tol):
    return any(math.hypot(x - a, y - b) <= tol for a, b in pts)


def match_one_to_one(rec_pts, truth_pts, tol):
    """Greedy nearest-first one-to-one pairs within tol: {record index: truth index}."""
    cands = []
    for i, (x, y) in enumerate(rec_pts):
        for j, (a, b) in enumerate(truth_pts):
            d = math.hypot(x - a, y - b)
            if d <= tol:
                cands.append((d, i, j))
    cands.sort()
    pairs, used_t = {}, set()
    for _, i, j in cands:
        if i in pairs or j in used_t:
            continue
        pairs[i] = j
        used_t.add(j)
    return pairs


def inside(x, y, w, h):
    """At least BORDER_PX inside the border."""
    return BORDER_PX <= x <= w - 1 - BORDER_PX and BORDER_PX <= y <= h - 1 - BORDER_PX


def detectable(p, w, h):
    return (inside(p["x"], p["y"], w, h)
            and p.get("peak_snr", 0.0) >= DETECTABLE_SNR)


# ----------------------------------------------------------------------------- per frame

def score_frame(t, rec):
    """Everything this report needs from one truth frame and its record (or None)."""
    w, h = t["width"], t["height"]
    err = attitude_error(rec, t)
    out = {"file": t["file"], "index": t["index"], "sequence": t.get("sequence"),
           "status": (rec or {}).get("status", "missing"), "solved": err is not None, "error_arcsec": err,
           "wrong": err is not None and err > WRONG_ARCSEC}
    out["correct"] = out["solved"] and not out["wrong"]
    mode = (rec or {}).get("sequence_mode")
    out["mode"] = mode if mode in ("tracking", "lost_in_space") else "missing"
    out["identify_ms"] = identify_ms(rec)

    # particles
    tp_list = t.get("particles", [])
    tpts = [(p["x"], p["y"]) for p in tp_list]
    rparts = (rec or {}).get("particles")
    out["has_particles_field"] = rparts is not None
    rpts = [(float(p["x"]), float(p["y"])) for p in (rparts or [])]
    pairs = match_one_to_one(rpts, tpts, PARTICLE_TOL_PX)
    det = [j for j, p in enumerate(tp_list) if detectable(p, w, h)]
    matched_t = set(pairs.values())
    stars_xy = [(s["x"], s["y"]) for s in t["stars"]]
    hot = [tuple(p) for p in t.get("hot_pixels", [])]
    unmatched = [rpts[i] for i in range(len(rpts)) if i not in pairs]
    inner = [i for i, (x, y) in enumerate(rpts) if inside(x, y, w, h)]
    out.update({
        "reported": len(rpts), "tp": len(pairs), "truth_particles": len(tp_list),
        "inner_reported": len(inner), "inner_tp": sum(i in pairs for i in inner),
        "detectable": len(det), "detectable_found": sum(j in matched_t for j in det),
        "flagged_stars": sum(near(x, y, stars_xy, PARTICLE_TOL_PX) for x, y in unmatched),
        "flagged_hot": sum(near(x, y, hot, HOT_TOL_PX) for x, y in unmatched),
    })

    # identified stars
    truth_by_id = {star_key(s): (s["x"], s["y"]) for s in t["stars"]}
    on_particle = correct_ids = wrong_ids = unverified = on_hot = 0
    wrong_list = []
    for m in (rec or {}).get("matches") or []:
        x, y, hip = float(m["x"]), float(m["y"]), m["hip"]
        own = truth_by_id.get(star_key(m))
        at_own = own is not None and math.hypot(x - own[0], y - own[1]) <= STAR_TOL_PX
        if not at_own and near(x, y, tpts, STAR_TOL_PX):
            on_particle += 1
        if not at_own and near(x, y, hot, HOT_TOL_PX):
            on_hot += 1
        if own is None:
            unverified += 1
        elif at_own:
            correct_ids += 1
        else:
            wrong_ids += 1
            wrong_list.append(hip)
    out.update({"ids_on_particles": on_particle, "ids_on_hot_pixels": on_hot, "ids_correct": correct_ids,
                "ids_wrong": wrong_ids, "ids_unverified": unverified, "wrong_hips": wrong_list,
                "stars_matched": (rec or {}).get("stars_matched")})
    return out


# ----------------------------------------------------------------------------- aggregation

def summarise(frames):
    """Totals over a list of per-frame results."""
    n = len(frames)
    solved = sum(f["solved"] for f in frames)
    correct = sum(f["correct"] for f in frames)
    rep = sum(f["reported"] for f in frames)
    tp = sum(f["tp"] for f in frames)
    det = sum(f["detectable"] for f in frames)
    found = sum(f["detectable_found"] for f in frames)
    return {
        "frames": n, "solved": solved, "correct": correct, "wrong": sum(f["wrong"] for f in frames),
        "unsolved": n - solved, "missing": sum(f["status"] == "missing" for f in frames),
        "solved_frac": ratio(solved, n), "correct_frac": ratio(correct, n),
        "error_arcsec": stats([f["error_arcsec"] for f in frames if f["solved"]]),
        "particles": {"reported": rep, "tp": tp, "precision": ratio(tp, rep), "truth": sum(f["truth_particles"] for f in frames),
                      "inner_precision": ratio(sum(f["inner_tp"] for f in frames), sum(f["inner_reported"] for f in frames)),
                      "detectable": det, "detectable_found": found, "recall": ratio(found, det),
                      "flagged_stars": sum(f["flagged_stars"] for f in frames),
                      "flagged_hot_pixels": sum(f["flagged_hot"] for f in frames),
                      "records_without_field": sum(not f["has_particles_field"] and f["status"] != "missing" for f in frames)},
        "ids": {k: sum(f[f"ids_{k}"] for f in frames) for k in ("correct", "wrong", "unverified", "on_particles", "on_hot_pixels")},
    }


def mode_summary(frames):
    by = defaultdict(list)
    for f in frames:
        by[f["mode"]].append(f)
    return {m: {"frames": len(by[m]), "correct": sum(f["correct"] for f in by[m]),
                "identify_ms_median": median([f["identify_ms"] for f in by[m]])} for m in MODES}


def per_index(frames):
    by = defaultdict(list)
    for f in frames:
        by[f["index"]].append(f)
    return {i: {"n": len(by[i]), "correct_frac": ratio(sum(f["correct"] for f in by[i]), len(by[i])),
                "wrong": sum(f["wrong"] for f in by[i])} for i in sorted(by)}


def compare_baseline(truth, recs, base):
    """Frames the sequence mode made worse than the single-frame baseline, and the two's
    timing and attitude agreement."""
    worse, diffs = [], []
    for t in truth:
        r, b = recs.get(key(t["file"])), base.get(key(t["file"]))
        eb, er = attitude_error(b, t), attitude_error(r, t)
        b_ok = eb is not None and eb <= WRONG_ARCSEC
        r_ok = er is not None and er <= WRONG_ARCSEC
        if b_ok:
            why = None
            if er is None:
                why = "unsolved"
            elif not r_ok:
                why = f"wrong ({er:.0f}\")"
            elif (r.get("stars_matched") or 0) < (b.get("stars_matched") or 0):
                why = f"stars_matched {r.get('stars_matched')} < {b.get('stars_matched')}"
            if why:
                worse.append({"file": t["file"], "why": why})
        if b_ok and r_ok:
            diffs.append(rotation_angle_arcsec(r["rotation_matrix"], b["rotation_matrix"]))
    files = [key(t["file"]) for t in truth]
    return {
        "worse": len(worse), "worse_files": worse[:10],
        "baseline_correct": sum(1 for t in truth if (e := attitude_error(base.get(key(t["file"])), t)) is not None and e <= WRONG_ARCSEC),
        "identify_ms_median_baseline": median([identify_ms(base.get(f)) for f in files if f in base]),
        "identify_ms_median_records": median([identify_ms(recs.get(f)) for f in files if f in recs]),
        "both_correct": len(diffs),
        "attitude_diff_arcsec_median": median(diffs), "attitude_diff_arcsec_max": max(diffs) if diffs else None,
    }


# ----------------------------------------------------------------------------- report

def fmt(v, spec=".1f", none="-"):
    return none if v is None else format(v, spec)


def pct(v):
    return "-" if v is None else f"{100 * v:.1f}%"


def print_report(res, from_index):
    late, alll = res["late"], res["all"]
    print(f"{'':30} {'index >= ' + str(from_index):>16} {'all frames':>16}")

    def row(label, a, b):
        print(f"{label:30} {a:>16} {b:>16}")

    row("frames", late["frames"], alll["frames"])
    row("solved", f"{late['solved']} ({pct(late['solved_frac'])})", f"{alll['solved']} ({pct(alll['solved_frac'])})")
    row("correct (<= 60\")", f"{late['correct']} ({pct(late['correct_frac'])})", f"{alll['correct']} ({pct(alll['correct_frac'])})")
    row("wrong (> 60\")", late["wrong"], alll["wrong"])
    row("missing records", late["missing"], alll["missing"])
    for k in ("median", "p95", "max"):
        row(f"attitude error {k} (\")", fmt(late["error_arcsec"][k], ".2f"), fmt(alll["error_arcsec"][k], ".2f"))
    lp, ap_ = late["particles"], alll["particles"]
    row("particles reported", lp["reported"], ap_["reported"])
    row("  true positives", lp["tp"], ap_["tp"])
    row("  precision", pct(lp["precision"]), pct(ap_["precision"]))
    row("  precision (>= 3 px inside)", pct(lp["inner_precision"]), pct(ap_["inner_precision"]))
    row("  detectable truth", lp["detectable"], ap_["detectable"])
    row("  recall (detectable)", pct(lp["recall"]), pct(ap_["recall"]))
    row("  stars flagged as particles", lp["flagged_stars"], ap_["flagged_stars"])
    row("  hot pixels flagged", lp["flagged_hot_pixels"], ap_["flagged_hot_pixels"])
    if ap_["records_without_field"]:
        row("  records without 'particles'", lp["records_without_field"], ap_["records_without_field"])
    li, ai = late["ids"], alll["ids"]
    row("star IDs on particles (=0!)", li["on_particles"], ai["on_particles"])
    row("star IDs on hot pixels", li["on_hot_pixels"], ai["on_hot_pixels"])
    row("star IDs correct", li["correct"], ai["correct"])
    row("star IDs wrong (> 2 px)", li["wrong"], ai["wrong"])
    row("star IDs unverified", li["unverified"], ai["unverified"])

    print("\nsequence_mode (all frames): " + ", ".join(
        f"{m} {v['frames']} (correct {v['correct']}, identify median {fmt(v['identify_ms_median'], '.2f')} ms)"
        for m, v in res["modes"].items()))

    if "baseline" in res:
        b = res["baseline"]
        print(f"\nbaseline: correct {b['baseline_correct']}; worse with --sequence: {b['worse']}")
        for w in b["worse_files"]:
            print(f"  {w['file']}: {w['why']}")
        print(f"identify median: baseline {fmt(b['identify_ms_median_baseline'], '.2f')} ms, "
              f"records {fmt(b['identify_ms_median_records'], '.2f')} ms")
        print(f"correct in both: {b['both_correct']}; attitude difference median "
              f"{fmt(b['attitude_diff_arcsec_median'], '.2f')}\", max {fmt(b['attitude_diff_arcsec_max'], '.2f')}\"")

    pi = res["per_index"]
    print("\ncorrect fraction per frame index: " + " ".join(
        f"{i}:{fmt(v['correct_frac'], '.2f')}" for i, v in pi.items()))
    wrong = {i: v["wrong"] for i, v in pi.items() if v["wrong"]}
    if wrong:
        print("wrong per frame index: " + " ".join(f"{i}:{n}" for i, n in wrong.items()))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--truth", required=True)
    ap.add_argument("--records", required=True)
    ap.add_argument("--baseline")
    ap.add_argument("--from-index", type=int, default=9)
    ap.add_argument("--json")
    a = ap.parse_args(argv)
    try:
        truth = load_jsonl(a.truth)
        recs = index_records(load_jsonl(a.records))
        base = index_records(load_jsonl(a.baseline)) if a.baseline else None
    except OSError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    if not truth:
        print(f"error: no truth lines in {a.truth}", file=sys.stderr)
        return 2
    unknown = set(recs) - {key(t["file"]) for t in truth}
    if unknown:
        print(f"warning: {len(unknown)} records for files not in the truth (e.g. {sorted(unknown)[0]})", file=sys.stderr)

    frames = [score_frame(t, recs.get(key(t["file"]))) for t in truth]
    res = {"from_index": a.from_index,
           "late": summarise([f for f in frames if f["index"] >= a.from_index]),
           "all": summarise(frames), "modes": mode_summary(frames), "per_index": per_index(frames)}
    if base is not None:
        res["baseline"] = compare_baseline(truth, recs, base)
    print_report(res, a.from_index)
    if a.json:
        with open(a.json, "w") as f:
            json.dump(res, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main())
