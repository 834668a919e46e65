#!/usr/bin/env python3
"""How well does each real frame's truth attitude agree with itself?

    python3 scripts/truth_check.py [REAL_DIR] [--records DIR] [--min-deg 0.05]

For every frame of REAL_DIR (default ../shared/data/real) the truth gives a rotation matrix
(camera X axis = image right, from the astrometry.net WCS at the centre), a roll
(`roll_tetra3_deg`: from image up, the Y axis) and the identified stars (pixel, HIP). Printed
per frame, for square-pixel frames (the roll comparison assumes square pixels):

  roll_diff   the matrix's roll minus roll_tetra3 (deg): the WCS's axis skew at the centre;
  star_fit    the angle (deg) between the matrix and the pinhole attitude fitted (Wahba, SVD)
              to the truth's own identified stars at the truth's centre scale;
  truth_px    the median distance (pixels) between the truth's identified stars and their
              catalog positions projected through the matrix (pinhole, centre scale);
with --records DIR (DIR/<set>.jsonl, as scripts/real_sets.sh writes them), also
  ours        the angle (deg) between the record's attitude and the matrix;
  ours_fit    the angle (deg) between the record's attitude and the pinhole fit of the truth's
              stars that the record identified (the same stars, the truth's pixel positions);
  ours_px     truth_px with the record's attitude in place of the matrix.

Frames where |roll_diff| or star_fit exceed --min-deg are marked '*'. Needs numpy and
../shared/catalog/hip2.dat (positions moved to the truth epoch by proper motion).
"""
import argparse
import json
import math
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent


def catalog(path):
    """HIP -> (RA rad, Dec rad, pmRA mas/yr, pmDE mas/yr) at J1991.25 (hip2.dat columns)."""
    out = {}
    for line in open(path):
        f = line.split()
        out[int(f[0])] = (float(f[4]), float(f[5]), float(f[7]), float(f[8]))
    return out


def unit(ra, de):
    return np.array([math.cos(de) * math.cos(ra), math.cos(de) * math.sin(ra), math.sin(de)])


def at_epoch(star, epoch):
    ra, de, pmra, pmde = star
    dt = epoch - 1991.25
    mas = math.radians(1 / 3.6e6)
    return unit(ra + pmra * mas * dt / math.cos(de), de + pmde * mas * dt)


def wahba(cam, sky):
    """The rotation R (sky -> camera) that best maps the sky vectors onto the camera vectors."""
    u, _, vt = np.linalg.svd(np.asarray(sky).T @ np.asarray(cam))
    d = np.sign(np.linalg.det(u @ vt))
    return (u @ np.diag([1, 1, d]) @ vt).T


def angle_deg(a, b):
    c = (np.trace(a @ b.T) - 1) / 2
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def roll_deg(r):
    """tetra3's roll of a rotation matrix: image up to celestial north, counter-clockwise."""
    north = r[:, 2]
    return (math.degrees(math.atan2(north[0], north[1])) + 180) % 360


def median_px(r, sky, pixels, f, cx, cy):
    """Median distance (px) between `pixels` and the `sky` vectors projected through r
    (pinhole of focal length f, centre (cx, cy))."""
    v = np.asarray(sky) @ r.T
    proj = np.stack([cx + f * v[:, 0] / v[:, 2], cy + f * v[:, 1] / v[:, 2]], axis=1)
    return float(np.median(np.hypot(*(proj - pixels).T)))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("real", nargs="?", default=str(HERE / "../../shared/data/real"))
    ap.add_argument("--records", help="directory of <set>.jsonl records")
    ap.add_argument("--min-deg", type=float, default=0.05)
    a = ap.parse_args()
    real = Path(a.real)
    hip = catalog(real / "../../catalog/hip2.dat")
    print(
        f"{'set/file':44} {'stars':>5} {'roll_diff':>9} {'star_fit':>8} {'truth_px':>8} "
        f"{'ours':>6} {'ours_fit':>8} {'ours_px':>7}"
    )
    for truth_file in sorted(real.glob("*/truth.jsonl")):
        records = {}
        if a.records:
            path = Path(a.records) / f"{truth_file.parent.name}.jsonl"
            if path.exists():
                for line in open(path):
                    r = json.loads(line)
                    records[r["file"].rsplit("/", 1)[-1]] = r
        for line in open(truth_file):
            t = json.loads(line)
            if abs(t["scale_x_arcsec_per_px"] / t["scale_y_arcsec_per_px"] - 1) > 0.01:
                continue
            truth = np.array(t["rotation_matrix"])
            f = math.radians(1 / 3600) ** -1 / t["scale_x_arcsec_per_px"]
            cx, cy = (t["width"] - 1) / 2, (t["height"] - 1) / 2
            stars = [s for s in t["stars"] if s["hip"] in hip]
            cam = [np.array([s["x"] - cx, s["y"] - cy, f]) / math.hypot(s["x"] - cx, s["y"] - cy, f) for s in stars]
            sky = [at_epoch(hip[s["hip"]], t["epoch"]) for s in stars]
            fit = wahba(cam, sky)
            pixels = np.array([[s["x"], s["y"]] for s in stars])

            roll_diff = (roll_deg(truth) - t["roll_tetra3_deg"] + 180) % 360 - 180
            star_fit = angle_deg(fit, truth)
            ours = ours_fit = ours_px = ""
            rec = records.get(t["file"])
            if rec and rec.get("status") == "solved":
                r = np.array(rec["rotation_matrix"])
                ours = f"{angle_deg(r, truth):.3f}"
                ours_px = f"{median_px(r, sky, pixels, f, cx, cy):.2f}"
                ids = {m["hip"] for m in rec["matches"]}
                same = [k for k, s in enumerate(stars) if s["hip"] in ids]
                if len(same) >= 3:
                    ours_fit = f"{angle_deg(r, wahba([cam[k] for k in same], [sky[k] for k in same])):.3f}"
            mark = "*" if max(abs(roll_diff), star_fit) > a.min_deg else ""
            name = f"{truth_file.parent.name}/{t['file']}"[:44]
            print(
                f"{name:44} {len(stars):5} {roll_diff:9.3f} {star_fit:8.3f} {median_px(truth, sky, pixels, f, cx, cy):8.2f} "
                f"{ours:>6} {ours_fit:>8} {ours_px:>7} {mark}"
            )


if __name__ == "__main__":
    main()
