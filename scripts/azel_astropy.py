#!/usr/bin/env python3
"""Reference topocentric Az/El from astropy, to check gpustar's streak END az_deg/el_deg.

Usage:
    python3 scripts/azel_astropy.py --dir DIR RECORDS.jsonl [--station LAT,LON,H] [--json OUT]
    python3 scripts/azel_astropy.py --point RA_DEG DEC_DEG TIME_UTC LAT_DEG LON_DEG HEIGHT_M

For every streak END with non-null time_utc, az_deg and el_deg, the END's own ra_deg/dec_deg
(ICRS) are reduced with
    SkyCoord(ra, dec, frame='icrs').transform_to(AltAz(obstime=Time(time_utc, scale='utc'),
             location=EarthLocation.from_geodetic(lon, lat, height), pressure=0))
i.e. the airless "as a star" chain (IAU 2006/2000A, annual aberration, Earth rotation from UT1,
polar motion) that INTERFACE.md promises. The station comes from --station, else the FITS
header of DIR/<file>: OBSGEO-B/L/H, else SITELAT/SITELONG/SITEELEV (degrees, metres).
Reported: the angular distance on the sphere between astropy's and the record's (az, el),
max and median in arcsec, and how many ENDs were compared. Only the reduction is checked
here (record RA/Dec and time in, Az/El out); score_streaks.py checks the RA/Dec and times.

astropy runs offline on its bundled IERS/leap-second tables (auto_download = False); the
bundled IERS-B covers the simulator's 2020-2024.5 epochs.
"""
import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np
from astropy.utils import iers

iers.conf.auto_download = False
import astropy.units as u  # noqa: E402
from astropy.coordinates import AltAz, EarthLocation, SkyCoord  # noqa: E402
from astropy.io import fits  # noqa: E402
from astropy.time import Time  # noqa: E402


def azel(ra_deg, dec_deg, time_utc, lat_deg, lon_deg, height_m):
    """Vectorised: arrays of ICRS RA/Dec and UTC ISO times at one station -> (az, el) deg."""
    loc = EarthLocation.from_geodetic(lon=lon_deg * u.deg, lat=lat_deg * u.deg, height=height_m * u.m)
    t = Time(time_utc, scale="utc")
    c = SkyCoord(ra=np.asarray(ra_deg) * u.deg, dec=np.asarray(dec_deg) * u.deg, frame="icrs")
    aa = c.transform_to(AltAz(obstime=t, location=loc, pressure=0 * u.hPa))
    return aa.az.deg, aa.alt.deg


def sphere_sep_arcsec(az1, el1, az2, el2):
    a1, e1, a2, e2 = (np.radians(np.asarray(v, float)) for v in (az1, el1, az2, el2))
    h = np.sin((e2 - e1) / 2) ** 2 + np.cos(e1) * np.cos(e2) * np.sin((a2 - a1) / 2) ** 2
    return np.degrees(2 * np.arcsin(np.minimum(1.0, np.sqrt(h)))) * 3600.0


def station_from_header(path):
    h = fits.getheader(path)
    for lat, lon, hgt in (("OBSGEO-B", "OBSGEO-L", "OBSGEO-H"), ("SITELAT", "SITELONG", "SITEELEV")):
        if lat in h and lon in h:
            return float(h[lat]), float(h[lon]), float(h.get(hgt, 0.0))
    return None


def main(argv=None):
    ap = argparse.ArgumentParser(description="astropy reference Az/El for gpustar streak ends")
    ap.add_argument("records", nargs="?", help="gpustar records (JSON lines)")
    ap.add_argument("--dir", help="directory of the FITS frames (for the station keywords)")
    ap.add_argument("--station", help="LAT,LON,HEIGHT_M for all frames (overrides the headers)")
    ap.add_argument("--point", nargs=6, metavar=("RA", "DEC", "TIME", "LAT", "LON", "H"),
                    help="print astropy's az el (deg) for one direction, UTC time and station")
    ap.add_argument("--json", help="write per-END comparisons here")
    ap.add_argument("--worst", type=int, default=5, help="list this many worst ENDs")
    args = ap.parse_args(argv)

    if args.point:
        ra, dec, t, lat, lon, h = args.point
        az, el = azel([float(ra)], [float(dec)], [t], float(lat), float(lon), float(h))
        print(f"{az[0]:.9f} {el[0]:.9f}")
        return
    if not args.records or not (args.dir or args.station):
        ap.error("RECORDS and --dir (or --station) are needed without --point")

    fixed = tuple(float(v) for v in args.station.split(",")) if args.station else None
    rows, skipped = [], {"no_station": 0, "null_time_or_azel": 0, "no_radec": 0}
    with open(args.records) as f:
        records = [json.loads(line) for line in f if line.strip()]
    for rec in records:
        name = str(rec.get("file", "")).replace("\\", "/").rsplit("/", 1)[-1]
        ends = [(si, k, e) for si, s in enumerate(rec.get("streaks") or []) for k, e in enumerate(s.get("ends") or [])]
        todo = [(si, k, e) for si, k, e in ends
                if e.get("time_utc") and e.get("az_deg") is not None and e.get("el_deg") is not None]
        skipped["null_time_or_azel"] += len(ends) - len(todo)
        if not todo:
            continue
        st = fixed
        if st is None:
            p = Path(args.dir) / name
            st = station_from_header(p) if p.exists() else None
        if st is None:
            skipped["no_station"] += len(todo)
            continue
        good = [(si, k, e) for si, k, e in todo if e.get("ra_deg") is not None and e.get("dec_deg") is not None]
        skipped["no_radec"] += len(todo) - len(good)
        if not good:
            continue
        with warnings.catch_warnings():
            # ERFA's "dubious year" warnings are about leap-second tables for far-future dates
            warnings.simplefilter("ignore")
            az, el = azel([e["ra_deg"] for _, _, e in good], [e["dec_deg"] for _, _, e in good],
                          [e["time_utc"] for _, _, e in good], *st)
        sep = sphere_sep_arcsec(az, el, [e["az_deg"] for _, _, e in good], [e["el_deg"] for _, _, e in good])
        for (si, k, e), a, b, d in zip(good, az, el, sep):
            rows.append({"file": name, "streak": si, "end": k, "time_utc": e["time_utc"],
                         "ra_deg": e["ra_deg"], "dec_deg": e["dec_deg"], "station": list(st),
                         "az_record": e["az_deg"], "el_record": e["el_deg"],
                         "az_astropy": float(a), "el_astropy": float(b), "sep_arcsec": float(d)})

    seps = np.array([r["sep_arcsec"] for r in rows])
    if len(seps):
        print(f"compared {len(seps)} streak ends: max {seps.max():.3f}\", median {np.median(seps):.3f}\", "
              f"p95 {np.percentile(seps, 95):.3f}\"")
        for r in sorted(rows, key=lambda r: -r["sep_arcsec"])[:args.worst]:
            print(f"  {r['file']} streak {r['streak']} end {r['end']}: {r['sep_arcsec']:.3f}\"  "
                  f"record az/el {r['az_record']:.6f} {r['el_record']:.6f}  "
                  f"astropy {r['az_astropy']:.6f} {r['el_astropy']:.6f}")
    else:
        print("compared 0 streak ends")
    print("not compared: " + ", ".join(f"{k} {v}" for k, v in skipped.items()))
    if args.json:
        with open(args.json, "w") as f:
            json.dump({"compared": len(rows), "max_arcsec": float(seps.max()) if len(seps) else None,
                       "median_arcsec": float(np.median(seps)) if len(seps) else None,
                       "skipped": skipped, "ends": rows}, f, indent=1)
    return rows


if __name__ == "__main__":
    sys.exit(main() and 0)
