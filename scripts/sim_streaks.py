#!/usr/bin/env python3
"""Independent simulator of ground optical-tracking frames with satellite streaks.

Written from the spec alone (no gpustar code or model), so that gpustar's streak detection,
endpoint astrometry and Az/El chain are tested against something that does not share its
assumptions.

Usage:
    python3 scripts/sim_streaks.py --out DIR -n 300 --seed 1 [--fov-deg 12 --size 1024]
            [--no-streak-fraction 0.2] [--defects] [--glints] [--hard-negatives] [-j 2]

Writes DIR/frame_NNNN.fits, DIR/truth.jsonl (one JSON object per frame) and DIR/camera.toml.
Frame i depends only on (seed, i), so -j does not change the output.

Model
-----
* Camera: pinhole, square pixels, no distortion. Principal point ((W-1)/2, (H-1)/2),
  fx = fy = (W/2)/tan(fov_x/2). Pixels: x = column, y = row, 0-based, centre of the top-left
  pixel = (0, 0). Camera +X = increasing column, +Y = increasing row, +Z = boresight;
  R maps ICRS unit vectors to camera (v_cam = R v_icrs); x = cx + fx X/Z, y = cy + fy Y/Z.
* Attitude: uniform random rotation (normalised 4-D Gaussian quaternion). Exposure start:
  uniform UTC instant in [2020-01-01, 2024-06-30]; exposure time uniform 2..20 s.
* Stars: Hipparcos-2 (the Hp <= 8 stars of catalog/hip2_hp9.csv, or a --catalog file's, ICRS at
  J1991.25), proper motion applied on the tangent plane to mid-exposure; every star is rendered
  (also those just off the frame whose halo reaches in). No aberration/refraction: the "sky" is
  the catalogue itself, so a plate solution maps pixels straight to catalogue ICRS, as
  gpustar's RA/Dec claim.
* Photometry: the zero point is set per frame so that a Hp 6.0 star centred on a pixel has
  peak SNR 8 (peak noise-free signal / sqrt(sky + read^2), all in electrons); each star's flux
  gets lognormal scatter (sigma 0.15 in ln). Exposure time does not scale the flux (only the
  streak timing), so the SNR scale is the same on every frame.
* PSF: Moffat, beta = 3, FWHM uniform 2.2..3.2 px per frame, integrated over each pixel by
  5x5 sub-samples.
* Detector: sky 300..800 e-/px plus a linear gradient (0..10% from the centre to the edge), Poisson
  noise on sky + signal, Gaussian read noise 8 e-, gain 1 e-/ADU, bias 500 ADU, rounded and
  clipped to uint16 [0, 65535] (a clipped star is flagged "saturated").
* Streaks (on 1 - no-streak-fraction of the frames): 1 streak, 2 with p = 0.3, or with p = 0.1
  a "train" of 2-3 parallel streaks 15-40 px apart (same direction and length). An object
  moves at constant speed from P0 (exposure start) to P1 (exposure end); its image is the PSF
  integrated along the segment. The along-track integral of a beta = 3 Moffat has a closed
  form, so the trail is the exact continuous integral (the limit of ever finer sub-steps),
  then integrated over each pixel by 5x5 sub-samples like the stars.
  Length |P1-P0| log-uniform 40..1200 px, direction uniform. With p = 0.5 both ends are inside
  (when that length/direction fits); otherwise at least one end is off the frame: on 30% of
  those the segment crosses the frame entirely (ends on both sides of a random chord shorter
  than it), else a point of the segment is placed uniformly in the frame and the segment
  slid along its line until an end is off. An end inside the frame is >= 3 px from the
  border (pixel-centre box [3, W-4]); an end "outside" (edge = true) is off the detector
  (x < -0.5 or x > W-0.5, same for y), so there is no ambiguous band. The visible part must be
  >= 20 px long.
  Peak SNR uniform 3..25, defined as the noise-free value of a pixel whose centre lies on the
  track centre line far from the ends (the infinite-line profile, pixel-integrated with the
  same 5x5 sub-samples, at the track's angle), divided by sqrt(sky + read^2) with the sky at
  the midpoint of the visible part.
* Defects (--defects, ~30% of frames, one each): hot column, saturated star with a vertical
  bleed trail, cosmic-ray track (sharp, no PSF), chain of 5-7 false point sources 6-15 px
  apart, 20 hot pixels. Listed per frame in truth "defects" (with their parameters).
* Glints (--glints): each streak gets a light curve, one of five equally often (draw_glint):
  steady, periodic, irregular, with gaps, with flashes; rendered as uniform pieces 1 px long
  at the light curve's mean over each. The peak SNR is the nominal level's (median 1).
* Hard negatives (--hard-negatives, every frame): 1-3 chains of stars, a defective column
  (hot, cold or a warm pair) with p = 0.5, hot pixels with p = 0.3 (add_hard_negatives).
  Both options draw from their own random stream: without them a frame is as before.
* FITS: uint16 (BITPIX 16, BZERO 32768), DATE-BEG/DATE-END/DATE-OBS (ms), EXPTIME, TIMESYS;
  station as OBSGEO-B/L/H (~80%), SITELAT/SITELONG/SITEELEV (~10%) or none (~10%); ~5% of
  frames in TT (DATE-* converted from the true UTC with astropy). A TAN WCS (CD matrix) of the
  true attitude is written and checked against astropy.wcs on every frame.
"""
import argparse
import csv
import json
import math
import sys
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np

# astropy is only needed for the time scales and the FITS/WCS I/O; keep it offline.
from astropy.utils import iers

iers.conf.auto_download = False
from astropy import units  # noqa: E402
from astropy.io import fits  # noqa: E402
from astropy.time import Time  # noqa: E402
from astropy.wcs import WCS  # noqa: E402

DEFAULT_CATALOG = Path(__file__).resolve().parent.parent / "catalog" / "hip2_hp9.csv"
# The stars drawn from it: those of the Hp <= 8 catalog the repository shipped before, so that
# every set made since is made again byte for byte (a --catalog file is read whole).
DEFAULT_CATALOG_MAX_MAG = 8.0

BETA = 3.0
READ_NOISE = 8.0  # e-
GAIN = 1.0  # e-/ADU
BIAS = 500.0  # ADU
SAT_ADU = 65535
SUB = 5  # sub-samples per pixel axis for pixel integration
SUB_OFF = (np.arange(SUB) + 0.5) / SUB - 0.5  # sub-sample offsets from the pixel centre
INSIDE_MARGIN = 3.0  # an inside end is at least this far from the border (pixel centres)
MIN_VISIBLE = 20.0  # px: shorter visible parts are re-drawn (not a streak anyone could see)
EPOCH_CAT_JYEAR = 1991.25
PIECE_PX = 1.0  # a modulated trail is rendered as uniform pieces this long
GLINT_KINDS = ["steady", "periodic", "irregular", "gaps", "flashes"]

# Worker globals (filled once per process; fork shares them copy-on-write).
CAT = None


# ----------------------------------------------------------------------------- geometry

def random_rotation(rng):
    """Uniform random rotation: a normalised 4-D Gaussian is a uniform unit quaternion."""
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def radec_to_vec(ra, dec):
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def vec_to_radec_deg(v):
    v = np.asarray(v, float)
    ra = math.degrees(math.atan2(v[1], v[0])) % 360.0
    dec = math.degrees(math.asin(max(-1.0, min(1.0, v[2] / np.linalg.norm(v)))))
    return ra, dec


class Camera:
    def __init__(self, width, height, fov_x_deg):
        self.w, self.h = width, height
        self.fx = self.fy = (width / 2.0) / math.tan(math.radians(fov_x_deg) / 2.0)
        self.cx, self.cy = (width - 1) / 2.0, (height - 1) / 2.0

    def project(self, R, v):
        """ICRS unit vectors (N,3) -> pixel x, y and camera Z (x,y meaningless where Z <= 0)."""
        c = v @ R.T
        z = c[:, 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.cx + self.fx * c[:, 0] / z
            y = self.cy + self.fy * c[:, 1] / z
        return x, y, z

    def pixel_to_icrs(self, R, x, y):
        d = np.array([(x - self.cx) / self.fx, (y - self.cy) / self.fy, 1.0])
        return R.T @ (d / np.linalg.norm(d))


def clip_segment(p0, p1, xmin, xmax, ymin, ymax):
    """Liang-Barsky: the part of p0->p1 inside the box, as (q0, q1) or None."""
    x0, y0 = p0
    dx, dy = p1[0] - x0, p1[1] - y0
    t0, t1 = 0.0, 1.0
    for p, q in ((-dx, x0 - xmin), (dx, xmax - x0), (-dy, y0 - ymin), (dy, ymax - y0)):
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


# ----------------------------------------------------------------------------- PSF

def moffat_alpha(fwhm):
    return fwhm / (2.0 * math.sqrt(2.0 ** (1.0 / BETA) - 1.0))


def moffat(r2, alpha):
    """Unit-flux Moffat surface brightness at squared radius r2."""
    return (BETA - 1.0) / (math.pi * alpha * alpha) * (1.0 + r2 / (alpha * alpha)) ** (-BETA)


def moffat_radius(flux, alpha, floor=0.02, rmin=6, rmax=80):
    """Stamp half-size where the profile falls below `floor` e-/px (keeps faint stars cheap)."""
    # flux * (2/(pi a^2)) * (1+r^2/a^2)^-3 = floor
    k = flux * (BETA - 1.0) / (math.pi * alpha * alpha) / floor
    r = alpha * math.sqrt(max(k, 1.0) ** (1.0 / BETA) - 1.0) if k > 1 else 0.0
    return int(min(max(math.ceil(r), rmin), rmax))


def render_point(img, x, y, flux, alpha, rad=None):
    """Add a pixel-integrated Moffat of total `flux` centred at (x, y); returns the peak added."""
    h, w = img.shape
    if rad is None:
        rad = moffat_radius(flux, alpha)
    ix, iy = int(round(x)), int(round(y))
    x0, x1 = max(ix - rad, 0), min(ix + rad + 1, w)
    y0, y1 = max(iy - rad, 0), min(iy + rad + 1, h)
    if x0 >= x1 or y0 >= y1:
        return 0.0
    # sub-sample grid: (rows, SUB) x (cols, SUB)
    dx = (np.arange(x0, x1)[:, None] + SUB_OFF[None, :]).ravel() - x
    dy = (np.arange(y0, y1)[:, None] + SUB_OFF[None, :]).ravel() - y
    prof = moffat(dy[:, None] ** 2 + dx[None, :] ** 2, alpha)
    stamp = flux * prof.reshape(y1 - y0, SUB, x1 - x0, SUB).mean(axis=(1, 3))
    img[y0:y1, x0:x1] += stamp
    return float(stamp.max())


def _line_antiderivative(wv, a2):
    """Antiderivative in w of 1/(a^2 + w^2)^3 (closed form, beta = 3)."""
    a = np.sqrt(a2)
    s = a2 + wv * wv
    return wv / (4 * a2 * s * s) + 3 * wv / (8 * a2 * a2 * s) + 3 / (8 * a2 * a2 * a) * np.arctan(wv / a)


def line_profile(d, alpha):
    """Infinite-line profile (per unit line flux density) of the beta=3 Moffat at distance d."""
    return 0.75 * alpha ** 4 / (alpha * alpha + d * d) ** 2.5


def streak_peak_factor(theta, alpha):
    """Pixel-integrated centre-line value of a unit-density infinite line at angle theta.

    This is what turns a requested peak SNR into a line flux density; it uses the same 5x5
    sub-samples as the renderer so the truth SNR describes the rendered image."""
    nx, ny = -math.sin(theta), math.cos(theta)
    ox, oy = np.meshgrid(SUB_OFF, SUB_OFF)
    return float(line_profile(np.abs(ox * nx + oy * ny), alpha).mean())


def render_streak(img, p0, p1, density, alpha, brightness=None):
    """Add the image of an object moving uniformly from p0 to p1 (line density e-/px).

    brightness: optional function of the distance along the track from p0 (px, numpy array)
    giving the object's relative brightness there (a tumbling object's light curve, a glint,
    a gap where it is dark); the trail is then the sum of pieces at most PIECE_PX long, each
    the exact integral of a uniform piece at the mean brightness over it (from 8 samples)."""
    if brightness is not None:
        p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
        L = float(np.linalg.norm(p1 - p0))
        n = max(int(math.ceil(L / PIECE_PX)), 1)
        edges = np.linspace(0.0, L, n + 1)
        for a, b in zip(edges[:-1], edges[1:]):
            m = float(np.mean(brightness(a + (np.arange(8) + 0.5) / 8 * (b - a))))
            if m > 0:
                render_streak(img, p0 + (p1 - p0) * (a / L), p0 + (p1 - p0) * (b / L), density * m, alpha)
        return
    h, w = img.shape
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    L = float(np.linalg.norm(p1 - p0))
    u = (p1 - p0) / L
    n = np.array([-u[1], u[0]])
    # half-width of the band where the line profile exceeds 0.02 e-/px
    k = 0.75 * alpha ** 4 * density / 0.02
    rcut = max(8.0, math.sqrt(max(k ** 0.4 - alpha * alpha, 0.0)))
    rcut = min(rcut, 60.0)
    vis = clip_segment(p0, p1, -rcut, w - 1 + rcut, -rcut, h - 1 + rcut)
    if vis is None:
        return
    (ax, ay), (bx, by) = vis
    x0 = max(int(math.floor(min(ax, bx) - rcut)), 0)
    x1 = min(int(math.ceil(max(ax, bx) + rcut)) + 1, w)
    y0 = max(int(math.floor(min(ay, by) - rcut)), 0)
    y1 = min(int(math.ceil(max(ay, by) + rcut)) + 1, h)
    if x0 >= x1 or y0 >= y1:
        return
    # select pixels within rcut (+1 for the pixel's own extent) of the segment first, so a long
    # diagonal streak costs its band, not its bounding box
    yy, xx = np.mgrid[y0:y1, x0:x1]
    rx, ry = xx - p0[0], yy - p0[1]
    s = rx * u[0] + ry * u[1]
    d = rx * n[0] + ry * n[1]
    sc = np.clip(s, 0.0, L)
    dist2 = (s - sc) ** 2 + d * d
    sel = dist2 <= (rcut + 1.0) ** 2
    py, px = yy[sel], xx[sel]
    s, d = s[sel], d[sel]
    # sub-samples of each selected pixel, in the segment's (s, d) frame
    ox, oy = np.meshgrid(SUB_OFF, SUB_OFF)
    ox, oy = ox.ravel(), oy.ravel()
    ss = s[:, None] + ox[None, :] * u[0] + oy[None, :] * u[1]
    dd = d[:, None] + ox[None, :] * n[0] + oy[None, :] * n[1]
    a2 = alpha * alpha + dd * dd
    integ = _line_antiderivative(L - ss, a2) - _line_antiderivative(-ss, a2)
    # (beta-1)/(pi alpha^2) * alpha^(2 beta) = 2 alpha^4 / pi for beta = 3
    val = density * (2.0 * alpha ** 4 / math.pi) * integ.mean(axis=1)
    np.add.at(img, (py, px), val)


# ----------------------------------------------------------------------------- streak geometry

def inside_box(p, w, h, m=INSIDE_MARGIN):
    return m <= p[0] <= w - 1 - m and m <= p[1] <= h - 1 - m


def off_detector(p, w, h):
    return p[0] < -0.5 or p[0] > w - 0.5 or p[1] < -0.5 or p[1] > h - 0.5


def valid_end(p, w, h):
    """An end is either clearly inside (>= margin) or off the detector, never in between."""
    return inside_box(p, w, h) or off_detector(p, w, h)


def visible_part(p0, p1, w, h):
    return clip_segment(p0, p1, 0.0, w - 1.0, 0.0, h - 1.0)


def streak_ok(p0, p1, w, h):
    if not (valid_end(p0, w, h) and valid_end(p1, w, h)):
        return False
    vis = visible_part(p0, p1, w, h)
    return vis is not None and math.dist(vis[0], vis[1]) >= MIN_VISIBLE


def _inside_range(lo, hi, d):
    """Range of start coordinates for which start and start + d both lie in [lo, hi]."""
    return lo - min(0.0, d), hi - max(0.0, d)


def draw_geometry(rng, w, h, n_parallel=1, spacing=0.0):
    """Draw P0/P1 for one streak or a train of parallel ones; returns a list of (p0, p1).

    Length and direction are drawn first and kept (so lengths stay log-uniform and directions
    uniform); then both-ends-inside is chosen with p = 0.5 where that length/direction fits at
    all, else the segment gets at least one end off the frame."""
    offs = (np.arange(n_parallel) - (n_parallel - 1) / 2.0) * spacing
    omax = float(np.abs(offs).max())
    for _ in range(100):
        L = math.exp(rng.uniform(math.log(40.0), math.log(1200.0)))
        th = rng.uniform(0.0, 2 * math.pi)
        u = np.array([math.cos(th), math.sin(th)])
        n = np.array([-u[1], u[0]])
        # train members are offset along the normal; shrink the box so they all fit
        m = INSIDE_MARGIN + omax
        xr = _inside_range(m, w - 1 - m, L * u[0])
        yr = _inside_range(m, h - 1 - m, L * u[1])
        fits_inside = xr[0] <= xr[1] and yr[0] <= yr[1]
        want_inside = fits_inside and rng.random() < 0.5
        # sliding a random segment rarely makes it cross the whole frame (~2%), so ask for
        # that explicitly on part of the edge cases
        want_cross = not want_inside and rng.random() < 0.3
        for _try in range(1 if want_inside else 3000):
            if want_inside:
                p0 = np.array([rng.uniform(*xr), rng.uniform(*yr)])
                p1 = p0 + L * u
            elif want_cross:
                c = np.array([rng.uniform(0, w - 1), rng.uniform(0, h - 1)])
                chord = clip_segment(c - 4 * (w + h) * u, c + 4 * (w + h) * u, -0.5, w - 0.5, -0.5, h - 0.5)
                lc = math.dist(*chord)
                if L - lc < 0.01:
                    continue
                # start before the chord and end after it, both strictly off the detector
                t = rng.uniform(-(L - lc) + 1e-3, -1e-3)
                p0 = np.asarray(chord[0]) + t * u
                p1 = p0 + L * u
            else:
                # a point of the line uniform in the frame, the segment slid along the line
                c = np.array([rng.uniform(0, w - 1), rng.uniform(0, h - 1)])
                f = rng.random()
                p0, p1 = c - f * L * u, c + (1 - f) * L * u
                if not (off_detector(p0, w, h) or off_detector(p1, w, h)):
                    continue
            segs = [(p0 + o * n, p1 + o * n) for o in offs]
            if all(streak_ok(a, b, w, h) for a, b in segs):
                return segs
    raise RuntimeError("could not place a streak")


# ----------------------------------------------------------------------------- glints

def draw_glint(rng, L, kind=None):
    """A tumbling object's light along a track of length L (px from the exposure start's end).

    Returns (truth dict, brightness function of the distance along the track, or None for a
    steady object). The brightness is relative to the streak's nominal level (its peak SNR):
    * periodic: 1 + m sin(2 pi s / P + phi), depth m 0.3..1, period P log-uniform 12..300 px
      (a spinning body's light curve; at m = 1 it falls to 0 once a period);
    * irregular: exp of smoothed Gaussian noise (correlation length 4..60 px, 0.3..0.8 in ln),
      scaled to median 1 (an irregular tumbler);
    * gaps: steady, dark on 1..3 intervals of 4..20 % of the track each (at least 10 px), all
      between 15 % and 85 % of it (eclipses, a shadowed face; both ends lit);
    * flashes: steady at 1 with 2..8 glints of 2..8 times that, Gaussian in time, sigma
      0.3..4 px along the track (specular glints, many shorter than the PSF).
    """
    kind = kind or GLINT_KINDS[int(rng.integers(len(GLINT_KINDS)))]
    if kind == "steady":
        return {"kind": kind}, None
    if kind == "periodic":
        m = float(rng.uniform(0.3, 1.0))
        period = math.exp(rng.uniform(math.log(12.0), math.log(300.0)))
        phi = float(rng.uniform(0, 2 * math.pi))
        return ({"kind": kind, "depth": round(m, 3), "period_px": round(period, 2), "phase": round(phi, 3)},
                lambda x: 1.0 + m * np.sin(2 * math.pi * x / period + phi))
    if kind == "irregular":
        ell = float(rng.uniform(4.0, 60.0))
        sd = float(rng.uniform(0.3, 0.8))
        n = int(math.ceil(L)) + 1
        k = np.arange(-int(3 * ell), int(3 * ell) + 1)
        ker = np.exp(-0.5 * (k / ell) ** 2)
        g = np.convolve(rng.normal(size=n + 2 * len(k)), ker, mode="same")[len(k):len(k) + n]
        g = (g - g.mean()) / max(g.std(), 1e-9) * sd
        b = np.exp(g)
        b /= np.median(b)
        grid = np.arange(n, dtype=float)
        return ({"kind": kind, "corr_px": round(ell, 2), "sigma_ln": round(sd, 3)},
                lambda x: np.interp(x, grid, b))
    if kind == "gaps":
        gaps = []
        for _ in range(int(rng.integers(1, 4))):
            for _try in range(50):
                g = max(float(rng.uniform(0.04, 0.2)) * L, 10.0)
                a = float(rng.uniform(0.15 * L, 0.85 * L - g))
                if a >= 0.15 * L and all(a > e + 4 or a + g < b - 4 for b, e in gaps):
                    gaps.append((a, a + g))
                    break
        gaps.sort()
        iv = np.array(gaps) if gaps else np.zeros((0, 2))

        def bright(x):
            x = np.asarray(x, float)
            dark = np.zeros(x.shape, bool)
            for a, b in iv:
                dark |= (x >= a) & (x < b)
            return np.where(dark, 0.0, 1.0)
        return {"kind": kind, "gaps_px": [[round(a, 2), round(b, 2)] for a, b in gaps]}, bright
    if kind == "flashes":
        k = int(rng.integers(2, 9))
        at = rng.uniform(0.05 * L, 0.95 * L, k)
        amp = rng.uniform(2.0, 8.0, k)
        wid = rng.uniform(0.3, 4.0, k)
        return ({"kind": kind, "at_px": [round(float(v), 2) for v in at], "amp": [round(float(v), 2) for v in amp],
                 "sigma_px": [round(float(v), 2) for v in wid]},
                lambda x: 1.0 + sum(a * np.exp(-0.5 * ((np.asarray(x, float) - c) / w) ** 2)
                                    for c, a, w in zip(at, amp, wid)))
    raise ValueError(f"unknown glint kind {kind}")


# ----------------------------------------------------------------------------- hard negatives

def add_hard_negatives(rng, signal, post, W, H, alpha, centred_peak, sigma_at):
    """Things that are not streaks, on every frame (--hard-negatives): 1..3 chains of stars,
    a defective column with p = 0.5, 20 hot pixels with p = 0.3. Returns their truth.

    Chains: 4..14 point sources along a line (jitter 0.3 px across it), spaced 5..25 px
    (dense chains, 5..9 px, overlap in their wings), each with its own peak SNR (a chain's
    brightness drawn 5..40, each star 0.5..1.5 times it): as close to a flashing streak as
    point sources get. Columns: a hot column (+50..2000 ADU) over 60 px to the whole height,
    or a cold one (-50..-300 ADU), or a 2-pixel-wide warm pair (+30..300 ADU)."""
    out = []
    for _ in range(int(rng.integers(1, 4))):
        m = int(rng.integers(4, 15))
        sp = float(rng.uniform(5.0, 9.0)) if rng.random() < 0.4 else float(rng.uniform(9.0, 25.0))
        th = rng.uniform(0, 2 * math.pi)
        ext = (m - 1) * sp
        if ext > min(W, H) - 60:
            m = int((min(W, H) - 60) // sp) + 1
            ext = (m - 1) * sp
        cx = float(rng.uniform(20 + ext / 2, W - 20 - ext / 2))
        cy = float(rng.uniform(20 + ext / 2, H - 20 - ext / 2))
        x0, y0 = cx - ext / 2 * math.cos(th), cy - ext / 2 * math.sin(th)
        level = float(rng.uniform(5.0, 40.0))
        pts = []
        for j in range(m):
            jit = float(rng.normal(0.0, 0.3))
            x = x0 + j * sp * math.cos(th) - jit * math.sin(th)
            y = y0 + j * sp * math.sin(th) + jit * math.cos(th)
            snr = level * float(rng.uniform(0.5, 1.5))
            render_point(signal, x, y, snr * sigma_at(x, y) / centred_peak, alpha)
            pts.append([round(x, 3), round(y, 3)])
        out.append({"type": "star_chain", "points": pts, "spacing_px": round(sp, 2), "peak_snr": round(level, 2)})
    if rng.random() < 0.5:
        x = int(rng.integers(0, W))
        if rng.random() < 0.5:
            y0, y1 = 0, H - 1
        else:
            y0 = int(rng.integers(0, H - 60))
            y1 = int(rng.integers(y0 + 60, H))
        r = rng.random()
        if r < 0.4:
            kind, adu, cols = "hot_column", float(rng.uniform(50, 2000)), [x]
        elif r < 0.7:
            kind, adu, cols = "cold_column", -float(rng.uniform(50, 300)), [x]
        else:
            kind, adu, cols = "warm_pair", float(rng.uniform(30, 300)), [x, min(x + 1, W - 1)]
        out.append({"type": kind, "x": x, "y0": y0, "y1": y1, "adu": round(adu, 1)})
        for c in cols:
            post.append(("add", (slice(y0, y1 + 1), c), adu))
    if rng.random() < 0.3:
        xs_ = rng.integers(0, W, 20)
        ys_ = rng.integers(0, H, 20)
        adus = rng.uniform(300, 30000, 20)
        out.append({"type": "hot_pixels", "pixels": [[int(a), int(b)] for a, b in zip(xs_, ys_)]})
        for a, b, c in zip(xs_, ys_, adus):
            post.append(("add", (int(b), int(a)), float(c)))
    return out


# ----------------------------------------------------------------------------- frame

def load_catalog(path):
    # the header comments contain commas, so skip them before handing the rest to csv
    with open(path) as f:
        rd = csv.DictReader(line for line in f if not line.startswith("#"))
        cols = {k: [] for k in ("hip", "ra_rad", "dec_rad", "pmra_mas_yr", "pmdec_mas_yr", "hp_mag")}
        for row in rd:
            for k in cols:
                cols[k].append(float(row[k]))
    rows = {k: np.array(v) for k, v in cols.items()}
    if Path(path).resolve() == DEFAULT_CATALOG:
        shipped = rows["hp_mag"] <= DEFAULT_CATALOG_MAX_MAG
        rows = {k: v[shipped] for k, v in rows.items()}
    ra, dec = rows["ra_rad"], rows["dec_rad"]
    u = radec_to_vec(ra, dec)
    e_ra = np.stack([-np.sin(ra), np.cos(ra), np.zeros_like(ra)], axis=-1)
    e_dec = np.stack([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)], axis=-1)
    mas = math.radians(1.0 / 3.6e6)
    # pmra already includes cos(dec): a tangent-plane velocity in rad/yr
    vel = (rows["pmra_mas_yr"] * mas)[:, None] * e_ra + (rows["pmdec_mas_yr"] * mas)[:, None] * e_dec
    return {"hip": rows["hip"].astype(int), "u": u, "vel": vel, "mag": rows["hp_mag"]}


def iso_ms(t):
    """ISO time rounded to the millisecond (the header's precision)."""
    t = t.copy()
    t.precision = 3
    return t.isot


def make_wcs_header(cam, R):
    """TAN WCS of the true attitude (FITS 1-based pixels, CD in deg/px)."""
    b = R[2]  # boresight in ICRS
    ra0, dec0 = vec_to_radec_deg(b)
    ra, dec = math.radians(ra0), math.radians(dec0)
    east = np.array([-math.sin(ra), math.cos(ra), 0.0])
    north = np.array([-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec)])
    # X/Z = (cx.e) xi + (cx.n) eta, same for Y; M is orthogonal, so the inverse is M^T
    M = np.array([[R[0] @ east, R[0] @ north], [R[1] @ east, R[1] @ north]])
    cd = np.degrees(M.T @ np.diag([1.0 / cam.fx, 1.0 / cam.fy]))
    hdr = {
        "WCSAXES": 2, "CTYPE1": "RA---TAN", "CTYPE2": "DEC--TAN", "CUNIT1": "deg", "CUNIT2": "deg",
        "CRPIX1": cam.cx + 1.0, "CRPIX2": cam.cy + 1.0, "CRVAL1": ra0, "CRVAL2": dec0,
        "CD1_1": cd[0, 0], "CD1_2": cd[0, 1], "CD2_1": cd[1, 0], "CD2_2": cd[1, 1],
        "RADESYS": "ICRS",
    }
    return hdr


def simulate_frame(i, args):
    rng = np.random.default_rng([args.seed, i])
    # --glints and --hard-negatives draw from their own stream, so frames made without them
    # are the same as before they existed.
    rng2 = np.random.default_rng([args.seed, i, 2])
    W = H = args.size
    cam = Camera(W, H, args.fov_deg)
    R = random_rotation(rng)

    # --- time
    t_lo = Time("2020-01-01T00:00:00", scale="utc")
    t_hi = Time("2024-06-30T00:00:00", scale="utc")
    t_beg = t_lo + rng.uniform(0, (t_hi - t_lo).to_value(units.s)) * units.s
    # whole milliseconds, so that header, truth and record times can agree exactly
    t_beg = Time(iso_ms(t_beg), format="isot", scale="utc")
    exptime = round(float(rng.uniform(2.0, 20.0)), 3)
    t_end = Time(iso_ms(t_beg + exptime * units.s), format="isot", scale="utc")
    t_mid_jyear = (t_beg.jyear + t_end.jyear) / 2.0

    # --- frame parameters
    fwhm = float(rng.uniform(2.2, 3.2))
    alpha = moffat_alpha(fwhm)
    sky0 = float(rng.uniform(300.0, 800.0))
    gdir = rng.uniform(0, 2 * math.pi)
    gfrac = rng.uniform(0.0, 0.10)  # fractional sky change from the centre to the edge
    gx = sky0 * gfrac * math.cos(gdir) / (W / 2.0)
    gy = sky0 * gfrac * math.sin(gdir) / (H / 2.0)

    def sky_at(x, y):
        return sky0 + gx * (x - cam.cx) + gy * (y - cam.cy)

    def sigma_at(x, y):
        return math.sqrt(sky_at(x, y) + READ_NOISE ** 2)

    # zero point: a centred Hp 6 star has peak SNR 8 at the frame's mean sky
    centred_peak = float(moffat(np.add.outer(SUB_OFF ** 2, SUB_OFF ** 2), alpha).mean())
    flux6 = 8.0 * math.sqrt(sky0 + READ_NOISE ** 2) / centred_peak

    signal = np.zeros((H, W))

    # --- stars
    dt = t_mid_jyear - EPOCH_CAT_JYEAR
    u = CAT["u"] + dt * CAT["vel"]
    u /= np.linalg.norm(u, axis=1)[:, None]
    sx, sy, sz = cam.project(R, u)
    flux = flux6 * 10 ** (-0.4 * (CAT["mag"] - 6.0)) * np.exp(rng.normal(0.0, 0.15, size=len(sx)))
    near = (sz > 0) & (sx > -90) & (sx < W + 89) & (sy > -90) & (sy < H + 89)
    stars = []
    for k in np.nonzero(near)[0]:
        rad = moffat_radius(flux[k], alpha)
        if not (-rad - 1 < sx[k] < W + rad and -rad - 1 < sy[k] < H + rad):
            continue
        stamp = np.zeros((2 * rad + 3, 2 * rad + 3))
        ix, iy = int(round(sx[k])), int(round(sy[k]))
        # render on a private stamp so the star's own peak (for its SNR) is known
        peak = render_point(stamp, sx[k] - ix + rad + 1, sy[k] - iy + rad + 1, flux[k], alpha, rad)
        ys, xs = iy - rad - 1, ix - rad - 1
        a0, b0 = max(ys, 0), max(xs, 0)
        a1, b1 = min(ys + stamp.shape[0], H), min(xs + stamp.shape[1], W)
        signal[a0:a1, b0:b1] += stamp[a0 - ys:a1 - ys, b0 - xs:b1 - xs]
        if -0.5 <= sx[k] <= W - 0.5 and -0.5 <= sy[k] <= H - 0.5:
            stars.append({"hip": int(CAT["hip"][k]), "x": round(float(sx[k]), 4), "y": round(float(sy[k]), 4),
                          "mag": round(float(CAT["mag"][k]), 4),
                          "peak_snr": round(peak / sigma_at(sx[k], sy[k]), 3), "_peak_e": peak})

    # --- streaks
    streaks = []
    if rng.random() >= args.no_streak_fraction:
        r = rng.random()
        if r < 0.1:
            groups = [draw_geometry(rng, W, H, int(rng.integers(2, 4)), float(rng.uniform(15.0, 40.0)))]
        elif r < 0.1 + 0.9 * 0.3:
            groups = [draw_geometry(rng, W, H), draw_geometry(rng, W, H)]
        else:
            groups = [draw_geometry(rng, W, H)]
        train_id = 0
        for g in groups:
            for p0, p1 in g:
                vis = visible_part(p0, p1, W, H)
                vmid = ((vis[0][0] + vis[1][0]) / 2, (vis[0][1] + vis[1][1]) / 2)
                snr = float(rng.uniform(3.0, 25.0))
                theta = math.atan2(p1[1] - p0[1], p1[0] - p0[0])
                density = snr * sigma_at(*vmid) / streak_peak_factor(theta, alpha)
                glint, bright = (draw_glint(rng2, float(np.linalg.norm(p1 - p0)))
                                 if getattr(args, "glints", False) else (None, None))
                render_streak(signal, p0, p1, density, alpha, bright)
                ra0, dec0 = vec_to_radec_deg(cam.pixel_to_icrs(R, *p0))
                ra1, dec1 = vec_to_radec_deg(cam.pixel_to_icrs(R, *p1))
                s = {"p0": [round(float(p0[0]), 4), round(float(p0[1]), 4)],
                     "p1": [round(float(p1[0]), 4), round(float(p1[1]), 4)],
                     "edge0": bool(off_detector(p0, W, H)), "edge1": bool(off_detector(p1, W, H)),
                     "visible": [[round(vis[0][0], 4), round(vis[0][1], 4)], [round(vis[1][0], 4), round(vis[1][1], 4)]],
                     "visible_length_px": round(math.dist(vis[0], vis[1]), 3),
                     "length_px": round(float(np.linalg.norm(p1 - p0)), 3),
                     "peak_snr": round(snr, 3),
                     "ra0_deg": ra0, "dec0_deg": dec0, "ra1_deg": ra1, "dec1_deg": dec1,
                     "flux_e": round(density * float(np.linalg.norm(p1 - p0)), 1)}
                if glint is not None:
                    s["glint"] = glint
                if len(g) > 1:
                    s["train"] = train_id
                streaks.append(s)
            if len(g) > 1:
                train_id += 1

    # --- defects that are light (added before the noise)
    defects = []
    post = []  # defects applied in ADU after digitisation
    if args.defects and rng.random() < 0.3:
        kind = ["hot_column", "bleed", "cosmic_ray", "false_chain", "hot_pixels"][int(rng.integers(5))]
        if kind == "hot_column":
            x = int(rng.integers(0, W))
            if rng.random() < 0.5:
                y0, y1 = 0, H - 1
            else:
                y0 = int(rng.integers(0, H - 50))
                y1 = int(rng.integers(y0 + 50, H))
            adu = float(rng.uniform(200, 2000))
            defects.append({"type": kind, "x": x, "y0": y0, "y1": y1, "adu": round(adu, 1)})
            post.append(("add", (slice(y0, y1 + 1), x), adu))
        elif kind == "bleed":
            x = float(rng.uniform(40, W - 41))
            y = float(rng.uniform(160, H - 161))
            # bright enough that the core saturates by a wide margin
            fl = float(rng.uniform(3e6, 3e7))
            render_point(signal, x, y, fl, alpha)
            up, down = int(rng.integers(20, 151)), int(rng.integers(20, 151))
            ix, iy = int(round(x)), int(round(y))
            defects.append({"type": kind, "x": round(x, 3), "y": round(y, 3), "flux_e": round(fl),
                            "bleed_y0": iy - up, "bleed_y1": iy + down})
            post.append(("set", (slice(iy - up, iy + down + 1), ix), SAT_ADU))
        elif kind == "cosmic_ray":
            ln = float(rng.uniform(2, 12))
            th = rng.uniform(0, 2 * math.pi)
            x0, y0 = float(rng.uniform(20, W - 20)), float(rng.uniform(20, H - 20))
            tt = np.linspace(0, ln, int(ln * 2) + 2)
            px = np.round(x0 + tt * math.cos(th)).astype(int)
            py = np.round(y0 + tt * math.sin(th)).astype(int)
            pix = sorted(set(zip(py.tolist(), px.tolist())))
            adu = float(rng.uniform(300, 5000))
            defects.append({"type": kind, "x0": round(x0, 2), "y0": round(y0, 2),
                            "x1": round(x0 + ln * math.cos(th), 2), "y1": round(y0 + ln * math.sin(th), 2),
                            "adu": round(adu, 1)})
            for py_, px_ in pix:
                post.append(("add", (py_, px_), adu * rng.uniform(0.6, 1.0)))
        elif kind == "false_chain":
            m = int(rng.integers(5, 8))
            sp = float(rng.uniform(6, 15))
            th = rng.uniform(0, 2 * math.pi)
            ext = (m - 1) * sp
            # centre the chain so that it stays >= 20 px from the border
            x0 = float(rng.uniform(20 + ext / 2, W - 20 - ext / 2)) - ext / 2 * math.cos(th)
            y0 = float(rng.uniform(20 + ext / 2, H - 20 - ext / 2)) - ext / 2 * math.sin(th)
            snr = float(rng.uniform(5, 30))
            pts = []
            for j in range(m):
                x, y = x0 + j * sp * math.cos(th), y0 + j * sp * math.sin(th)
                render_point(signal, x, y, snr * sigma_at(x, y) / centred_peak, alpha)
                pts.append([round(x, 3), round(y, 3)])
            defects.append({"type": kind, "points": pts, "peak_snr": round(snr, 2)})
        else:
            xs_ = rng.integers(0, W, 20)
            ys_ = rng.integers(0, H, 20)
            adus = rng.uniform(300, 30000, 20)
            defects.append({"type": kind, "pixels": [[int(a), int(b)] for a, b in zip(xs_, ys_)]})
            for a, b, c in zip(xs_, ys_, adus):
                post.append(("add", (int(b), int(a)), float(c)))

    if getattr(args, "hard_negatives", False):
        defects += add_hard_negatives(rng2, signal, post, W, H, alpha, centred_peak, sigma_at)

    # --- detector
    yy, xx = np.mgrid[0:H, 0:W]
    sky = sky0 + gx * (xx - cam.cx) + gy * (yy - cam.cy)
    electrons = rng.poisson(sky + signal).astype(np.float64) + rng.normal(0.0, READ_NOISE, (H, W))
    adu = electrons / GAIN + BIAS
    for op, idx, val in post:
        if op == "add":
            adu[idx] += val
        else:
            adu[idx] = val
    img = np.clip(np.round(adu), 0, SAT_ADU).astype(np.uint16)
    sat_level = SAT_ADU - BIAS
    for s in stars:
        # saturated when the noise-free core (on top of the sky) reaches full scale
        s["saturated"] = bool(s.pop("_peak_e") + sky_at(s["x"], s["y"]) >= sat_level)

    # --- header
    station = None
    hdr = fits.Header()
    r = rng.random()
    lat, lon, hgt = float(rng.uniform(-60, 60)), float(rng.uniform(-180, 180)), float(rng.uniform(0, 3000))
    tt = rng.random() < 0.05
    if tt:
        beg_s, end_s, timesys = iso_ms(t_beg.tt), iso_ms(t_end.tt), "TT"
    else:
        beg_s, end_s, timesys = iso_ms(t_beg), iso_ms(t_end), "UTC"
    hdr["DATE-OBS"] = (beg_s, "exposure start (= DATE-BEG)")
    hdr["DATE-BEG"] = (beg_s, "exposure start")
    hdr["DATE-END"] = (end_s, "exposure end")
    hdr["EXPTIME"] = (exptime, "[s]")
    hdr["TIMESYS"] = timesys
    if r < 0.8:
        hdr["OBSGEO-B"] = (round(lat, 6), "[deg] geodetic latitude")
        hdr["OBSGEO-L"] = (round(lon, 6), "[deg] geodetic longitude, east positive")
        hdr["OBSGEO-H"] = (round(hgt, 2), "[m] height above the WGS84 ellipsoid")
    elif r < 0.9:
        hdr["SITELAT"] = (round(lat, 6), "[deg]")
        hdr["SITELONG"] = (round(lon, 6), "[deg] east positive")
        hdr["SITEELEV"] = (round(hgt, 2), "[m]")
    if r < 0.9:
        station = {"lat_deg": round(lat, 6), "lon_deg": round(lon, 6), "height_m": round(hgt, 2)}
    wcs_cards = make_wcs_header(cam, R)
    for k, v in wcs_cards.items():
        hdr[k] = v
    hdr["GAIN"] = (GAIN, "[e-/ADU]")
    hdr["RDNOISE"] = (READ_NOISE, "[e-]")
    hdr["PEDESTAL"] = (BIAS, "[ADU] bias level")
    hdr["CREATOR"] = "gpustar scripts/sim_streaks.py"

    check_wcs(fits.Header(wcs_cards), cam, R, u[near][:50] if near.any() else None)

    name = f"frame_{i:04d}.fits"
    hdu = fits.PrimaryHDU(data=img, header=hdr)  # astropy stores uint16 as int16 + BZERO 32768
    hdu.writeto(Path(args.out) / name, overwrite=True)

    truth = {
        "file": name, "width": W, "height": H, "fov_x_deg": args.fov_deg,
        "rotation_matrix": [[float(v) for v in row] for row in R],
        "date_beg_utc": iso_ms(t_beg), "date_end_utc": iso_ms(t_end), "exptime_s": exptime,
        "timesys_header": timesys, "station": station, "psf_fwhm_px": round(fwhm, 4),
        "sky_e": round(sky0, 2), "defects": defects, "stars": stars, "streaks": streaks,
    }
    return truth


def check_wcs(hdr, cam, R, vecs):
    """Our projection and astropy's reading of the header WCS must agree to < 0.01 px."""
    w = WCS(hdr)
    # a grid of directions across the frame (plus a few stars), not only where stars happen to be
    pts = [(x, y) for x in (0.0, cam.cx, cam.w - 1.0) for y in (0.0, cam.cy, cam.h - 1.0)]
    dirs = [cam.pixel_to_icrs(R, x, y) for x, y in pts]
    if vecs is not None:
        dirs += list(vecs)
    dirs = np.array(dirs)
    x, y, z = cam.project(R, dirs)
    keep = z > 0.05
    ra = np.degrees(np.arctan2(dirs[keep, 1], dirs[keep, 0])) % 360
    dec = np.degrees(np.arcsin(np.clip(dirs[keep, 2], -1, 1)))
    wx, wy = w.wcs_world2pix(ra, dec, 0)
    err = np.hypot(wx - x[keep], wy - y[keep]).max()
    if not err < 0.01:
        raise AssertionError(f"WCS check failed: {err:.4f} px")


def _worker_init(catalog):
    global CAT
    CAT = load_catalog(catalog)


def _run(job):
    i, args = job
    return simulate_frame(i, args)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("-n", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--fov-deg", type=float, default=12.0)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--no-streak-fraction", type=float, default=0.2)
    ap.add_argument("--defects", action="store_true")
    ap.add_argument("--glints", action="store_true",
                    help="tumbling objects: each streak steady, periodic, irregular, with gaps or flashes (1/5 each)")
    ap.add_argument("--hard-negatives", action="store_true",
                    help="on every frame 1-3 chains of stars, with p = 0.5 a defective column, p = 0.3 hot pixels")
    ap.add_argument("--catalog", default=str(DEFAULT_CATALOG))
    ap.add_argument("-j", "--jobs", type=int, default=1, help="worker processes (default 1)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.toml").write_text(f"width = {args.size}\nheight = {args.size}\nfov_x_deg = {args.fov_deg}\n")
    t0 = time.time()
    jobs = [(i, args) for i in range(args.n)]
    if args.jobs > 1:
        with Pool(args.jobs, initializer=_worker_init, initargs=(args.catalog,)) as pool:
            truths = pool.map(_run, jobs, chunksize=1)
    else:
        _worker_init(args.catalog)
        truths = [_run(j) for j in jobs]
    with open(out / "truth.jsonl", "w") as f:
        for t in truths:
            f.write(json.dumps(t) + "\n")
    ns = sum(len(t["streaks"]) for t in truths)
    ne = sum(t["streaks"][k]["edge0"] or t["streaks"][k]["edge1"] for t in truths for k in range(len(t["streaks"])))
    nc = sum(s["edge0"] and s["edge1"] for t in truths for s in t["streaks"])
    print(f"{args.n} frames in {time.time() - t0:.1f} s -> {out}; {ns} streaks "
          f"({ne} with an edge end, {nc} crossing), "
          f"{sum(1 for t in truths if not t['streaks'])} frames without streaks, "
          f"{sum(1 for t in truths if t['defects'])} with defects", file=sys.stderr)


if __name__ == "__main__":
    main()
