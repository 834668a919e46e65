#!/usr/bin/env python3
"""Reference numbers for gpustar's TEME -> topocentric chain (src/sky/tle.rs), made by
independent code: python-sgp4 (Vallado's SGP4, `pip install sgp4`) for the TEME state, and
astropy's TEME -> ITRS -> AltAz (pressure 0: geometric, airless) at the station.

Prints the Rust table that src/sky/tests.rs `tle_chain_matches_astropy` checks against:
(label, TLE line 1, TLE line 2, lat, lon, height_m, utc, teme x y z km, az, el, range km,
astropy's dut1 s, xp rad, yp rad).

    python3 scripts/tle_astropy.py
"""
import math

import numpy as np
from astropy.utils import iers

iers.conf.auto_download = False
from astropy import units as u  # noqa: E402
from astropy.coordinates import (  # noqa: E402
    TEME, AltAz, CartesianDifferential, CartesianRepresentation, EarthLocation, ITRS)
from astropy.time import Time  # noqa: E402
from sgp4.api import WGS72, Satrec, jday  # noqa: E402
from sgp4.exporter import export_tle  # noqa: E402


def elements(norad, epoch, incl, raan, ecc, argp, ma, n_rev_day, bstar=1e-4):
    """A Satrec from mean elements (degrees, rev/day) at epoch (astropy Time, UTC)."""
    s = Satrec()
    jd, fr = epoch.jd1, epoch.jd2
    s.sgp4init(WGS72, "i", norad, (jd + fr) - 2433281.5, bstar, 0.0, 0.0, ecc,
               math.radians(argp), math.radians(incl), math.radians(ma),
               n_rev_day * 2 * math.pi / 1440.0, math.radians(raan))
    l1, l2 = export_tle(s)
    # Read back from the text, as gpustar reads it.
    return Satrec.twoline2rv(l1, l2), l1, l2


CASES = [
    # label, (norad, epoch, incl, raan, ecc, argp, M, n), station (lat, lon, h), hours after epoch
    ("LEO 51.6 deg, Graz", (25544, "2024-03-15T00:00:00", 51.64, 247.46, 0.0006703, 130.5, 325.0, 15.5),
     (47.0678, 15.4933, 493.0), 3.7),
    ("LEO polar, Siding Spring", (43013, "2025-06-01T12:00:00", 98.7, 10.0, 0.0012, 90.0, 200.0, 14.2),
     (-31.2733, 149.0644, 1165.0), 20.25),
    ("MEO GNSS, Tenerife", (40105, "2024-11-20T06:00:00", 55.0, 120.0, 0.005, 30.0, 10.0, 2.0056),
     (28.3, -16.51, 2390.0), 30.0),
    ("GEO, Mauna Kea", (41866, "2026-01-10T00:00:00", 0.05, 80.0, 0.0002, 250.0, 100.0, 1.00273),
     (19.8207, -155.4681, 4205.0), 50.5),
    ("Molniya, Svalbard", (40296, "2025-02-02T00:00:00", 63.4, 300.0, 0.72, 270.0, 45.0, 2.006),
     (78.2297, 15.4077, 520.0), 7.1),
    ("LEO, leap day near zenith check", (28654, "2024-02-28T22:00:00", 85.0, 33.0, 0.0009, 15.0, 80.0, 14.9),
     (-24.6272, -70.4042, 2635.0), 6.0),
]


def main():
    print("    // python-sgp4 %s, astropy %s, numpy %s" % (
        __import__("sgp4").__version__, __import__("astropy").__version__, np.__version__))
    for label, el, (lat, lon, h), hours in CASES:
        norad, epoch, incl, raan, ecc, argp, ma, n = el
        sat, l1, l2 = elements(norad, Time(epoch, scale="utc"), incl, raan, ecc, argp, ma, n)
        t = Time(sat.jdsatepoch, sat.jdsatepochF, format="jd", scale="utc") + hours * u.hour
        t = Time(t.isot[:23], format="isot", scale="utc")
        ymd = t.ymdhms
        jd, fr = jday(int(ymd["year"]), int(ymd["month"]), int(ymd["day"]), int(ymd["hour"]),
                      int(ymd["minute"]), float(ymd["second"]))
        e, r, v = sat.sgp4(jd, fr)
        assert e == 0, e
        teme = TEME(CartesianRepresentation(r * u.km).with_differentials(
            CartesianDifferential(v * u.km / u.s)), obstime=t)
        itrs = teme.transform_to(ITRS(obstime=t))
        loc = EarthLocation.from_geodetic(lon * u.deg, lat * u.deg, h * u.m)
        # Topocentric ITRS (astropy's recipe for nearby objects): ITRS -> AltAz is then a
        # rotation, no aberration and no refraction.
        topo = itrs.cartesian.without_differentials() - loc.get_itrs(t).cartesian
        itrs_topo = ITRS(topo, obstime=t, location=loc)
        aa = itrs_topo.transform_to(AltAz(obstime=t, location=loc, pressure=0 * u.hPa))
        dut1 = float(t.delta_ut1_utc)
        xp, yp = iers.earth_orientation_table.get().pm_xy(t)
        print('    ("%s", "%s", "%s", %r, %r, %r, "%s", [%r, %r, %r], %r, %r, %r, %r, %r, %r),' % (
            label, l1, l2, lat, lon, h, t.isot, *[float(x) for x in r],
            float(aa.az.deg), float(aa.alt.deg), float(aa.distance.to_value(u.km)),
            dut1, float(xp.to_value(u.rad)), float(yp.to_value(u.rad))))


if __name__ == "__main__":
    main()
