#!/usr/bin/env python3
"""Which plate model serves a long-focal-length frame (issue 24, item 4)? Held-out residuals of
four models fitted to gpustar's matched stars (record x, y against the catalog's RA/Dec):

  tan     gnomonic, linear CD matrix (astropy fit_wcs_from_points, no SIP)
  radial  gnomonic + radial k1 about the frame centre, focal length and attitude (scipy, our
          own fit: gpustar's model, fitted independently of gpustar)
  sip2    TAN-SIP of order 2 (astropy)
  sip3    TAN-SIP of order 3 (astropy): as many terms as seed 004's cubic tangent-plane
          polynomial

Five-fold cross-validation per frame (every fifth match held out in turn, the model fitted to
the other four fifths), so a model with more terms gains only where the frame's distortion has
them and the frame has the stars to fix them.
Centroid errors against the truth of scripts/sim_narrow.py are printed for scale.

Usage: python3 scripts/plate_models.py TRUTH_DIR RECORDS.jsonl [--min-matches 20]
"""
import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from astropy.coordinates import SkyCoord
from astropy.wcs.utils import fit_wcs_from_points
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation


FOLDS = 5


def unit(ra, dec):
    ra, dec = np.radians(ra), np.radians(dec)
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def fit_astropy(xy, radec, size, sip):
    coords = SkyCoord(radec[:, 0], radec[:, 1], unit="deg")
    w = fit_wcs_from_points((xy[:, 0], xy[:, 1]), coords, proj_point="center", sip_degree=sip)
    return lambda rd: np.stack(
        w.world_to_pixel(SkyCoord(rd[:, 0], rd[:, 1], unit="deg")), axis=-1)


def fit_radial(xy, radec, size, r0, f0):
    c = (np.array(size) - 1) / 2.0
    v = unit(radec[:, 0], radec[:, 1])

    def project(p, v):
        rot = Rotation.from_rotvec(p[:3]).as_matrix() @ r0
        cam = v @ rot.T
        u = cam[:, :2] / cam[:, 2:3]
        s = 1 + p[4] * (u ** 2).sum(axis=1, keepdims=True)
        return c + f0 * math.exp(p[3]) * u * s

    res = least_squares(lambda p: (project(p, v) - xy).ravel(), np.zeros(5), x_scale="jac")
    return lambda rd: project(res.x, unit(rd[:, 0], rd[:, 1]))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("truth_dir")
    ap.add_argument("records")
    ap.add_argument("--min-matches", type=int, default=20)
    a = ap.parse_args()
    truth = {}
    for line in open(Path(a.truth_dir) / "truth.jsonl"):
        if line.strip():
            t = json.loads(line)
            truth[t["file"]] = t
    sums = {m: [0.0, 0] for m in ("tan", "radial", "sip2", "sip3")}
    err2, nerr, frames = 0.0, 0, 0
    for line in open(a.records):
        r = json.loads(line)
        ms = r.get("matches") or []
        t = truth.get(Path(r["file"]).name)
        if r.get("status") != "solved" or len(ms) < a.min_matches or t is None:
            continue
        frames += 1
        size = (t["width"], t["height"])
        xy = np.array([[m["x"], m["y"]] for m in ms])
        rd = np.array([[m["ra_deg"], m["dec_deg"]] for m in ms])
        r0 = np.array(r["rotation_matrix"])
        for k in range(FOLDS):
            test_on = np.arange(len(ms)) % FOLDS == k
            fit_on = ~test_on
            models = {
                "tan": fit_astropy(xy[fit_on], rd[fit_on], size, None),
                "radial": fit_radial(xy[fit_on], rd[fit_on], size, r0, t["fx_px"]),
                "sip2": fit_astropy(xy[fit_on], rd[fit_on], size, 2),
                "sip3": fit_astropy(xy[fit_on], rd[fit_on], size, 3),
            }
            for name, predict in models.items():
                d = predict(rd[test_on]) - xy[test_on]
                sums[name][0] += float((d ** 2).sum())
                sums[name][1] += int(test_on.sum())
        by_id = {}
        for s in t["stars"]:
            by_id[str(s.get("source_id", s["catalog_id"]))] = s
        for m in ms:
            key = m["catalog_id"].replace("Gaia DR3 ", "")
            s = by_id.get(key)
            if s is not None and not s.get("saturated"):
                err2 += (m["x"] - s["x"]) ** 2 + (m["y"] - s["y"]) ** 2
                nerr += 1
    if frames == 0:
        print("no frame with enough matches")
        return 1
    noise = math.sqrt(err2 / nerr) if nerr else float("nan")
    print(f"{frames} frames with >= {a.min_matches} matches; rms centroid error against the "
          f"truth {noise:.4f} px (2-D, {nerr} stars)")
    print("model   held-out rms (px)   / centroid error")
    for name, (s2, n) in sums.items():
        rms = math.sqrt(s2 / n)
        print(f"{name:7s} {rms:12.4f}        {rms / noise:8.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
