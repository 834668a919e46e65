#!/usr/bin/env python3
"""Independent simulator of star-tracker frame sequences with moving luminous particles.

Written from the spec alone (no gpustar code or model: its own PSF, noise and brightness
model), so that gpustar's --sequence mode (particle rejection over frames, frame-to-frame
attitude tracking) is measured on frames it did not make.

Usage:
    python3 scripts/sim_sequence.py --out DIR --sequences N --frames 30 --seed S
            [--particle-ratio 1.5] [--fov-deg 18] [--size 1024] [-j 2]

Writes DIR/seq_NNN/frame_NNN.fits, DIR/camera.toml and DIR/truth.jsonl (one JSON object per
frame, "file" relative to DIR, e.g. "seq_003/frame_017.fits"). Sequence s depends only on
(seed, s), so -j (worker processes over sequences) does not change the output.

Model
-----
* Camera: pinhole, square pixels, no distortion. Principal point ((W-1)/2, (H-1)/2),
  fx = fy = (W/2)/tan(fov_x/2). Pixels: x = column, y = row, 0-based, centre of the top-left
  pixel = (0, 0). Camera +X = increasing column, +Y = increasing row, +Z = boresight;
  R maps ICRS unit vectors to camera (v_cam = R v_icrs); x = cx + fx X/Z, y = cy + fy Y/Z.
* Attitude: R0 at t = 0 (exposure start of frame 0) uniform random (normalised 4-D Gaussian
  quaternion). The camera turns at a constant rate omega uniform 0.05..0.5 deg/s about a fixed
  axis a uniform on the sphere, expressed in the camera frame (so roll occurs): the camera
  turns by +omega t about a (right hand), i.e. R(t) = Rot(a, -omega t) R0.
* Time: t0 (frame 0 exposure start) uniform UTC instant in [2020-01-01, 2025-01-01), whole
  milliseconds; frame interval dt uniform 0.5..2.0 s (--interval) per sequence (whole ms); frame k starts
  at t0 + k dt; exposure 0.05 s. The truth attitude is R at mid-exposure. No leap second
  falls in 2020..2025, so UTC seconds are uniform here.
* Motion smear: every source (star or particle) is rendered at n sub-steps at the midpoints of
  n equal slices of the exposure, each with 1/n of the flux; n = max(8, ceil(smear / 0.25 px))
  so consecutive sub-images are <= 0.25 px apart. Star and particle positions are computed
  exactly (attitude and particle motion) at each sub-step.
* Stars: Hipparcos-2 (catalog/hip2_hp9.csv, ICRS at J1991.25), proper motion applied on the
  tangent plane to each frame's mid-exposure epoch; every star with Hp <= 6.0 is rendered (also
  those just off the frame whose PSF window reaches in). No aberration/refraction: the "sky" is
  the catalogue itself.
* PSF: Moffat I(r) = (beta-1)/(pi alpha^2) (1 + r^2/alpha^2)^-beta (unit flux), beta uniform
  2.5..4.0 and star FWHM uniform 1.8..2.8 px per sequence (alpha = FWHM / (2 sqrt(2^(1/beta)-1))),
  integrated over each pixel by 5x5 sub-samples. A source is rendered in a window around its
  smear path whose half-size is the larger of the radius enclosing 99.5% of the flux and the
  radius where the profile drops below 1% of the background noise sigma (clamped to 4..120 px).
* Photometry: flux(m) = F6 10^(-0.4 (m - 6)) electrons per exposure, F6 per sequence such that a
  static (unsmeared) Hp 6.0 star centred on a pixel has peak SNR uniform 8..15, peak SNR =
  noise-free peak pixel / sqrt(sky + read^2). Each star's flux gets a lognormal factor
  exp(N(0, 0.10)) fixed over the sequence, and every source (stars and particles) a per-frame
  factor exp(N(0, 0.03)) (3% jitter). Truth peak_snr is that of the rendered (smeared) source.
* Detector: sky uniform 50..300 e-/px per sequence (flat, constant over the sequence); Poisson
  noise on sky + signal (+ hot pixels), Gaussian read noise 6 e-, gain 1 e-/ADU, bias 200 ADU,
  rounded and clipped to uint16 [0, 65535]. A source is "saturated" when its noise-free peak
  plus sky reaches 65535 - 200 e-. 5 hot pixels per sequence at fixed positions (uniform, all
  frames), each a fixed 500..5000 e- (uniform) added to the expected charge of every frame.
* Particles (sunlit debris near the spacecraft): N = round(ratio x number of Hp <= 6 stars whose
  centre is in frame 0 at mid-exposure) with a centre in the frame. At each frame's
  mid-exposure, a particle whose centre has left the frame (outside [-0.5, W-0.5] x [-0.5,
  H-0.5]) is replaced by a new one born at a uniform random position in [0, W-1] x [0, H-1]
  (at that frame's mid-exposure); the departed one is still rendered (and listed again should
  it drift back in) while its window touches the frame, then dropped.
  Magnitude (same zero point as stars) uniform 1.5..5.0 (--particle-mag), fixed per particle; PSF FWHM =
  f x star FWHM, f uniform 1.0..3.0 per particle (out of focus), same beta.
  Motion against the stars, on the ICRS sphere: from its birth point p0 in direction d0
  (uniform in the tangent plane), n0 = p0 x d0, with tau = t - t_birth:
      theta(tau) = w tau + a_par tau^2 / 2,  phi(tau) = a_perp tau^2 / 2,
      p(tau) = cos(phi) (cos(theta) p0 + sin(theta) d0) + sin(phi) n0,
  birth speed w uniform 6..40 arcmin/s (--particle-speed), acceleration (a_par, a_perp) = A (cos c, sin c), A uniform
  0..0.01 w per s (<= 10% of the speed per 10 s), c uniform: a great circle at constant speed
  plus a small along- and cross-track acceleration, so tracks are not perfectly linear.
  Truth vx/vy = apparent sensor velocity at mid-exposure (attitude and particle both moving,
  central difference over +-1 ms); sky_speed_px_s = the same with the attitude frozen
  (speed against the stars).
* FITS: uint16 (BITPIX 16, BZERO 32768), primary HDU; DATE-OBS = DATE-BEG = exposure start,
  DATE-END (UTC, ms), TIMESYS = 'UTC', EXPTIME = 0.05, SEQUENCE, FRAMENUM; a TAN WCS (CD
  matrix) of the true mid-exposure attitude, checked on every frame against the pinhole
  projection with astropy.wcs (agreement < 1e-6 px).
* Truth (truth.jsonl, per frame): the star-truth fields of scripts/sim_streaks.py /
  gpustar's Truth (file, ra_deg, dec_deg of the boresight, roll_tetra3_deg as in
  scripts/truth_check.py, rotation_matrix, quaternion [w, x, y, z] Hamilton w >= 0 of R,
  epoch (Julian year, mid-exposure), width, height, fov_x_deg, fov_y_deg, mirrored, stars
  [{hip, x, y, mag, peak_snr, saturated}] with centre in the frame at mid-exposure, brightest
  first) plus sequence, index, time_utc (mid-exposure), interval_s, rate_deg_s, axis_cam,
  particles [{id, x, y, vx_px_s, vy_px_s, mag, fwhm_px, peak_snr, ...}] with centre in the
  frame at mid-exposure, and hot_pixels [[x, y], ...].
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

# astropy is only needed for time arithmetic and the FITS/WCS I/O; keep it offline.
from astropy.utils import iers

iers.conf.auto_download = False
from astropy import units  # noqa: E402
from astropy.io import fits  # noqa: E402
from astropy.time import Time  # noqa: E402
from astropy.wcs import WCS  # noqa: E402

DEFAULT_CATALOG = Path(__file__).resolve().parent.parent / "catalog" / "hip2_hp9.csv"

MAG_LIMIT = 6.0  # render (and list in the truth) every star this bright
EPOCH_CAT_JYEAR = 1991.25
EXPTIME = 0.05  # s
MIN_SUBSTEPS = 8  # exposure sub-steps for motion smear (at least)
MAX_SUBSTEP_PX = 0.25  # ... and more when a source moves further than this per sub-step
READ_NOISE = 6.0  # e-
GAIN = 1.0  # e-/ADU
BIAS = 200.0  # ADU
SAT_ADU = 65535
SUB = 5  # sub-samples per pixel axis for pixel integration
SUB_OFF = (np.arange(SUB) + 0.5) / SUB - 0.5  # sub-sample offsets from the pixel centre
WINDOW_FLOOR = 0.01  # render out to where the profile is this fraction of the noise sigma ...
WINDOW_LOST = 0.005  # ... and at least far enough that this fraction of the flux is left out
N_HOT = 5
DERIV_H = 1e-3  # s, half-step of the central difference for truth velocities
WCS_TOL_PX = 1e-6
ARCMIN = math.radians(1.0 / 60.0)

# Worker globals (filled once per process).
CAT = None
PARTICLE_MAG = (1.5, 5.0)  # --particle-mag
PARTICLE_SPEED = (6.0, 40.0)  # --particle-speed, arcmin/s against the stars at birth


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
    """Quaternion [w, x, y, z] with w >= 0 of a rotation matrix (inverse of quat_to_matrix).

    Shepperd's method: divide by the largest of the four candidates, so it is accurate for
    every rotation, not only those near identity."""
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


def random_unit(rng):
    v = rng.normal(size=3)
    return v / np.linalg.norm(v)


def random_rotation(rng):
    """Uniform random rotation: a normalised 4-D Gaussian is a uniform unit quaternion."""
    q = rng.normal(size=4)
    return quat_to_matrix(q / np.linalg.norm(q))


def rodrigues(axis, angle):
    """Rotation by `angle` (rad, right hand) about the unit vector `axis`."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(angle) * k + (1 - math.cos(angle)) * (k @ k)


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
    def __init__(self, width, height, fov_x_deg):
        self.w, self.h = width, height
        self.fx = self.fy = (width / 2.0) / math.tan(math.radians(fov_x_deg) / 2.0)
        self.cx, self.cy = (width - 1) / 2.0, (height - 1) / 2.0

    @property
    def fov_y_deg(self):
        return math.degrees(2.0 * math.atan((self.h / 2.0) / self.fy))

    def project(self, R, v):
        """ICRS unit vectors (..., 3) -> pixel x, y and camera Z (x, y meaningless where Z <= 0)."""
        c = v @ R.T
        z = c[..., 2]
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.cx + self.fx * c[..., 0] / z
            y = self.cy + self.fy * c[..., 1] / z
        return x, y, z

    def pixel_to_icrs(self, R, x, y):
        d = np.array([(x - self.cx) / self.fx, (y - self.cy) / self.fy, 1.0])
        return R.T @ (d / np.linalg.norm(d))

    def in_frame(self, x, y):
        """Centre on the detector (the pixel area, not only the pixel-centre box)."""
        return (-0.5 <= x) & (x <= self.w - 0.5) & (-0.5 <= y) & (y <= self.h - 0.5)


class Motion:
    """Constant-rate rotation of the camera about a fixed axis (camera frame)."""

    def __init__(self, R0, axis, omega):
        self.R0, self.axis, self.omega = R0, axis, omega

    def R(self, t):
        # the camera turns by +omega t about `axis`, so camera coordinates of a fixed
        # inertial vector turn by -omega t
        return rodrigues(self.axis, -self.omega * t) @ self.R0


# ----------------------------------------------------------------------------- PSF

class Moffat:
    def __init__(self, fwhm, beta):
        self.fwhm, self.beta = fwhm, beta
        self.alpha = fwhm / (2.0 * math.sqrt(2.0 ** (1.0 / beta) - 1.0))
        self.norm = (beta - 1.0) / (math.pi * self.alpha ** 2)

    def profile(self, r2):
        """Unit-flux surface brightness at squared radius r2 (px^2)."""
        return self.norm * (1.0 + r2 / self.alpha ** 2) ** (-self.beta)

    def centred_peak(self):
        """Pixel-integrated value of the pixel on which a static unit-flux source is centred."""
        return float(self.profile(np.add.outer(SUB_OFF ** 2, SUB_OFF ** 2)).mean())

    def radius(self, flux, floor, rmin=4, rmax=120):
        """Window half-size: the larger of the radius enclosing 1 - WINDOW_LOST of the flux and
        the radius where flux * profile falls below `floor` (e-/px)."""
        # flux outside r is (1 + r^2/alpha^2)^(1 - beta)
        r_flux = self.alpha * math.sqrt(WINDOW_LOST ** (1.0 / (1.0 - self.beta)) - 1.0)
        k = flux * self.norm / floor
        r_floor = self.alpha * math.sqrt(k ** (1.0 / self.beta) - 1.0) if k > 1 else 0.0
        return int(min(max(math.ceil(max(r_flux, r_floor)), rmin), rmax))


def n_substeps(xs, ys):
    """Sub-steps for a source whose image moves along (xs, ys) (a fine sampling of the exposure)."""
    smear = float(np.hypot(np.diff(xs), np.diff(ys)).sum())
    return max(MIN_SUBSTEPS, math.ceil(smear / MAX_SUBSTEP_PX))


def substep_times(t_beg, n):
    return t_beg + (np.arange(n) + 0.5) / n * EXPTIME


def render_source(img, xs, ys, flux, psf, floor):
    """Add a source imaged at sub-step positions (xs, ys), each carrying flux/len(xs).

    The source is rendered on its own stamp (so its noise-free peak, for the truth SNR, is
    known) and the part on the detector is added to `img`. Returns the stamp's peak, or None
    when the window misses the detector."""
    h, w = img.shape
    rad = psf.radius(flux, floor)
    x0, x1 = int(math.floor(xs.min())) - rad, int(math.ceil(xs.max())) + rad + 1
    y0, y1 = int(math.floor(ys.min())) - rad, int(math.ceil(ys.max())) + rad + 1
    if x1 <= 0 or y1 <= 0 or x0 >= w or y0 >= h:
        return None
    gx = (np.arange(x0, x1)[:, None] + SUB_OFF[None, :]).ravel()
    gy = (np.arange(y0, y1)[:, None] + SUB_OFF[None, :]).ravel()
    acc = np.zeros((gy.size, gx.size))
    for x, y in zip(xs, ys):
        acc += psf.profile((gy - y)[:, None] ** 2 + (gx - x)[None, :] ** 2)
    stamp = (flux / len(xs)) * acc.reshape(y1 - y0, SUB, x1 - x0, SUB).mean(axis=(1, 3))
    a0, b0 = max(y0, 0), max(x0, 0)
    a1, b1 = min(y1, h), min(x1, w)
    img[a0:a1, b0:b1] += stamp[a0 - y0:a1 - y0, b0 - x0:b1 - x0]
    return float(stamp.max())


# ----------------------------------------------------------------------------- particles

class Particle:
    """A sunlit particle moving on the ICRS sphere (see the module docstring)."""

    def __init__(self, pid, rng, p0, t_birth, star_fwhm, born_index):
        self.id, self.t_birth, self.born_index = pid, t_birth, born_index
        self.p0 = p0
        # an orthonormal tangent basis at p0; any basis gives a uniform direction
        e1 = np.cross(p0, [0.0, 0.0, 1.0] if abs(p0[2]) < 0.9 else [1.0, 0.0, 0.0])
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(p0, e1)
        psi = rng.uniform(0.0, 2 * math.pi)
        self.d0 = math.cos(psi) * e1 + math.sin(psi) * e2
        self.n0 = np.cross(self.p0, self.d0)
        self.w = rng.uniform(*PARTICLE_SPEED) * ARCMIN  # rad/s
        acc = rng.uniform(0.0, 0.01) * self.w  # rad/s^2: <= 10% of the speed per 10 s
        chi = rng.uniform(0.0, 2 * math.pi)
        self.a_par, self.a_perp = acc * math.cos(chi), acc * math.sin(chi)
        self.mag = rng.uniform(*PARTICLE_MAG)
        self.fwhm_factor = rng.uniform(1.0, 3.0)
        self.fwhm = self.fwhm_factor * star_fwhm
        self.counted = True  # its centre is in the frame (False once it has left: replaced)

    def position(self, t):
        """ICRS unit vector(s) at time(s) t (s since the sequence start)."""
        tau = np.asarray(t, float) - self.t_birth
        theta = self.w * tau + 0.5 * self.a_par * tau ** 2
        phi = 0.5 * self.a_perp * tau ** 2
        v = (np.cos(phi) * np.cos(theta))[..., None] * self.p0 \
            + (np.cos(phi) * np.sin(theta))[..., None] * self.d0 \
            + np.sin(phi)[..., None] * self.n0
        return v

    def sky_speed_arcmin_s(self, t):
        tau = t - self.t_birth
        phi = 0.5 * self.a_perp * tau ** 2
        return math.hypot((self.w + self.a_par * tau) * math.cos(phi), self.a_perp * tau) / ARCMIN


def spawn_particle(pid, rng, cam, R, t, star_fwhm, index):
    x, y = rng.uniform(0.0, cam.w - 1.0), rng.uniform(0.0, cam.h - 1.0)
    return Particle(pid, rng, cam.pixel_to_icrs(R, x, y), t, star_fwhm, index)


def pixel_velocity(cam, motion, part, t, frozen):
    """Apparent sensor velocity (px/s) of a particle at t, by central difference; with
    `frozen` the attitude is held at R(t) (velocity against the stars)."""
    h = DERIV_H
    Ra = motion.R(t) if frozen else motion.R(t - h)
    Rb = motion.R(t) if frozen else motion.R(t + h)
    xa, ya, _ = cam.project(Ra, part.position(t - h))
    xb, yb, _ = cam.project(Rb, part.position(t + h))
    return (float(xb) - float(xa)) / (2 * h), (float(yb) - float(ya)) / (2 * h)


# ----------------------------------------------------------------------------- FITS helpers

def iso_ms(t):
    """ISO time rounded to the millisecond (the header's precision)."""
    t = t.copy()
    t.precision = 3
    return t.isot


def make_wcs_header(cam, R):
    """TAN WCS of attitude R (FITS 1-based pixels, CD in deg/px), as scripts/sim_streaks.py."""
    ra0, dec0 = vec_to_radec_deg(R[2])  # boresight = principal point
    ra, dec = math.radians(ra0), math.radians(dec0)
    east = np.array([-math.sin(ra), math.cos(ra), 0.0])
    north = np.array([-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec)])
    # X/Z = (cx.e) xi + (cx.n) eta, same for Y; M is orthogonal, so the inverse is M^T
    M = np.array([[R[0] @ east, R[0] @ north], [R[1] @ east, R[1] @ north]])
    cd = np.degrees(M.T @ np.diag([1.0 / cam.fx, 1.0 / cam.fy]))
    return {
        "WCSAXES": 2, "CTYPE1": "RA---TAN", "CTYPE2": "DEC--TAN", "CUNIT1": "deg", "CUNIT2": "deg",
        "CRPIX1": cam.cx + 1.0, "CRPIX2": cam.cy + 1.0, "CRVAL1": ra0, "CRVAL2": dec0,
        "CD1_1": cd[0, 0], "CD1_2": cd[0, 1], "CD2_1": cd[1, 0], "CD2_2": cd[1, 1],
        "RADESYS": "ICRS",
    }


def check_wcs(cards, cam, R, vecs):
    """astropy's reading of the TAN WCS and our pinhole projection must agree to 1e-6 px,
    on a grid across the frame plus a few stars."""
    w = WCS(fits.Header(cards))
    pts = [(x, y) for x in (0.0, cam.cx, cam.w - 1.0) for y in (0.0, cam.cy, cam.h - 1.0)]
    dirs = np.array([cam.pixel_to_icrs(R, x, y) for x, y in pts] + list(vecs))
    x, y, z = cam.project(R, dirs)
    keep = z > 0.05
    ra = np.degrees(np.arctan2(dirs[keep, 1], dirs[keep, 0])) % 360
    dec = np.degrees(np.arcsin(np.clip(dirs[keep, 2], -1, 1)))
    wx, wy = w.wcs_world2pix(ra, dec, 0)
    err = float(np.hypot(wx - x[keep], wy - y[keep]).max())
    if not err < WCS_TOL_PX:
        raise AssertionError(f"WCS check failed: {err:.3g} px")
    return err


# ----------------------------------------------------------------------------- catalog

def load_catalog(path, max_mag=MAG_LIMIT):
    """Hipparcos-2 stars with Hp <= max_mag: unit vectors and tangent-plane velocities (rad/yr)."""
    # the header comments contain commas, so skip them before handing the rest to csv
    with open(path) as f:
        rd = csv.DictReader(line for line in f if not line.startswith("#"))
        cols = {k: [] for k in ("hip", "ra_rad", "dec_rad", "pmra_mas_yr", "pmdec_mas_yr", "hp_mag")}
        for row in rd:
            if float(row["hp_mag"]) > max_mag:
                continue
            for k in cols:
                cols[k].append(float(row[k]))
    rows = {k: np.array(v) for k, v in cols.items()}
    ra, dec = rows["ra_rad"], rows["dec_rad"]
    e_ra = np.stack([-np.sin(ra), np.cos(ra), np.zeros_like(ra)], axis=-1)
    e_dec = np.stack([-np.sin(dec) * np.cos(ra), -np.sin(dec) * np.sin(ra), np.cos(dec)], axis=-1)
    mas = math.radians(1.0 / 3.6e6)
    # pmra already includes cos(dec): a tangent-plane velocity in rad/yr
    vel = (rows["pmra_mas_yr"] * mas)[:, None] * e_ra + (rows["pmdec_mas_yr"] * mas)[:, None] * e_dec
    return {"hip": rows["hip"].astype(int), "u": radec_to_vec(ra, dec), "vel": vel, "mag": rows["hp_mag"]}


def stars_at(jyear):
    u = CAT["u"] + (jyear - EPOCH_CAT_JYEAR) * CAT["vel"]
    return u / np.linalg.norm(u, axis=1)[:, None]


# ----------------------------------------------------------------------------- sequence

class SequenceParams:
    """Everything drawn once per sequence."""

    def __init__(self, rng, args):
        self.R0 = random_rotation(rng)
        self.axis = random_unit(rng)
        self.rate_deg_s = float(rng.uniform(0.05, 0.5))
        self.interval_s = round(float(rng.uniform(*args.interval)), 3)
        t_lo = Time("2020-01-01T00:00:00", scale="utc")
        t_hi = Time("2025-01-01T00:00:00", scale="utc")
        t0 = t_lo + rng.uniform(0, (t_hi - t_lo).to_value(units.s)) * units.s
        self.t0 = Time(iso_ms(t0), format="isot", scale="utc")  # whole ms
        self.beta = float(rng.uniform(2.5, 4.0))
        self.fwhm = float(rng.uniform(1.8, 2.8))
        self.snr6 = float(rng.uniform(8.0, 15.0))
        self.sky = float(rng.uniform(50.0, 300.0))
        W = H = args.size
        idx = rng.choice(W * H, N_HOT, replace=False)
        self.hot = [(int(i % W), int(i // W)) for i in idx]
        self.hot_e = rng.uniform(500.0, 5000.0, N_HOT)
        self.star_scatter = np.exp(rng.normal(0.0, 0.10, len(CAT["mag"])))
        self.sigma = math.sqrt(self.sky + READ_NOISE ** 2)  # background noise per pixel (e-)
        self.psf = Moffat(self.fwhm, self.beta)
        self.flux6 = self.snr6 * self.sigma / self.psf.centred_peak()

    def flux(self, mag):
        return self.flux6 * 10.0 ** (-0.4 * (np.asarray(mag) - 6.0))


def render_stars(signal, cam, motion, sp, t_beg, u, jitter, sat_e):
    """Render every Hp <= 6 star (directions u) near the frame; return the truth list (centre
    in frame, brightest first) and those stars' catalogue indices."""
    R_mid = motion.R(t_beg + EXPTIME / 2)
    x, y, z = cam.project(R_mid, u)
    margin = 150  # px: wider than any window (<= 120) plus the smear
    near = np.nonzero((z > 0.1) & (x > -margin) & (x < cam.w + margin) & (y > -margin) & (y < cam.h + margin))[0]
    if near.size == 0:
        return [], []
    # the star images move together, so one sub-step count (from the fastest) serves all
    ends = [cam.project(motion.R(t), u[near]) for t in (t_beg, t_beg + EXPTIME)]
    smear = float(np.hypot(ends[1][0] - ends[0][0], ends[1][1] - ends[0][1]).max())
    n = max(MIN_SUBSTEPS, math.ceil(smear / MAX_SUBSTEP_PX))
    pos = [cam.project(motion.R(t), u[near]) for t in substep_times(t_beg, n)]
    xs = np.array([p[0] for p in pos])  # (n, stars)
    ys = np.array([p[1] for p in pos])
    flux = sp.flux(CAT["mag"][near]) * sp.star_scatter[near] * jitter[near]
    floor = WINDOW_FLOOR * sp.sigma
    stars = []
    for j, k in enumerate(near):
        peak = render_source(signal, xs[:, j], ys[:, j], flux[j], sp.psf, floor)
        if peak is None or not cam.in_frame(x[k], y[k]):
            continue
        stars.append({"_k": int(k), "hip": int(CAT["hip"][k]), "x": round(float(x[k]), 4), "y": round(float(y[k]), 4),
                      "mag": round(float(CAT["mag"][k]), 4), "peak_snr": round(peak / sp.sigma, 3),
                      "saturated": bool(peak + sp.sky >= sat_e)})
    stars.sort(key=lambda s: s["mag"])
    return stars, [s.pop("_k") for s in stars]


def render_particles(signal, cam, motion, sp, particles, t_beg, rng, sat_e):
    """Render the live particles; drop those whose window no longer touches the frame.

    Returns the truth list (centre in frame at mid-exposure) and the surviving particles."""
    t_mid = t_beg + EXPTIME / 2
    R_mid = motion.R(t_mid)
    floor = WINDOW_FLOOR * sp.sigma
    jitter = np.exp(rng.normal(0.0, 0.03, len(particles)))
    truth, alive = [], []
    for part, jit in zip(particles, jitter):
        psf = Moffat(part.fwhm, sp.beta)
        # sub-step count from the particle's own smear (ends of the exposure)
        ex, ey, _ = zip(*[cam.project(motion.R(t), part.position(t)) for t in (t_beg, t_beg + EXPTIME)])
        n = n_substeps(np.array(ex, float), np.array(ey, float))
        ts = substep_times(t_beg, n)
        pos = [cam.project(motion.R(t), part.position(t)) for t in ts]
        xs = np.array([float(p[0]) for p in pos])
        ys = np.array([float(p[1]) for p in pos])
        if min(float(p[2]) for p in pos) <= 0.1:
            continue  # wandered far behind the field: gone
        flux = float(sp.flux(part.mag)) * jit
        peak = render_source(signal, xs, ys, flux, psf, floor)
        if peak is None:
            if not part.counted:
                continue  # left the frame for good
            peak = 0.0
        alive.append(part)
        x, y, _ = cam.project(R_mid, part.position(t_mid))
        x, y = float(x), float(y)
        if not cam.in_frame(x, y):
            continue
        vx, vy = pixel_velocity(cam, motion, part, t_mid, frozen=False)
        svx, svy = pixel_velocity(cam, motion, part, t_mid, frozen=True)
        truth.append({"id": part.id, "x": round(x, 4), "y": round(y, 4),
                      "vx_px_s": round(vx, 4), "vy_px_s": round(vy, 4),
                      "mag": round(part.mag, 4), "fwhm_px": round(part.fwhm, 4),
                      "peak_snr": round(peak / sp.sigma, 3), "saturated": bool(peak + sp.sky >= sat_e),
                      "sky_speed_px_s": round(math.hypot(svx, svy), 4),
                      "sky_speed_arcmin_s": round(part.sky_speed_arcmin_s(t_mid), 4),
                      "born_index": part.born_index})
    return truth, alive


def update_particles(particles, cam, motion, t_mid, rng, fwhm, index, next_id, target):
    """Mark particles whose centre left the frame and spawn replacements, so `target` have a
    centre in the frame at t_mid. Returns (particles, next_id)."""
    R_mid = motion.R(t_mid)
    counted = 0
    for part in particles:
        if part.counted:
            x, y, z = cam.project(R_mid, part.position(t_mid))
            part.counted = bool(z > 0 and cam.in_frame(float(x), float(y)))
            counted += part.counted
    while counted < target:
        particles.append(spawn_particle(next_id, rng, cam, R_mid, t_mid, fwhm, index))
        next_id += 1
        counted += 1
    return particles, next_id


def frame_header(cam, s, k, t_beg_time, t_end_time, R_mid):
    hdr = fits.Header()
    beg = iso_ms(t_beg_time)
    hdr["DATE-OBS"] = (beg, "exposure start, UTC")
    hdr["DATE-BEG"] = (beg, "exposure start, UTC")
    hdr["DATE-END"] = (iso_ms(t_end_time), "exposure end, UTC")
    hdr["TIMESYS"] = "UTC"
    hdr["EXPTIME"] = (EXPTIME, "[s]")
    hdr["SEQUENCE"] = (s, "sequence index")
    hdr["FRAMENUM"] = (k, "frame index in the sequence")
    cards = make_wcs_header(cam, R_mid)
    for key, v in cards.items():
        hdr[key] = v
    hdr["GAIN"] = (GAIN, "[e-/ADU]")
    hdr["RDNOISE"] = (READ_NOISE, "[e-]")
    hdr["PEDESTAL"] = (BIAS, "[ADU] bias level")
    hdr["CREATOR"] = "gpustar scripts/sim_sequence.py"
    return hdr, cards


def simulate_sequence(s, args):
    rng = np.random.default_rng([args.seed, s])
    W = H = args.size
    cam = Camera(W, H, args.fov_deg)
    sp = SequenceParams(rng, args)
    motion = Motion(sp.R0, sp.axis, math.radians(sp.rate_deg_s))
    seq_dir = Path(args.out) / f"seq_{s:03d}"
    seq_dir.mkdir(parents=True, exist_ok=True)
    sat_e = (SAT_ADU - BIAS) * GAIN
    hot_map = np.zeros((H, W))
    for (hx, hy), e in zip(sp.hot, sp.hot_e):
        hot_map[hy, hx] += e

    particles, next_id, target = [], 0, None
    truths = []
    for k in range(args.frames):
        t_beg = k * sp.interval_s
        t_mid = t_beg + EXPTIME / 2
        t_beg_time = sp.t0 + t_beg * units.s
        t_end_time = sp.t0 + (t_beg + EXPTIME) * units.s
        t_mid_time = sp.t0 + t_mid * units.s
        jyear = float(t_mid_time.jyear)
        R_mid = motion.R(t_mid)

        signal = np.zeros((H, W))
        jitter = np.exp(rng.normal(0.0, 0.03, len(CAT["mag"])))
        u = stars_at(jyear)
        stars, star_idx = render_stars(signal, cam, motion, sp, t_beg, u, jitter, sat_e)
        if target is None:
            target = int(round(args.particle_ratio * len(stars)))
        particles, next_id = update_particles(particles, cam, motion, t_mid, rng, sp.fwhm, k, next_id, target)
        ptruth, particles = render_particles(signal, cam, motion, sp, particles, t_beg, rng, sat_e)

        electrons = rng.poisson(sp.sky + signal + hot_map).astype(np.float64) \
            + rng.normal(0.0, READ_NOISE, (H, W))
        img = np.clip(np.round(electrons / GAIN + BIAS), 0, SAT_ADU).astype(np.uint16)

        hdr, cards = frame_header(cam, s, k, t_beg_time, t_end_time, R_mid)
        # a grid across the frame plus the five brightest in-frame stars
        check_wcs(cards, cam, R_mid, u[star_idx[:5]])
        name = f"seq_{s:03d}/frame_{k:03d}.fits"
        # astropy stores uint16 as int16 + BZERO 32768 (BITPIX 16)
        fits.PrimaryHDU(data=img, header=hdr).writeto(Path(args.out) / name, overwrite=True)

        ra, dec = vec_to_radec_deg(R_mid[2])
        truths.append({
            "file": name, "sequence": s, "index": k, "time_utc": iso_ms(t_mid_time),
            "date_beg_utc": iso_ms(t_beg_time), "date_end_utc": iso_ms(t_end_time), "exptime_s": EXPTIME,
            "interval_s": sp.interval_s, "rate_deg_s": sp.rate_deg_s,
            "axis_cam": [float(a) for a in sp.axis],
            "ra_deg": ra, "dec_deg": dec, "roll_tetra3_deg": roll_tetra3_deg(R_mid),
            "rotation_matrix": [[float(v) for v in row] for row in R_mid],
            "quaternion": [float(v) for v in matrix_to_quat(R_mid)],
            "epoch": jyear, "width": W, "height": H, "fov_x_deg": args.fov_deg,
            "fov_y_deg": cam.fov_y_deg, "mirrored": False,
            "psf_fwhm_px": round(sp.fwhm, 4), "moffat_beta": round(sp.beta, 4), "sky_e": round(sp.sky, 2),
            "read_noise_e": READ_NOISE, "snr_hp6": round(sp.snr6, 3), "flux_hp6_e": round(sp.flux6, 2),
            "stars": stars, "particles": ptruth, "hot_pixels": [list(p) for p in sp.hot],
            "hot_pixel_e": [round(float(e), 1) for e in sp.hot_e],
        })
    return truths


# ----------------------------------------------------------------------------- driver

def sequence_summary(truths):
    """Numbers for the log: stars and particles per frame, brightness against the stars."""
    star_mags = [st["mag"] for t in truths for st in t["stars"]]
    star_snr = [st["peak_snr"] for t in truths for st in t["stars"]]
    parts = [p for t in truths for p in t["particles"]]
    out = {"stars_per_frame": float(np.mean([len(t["stars"]) for t in truths])),
           "particles_per_frame": float(np.mean([len(t["particles"]) for t in truths])),
           "births": len({p["id"] for p in parts})}
    if parts and star_mags:
        med_mag, med_snr = float(np.median(star_mags)), float(np.median(star_snr))
        out["median_star_mag"] = med_mag
        out["frac_brighter_mag"] = float(np.mean([p["mag"] < med_mag for p in parts]))
        out["frac_higher_peak_snr"] = float(np.mean([p["peak_snr"] > med_snr for p in parts]))
        out["sky_speed_px_s"] = [p["sky_speed_px_s"] for p in parts]
    return out


def _worker_init(catalog):
    global CAT
    CAT = load_catalog(catalog)


def _run(job):
    s, args = job
    global PARTICLE_MAG, PARTICLE_SPEED
    PARTICLE_MAG, PARTICLE_SPEED = tuple(args.particle_mag), tuple(args.particle_speed)
    t = time.time()
    truths = simulate_sequence(s, args)
    sm = sequence_summary(truths)
    extra = ""
    if "frac_brighter_mag" in sm:
        extra = (f", particles brighter than the median star: {100 * sm['frac_brighter_mag']:.0f}% by mag, "
                 f"{100 * sm['frac_higher_peak_snr']:.0f}% by peak SNR")
    print(f"seq {s:03d}: {len(truths)} frames in {time.time() - t:.1f} s, "
          f"{sm['stars_per_frame']:.1f} stars/frame, {sm['particles_per_frame']:.1f} particles/frame, "
          f"{truths[0]['rate_deg_s']:.3f} deg/s, dt {truths[0]['interval_s']:.3f} s{extra}",
          file=sys.stderr, flush=True)
    return truths


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--sequences", type=int, default=20)
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--particle-ratio", type=float, default=1.5)
    ap.add_argument("--particle-mag", type=float, nargs=2, default=[1.5, 5.0], metavar=("LO", "HI"),
                    help="particle magnitudes, uniform (default 1.5 5.0)")
    ap.add_argument("--particle-speed", type=float, nargs=2, default=[6.0, 40.0], metavar=("LO", "HI"),
                    help="particle birth speed against the stars, arcmin/s, uniform (default 6 40)")
    ap.add_argument("--interval", type=float, nargs=2, default=[0.5, 2.0], metavar=("LO", "HI"),
                    help="frame interval per sequence, s, uniform (default 0.5 2.0)")
    ap.add_argument("--fov-deg", type=float, default=18.0)
    ap.add_argument("--size", type=int, default=1024)
    ap.add_argument("--catalog", default=str(DEFAULT_CATALOG))
    ap.add_argument("-j", "--jobs", type=int, default=1, help="worker processes (default 1)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.toml").write_text(f"width = {args.size}\nheight = {args.size}\nfov_x_deg = {args.fov_deg}\n")
    t0 = time.time()
    jobs = [(s, args) for s in range(args.sequences)]
    if args.jobs > 1:
        with Pool(args.jobs, initializer=_worker_init, initargs=(args.catalog,)) as pool:
            results = pool.map(_run, jobs, chunksize=1)
    else:
        _worker_init(args.catalog)
        results = [_run(j) for j in jobs]
    truths = [t for seq in results for t in seq]
    with open(out / "truth.jsonl", "w") as f:
        for t in truths:
            f.write(json.dumps(t) + "\n")
    sm = sequence_summary(truths)
    msg = (f"{args.sequences} sequences x {args.frames} frames in {time.time() - t0:.1f} s -> {out}; "
           f"{sm['stars_per_frame']:.1f} stars/frame, {sm['particles_per_frame']:.1f} particles/frame, "
           f"{sm['births']} particles in all")
    if "frac_brighter_mag" in sm:
        v = np.array(sm["sky_speed_px_s"])
        msg += (f"; particles brighter than the median in-view star (Hp {sm['median_star_mag']:.2f}): "
                f"{100 * sm['frac_brighter_mag']:.1f}% by magnitude, {100 * sm['frac_higher_peak_snr']:.1f}% "
                f"by peak SNR; speed against the stars {v.min():.1f}..{v.max():.1f} px/s (median {np.median(v):.1f})")
    print(msg, file=sys.stderr)


if __name__ == "__main__":
    main()
