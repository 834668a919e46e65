#!/usr/bin/env python3
"""Independent simulator of satellite passes seen by one station: multi-frame sequences with
streaks of objects propagated by python-sgp4, and the TLE file of (most of) those objects.

Written without gpustar's code: orbits by python-sgp4 (`pip install sgp4`), the TEME -> ITRS
-> topocentric AltAz -> ICRS chain by astropy, frames rendered with scripts/sim_streaks.py's
PSF, streak and star functions (Moffat beta 3, Poisson and read noise).

Usage:
    python3 scripts/sim_passes.py --out DIR [--passes 40 --decoys 2000 --seed 1]

Writes DIR/pass_NNN/frame_MM.fits (one directory per pass: gpustar batch DIR -r --streaks),
DIR/objects.tle (3-line TLEs), DIR/truth.jsonl (one JSON object per frame) and DIR/camera.toml.

Model
-----
* Station: one site (OBSGEO-B/L/H in every header), lat 47.0678, lon 15.4933, 493 m.
* A pass: an object on a near-circular orbit (altitude 400..2000 km) built to cross the sky
  at elevation 25..85 deg at the pass's middle instant (a random UTC in 2024-2025); its state
  there (position on the line of sight at that altitude, circular speed in a random direction
  across it) is turned into Keplerian elements and given to SGP4 as mean elements, and from
  then on SGP4 alone says where it is. The camera points at where the object is seen at the
  middle instant (plus up to 10 % of the field at random, random roll) and tracks the stars.
* Frames: 3..5 per pass, exposure chosen so the object's streak is 80..250 px long at the
  middle, gaps 20..60 % of the exposure. 1024 x 1024 px, 10 deg field, pinhole.
* Apparent places: the object's TEME position at t - range/c (light time, iterated) -> ITRS ->
  topocentric (astropy, pressure 0) -> the ICRS direction a star seen there would have (astropy
  AltAz -> ICRS), projected by the camera: the sky the stars are drawn in. Each streak is the
  straight segment between the places at exposure start and end.
* --night UTC: every pass within 10 h of UTC and the decoys' elements 0-3 days older than it
  (a night's archive against a current catalog); otherwise passes over 2024-2025.
* Other objects: with p = 0.6 one object NOT in the TLE file crosses the field during the pass,
  with p = 0.3 one more object of the file; each built like the pass's object to cross a random
  point of the field at a random instant of the pass. The file also holds --decoys random
  objects (LEO 70 %, MEO 15 %, GEO 15 %); any of them that crosses a frame is rendered too.
* The TLE file holds each file object's elements perturbed as real elements are off: mean
  anomaly shifted by n * dt (dt uniform +-1.5 s: along-track) and the node by +-0.002 deg
  (cross-track); the truth records both. Streak peak SNR uniform 5..25 per pixel (as
  sim_streaks.py defines it); stars Hipparcos Hp <= 8 as sim_streaks.py renders them.
* --glints: each streak gets a tumbling object's light curve, one of sim_streaks.py's five
  (steady, periodic, irregular, gaps, flashes) equally often, its own along each frame's
  track; truth "glint". --faint: peak SNR uniform 3..25 instead of 5..25 (streaks near the
  detection limit). Both draw from their own random stream, so the passes, objects and frames
  are those made without them.
"""
import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import sim_streaks as ss  # noqa: E402
from astropy import units as u  # noqa: E402
from astropy.coordinates import (  # noqa: E402
    ICRS, TEME, AltAz, CartesianRepresentation, EarthLocation, ITRS, SkyCoord)
from astropy.io import fits  # noqa: E402
from astropy.time import Time  # noqa: E402
from sgp4.api import WGS72, Satrec, SatrecArray  # noqa: E402
from sgp4.exporter import export_tle  # noqa: E402

MU = 398600.8  # km^3/s^2, WGS-72 (what SGP4 uses)
RE = 6378.135  # km, WGS-72
C_KM_S = 299792.458
LAT, LON, HGT = 47.0678, 15.4933, 493.0
SIZE, FOV = 1024, 10.0


def kepler(r, v):
    """Osculating elements (a km, e, i, raan, argp, M in radians) of a TEME state."""
    r, v = np.asarray(r, float), np.asarray(v, float)
    h = np.cross(r, v)
    n = np.cross([0, 0, 1.0], h)
    rn, vn = np.linalg.norm(r), np.linalg.norm(v)
    ev = ((vn ** 2 - MU / rn) * r - np.dot(r, v) * v) / MU
    e = np.linalg.norm(ev)
    a = 1.0 / (2.0 / rn - vn ** 2 / MU)
    i = math.acos(h[2] / np.linalg.norm(h))
    raan = math.atan2(n[1], n[0]) % (2 * math.pi)
    nn = np.linalg.norm(n)
    if e > 1e-6:
        argp = math.acos(np.clip(np.dot(n, ev) / (nn * e), -1, 1))
        if ev[2] < 0:
            argp = 2 * math.pi - argp
        nu = math.acos(np.clip(np.dot(ev, r) / (e * rn), -1, 1))
        if np.dot(r, v) < 0:
            nu = 2 * math.pi - nu
    else:
        argp = 0.0
        nu = math.acos(np.clip(np.dot(n, r) / (nn * rn), -1, 1))
        if r[2] < 0:
            nu = 2 * math.pi - nu
    E = 2 * math.atan2(math.sqrt(1 - e) * math.sin(nu / 2), math.sqrt(1 + e) * math.cos(nu / 2))
    M = (E - e * math.sin(E)) % (2 * math.pi)
    return a, e, i, raan, argp, M


def satrec(norad, epoch, a, e, i, raan, argp, M, bstar=2e-5):
    s = Satrec()
    n = math.sqrt(MU / a ** 3) * 60.0  # rad/min
    s.sgp4init(WGS72, "i", norad, epoch.jd1 + epoch.jd2 - 2433281.5, bstar, 0.0, 0.0, e, argp, i, M, n, raan)
    return s


def teme_of_itrs(x_km, t):
    c = ITRS(CartesianRepresentation(np.asarray(x_km).T * u.km), obstime=t).transform_to(TEME(obstime=t))
    return c.cartesian.xyz.to_value(u.km).T


def orbit_through(rng, norad, t, loc, az, el, alt_km):
    """An object seen at (az, el) at time t at altitude alt_km, moving in a random direction."""
    d_enu = np.array([math.cos(el) * math.sin(az), math.cos(el) * math.cos(az), math.sin(el)])
    lat, lon = math.radians(LAT), math.radians(LON)
    E = np.array([-math.sin(lon), math.cos(lon), 0])
    N = np.array([-math.sin(lat) * math.cos(lon), -math.sin(lat) * math.sin(lon), math.cos(lat)])
    U = np.array([math.cos(lat) * math.cos(lon), math.cos(lat) * math.sin(lon), math.sin(lat)])
    d = d_enu[0] * E + d_enu[1] * N + d_enu[2] * U
    s = loc.get_itrs(t).cartesian.xyz.to_value(u.km)
    rr = RE + alt_km
    b = np.dot(s, d)
    rng_km = -b + math.sqrt(b * b - (np.dot(s, s) - rr * rr))
    r_teme = teme_of_itrs((s + rng_km * d)[None, :], t)[0]
    # Circular speed, across the position in a random direction.
    rhat = r_teme / np.linalg.norm(r_teme)
    w = rng.normal(size=3)
    w -= np.dot(w, rhat) * rhat
    w /= np.linalg.norm(w)
    v = w * math.sqrt(MU / np.linalg.norm(r_teme))
    return satrec(norad, t, *kepler(r_teme, v))


def random_orbit(rng, norad, t_epoch):
    k = rng.random()
    if k < 0.7:
        a = RE + rng.uniform(350, 2000)
        e = rng.uniform(0, 0.02)
    elif k < 0.85:
        a = RE + rng.uniform(19000, 24000)
        e = rng.uniform(0, 0.02)
    else:
        a = 42164.0 + rng.uniform(-300, 300)
        e = rng.uniform(0, 0.001)
    i = math.radians(rng.uniform(0, 100) if k < 0.85 else rng.uniform(0, 15))
    return satrec(norad, t_epoch, a, e, i, *rng.uniform(0, 2 * math.pi, 3))


def perturbed(rng, sat, norad):
    """The elements as the file gives them: along-track time and node offsets."""
    dt = float(rng.uniform(-1.5, 1.5))
    dnode = math.radians(float(rng.uniform(-0.002, 0.002)))
    s = Satrec()
    s.sgp4init(WGS72, "i", norad, sat.jdsatepoch + sat.jdsatepochF - 2433281.5, sat.bstar, 0.0, 0.0,
               sat.ecco, sat.argpo, sat.inclo, (sat.mo + sat.no_kozai * dt / 60.0) % (2 * math.pi),
               sat.no_kozai, (sat.nodeo + dnode) % (2 * math.pi))
    return s, dt, math.degrees(dnode)


def apparent(sats, t, loc):
    """ICRS unit vectors (as a star) and elevations (deg) of each Satrec seen at time t (scalar Time),
    light time taken off; None rows where SGP4 fails."""
    arr = SatrecArray(sats)
    jd = np.array([t.jd1])
    fr = np.array([t.jd2])
    e, r, v = arr.sgp4(jd, fr)
    r, v = r[:, 0, :], v[:, 0, :]
    ok = e[:, 0] == 0
    itrs = ITRS(CartesianRepresentation(r.T * u.km), obstime=t)
    s = loc.get_itrs(t).cartesian.xyz.to_value(u.km)
    for _ in range(2):
        x = TEME(CartesianRepresentation(r.T * u.km), obstime=t).transform_to(ITRS(obstime=t))
        rg = np.linalg.norm(x.cartesian.xyz.to_value(u.km).T - s, axis=1)
        lt = rg / C_KM_S
        r = r - v * lt[:, None]
    x = TEME(CartesianRepresentation(r.T * u.km), obstime=t).transform_to(ITRS(obstime=t))
    topo = x.cartesian.without_differentials() - loc.get_itrs(t).cartesian
    itrs = ITRS(topo, obstime=t, location=loc)
    aa = itrs.transform_to(AltAz(obstime=t, location=loc, pressure=0 * u.hPa))
    star = SkyCoord(AltAz(az=aa.az, alt=aa.alt, obstime=t, location=loc, pressure=0 * u.hPa)).transform_to(ICRS())
    vec = ss.radec_to_vec(star.ra.rad, star.dec.rad)
    return vec, aa.alt.deg, ok


def camera_towards(rng, b):
    """R (ICRS -> camera rows) with boresight b and a random roll."""
    b = b / np.linalg.norm(b)
    w = rng.normal(size=3)
    x = w - np.dot(w, b) * b
    x /= np.linalg.norm(x)
    y = np.cross(b, x)
    return np.array([x, y, b])


def render_frame(rng, cam, R, t_beg, t_end, streaks_px, path):
    W = H = SIZE
    fwhm = float(rng.uniform(2.2, 3.2))
    alpha = ss.moffat_alpha(fwhm)
    sky0 = float(rng.uniform(300.0, 800.0))
    sig = math.sqrt(sky0 + ss.READ_NOISE ** 2)
    centred_peak = float(ss.moffat(np.add.outer(ss.SUB_OFF ** 2, ss.SUB_OFF ** 2), alpha).mean())
    flux6 = 8.0 * sig / centred_peak
    signal = np.zeros((H, W))
    dt = (t_beg.jyear + t_end.jyear) / 2 - ss.EPOCH_CAT_JYEAR
    uu = ss.CAT["u"] + dt * ss.CAT["vel"]
    uu /= np.linalg.norm(uu, axis=1)[:, None]
    sx, sy, sz = cam.project(R, uu)
    flux = flux6 * 10 ** (-0.4 * (ss.CAT["mag"] - 6.0)) * np.exp(rng.normal(0.0, 0.15, size=len(sx)))
    near = (sz > 0) & (sx > -90) & (sx < W + 89) & (sy > -90) & (sy < H + 89)
    for k in np.nonzero(near)[0]:
        ss.render_point(signal, sx[k], sy[k], flux[k], alpha, ss.moffat_radius(flux[k], alpha))
    for st in streaks_px:
        p0, p1 = np.array(st["p0"]), np.array(st["p1"])
        theta = math.atan2(p1[1] - p0[1], p1[0] - p0[0])
        density = st["peak_snr"] * sig / ss.streak_peak_factor(theta, alpha)
        ss.render_streak(signal, p0, p1, density, alpha, st.get("_bright"))
    electrons = rng.poisson(sky0 + signal).astype(np.float64) + rng.normal(0.0, ss.READ_NOISE, (H, W))
    img = np.clip(np.round(electrons / ss.GAIN + ss.BIAS), 0, ss.SAT_ADU).astype(np.uint16)
    hdr = fits.Header()
    hdr["DATE-OBS"] = ss.iso_ms(t_beg)
    hdr["DATE-BEG"] = ss.iso_ms(t_beg)
    hdr["DATE-END"] = ss.iso_ms(t_end)
    hdr["EXPTIME"] = round((t_end - t_beg).to_value(u.s), 3)
    hdr["TIMESYS"] = "UTC"
    hdr["OBSGEO-B"] = LAT
    hdr["OBSGEO-L"] = LON
    hdr["OBSGEO-H"] = HGT
    hdr["OBSERVAT"] = "SIMPASS"
    for k, v in ss.make_wcs_header(cam, R).items():
        hdr[k] = v
    fits.PrimaryHDU(data=img, header=hdr).writeto(path, overwrite=True)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", required=True)
    ap.add_argument("--passes", type=int, default=40)
    ap.add_argument("--decoys", type=int, default=2000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--catalog", default=str(ss.DEFAULT_CATALOG))
    ap.add_argument("--night", help="one night from this UTC (passes over 10 h, elements of the "
                    "decoys 0-3 days old) instead of passes spread over 2024-2025")
    ap.add_argument("--first-id", type=int, default=1000,
                    help="NORAD ids are drawn from FIRST..FIRST+89000 (another file's ids apart)")
    ap.add_argument("--glints", action="store_true",
                    help="tumbling objects: a light curve along each streak (sim_streaks.py's)")
    ap.add_argument("--faint", action="store_true",
                    help="peak SNR 3..25 instead of 5..25: streaks near the detection limit")
    args = ap.parse_args(argv)
    # --glints and --faint draw from their own stream: the geometry stays that of the seed.
    rng2 = np.random.default_rng([args.seed, 2])
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "camera.toml").write_text(f"width = {SIZE}\nheight = {SIZE}\nfov_x_deg = {FOV}\n")
    ss._worker_init(args.catalog)
    rng = np.random.default_rng(args.seed)
    loc = EarthLocation.from_geodetic(LON * u.deg, LAT * u.deg, HGT * u.m)
    cam = ss.Camera(SIZE, SIZE, FOV)
    scale_deg = FOV / SIZE
    ids = iter(rng.permutation(np.arange(args.first_id, args.first_id + 89000))[: 4 * args.passes + args.decoys + 10].tolist())
    t0 = Time("2024-01-01T00:00:00", scale="utc")
    file_objs = []  # (norad, name, des, satrec as written)
    true_objs = {}  # norad -> (true satrec, in_file, along_s, dnode_deg)
    used_des = set()

    def add_object(sat, norad, in_file):
        if in_file:
            s, dt, dn = perturbed(rng, sat, norad)
            while True:  # designators are unique, as real ones are
                des = (f"{20 + int(rng.integers(0, 6)):02d}{int(rng.integers(1, 300)):03d}"
                       f"{'ABCDEFGHJKLMNPQRSTUVWXYZ'[int(rng.integers(0, 24))]}")
                if des not in used_des:
                    used_des.add(des)
                    break
            file_objs.append((norad, f"SIM-{norad}", des, s))
            true_objs[norad] = (sat, True, dt, dn)
        else:
            true_objs[norad] = (sat, False, 0.0, 0.0)

    passes = []
    for p in range(args.passes):
        if args.night:
            t_mid = Time(args.night, scale="utc") + rng.uniform(0, 10) * u.hour
        else:
            t_mid = t0 + rng.uniform(0, 730) * u.day
        t_mid = Time(ss.iso_ms(t_mid), format="isot", scale="utc")
        norad = next(ids)
        main_sat = orbit_through(rng, norad, t_mid, loc, rng.uniform(0, 2 * math.pi),
                                 math.radians(rng.uniform(25, 85)), rng.uniform(400, 2000))
        add_object(main_sat, norad, True)
        v0, el0, _ = apparent([main_sat], t_mid, loc)
        v1, _, _ = apparent([main_sat], t_mid + 1 * u.s, loc)
        rate_px = math.degrees(math.acos(np.clip(v0[0] @ v1[0], -1, 1))) / scale_deg
        length = rng.uniform(80, 250)
        exp_s = float(np.clip(length / max(rate_px, 1e-3), 0.3, 30.0))
        gap_s = exp_s * rng.uniform(0.2, 0.6)
        n = int(rng.integers(3, 6))
        off = rng.normal(size=3)
        b = v0[0] + 0.1 * math.radians(FOV) * (off - (off @ v0[0]) * v0[0]) / np.linalg.norm(off)
        R = camera_towards(rng, b)
        span = n * exp_s + (n - 1) * gap_s
        starts = [t_mid + (-span / 2 + k * (exp_s + gap_s)) * u.s for k in range(n)]
        starts = [Time(ss.iso_ms(s), format="isot", scale="utc") for s in starts]
        ends = [Time(ss.iso_ms(s + exp_s * u.s), format="isot", scale="utc") for s in starts]
        others = [norad]
        for in_file, prob in ((False, 0.6), (True, 0.3)):
            if rng.random() < prob:
                # Through a random point of the field at a random instant of the pass.
                x, y = rng.uniform(0.15, 0.85, 2) * SIZE
                d = cam.pixel_to_icrs(R, x, y)
                tc = t_mid + rng.uniform(-span / 2, span / 2) * u.s
                sc = SkyCoord(ICRS(ra=math.atan2(d[1], d[0]) * u.rad, dec=math.asin(d[2] / np.linalg.norm(d)) * u.rad))
                aa = sc.transform_to(AltAz(obstime=tc, location=loc, pressure=0 * u.hPa))
                if aa.alt.deg < 15:
                    continue
                k = next(ids)
                sat = orbit_through(rng, k, tc, loc, aa.az.rad, aa.alt.rad, rng.uniform(400, 3000))
                add_object(sat, k, in_file)
                others.append(k)
        passes.append(dict(t_mid=t_mid, R=R, starts=starts, ends=ends, objects=others, exp_s=exp_s))

    for _ in range(args.decoys):
        k = next(ids)
        if args.night:
            epoch = Time(args.night, scale="utc") - rng.uniform(0, 3) * u.day
        else:
            epoch = t0 + rng.uniform(0, 730) * u.day
        add_object(random_orbit(rng, k, epoch), k, True)

    # The file: 3-line TLEs, in random order.
    order = rng.permutation(len(file_objs))
    with open(out / "objects.tle", "w") as f:
        for j in order:
            norad, name, des, s = file_objs[j]
            l1, l2 = export_tle(s)
            l1 = l1[:9] + f"{des:<8}" + l1[17:]
            # The checksum after the designator went in.
            body = l1[:68]
            cs = sum(int(c) if c.isdigit() else (1 if c == "-" else 0) for c in body) % 10
            f.write(f"{name}\n{body}{cs}\n{l2}\n")

    all_norads = list(true_objs)
    all_sats = [true_objs[k][0] for k in all_norads]
    truths = []
    for p, ps in enumerate(passes):
        d = out / f"pass_{p:03d}"
        d.mkdir(exist_ok=True)
        for f, (tb, te) in enumerate(zip(ps["starts"], ps["ends"])):
            # Every object of the run seen in the frame (the pass's own, and any other).
            vb, elb, okb = apparent(all_sats, tb, loc)
            ve, ele, oke = apparent(all_sats, te, loc)
            xb, yb, zb = cam.project(ps["R"], vb)
            xe, ye, ze = cam.project(ps["R"], ve)
            streaks = []
            for j, k in enumerate(all_norads):
                if not (okb[j] and oke[j] and zb[j] > 0 and ze[j] > 0 and elb[j] > 5 and ele[j] > 5):
                    continue
                p0, p1 = np.array([xb[j], yb[j]]), np.array([xe[j], ye[j]])
                vis = ss.clip_segment(p0, p1, -0.5, SIZE - 0.5, -0.5, SIZE - 0.5)
                if vis is None or math.dist(vis[0], vis[1]) < 20:
                    continue
                sat, in_file, along, dnode = true_objs[k]
                streaks.append({
                    "norad": int(k), "in_file": in_file, "pass_object": k in ps["objects"],
                    "p0": [float(p0[0]), float(p0[1])], "p1": [float(p1[0]), float(p1[1])],
                    "edge0": bool(ss.off_detector(p0, SIZE, SIZE)), "edge1": bool(ss.off_detector(p1, SIZE, SIZE)),
                    "visible_length_px": round(math.dist(vis[0], vis[1]), 2),
                    "length_px": round(float(np.linalg.norm(p1 - p0)), 2),
                    "peak_snr": round(float(rng.uniform(5.0, 25.0)), 2),
                    "file_along_s": along, "file_dnode_deg": dnode,
                })
                if args.faint:
                    streaks[-1]["peak_snr"] = round(float(rng2.uniform(3.0, 25.0)), 2)
                if args.glints:
                    glint, bright = ss.draw_glint(rng2, float(np.linalg.norm(p1 - p0)))
                    streaks[-1]["glint"] = glint
                    if bright is not None:
                        streaks[-1]["_bright"] = bright
            name = f"pass_{p:03d}/frame_{f:02d}.fits"
            render_frame(rng, cam, ps["R"], tb, te, streaks, out / name)
            streaks = [{k: v for k, v in st.items() if k != "_bright"} for st in streaks]
            truths.append({"file": name, "pass": p, "frame": f, "date_beg_utc": ss.iso_ms(tb),
                           "date_end_utc": ss.iso_ms(te), "streaks": streaks})
        print(f"pass {p}: {len(ps['starts'])} frames, exposure {ps['exp_s']:.2f} s, "
              f"{sum(len(t['streaks']) for t in truths if t['pass'] == p)} streaks", file=sys.stderr)
    with open(out / "truth.jsonl", "w") as f:
        for t in truths:
            f.write(json.dumps(t) + "\n")
    n = sum(len(t["streaks"]) for t in truths)
    nin = sum(s["in_file"] for t in truths for s in t["streaks"])
    print(f"{len(truths)} frames, {n} streaks ({nin} of objects in the file), "
          f"{len(file_objs)} objects in {out / 'objects.tle'}", file=sys.stderr)


if __name__ == "__main__":
    main()
