#!/usr/bin/env python3
"""Each solved frame's centre against a plate solution fitted to its own identified stars by an
independent tool: astropy's fit_wcs_from_points (TAN + SIP).

    check_centre_wcs.py --records REC.jsonl [--truth DIR/truth.jsonl] [--sip-degree 3 5]
                        [--tolerance-deg 0.1] [--json OUT.json]

For every solved record: the matches' pixels (x, y) and catalog RA/Dec are handed to
astropy.wcs.utils.fit_wcs_from_points (projection TAN about the stars' mean direction, SIP
of each --sip-degree); the fitted WCS gives the direction of the image centre pixel ((W-1)/2, (H-1)/2),
which is what a record's ra_deg/dec_deg are (spec/INTERFACE.md). Reported per frame: the
angle between the record's centre and each fit's, the fit's own rms (arcsec), where the stars
lie (the fraction of the frame's width and height their bounding box spans, and the distance of
their mean from the centre, px), and with --truth (scripts/sim_frames.py's centre_ra_deg /
centre_dec_deg, else ra_deg/dec_deg) each one's angle from the truth. gpustar pixels are
0-based with (0, 0) the centre of the top-left pixel, as astropy's pixel coordinates.

Exit code 0 (a report) unless an input cannot be read. Needs numpy and astropy.
"""
import argparse
import json
import math
import sys
import warnings

import numpy as np
from astropy import units as u
from astropy.coordinates import SkyCoord
from astropy.utils import iers
from astropy.wcs.utils import fit_wcs_from_points

iers.conf.auto_download = False


def key(name):
    return str(name).replace("\\", "/").split("/")[-1]


def sep_deg(ra1, dec1, ra2, dec2):
    a = SkyCoord(ra1 * u.deg, dec1 * u.deg)
    b = SkyCoord(ra2 * u.deg, dec2 * u.deg)
    return float(a.separation(b).deg)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--records", required=True)
    ap.add_argument("--truth")
    ap.add_argument("--sip-degree", type=int, nargs="+", default=[3, 5])
    ap.add_argument("--tolerance-deg", type=float, default=0.1)
    ap.add_argument("--json")
    args = ap.parse_args(argv)

    recs = [json.loads(line) for line in open(args.records) if line.strip()]
    truth = {}
    if args.truth:
        for line in open(args.truth):
            if line.strip():
                t = json.loads(line)
                truth[key(t["file"])] = t
    rows = []
    for r in recs:
        if r.get("status") != "solved" or not r.get("matches"):
            continue
        m = r["matches"]
        x = np.array([s["x"] for s in m])
        y = np.array([s["y"] for s in m])
        world = SkyCoord(np.array([s["ra_deg"] for s in m]) * u.deg,
                         np.array([s["dec_deg"] for s in m]) * u.deg)
        # The tangent point: the stars' mean direction. astropy's "center" is the middle of
        # their RA and Dec ranges, which near a pole or across RA 0 is far from the field (the
        # TAN + SIP fit then fails by degrees).
        v = world.cartesian.xyz.value.mean(axis=1)
        centre = SkyCoord(math.degrees(math.atan2(v[1], v[0])) % 360.0 * u.deg,
                          math.degrees(math.atan2(v[2], math.hypot(v[0], v[1]))) * u.deg)
        t = truth.get(key(r["file"]))
        if t:
            w, h = t["width"], t["height"]
        else:
            # the record has no size: the centre is where the record's attitude puts it only
            # through the camera, so the size comes from the truth or a square guess
            w = h = int(round(max(x.max(), y.max()) + 1))
        xc, yc = (w - 1) / 2.0, (h - 1) / 2.0
        row = {"file": r["file"], "stars": len(m),
               "span_x": float((x.max() - x.min()) / w), "span_y": float((y.max() - y.min()) / h),
               "mean_off_centre_px": float(math.hypot(x.mean() - xc, y.mean() - yc))}
        for deg in args.sip_degree:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                wcs = fit_wcs_from_points((x, y), world, proj_point=centre, projection="TAN",
                                          sip_degree=deg if deg > 1 else None)
            c = wcs.pixel_to_world(xc, yc)
            back = wcs.pixel_to_world(x, y)
            row[f"sip{deg}_rms_arcsec"] = float(np.sqrt(np.mean(back.separation(world).arcsec ** 2)))
            row[f"sip{deg}_vs_record_deg"] = sep_deg(r["ra_deg"], r["dec_deg"], c.ra.deg, c.dec.deg)
            if t:
                tra, tdec = t.get("centre_ra_deg", t["ra_deg"]), t.get("centre_dec_deg", t["dec_deg"])
                row[f"sip{deg}_vs_truth_deg"] = sep_deg(tra, tdec, c.ra.deg, c.dec.deg)
        if t:
            tra, tdec = t.get("centre_ra_deg", t["ra_deg"]), t.get("centre_dec_deg", t["dec_deg"])
            row["record_vs_truth_deg"] = sep_deg(tra, tdec, r["ra_deg"], r["dec_deg"])
        rows.append(row)

    n_all = len(recs)
    print(f"{len(rows)} of {n_all} records solved with matches")
    for deg in args.sip_degree:
        d = np.array([row[f"sip{deg}_vs_record_deg"] for row in rows])
        fr = np.array([row[f"sip{deg}_rms_arcsec"] for row in rows])
        print(f"SIP {deg}: record centre vs astropy fit: median {3600 * np.median(d):.1f}\", "
              f"max {3600 * d.max():.1f}\" ({d.max():.4f} deg); within {args.tolerance_deg} deg: "
              f"{np.sum(d <= args.tolerance_deg)} / {len(rows)}; fit rms median {np.median(fr):.1f}\"")
        if args.truth:
            dt = np.array([row[f"sip{deg}_vs_truth_deg"] for row in rows])
            print(f"        astropy fit vs truth: median {3600 * np.median(dt):.1f}\", max {3600 * dt.max():.1f}\"")
    if args.truth:
        dr = np.array([row["record_vs_truth_deg"] for row in rows])
        print(f"record centre vs truth: median {3600 * np.median(dr):.1f}\", max {3600 * dr.max():.1f}\"")
    worst = sorted(rows, key=lambda row: -row[f"sip{args.sip_degree[0]}_vs_record_deg"])[:5]
    print("largest disagreements (first SIP degree):")
    for row in worst:
        print("  " + ", ".join(f"{k} {v:.4g}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(rows, f, indent=1)


if __name__ == "__main__":
    sys.exit(main())
