#!/usr/bin/env python3
"""Score gpustar's centroids and attitudes against the truth of scripts/sim_frames.py (issue 16).

    python3 scripts/score_centroids.py DIR/truth.jsonl cog.jsonl ml.jsonl [...]

For each records file: frames solved and wrong (attitude > 60" from the truth), the identified
stars' median centroid error (px) against the truth's positions, the median and p90 attitude
error ("), and for unsaturated stars of peak SNR >= 20 the error against the Cramer-Rao bound of
the same model (pixel-integrated Gaussian, Poisson + 5 e- read noise, 9x9 window, parameters
x0, y0, N, b, sigma; notes/sequences.md 3.3) with the truth's flux and sky: rms ratio and the
median-based one (median |e_x| / CRB / 0.6745). With --calibration: the median of
attitude error / attitude_sigma_arcsec (a Rayleigh's is 0.83 across the line of sight, |N|'s
0.67 in roll). Needs numpy.
"""
import argparse
import json
import math
from math import erf, exp, pi, sqrt

import numpy as np

READ_NOISE_E = 5.0  # scripts/sim_frames.py
WRONG_ARCSEC = 360.0  # gpustar evaluate --tolerance-deg 0.1


def star_key(s):
    """A star's identity in records and truth files: its catalog_id ("HIP 27989", "Gaia DR3 ...")
    where written, else its HIP (truth files of the Python simulators, older records)."""
    return s.get("catalog_id") or f"HIP {s['hip']}"


def crb_x(x0, y0, n, b, s, half=4):
    cx, cy = round(x0), round(y0)
    cdf = lambda u: 0.5 * (1 + erf(u / (s * sqrt(2))))
    pdf = lambda u: exp(-0.5 * (u / s) ** 2) / (s * sqrt(2 * pi))

    def axis(c, centre):
        out = []
        for k in range(c - half, c + half + 1):
            lo, hi = k - 0.5 - centre, k + 0.5 - centre
            out.append((cdf(hi) - cdf(lo), pdf(lo) - pdf(hi), (lo * pdf(lo) - hi * pdf(hi)) / s))
        return out

    info = np.zeros((5, 5))
    for py, dpy, spy in axis(cy, y0):
        for px, dpx, spx in axis(cx, x0):
            mu = b + n * px * py
            j = np.array([n * dpx * py, n * px * dpy, px * py, 1.0, n * (spx * py + px * spy)])
            info += np.outer(j, j) / (mu + READ_NOISE_E**2)
    return sqrt(np.linalg.inv(info)[0, 0])


def attitude_error_arcsec(a, b):
    d = np.array(a) @ np.array(b).T
    sin = np.linalg.norm([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]) / 2
    return math.degrees(math.atan2(sin, (np.trace(d) - 1) / 2)) * 3600


def roll_and_cross(a, b):
    """The error rotation's components about the boresight (camera z) and across it (")."""
    d = np.array(a) @ np.array(b).T
    w = np.array([d[2, 1] - d[1, 2], d[0, 2] - d[2, 0], d[1, 0] - d[0, 1]]) / 2
    to = lambda v: math.degrees(v) * 3600
    return to(abs(w[2])), to(math.hypot(w[0], w[1]))


def score(truth, path, calibration):
    frames = solved = wrong = 0
    errs, att, ex, crb, cal_b, cal_r = [], [], [], [], [], []
    for line in open(path):
        r = json.loads(line)
        t = truth[r["file"].split("/")[-1]]
        frames += 1
        if r.get("status") != "solved":
            continue
        e = attitude_error_arcsec(r["rotation_matrix"], t["rotation_matrix"])
        if e > WRONG_ARCSEC:
            wrong += 1
            continue
        solved += 1
        att.append(e)
        sig = r.get("attitude_sigma_arcsec")
        if calibration and sig:
            roll, cross = roll_and_cross(r["rotation_matrix"], t["rotation_matrix"])
            cal_b.append(cross / sig["boresight"])
            cal_r.append(roll / sig["roll"])
        stars = {star_key(s): s for s in t["stars"]}
        for m in r.get("matches") or []:
            s = stars.get(star_key(m))
            if not s:
                continue
            d = math.hypot(m["x"] - s["x"], m["y"] - s["y"])
            if d > 2:
                continue
            errs.append(d)
            if s["peak_snr"] >= 20 and not s.get("saturated"):
                ex.append(m["x"] - s["x"])
                crb.append(crb_x(s["x"], s["y"], s["flux_e"], t["sky_e"], t["psf_sigma_px"]))
    ex, crb = np.array(ex), np.array(crb)
    p90 = float(np.percentile(att, 90)) if att else float("nan")
    out = {
        "records": path,
        "frames": frames,
        "solved": solved,
        "wrong": wrong,
        "stars": len(errs),
        "centroid_median_px": float(np.median(errs)) if errs else float("nan"),
        "attitude_median_arcsec": float(np.median(att)) if att else float("nan"),
        "attitude_p90_arcsec": p90,
        "crb_stars": int(len(ex)),
        "error_over_crb_rms": float(np.sqrt(np.mean(ex**2)) / np.sqrt(np.mean(crb**2))) if len(ex) else float("nan"),
        "error_over_crb_median": float(np.median(np.abs(ex) / crb) / 0.6745) if len(ex) else float("nan"),
    }
    if calibration and cal_b:
        out["median_error_over_sigma_boresight"] = float(np.median(cal_b))
        out["median_error_over_sigma_roll"] = float(np.median(cal_r))
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("truth")
    ap.add_argument("records", nargs="+")
    ap.add_argument("--calibration", action="store_true")
    args = ap.parse_args()
    truth = {}
    for line in open(args.truth):
        t = json.loads(line)
        truth[t["file"]] = t
    for path in args.records:
        s = score(truth, path, args.calibration)
        print(
            f"{path}: solved {s['solved']}/{s['frames']} (wrong {s['wrong']}), {s['stars']} stars, "
            f"centroid median {s['centroid_median_px']:.4f} px, attitude median "
            f"{s['attitude_median_arcsec']:.2f}\" p90 {s['attitude_p90_arcsec']:.2f}\"; SNR>=20: "
            f"{s['crb_stars']} stars, error/CRB rms {s['error_over_crb_rms']:.3f} median-based "
            f"{s['error_over_crb_median']:.3f}"
            + (
                f"; error/sigma median {s['median_error_over_sigma_boresight']:.2f} boresight, "
                f"{s['median_error_over_sigma_roll']:.2f} roll"
                if "median_error_over_sigma_roll" in s
                else ""
            )
        )


if __name__ == "__main__":
    main()
