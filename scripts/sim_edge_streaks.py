#!/usr/bin/env python3
"""Streaks clipped by the frame's edge at every angle, and streaks that end just inside it:
an independent simulator of the `edge` flag's cases (issue 49, item 4), and its score.

    python3 scripts/sim_edge_streaks.py --out DIR -n 300 --seed 71 [--size 512]
    python3 scripts/sim_edge_streaks.py --score DIR RECORDS.jsonl

Written from the record spec alone (no gpustar code). Writes DIR/edge_NNNN.fits and
DIR/truth.jsonl; frame i depends only on (seed, i).

Model (another PSF, noise and brightness model than scripts/sim_streaks.py):
* PSF: a double Gaussian, core sigma s uniform 0.8..1.8 px per frame and a halo of 2.5 s
  holding 10 % of the light, integrated exactly over each pixel (erf differences), the track
  sampled every 0.05 px along its length.
* Detector: bias 100 ADU, sky 200..1000 ADU, Poisson noise on sky and signal, read noise 5 ADU,
  16-bit FITS (BZERO 32768). 20..60 point stars (peak SNR 5..200) anywhere.
* Track: peak SNR 6..30 on its centre line, length 60..400 px visible.
* A clipped streak (70 % of frames) leaves the frame through a random side at an angle to
  that side uniform in 2..90 deg (shallow crossings included), through a point at least
  20 px from the corners; its true end lies 0.5..40 px beyond the detector's edge (pixel
  edges at -0.5 and W-0.5). That end is `edge: true`. Its other end is inside, at least
  12 px from every edge.
* An inside streak (30 %) has one end near an edge: at a distance 3 s + 1.5 .. 12 px from it
  (its light stays on the frame: the core and most of the halo), the other at least 12 px
  from every edge. Both ends are `edge: false`.

Score: each truth streak is matched to the record streak whose ends lie within 3 px of its
line and whose direction agrees within 3 deg (the longest such); its ends are paired with the
truth's by distance (a clipped end by where its line leaves the frame). Prints how many
clipped ends are flagged `edge`, how many inside ends are not, and every disagreement.
"""
import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
from astropy.io import fits
from scipy.special import erf

HALO_FRACTION = 0.1
HALO_SCALE = 2.5


def pixel_integral(lo_edges, centre, sigma):
    """The share of a unit Gaussian (centre, sigma) in pixels [e, e+1) for each e."""
    a = (lo_edges - centre) / (math.sqrt(2) * sigma)
    b = (lo_edges + 1.0 - centre) / (math.sqrt(2) * sigma)
    return 0.5 * (erf(b) - erf(a))


def add_point(img, x, y, flux, s):
    """A point source of total `flux` at (x, y) with the double-Gaussian PSF."""
    h, w = img.shape
    r = int(math.ceil(HALO_SCALE * s * 5)) + 1
    x0, x1 = max(int(x) - r, 0), min(int(x) + r + 1, w)
    y0, y1 = max(int(y) - r, 0), min(int(y) + r + 1, h)
    if x0 >= x1 or y0 >= y1:
        return
    ex = np.arange(x0, x1) - 0.5
    ey = np.arange(y0, y1) - 0.5
    for frac, sg in ((1 - HALO_FRACTION, s), (HALO_FRACTION, HALO_SCALE * s)):
        px = pixel_integral(ex, x, sg)
        py = pixel_integral(ey, y, sg)
        img[y0:y1, x0:x1] += flux * frac * np.outer(py, px)


def add_track(img, p0, p1, density, s, step=0.1):
    """A uniform track from p0 to p1, `density` ADU per px of length, with the PSF."""
    length = math.dist(p0, p1)
    n = max(int(length / step), 1)
    t = (np.arange(n) + 0.5) / n
    xs = p0[0] + (p1[0] - p0[0]) * t
    ys = p0[1] + (p1[1] - p0[1]) * t
    f = density * length / n
    h, w = img.shape
    r = int(math.ceil(HALO_SCALE * s * 5)) + 1
    for x, y in zip(xs, ys):
        if -r <= x < w + r and -r <= y < h + r:
            add_point(img, x, y, f, s)


def peak_factor(theta, s):
    """The centre-line pixel value of a unit-density infinite track at angle theta: the
    cross-track profile's share in one pixel, near enough (the track runs through the
    pixel's centre)."""
    # The cross-track extent of a pixel grows from 1 (axis) to sqrt(2) (diagonal); the
    # profile is integrated over the pixel's mean cross-track width.
    width = 1.0 / max(abs(math.cos(theta)), abs(math.sin(theta)))
    v = 0.0
    for frac, sg in ((1 - HALO_FRACTION, s), (HALO_FRACTION, HALO_SCALE * s)):
        v += frac * erf(width / 2 / (math.sqrt(2) * sg))
    return v


def inside_by(p, w, h):
    """How far a point lies inside the detector (its edges at -0.5 and w-0.5)."""
    return min(p[0] + 0.5, w - 0.5 - p[0], p[1] + 0.5, h - 0.5 - p[1])


def boundary_point(side, u, w, h):
    """A point on the detector's edge: side 0 left, 1 right, 2 top (y = -0.5), 3 bottom."""
    return {0: (-0.5, u), 1: (w - 0.5, u), 2: (u, -0.5), 3: (u, h - 0.5)}[side]


def inward(side):
    return {0: (1.0, 0.0), 1: (-1.0, 0.0), 2: (0.0, 1.0), 3: (0.0, -1.0)}[side]


def clipped_geometry(rng, w, h):
    """A track leaving through a side at an angle alpha to it: (p_in, p_out, alpha)."""
    while True:
        side = int(rng.integers(4))
        span = h if side < 2 else w
        u = float(rng.uniform(20.0, span - 20.0))
        alpha = math.radians(float(rng.uniform(2.0, 90.0)))
        nx, ny = inward(side)
        # The in-plane direction along the side, either way.
        tx, ty = (-ny, nx) if rng.random() < 0.5 else (ny, -nx)
        # Into the frame: at alpha to the side.
        dx = nx * math.sin(alpha) + tx * math.cos(alpha)
        dy = ny * math.sin(alpha) + ty * math.cos(alpha)
        b = boundary_point(side, u, w, h)
        visible = float(rng.uniform(60.0, 400.0))
        beyond = float(rng.uniform(0.5, 40.0))
        p_in = (b[0] + dx * visible, b[1] + dy * visible)
        p_out = (b[0] - dx * beyond, b[1] - dy * beyond)
        if inside_by(p_in, w, h) >= 12.0 and inside_by(p_out, w, h) < 0:
            return p_in, p_out, math.degrees(alpha)


def inside_geometry(rng, w, h, s):
    """A track with one end near an edge, inside it: (p_near, p_far, distance of p_near)."""
    while True:
        side = int(rng.integers(4))
        span = h if side < 2 else w
        d = float(rng.uniform(3 * s + 1.5, 12.0))
        u = float(rng.uniform(20.0, span - 20.0))
        nx, ny = inward(side)
        b = boundary_point(side, u, w, h)
        p_near = (b[0] + nx * d, b[1] + ny * d)
        theta = float(rng.uniform(0, 2 * math.pi))
        length = float(rng.uniform(60.0, 400.0))
        p_far = (p_near[0] + length * math.cos(theta), p_near[1] + length * math.sin(theta))
        if inside_by(p_far, w, h) >= 12.0 and abs(inside_by(p_near, w, h) - d) < 1e-9:
            return p_near, p_far, d


def make_frame(seed, i, size):
    rng = np.random.default_rng([seed, i])
    w = h = size
    s = float(rng.uniform(0.8, 1.8))
    sky = float(rng.uniform(200.0, 1000.0))
    read = 5.0
    noise = math.sqrt(sky + read * read)
    img = np.zeros((h, w))
    for _ in range(int(rng.integers(20, 61))):
        x, y = rng.uniform(-5, w + 5), rng.uniform(-5, h + 5)
        peak = float(rng.uniform(5.0, 200.0)) * noise
        flux = peak / pixel_integral(np.array([-0.5]), 0.0, s)[0] ** 2
        add_point(img, x, y, flux, s)
    snr = float(rng.uniform(6.0, 30.0))
    if rng.random() < 0.7:
        p_in, p_out, alpha = clipped_geometry(rng, w, h)
        ends, edge, kind = (p_in, p_out), (False, True), {"angle_to_edge_deg": round(alpha, 3)}
    else:
        p_near, p_far, d = inside_geometry(rng, w, h, s)
        ends, edge, kind = (p_near, p_far), (False, False), {"near_end_inside_px": round(d, 3)}
    if rng.random() < 0.5:
        ends, edge = ends[::-1], edge[::-1]
    theta = math.atan2(ends[1][1] - ends[0][1], ends[1][0] - ends[0][0])
    density = snr * noise / peak_factor(theta, s)
    add_track(img, ends[0], ends[1], density, s)
    signal = img + sky
    counts = rng.poisson(np.clip(signal, 0, None)) + rng.normal(0.0, read, img.shape) + 100.0
    data = np.clip(np.round(counts), 0, 65535).astype(np.uint16)
    truth = {
        "p0": [round(ends[0][0], 4), round(ends[0][1], 4)],
        "p1": [round(ends[1][0], 4), round(ends[1][1], 4)],
        "edge0": edge[0],
        "edge1": edge[1],
        "peak_snr": round(snr, 3),
        "sigma_px": round(s, 4),
        **kind,
    }
    return data, {"file": f"edge_{i:04d}.fits", "width": w, "height": h, "streaks": [truth]}


def simulate(args):
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = []
    for i in range(args.n):
        data, truth = make_frame(args.seed, i, args.size)
        hdu = fits.PrimaryHDU(data)
        hdu.header["DATE-OBS"] = "2025-03-01T20:00:00"
        hdu.header["EXPTIME"] = 5.0
        hdu.writeto(out / truth["file"], overwrite=True)
        lines.append(json.dumps(truth))
    (out / "truth.jsonl").write_text("\n".join(lines) + "\n")
    print(f"{args.n} frames in {out}")


def leaves_at(p_in, p_out, w, h):
    """Where the segment from p_in (inside) towards p_out leaves the detector."""
    (x0, y0), (x1, y1) = p_in, p_out
    t = 1.0
    for a, b, lo, hi in ((x0, x1, -0.5, w - 0.5), (y0, y1, -0.5, h - 0.5)):
        if b < lo:
            t = min(t, (lo - a) / (b - a))
        if b > hi:
            t = min(t, (hi - a) / (b - a))
    return (x0 + t * (x1 - x0), y0 + t * (y1 - y0))


def line_distance(p, a, b):
    (x, y), (ax, ay), (bx, by) = p, a, b
    dx, dy = bx - ax, by - ay
    return abs((x - ax) * dy - (y - ay) * dx) / math.hypot(dx, dy)


def score(args):
    truths = {}
    for line in open(Path(args.score) / "truth.jsonl"):
        t = json.loads(line)
        truths[t["file"]] = t
    records = {}
    for line in open(args.records):
        r = json.loads(line)
        records[Path(r["file"]).name] = r
    found = clipped_ok = clipped_n = inside_ok = inside_n = 0
    bad = []
    for name, t in sorted(truths.items()):
        w, h = t["width"], t["height"]
        ts = t["streaks"][0]
        p0, p1 = ts["p0"], ts["p1"]
        # The visible ends: a clipped end where its line leaves the frame.
        v0 = leaves_at(p1, p0, w, h) if ts["edge0"] else tuple(p0)
        v1 = leaves_at(p0, p1, w, h) if ts["edge1"] else tuple(p1)
        tang = math.atan2(p1[1] - p0[1], p1[0] - p0[0])
        best = None
        for s in (records.get(name) or {}).get("streaks") or []:
            e = [(q["x"], q["y"]) for q in s["ends"]]
            if max(line_distance(q, p0, p1) for q in e) > 3.0:
                continue
            rang = math.atan2(e[1][1] - e[0][1], e[1][0] - e[0][0])
            diff = abs((math.degrees(rang - tang) + 90) % 180 - 90)
            if diff > 3.0:
                continue
            length = math.dist(*e)
            if best is None or length > best[0]:
                best = (length, s)
        if best is None:
            bad.append(f"{name}: not found ({ts})")
            continue
        found += 1
        ends = best[1]["ends"]
        e = [(q["x"], q["y"]) for q in ends]
        straight = math.dist(e[0], v0) + math.dist(e[1], v1)
        swapped = math.dist(e[1], v0) + math.dist(e[0], v1)
        order = [0, 1] if straight <= swapped else [1, 0]
        for k, truth_edge in enumerate((ts["edge0"], ts["edge1"])):
            q = ends[order[k]]
            v = (v0, v1)[k]
            flagged = bool(q.get("edge"))
            where = (f"end at ({q['x']:.1f}, {q['y']:.1f}), truth visible end "
                     f"({v[0]:.1f}, {v[1]:.1f}), {math.dist((q['x'], q['y']), v):.1f} px apart, "
                     f"sigma {ts['sigma_px']:.2f}")
            if truth_edge:
                clipped_n += 1
                clipped_ok += flagged
                if not flagged:
                    bad.append(f"{name}: clipped end not flagged, "
                               f"{ts.get('angle_to_edge_deg')} deg to the edge: {where}")
            else:
                inside_n += 1
                inside_ok += not flagged
                if flagged:
                    bad.append(f"{name}: inside end flagged edge "
                               f"({ts.get('near_end_inside_px', 'far')} px inside): {where}")
    print(f"streaks found: {found} / {len(truths)}")
    print(f"clipped ends flagged edge: {clipped_ok} / {clipped_n}")
    print(f"inside ends not flagged: {inside_ok} / {inside_n}")
    for b in bad:
        print("  " + b)
    return 0 if found == len(truths) and clipped_ok == clipped_n and inside_ok == inside_n else 1


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out")
    ap.add_argument("-n", type=int, default=300)
    ap.add_argument("--seed", type=int, default=71)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--score", help="a set's directory: score RECORDS against its truth")
    ap.add_argument("records", nargs="?")
    args = ap.parse_args()
    if args.score:
        sys.exit(score(args))
    if not args.out:
        ap.error("give --out DIR (simulate) or --score DIR RECORDS")
    simulate(args)


if __name__ == "__main__":
    main()
