#!/usr/bin/env python3
"""Independent simulator of single star-tracker frames (lost-in-space plate solving).

Written from the spec alone (no gpustar code or model: its own PSF, noise and brightness
model), so that gpustar's detection, identification and attitude are measured on frames it
did not make.

Usage:
    python3 scripts/sim_frames.py --out DIR -n 300 --seed 1 [--fov-deg 10] [--size 1024]
            [--psf-sigma 1.2] [--mag-limit 6.0] [--faint-snr 6] [--false-stars 3]
            [--hot-pixels 5] [--format fits|png] [-j 2]

Writes DIR/frame_NNNN.fits (or DIR/frame_NNNN.png, 16-bit grey), DIR/truth.jsonl (one JSON
object per frame, in frame order) and DIR/camera.toml (width, height, fov_x_deg). Frame i
depends only on (seed, i) (its generator is numpy default_rng([seed, 0, i]); the per-star
colour scatter, shared by all frames, comes from default_rng([seed, 1])), so -j (worker
processes over frames) does not change the output.

Model
-----
* Camera: pinhole, square pixels, no distortion (unless --k1/--k2: x = cx + fx u k, y = cy + fy
  v k with u = X/Z, v = Y/Z, k = 1 + k1 (u^2 + v^2) + k2 (u^2 + v^2)^2, nothing beyond 50 deg
  off axis; DIR/camera_true.toml then holds the true camera). W = H = --size. Principal point
  ((W-1)/2, (H-1)/2) (+ --centre-offset DX DY), fx = fy = (W/2)/tan(fov_x/2). Pixels: x = column, y = row, 0-based,
  centre of the top-left pixel = (0, 0); pixel (j, i) covers [j-0.5, j+0.5] x [i-0.5, i+0.5].
  Camera +X = increasing column, +Y = increasing row, +Z = boresight; R maps ICRS unit vectors
  to camera (v_cam = R v_icrs); x = cx + fx X/Z, y = cy + fy Y/Z. fov_y = 2 atan((H/2)/fy).
* Attitude: uniform random rotation per frame (a normalised 4-D Gaussian is a uniform unit
  quaternion). No motion during the exposure.
* Epoch: Julian year uniform in [2015, 2025) per frame, taken as a UTC instant and rounded to
  the whole millisecond; truth "epoch" is the Julian year of that instant and FITS DATE-OBS its
  ISO form (UTC, ms).
* Stars: Hipparcos-2 (the Hp <= 8 stars of catalog/hip2_hp9.csv, or a --catalog file's,
  ICRS at J1991.25), proper motion applied linearly on the tangent plane to the frame epoch
  (u = u0 + dt (pmra e_ra + pmdec e_dec), normalised; pmra includes cos dec). No aberration,
  parallax or refraction: the sky is the catalogue itself. Every star with Hp <= --mag-limit
  (default 6.0) in front of the camera is rendered whose render window (below) touches the
  detector, also those whose centre is just off it.
* PSF: circular Gaussian, sigma = --psf-sigma px (default 1.2), integrated EXACTLY over each
  pixel: the value of pixel (j, i) for a unit-flux source at (x, y) is
      [Phi((j+0.5-x)/s) - Phi((j-0.5-x)/s)] * [Phi((i+0.5-y)/s) - Phi((i-0.5-y)/s)],
  Phi(t) = (1 + erf(t/sqrt 2))/2, evaluated in double precision with math.erfc from the tail
  on the pixel's side of the centre (well conditioned far out); no sub-sampling. Each source
  is rendered in a square window of half-size r px about its nearest pixel, r the smallest
  integer >= max(6 s, the radius where the source's profile density flux/(2 pi s^2)
  exp(-r^2/(2 s^2)) falls to 1e-3 of the background noise sigma), capped at 200 px; the flux
  left outside (< 2e-9 of it at 6 s) is dropped.
* Brightness: flux(m) = 10^(-0.4 (m - zp)) electrons (zp = "zero_point", the magnitude of a
  1 e- source). zp is set per frame so that a Hp = --mag-limit star centred on a pixel has
  noise-free peak SNR = --faint-snr (default 6): flux(mag_limit) = faint_snr *
  sqrt(sky + read^2) / P0, P0 = erf(0.5/(s sqrt 2))^2 the centred-pixel fraction.
  SNR is always noise-free peak pixel signal / sqrt(sky + read^2), electrons. Each catalogue
  star's flux gets a lognormal factor exp(N(0, 0.2)) (sensor passband differs from Hp), fixed
  per star for a given seed (the same in every frame). Truth peak_snr and flux_e are those of
  the star as rendered (scatter applied, its sub-pixel position).
* False stars: --false-stars (default 3) point sources, same PSF, centre uniform on the
  detector area [-0.5, W-0.5) x [-0.5, H-0.5), flux that of a star of magnitude uniform in
  [mag_limit-3, mag_limit] times its own exp(N(0, 0.2)).
* Position noise: --position-noise PX (default 0) draws each catalogue star N(0, PX) px off
  its place in x and y (the truth lists the place), as centroid errors would.
* Blank bottom: --blank-bottom F renders no star and no false star whose centre is below
  y = (1 - F) H - 0.5 (hidden as by a baffle; the truth lists only what is rendered).
* Hot pixels: --hot-pixels (default 5) distinct pixels, uniform, each with 500..5000 e-
  (uniform) added to the expected charge (no PSF).
* Detector: sky uniform 100..400 e-/px per frame (flat); expected charge = sky + sources + hot
  pixels, Poisson noise on it, plus Gaussian read noise 5 e-; gain 1 e-/ADU, bias 100 ADU;
  ADU = round(e-/gain + bias) clipped to uint16 [0, 65535]. A star is "saturated" when its
  noise-free peak + sky (e-) / gain + bias reaches 65535.
* FITS: 16-bit primary HDU (BITPIX 16, BZERO 32768; astropy.io.fits) with DATE-OBS, TIMESYS,
  GAIN, RDNOISE, PEDESTAL, CREATOR; no WCS. PNG: 16-bit greyscale (colour type 0, depth 16),
  one IDAT, filter 0, zlib, written with zlib + struct and a tEXt DATE-OBS; every PNG is
  decoded again by this script's own reader and compared pixel for pixel.
* Truth (truth.jsonl, per frame): file (relative to DIR), ra_deg, dec_deg (boresight),
  centre_ra_deg, centre_dec_deg (the image centre pixel's direction),
  roll_tetra3_deg (image up to celestial north, counter-clockwise, as scripts/truth_check.py),
  rotation_matrix (R), quaternion [w, x, y, z] (Hamilton, w >= 0) of R, epoch, width, height,
  fov_x_deg, fov_y_deg, mirrored (false), stars [{hip, x, y, mag (Hp), peak_snr, flux_e,
  saturated}] (catalogue stars whose centre is on the detector area [-0.5, W-0.5] x
  [-0.5, H-0.5], brightest Hp first), stars_snr_ge_5 (how many of those have peak_snr >= 5),
  false_stars [[x, y], ...] (+ false_star_flux_e, false_star_peak_snr), hot_pixels
  [[x, y], ...] (+ hot_pixel_e), sky_e, zero_point, psf_sigma_px, bias_adu, read_noise_e,
  gain, mag_limit, faint_snr, position_noise_px, date_obs.
"""
import argparse
import csv
import json
import math
import struct
import sys
import time
import zlib
from multiprocessing import Pool
from pathlib import Path

import numpy as np

# astropy is only needed for time conversion and FITS output; keep it offline.
from astropy.utils import iers

iers.conf.auto_download = False
from astropy.io import fits  # noqa: E402
from astropy.time import Time  # noqa: E402

DEFAULT_CATALOG = Path(__file__).resolve().parent.parent / "catalog" / "hip2_hp9.csv"
# The stars drawn from it: those of the Hp <= 8 catalog the repository shipped before, so that
# every set made since is made again byte for byte (a --catalog file is read whole).
DEFAULT_CATALOG_MAX_MAG = 8.0

EPOCH_CAT_JYEAR = 1991.25
EPOCH_RANGE = (2015.0, 2025.0)
SKY_RANGE = (100.0, 400.0)  # e-/px
READ_NOISE = 5.0  # e-
GAIN = 1.0  # e-/ADU
BIAS = 100.0  # ADU
SAT_ADU = 65535
SCATTER_LN = 0.2  # lognormal sigma of star fluxes (ln)
HOT_RANGE = (500.0, 5000.0)  # e-
FALSE_MAG_SPAN = 3.0  # false stars: magnitude uniform in [mag_limit - span, mag_limit]
WIN_SIGMAS = 6.0  # render window half-size at least this many PSF sigmas ...
WIN_FLOOR = 1e-3  # ... and out to where the profile density is this fraction of the noise sigma
WIN_MAX = 200
SNR_SOLVABLE = 5.0
SQRT2 = math.sqrt(2.0)

CAT = None  # worker global: the catalogue (filled once per process)


# ----------------------------------------------------------------------------- geometry

def quat_to_matrix(q):
    """Rotation matrix of a unit quaternion [w, x, y, z] (Hamilton)."""
    w, x, y, z = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def matrix_to_quat(R):
    """Quaternion [w, x, y, z] with w >= 0 of a rotation matrix (Shepperd's method)."""
    t = np.trace(R)
    cand = [t, R[0, 0], R[1, 1], R[2, 2]]
    k = int(np.argmax(cand))
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


def random_rotation(rng):
    """Uniform random rotation: a normalised 4-D Gaussian is a uniform unit quaternion."""
    q = rng.normal(size=4)
    return quat_to_matrix(q / np.linalg.norm(q))


def radec_to_vec(ra, dec):
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], axis=-1)


def vec_to_radec_deg(v):
    v = np.asarray(v, float)
    ra = math.degrees(math.atan2(v[1], v[0])) % 360.0
    dec = math.degrees(math.asin(max(-1.0, min(1.0, v[2] / np.linalg.norm(v)))))
    return ra, dec


def roll_tetra3_deg(R):
    """tetra3's roll (as scripts/truth_check.py): image up to celestial north, counter-clockwise.

    north = ICRS +Z in camera coordinates; up = -Y, left = -X, so atan2(-n_x, -n_y)."""
    north = R[:, 2]
    return (math.degrees(math.atan2(north[0], north[1])) + 180.0) % 360.0


class Camera:
    def __init__(self, width, height, fov_x_deg, k1=0.0, k2=0.0, centre_offset=(0.0, 0.0)):
        self.w, self.h = width, height
        self.fx = self.fy = (width / 2.0) / math.tan(math.radians(fov_x_deg) / 2.0)
        self.cx, self.cy = (width - 1) / 2.0 + centre_offset[0], (height - 1) / 2.0 + centre_offset[1]
        self.k1, self.k2 = k1, k2

    def distortion(self, u, v):
        """Radial factor 1 + k1 r^2 + k2 r^4 of the normalised (pinhole) coordinates u, v."""
        r2 = u * u + v * v
        return 1.0 + self.k1 * r2 + self.k2 * r2 * r2

    def pixel_to_vector(self, x, y):
        """Camera-frame unit vector of pixel (x, y): the distortion inverted by fixed-point
        iteration (converges where the factor is monotonic, as here)."""
        ud, vd = (x - self.cx) / self.fx, (y - self.cy) / self.fy
        u, v = ud, vd
        for _ in range(100):
            k = self.distortion(u, v)
            u, v = ud / k, vd / k
        c = np.array([u, v, 1.0])
        return c / np.linalg.norm(c)

    @property
    def fov_y_deg(self):
        return math.degrees(2.0 * math.atan((self.h / 2.0) / self.fy))

    def project(self, R, v):
        """ICRS unit vectors (..., 3) -> pixel x, y and camera Z (x, y meaningless where Z <= 0)."""
        c = v @ R.T
        z = c[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            u, v = c[..., 0] / z, c[..., 1] / z
            if self.k1 or self.k2:
                k = self.distortion(u, v)
                # beyond 50 deg off axis the polynomial is not a lens: nothing is projected there
                z = np.where(u * u + v * v < math.tan(math.radians(50.0)) ** 2, z, -1.0)
                u, v = u * k, v * k
            x = self.cx + self.fx * u
            y = self.cy + self.fy * v
        return x, y, z

    def in_frame(self, x, y):
        """Centre on the detector area (not only the pixel-centre box)."""
        return (-0.5 <= x) & (x <= self.w - 0.5) & (-0.5 <= y) & (y <= self.h - 0.5)


# ----------------------------------------------------------------------------- PSF

def centred_fraction(sigma):
    """Fraction of a unit-flux Gaussian's flux in the pixel on which it is centred."""
    return math.erf(0.5 / (sigma * SQRT2)) ** 2


def window_radius(flux, sigma, noise):
    """Render-window half-size (px): the larger of WIN_SIGMAS sigma and the radius where the
    profile density flux/(2 pi s^2) exp(-r^2/(2 s^2)) falls to WIN_FLOOR * noise."""
    r = WIN_SIGMAS * sigma
    k = flux / (2.0 * math.pi * sigma * sigma) / (WIN_FLOOR * noise)
    if k > 1.0:
        r = max(r, sigma * math.sqrt(2.0 * math.log(k)))
    return int(min(math.ceil(r), WIN_MAX))


def pixel_integrals(lo, n, c, sigma):
    """1-D integrals of a unit Gaussian (centre c, sigma) over pixels lo .. lo+n-1 (each pixel
    k covering [k-0.5, k+0.5]): differences of Phi at the n+1 pixel edges, exactly via erf.

    Each pixel is computed on the side of the centre that keeps it well conditioned, from the
    lower tail P(t) = erfc(-t)/2 = Phi and the upper tail Q(t) = erfc(t)/2 = 1 - Phi at its
    edges: P(hi) - P(lo) below the centre, Q(lo) - Q(hi) above it, 1 - P(lo) - Q(hi) across it."""
    t = (lo - 0.5 + np.arange(n + 1) - c) / (sigma * SQRT2)
    p = np.array([0.5 * math.erfc(-v) for v in t])
    q = np.array([0.5 * math.erfc(v) for v in t])
    below = p[1:] - p[:-1]
    above = q[:-1] - q[1:]
    across = 1.0 - p[:-1] - q[1:]
    return np.where(t[1:] <= 0, below, np.where(t[:-1] >= 0, above, across))


def render_source(img, x, y, flux, sigma, noise):
    """Add a Gaussian point source of `flux` e- centred at (x, y) to `img` (the part of its
    window on the detector). Returns the noise-free peak pixel of the source (e-) over its whole
    window, or None when the window misses the detector."""
    h, w = img.shape
    r = window_radius(flux, sigma, noise)
    jx, jy = int(round(x)), int(round(y))
    x0, x1 = jx - r, jx + r + 1
    y0, y1 = jy - r, jy + r + 1
    if x1 <= 0 or y1 <= 0 or x0 >= w or y0 >= h:
        return None
    gx = pixel_integrals(x0, x1 - x0, x, sigma)
    gy = pixel_integrals(y0, y1 - y0, y, sigma)
    stamp = flux * np.outer(gy, gx)
    a0, b0 = max(y0, 0), max(x0, 0)
    a1, b1 = min(y1, h), min(x1, w)
    img[a0:a1, b0:b1] += stamp[a0 - y0:a1 - y0, b0 - x0:b1 - x0]
    return float(stamp.max())


# ----------------------------------------------------------------------------- PNG

def _png_chunk(tag, data):
    return struct.pack(">I", len(data)) + tag + data + struct.pack(">I", zlib.crc32(tag + data) & 0xFFFFFFFF)


def png_encode(img, text=None):
    """16-bit greyscale PNG bytes of a uint16 image (filter 0 on every row, one IDAT)."""
    img = np.ascontiguousarray(img, dtype=np.uint16)
    h, w = img.shape
    raw = np.zeros((h, 1 + 2 * w), np.uint8)  # filter byte 0 then big-endian samples
    raw[:, 1:] = img.astype(">u2").view(np.uint8).reshape(h, 2 * w)
    out = [b"\x89PNG\r\n\x1a\n", _png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, 0, 0, 0, 0))]
    for k, v in (text or {}).items():
        out.append(_png_chunk(b"tEXt", k.encode("latin-1") + b"\0" + v.encode("latin-1")))
    out.append(_png_chunk(b"IDAT", zlib.compress(raw.tobytes(), 6)))
    out.append(_png_chunk(b"IEND", b""))
    return b"".join(out)


def png_decode(data):
    """Decode a non-interlaced 8- or 16-bit greyscale PNG (all five filter types) to a numpy
    array, checking the signature and every chunk CRC. Returns (image, tEXt dict)."""
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ValueError("not a PNG")
    pos, idat, text, hdr = 8, [], {}, None
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        tag, body = data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]
        (crc,) = struct.unpack(">I", data[pos + 8 + n:pos + 12 + n])
        if zlib.crc32(tag + body) & 0xFFFFFFFF != crc:
            raise ValueError(f"bad CRC in {tag!r}")
        pos += 12 + n
        if tag == b"IHDR":
            hdr = struct.unpack(">IIBBBBB", body)
        elif tag == b"IDAT":
            idat.append(body)
        elif tag == b"tEXt":
            k, v = body.split(b"\0", 1)
            text[k.decode("latin-1")] = v.decode("latin-1")
        elif tag == b"IEND":
            break
    w, h, depth, ctype, comp, filt, interlace = hdr
    if ctype != 0 or depth not in (8, 16) or comp or filt or interlace:
        raise ValueError(f"unsupported PNG {hdr}")
    bpp = depth // 8
    stride = w * bpp
    raw = np.frombuffer(zlib.decompress(b"".join(idat)), np.uint8).reshape(h, stride + 1)
    out = np.zeros((h, stride), np.uint8)
    prev = np.zeros(stride, np.int32)
    for i in range(h):
        f, line = raw[i, 0], raw[i, 1:].astype(np.int32)
        if f == 0:
            cur = line
        elif f == 1:  # Sub: a running sum per byte lane, mod 256
            cur = (np.cumsum(line.reshape(w, bpp), axis=0) % 256).ravel()
        elif f == 2:  # Up
            cur = (line + prev) % 256
        elif f in (3, 4):  # Average, Paeth: sequential
            cur = np.zeros(stride, np.int32)
            for k in range(stride):
                a = cur[k - bpp] if k >= bpp else 0
                b = prev[k]
                c = prev[k - bpp] if k >= bpp else 0
                if f == 3:
                    pred = (a + b) // 2
                else:
                    p = a + b - c
                    pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                    pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                cur[k] = (line[k] + pred) % 256
        else:
            raise ValueError(f"bad filter {f}")
        out[i] = cur
        prev = cur
    img = out.view(">u2").astype(np.uint16) if depth == 16 else out
    return img.reshape(h, w), text


# ----------------------------------------------------------------------------- catalog

def load_catalog(path, max_mag, seed):
    """Hipparcos-2 stars with Hp <= max_mag: unit vectors, tangent-plane velocities (rad/yr) and
    the per-star lognormal flux factor (drawn for every row of the file, so a star's factor does
    not depend on --mag-limit)."""
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
    scatter = np.exp(np.random.default_rng([seed, 1]).normal(0.0, SCATTER_LN, len(rows["hip"])))
    keep = rows["hp_mag"] <= max_mag
    rows = {k: v[keep] for k, v in rows.items()}
    ra, dec = rows["ra_rad"], rows["dec_rad"]
    e_ra = np.stack([-np.sin(ra), np.cos(ra), np.zeros_like(ra)], axis=-1)
    e_dec = np.stack([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)], axis=-1)
    mas = math.radians(1.0 / 3.6e6)
    # pmra already includes cos(dec): a tangent-plane velocity in rad/yr
    vel = (rows["pmra_mas_yr"] * mas)[:, None] * e_ra + (rows["pmdec_mas_yr"] * mas)[:, None] * e_dec
    return {"hip": rows["hip"].astype(int), "u": radec_to_vec(ra, dec), "vel": vel,
            "mag": rows["hp_mag"], "scatter": scatter[keep]}


def stars_at(jyear):
    u = CAT["u"] + (jyear - EPOCH_CAT_JYEAR) * CAT["vel"]
    return u / np.linalg.norm(u, axis=1)[:, None]


# ----------------------------------------------------------------------------- frame

def iso_ms(t):
    """ISO time rounded to the millisecond (the header's precision)."""
    t = t.copy()
    t.precision = 3
    return t.isot


def frame_name(i, fmt):
    return f"frame_{i:04d}.{fmt}"


def simulate_frame(i, args):
    """Render frame i, write it, return its truth dict."""
    rng = np.random.default_rng([args.seed, 0, i])
    W = H = args.size
    cam = Camera(W, H, args.fov_deg, args.k1, args.k2, args.centre_offset)
    sigma = args.psf_sigma

    # --- draws, in a fixed order
    jy = float(rng.uniform(*EPOCH_RANGE))
    t_obs = Time(iso_ms(Time(jy, format="jyear", scale="utc")), format="isot", scale="utc")  # whole ms
    date_obs = iso_ms(t_obs)
    jyear = float(t_obs.jyear)
    R = random_rotation(rng)
    sky = float(rng.uniform(*SKY_RANGE))
    n_false = args.false_stars
    fx = rng.uniform(-0.5, W - 0.5, n_false)
    fy = rng.uniform(-0.5, H - 0.5, n_false)
    fmag = rng.uniform(args.mag_limit - FALSE_MAG_SPAN, args.mag_limit, n_false)
    fscat = np.exp(rng.normal(0.0, SCATTER_LN, n_false))
    hot_idx = rng.choice(W * H, args.hot_pixels, replace=False) if args.hot_pixels else np.zeros(0, int)
    hot_e = rng.uniform(*HOT_RANGE, len(hot_idx))

    # --- brightness scale
    noise = math.sqrt(sky + READ_NOISE ** 2)  # background noise sigma per pixel (e-)
    flux_lim = args.faint_snr * noise / centred_fraction(sigma)
    zp = args.mag_limit + 2.5 * math.log10(flux_lim)

    def flux_of(mag):
        return 10.0 ** (-0.4 * (np.asarray(mag, float) - zp))

    signal = np.zeros((H, W))

    # --- catalogue stars
    u = stars_at(jyear)
    x, y, z = cam.project(R, u)
    flux = flux_of(CAT["mag"]) * CAT["scatter"]
    # a generous pre-selection; render_source decides whether the window touches the frame
    rmax = window_radius(float(flux.max()), sigma, noise) + 2
    near = np.nonzero((z > 0.1) & (x > -rmax) & (x < W + rmax) & (y > -rmax) & (y < H + rmax))[0]
    # --position-noise: each star drawn off its catalogue place (the truth keeps the place),
    # as centroid errors would put it (the study's positional-noise sweep).
    jitter = rng.normal(0.0, args.position_noise, (2, len(x))) if args.position_noise > 0 else np.zeros((2, len(x)))
    stars = []
    if args.blank_bottom > 0:
        # a baffle or the Earth's limb hides the bottom of the frame: no star there
        near = near[y[near] <= (1.0 - args.blank_bottom) * H - 0.5]
    for k in near:
        peak = render_source(signal, float(x[k] + jitter[0, k]), float(y[k] + jitter[1, k]), float(flux[k]), sigma, noise)
        if peak is None or not cam.in_frame(x[k], y[k]):
            continue
        stars.append({"hip": int(CAT["hip"][k]), "x": round(float(x[k]), 4), "y": round(float(y[k]), 4),
                      "mag": round(float(CAT["mag"][k]), 4), "peak_snr": round(peak / noise, 3),
                      "flux_e": round(float(flux[k]), 2),
                      "saturated": bool((peak + sky) / GAIN + BIAS >= SAT_ADU)})
    stars.sort(key=lambda s: (s["mag"], s["hip"]))

    # --- false stars and hot pixels
    false_flux = flux_of(fmag) * fscat
    if args.blank_bottom > 0:
        false_flux = np.where(fy <= (1.0 - args.blank_bottom) * H - 0.5, false_flux, 0.0)
    false_peak = [render_source(signal, float(a), float(b), float(f), sigma, noise)
                  for a, b, f in zip(fx, fy, false_flux)]
    expected = signal + sky
    hot = [(int(k % W), int(k // W)) for k in hot_idx]
    for (hx, hy), e in zip(hot, hot_e):
        expected[hy, hx] += e

    # --- detector
    electrons = rng.poisson(expected).astype(np.float64) + rng.normal(0.0, READ_NOISE, (H, W))
    img = np.clip(np.round(electrons / GAIN + BIAS), 0, SAT_ADU).astype(np.uint16)

    name = frame_name(i, args.format)
    path = Path(args.out) / name
    if args.format == "fits":
        hdr = fits.Header()
        hdr["DATE-OBS"] = (date_obs, "UTC")
        hdr["TIMESYS"] = "UTC"
        hdr["GAIN"] = (GAIN, "[e-/ADU]")
        hdr["RDNOISE"] = (READ_NOISE, "[e-]")
        hdr["PEDESTAL"] = (BIAS, "[ADU] bias level")
        hdr["CREATOR"] = "gpustar scripts/sim_frames.py"
        # astropy stores uint16 as int16 + BZERO 32768 (BITPIX 16)
        fits.PrimaryHDU(data=img, header=hdr).writeto(path, overwrite=True)
    else:
        data = png_encode(img, {"DATE-OBS": date_obs, "Software": "gpustar scripts/sim_frames.py"})
        back, text = png_decode(data)
        if not (back.shape == img.shape and np.array_equal(back, img) and text.get("DATE-OBS") == date_obs):
            raise AssertionError(f"{name}: PNG does not round-trip")
        path.write_bytes(data)

    ra, dec = vec_to_radec_deg(R[2])
    # the sky direction of the image centre pixel ((W-1)/2, (H-1)/2): the boresight unless the
    # principal point is offset (then through the distortion)
    cra, cdec = vec_to_radec_deg(R.T @ cam.pixel_to_vector((W - 1) / 2.0, (H - 1) / 2.0))
    return {
        "centre_ra_deg": cra, "centre_dec_deg": cdec,
        "file": name, "ra_deg": ra, "dec_deg": dec, "roll_tetra3_deg": roll_tetra3_deg(R),
        "rotation_matrix": [[float(v) for v in row] for row in R],
        "quaternion": [float(v) for v in matrix_to_quat(R)],
        "epoch": jyear, "date_obs": date_obs, "width": W, "height": H, "fov_x_deg": args.fov_deg,
        "fov_y_deg": cam.fov_y_deg, "mirrored": False,
        "stars": stars,
        "stars_snr_ge_5": sum(s["peak_snr"] >= SNR_SOLVABLE for s in stars),
        "false_stars": [[round(float(a), 4), round(float(b), 4)] for a, b in zip(fx, fy)],
        "false_star_flux_e": [round(float(f), 2) for f in false_flux],
        "false_star_peak_snr": [round((p or 0.0) / noise, 3) for p in false_peak],
        "hot_pixels": [list(p) for p in hot],
        "hot_pixel_e": [round(float(e), 1) for e in hot_e],
        "sky_e": sky, "zero_point": zp, "psf_sigma_px": sigma, "bias_adu": BIAS,
        "read_noise_e": READ_NOISE, "gain": GAIN, "mag_limit": args.mag_limit, "faint_snr": args.faint_snr,
        "position_noise_px": args.position_noise,
    }


# ----------------------------------------------------------------------------- driver

def _worker_init(catalog, mag_limit, seed):
    global CAT
    CAT = load_catalog(catalog, mag_limit, seed)


def _run(job):
    i, args = job
    return simulate_frame(i, args)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("-n", "--frames", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--fov-deg", type=float, default=10.0)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--psf-sigma", type=float, default=1.2)
    ap.add_argument("--mag-limit", type=float, default=6.0)
    ap.add_argument("--faint-snr", type=float, default=6.0)
    ap.add_argument("--false-stars", type=int, default=3)
    ap.add_argument("--hot-pixels", type=int, default=5)
    ap.add_argument("--position-noise", type=float, default=0.0,
                    help="draw each catalogue star N(0, PX) px off its place per axis; the truth keeps the place")
    ap.add_argument("--k1", type=float, default=0.0, help="radial distortion (see Model; default 0)")
    ap.add_argument("--k2", type=float, default=0.0, help="radial distortion (see Model; default 0)")
    ap.add_argument("--centre-offset", type=float, nargs=2, default=[0.0, 0.0], metavar=("DX", "DY"),
                    help="principal point minus the image centre, px (default 0 0)")
    ap.add_argument("--blank-bottom", type=float, default=0.0, metavar="F",
                    help="render no star or false star whose centre is in the bottom F of the frame "
                         "(y > (1 - F) H - 0.5), as if hidden by a baffle (default 0)")
    ap.add_argument("--format", choices=("fits", "png"), default="fits")
    ap.add_argument("--catalog", default=str(DEFAULT_CATALOG))
    ap.add_argument("-j", "--jobs", type=int, default=1, help="worker processes (default 1)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.toml").write_text(f"width = {args.size}\nheight = {args.size}\nfov_x_deg = {args.fov_deg}\n")
    if args.k1 or args.k2 or any(args.centre_offset):
        cam = Camera(args.size, args.size, args.fov_deg, args.k1, args.k2, args.centre_offset)
        (out / "camera_true.toml").write_text(
            f"width = {args.size}\nheight = {args.size}\nfx_px = {cam.fx!r}\nfy_px = {cam.fy!r}\n"
            f"cx_px = {cam.cx!r}\ncy_px = {cam.cy!r}\nk1 = {args.k1!r}\nk2 = {args.k2!r}\n")
    t0 = time.time()
    jobs = [(i, args) for i in range(args.frames)]
    init = (args.catalog, args.mag_limit, args.seed)
    if args.jobs > 1:
        with Pool(args.jobs, initializer=_worker_init, initargs=init) as pool:
            truths = pool.map(_run, jobs, chunksize=4)
    else:
        _worker_init(*init)
        truths = [_run(j) for j in jobs]
    with open(out / "truth.jsonl", "w") as f:
        for t in truths:
            f.write(json.dumps(t) + "\n")
    n_stars = np.array([len(t["stars"]) for t in truths])
    n_snr5 = np.array([t["stars_snr_ge_5"] for t in truths])
    print(f"{args.frames} frames in {time.time() - t0:.1f} s -> {out}; stars/frame median "
          f"{np.median(n_stars):.0f} (mean {n_stars.mean():.1f}); frames with >= 4 stars of peak SNR >= 5: "
          f"{100 * np.mean(n_snr5 >= 4):.1f}%, >= 4 stars in view: {100 * np.mean(n_stars >= 4):.1f}%",
          file=sys.stderr)


if __name__ == "__main__":
    main()
