#!/usr/bin/env python3
"""Make catalog/eop.csv, the Earth orientation table that src/sky/earth.rs embeds, and the
astropy reference Az/El that its tests hold.

    pip install astropy astropy-iers-data
    scripts/make_eop.py [--out catalog/eop.csv] [--step 5]   # write the table, print the check
    scripts/make_eop.py --astropy-cases                      # print the Rust test cases

Source: the IERS 20 C04 series (daily at 0h UTC) that the PyPI package astropy-iers-data bundles
(`astropy.utils.iers.IERS_B`), and after its last day the IERS Rapid Service / Prediction Centre
series finals2000A.all bundled in the same package (`astropy.utils.iers.IERS_A`): its bulletin-A
columns UT1_UTC_A, PM_x_A, PM_y_A, observed (flag I) and then predicted (flag P) to about a year
ahead. C04 rows are kept unchanged where C04 exists; IERS-A only extends the table. Nothing is
downloaded, here or when gpustar builds or runs.

The table keeps one row every STEP days from 1973-01-01 to the C04 series' last day (always
included), then every STEP days from there to the last IERS-A prediction (always included):
mjd (UTC, 0h), UT1-UTC (s), polar motion x and y (arcsec). A comment line says from which MJD
the rows are IERS-A and from which they are predictions. src/sky/earth.rs interpolates linearly in UT1-TAI,
which has no leap-second steps, over TAI; this script prints the error of doing so against the
full daily series, in UT1 (ms) and in Earth rotation (arcsec, 15.04"/s), and compares the table's
UT1-UTC at a few instants with astropy's own (Time.delta_ut1_utc, bundled IERS-A, no download).

--astropy-cases: astropy's ICRS -> AltAz (pressure 0, bundled IERS tables, auto_download off)
for the stations, times and directions in CASES. Each case is picked as an (az, el) target,
turned into ICRS with astropy, rounded, and then transformed forward: the printed RA/Dec and
Az/El pair exactly. Printed with astropy's own UT1-UTC and polar motion at that instant.
"""
import argparse
import math
import os
import sys

STEP_DAYS = 5
START_MJD = 41683  # 1973-01-01

# (label, lat deg, lon deg east, height m, UTC, target az deg, target el deg)
CASES = [
    ("Mauna Kea, high", 19.8207, -155.4681, 4205.0, "2015-03-20T10:17:33.250", 123.0, 47.0),
    ("Siding Spring, south", -31.2733, 149.0644, 1165.0, "2018-06-11T13:02:05.125", 201.0, 63.0),
    ("Paranal, near zenith", -24.6272, -70.4042, 2635.0, "2024-02-29T04:44:44.444", 17.0, 89.7),
    ("Greenwich, near horizon", 51.4769, -0.0005, 46.0, "2020-12-21T22:30:00.000", 301.0, 0.8),
    ("Tehran, seed", 35.7, 51.4, 1200.0, "2015-09-24T12:05:47.660", 350.0, 30.0),
    ("Leap second, Kitt Peak", 31.9583, -111.5967, 2096.0, "2016-12-31T23:59:60.500", 80.0, 12.0),
    ("Svalbard, far north", 78.2297, 15.4077, 520.0, "2022-05-01T00:00:00.000", 210.0, 5.0),
    ("Hobart, south low", -42.8806, 147.3250, 50.0, "2019-01-15T16:20:00.000", 140.0, 21.0),
]

# The seed-004 paper's streak ends (RA h:m:s, Dec d:m:s, UTC); the paper gives no station, so
# Tehran (35.7 N, 51.4 E, 1200 m) stands in. src/sky/tests.rs's seed_004_example holds these.
SEED = [
    ("15:25:48.613", "+63:23:44.43", "2015-09-24T12:05:47.660"),
    ("15:26:24.533", "+63:13:29.72", "2015-09-24T12:06:17.260"),
]
SEED_STATION = (35.7, 51.4, 1200.0)


def repo_root():
    return os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def load_c04():
    """The bundled IERS-B (C04) table: file path, version, and daily rows."""
    import astropy_iers_data
    from astropy.utils import iers

    b = iers.IERS_B.open()
    mjd = [float(v) for v in b["MJD"].value]
    dut1 = [float(v) for v in b["UT1_UTC"].value]
    xp = [float(v) for v in b["PM_x"].value]
    yp = [float(v) for v in b["PM_y"].value]
    return iers.IERS_B_FILE, astropy_iers_data.__version__, mjd, dut1, xp, yp


def load_iers_a():
    """The bundled IERS-A (finals2000A.all) bulletin-A columns: file path and daily rows
    (mjd, UT1-UTC s, xp, yp arcsec, UT1 flag, UT1-UTC error s, PM x error arcsec)."""
    import numpy as np
    from astropy.utils import iers

    a = iers.IERS_A.open(iers.IERS_A_FILE)
    ut1 = a["UT1_UTC_A"]
    ok = ~(np.ma.getmaskarray(ut1) | np.ma.getmaskarray(a["PM_x_A"])
           | np.ma.getmaskarray(a["PM_y_A"]))
    col = lambda name: [float(v) for v in np.asarray(a[name].value)[ok]]
    flags = [str(f) for f in np.asarray(a["UT1Flag_A"])[ok]]
    return (iers.IERS_A_FILE, col("MJD"), col("UT1_UTC_A"), col("PM_x_A"), col("PM_y_A"),
            flags, col("e_UT1_UTC_A"), col("e_PM_x_A"))


def tai_minus_utc(mjd):
    """TAI-UTC (s) at 0h UTC of an integral MJD, from ERFA's leap-second table."""
    import erfa

    jd = 2400000.5 + mjd
    y, m, d, _ = erfa.jd2cal(jd, 0.0)
    return float(erfa.dat(y, m, d, 0.0))


def mjd_to_date(mjd):
    import erfa

    y, m, d, _ = erfa.jd2cal(2400000.5 + mjd, 0.0)
    return f"{int(y):04d}-{int(m):02d}-{int(d):02d}"


def make_table(out, step):
    path, version, mjd, dut1, xp, yp = load_c04()
    n_c04 = len(mjd)
    first = mjd.index(float(START_MJD))
    keep = list(range(first, n_c04, step))
    if keep[-1] != n_c04 - 1:
        keep.append(n_c04 - 1)
    c04_end = mjd[-1]

    # IERS-A after the last C04 day: daily, consecutive, appended to the same series.
    a_path, a_mjd, a_dut1, a_xp, a_yp, a_flag, a_err, a_pm_err = load_iers_a()
    after = [i for i, m in enumerate(a_mjd) if m > c04_end]
    if not after or a_mjd[after[0]] != c04_end + 1:
        raise SystemExit(f"IERS-A does not continue C04 (last C04 MJD {c04_end:.0f})")
    pred_mjd = None  # first predicted day
    for i in after:
        if a_mjd[i] != mjd[-1] + 1:
            raise SystemExit(f"IERS-A gap before MJD {a_mjd[i]:.0f}")
        mjd.append(a_mjd[i])
        dut1.append(a_dut1[i])
        xp.append(a_xp[i])
        yp.append(a_yp[i])
        if pred_mjd is None and a_flag[i] == "P":
            pred_mjd = a_mjd[i]
    a_keep = list(range(n_c04 - 1 + step, len(mjd), step))
    if a_keep[-1] != len(mjd) - 1:
        a_keep.append(len(mjd) - 1)
    keep += a_keep
    a_row0 = mjd[a_keep[0]]
    pred_row0 = next(mjd[i] for i in a_keep if mjd[i] >= pred_mjd)

    def a_err_after(days):
        m = pred_mjd + days
        i = a_mjd.index(m) if m in a_mjd else len(a_mjd) - 1
        return a_err[i], a_pm_err[i], a_mjd[i] - pred_mjd

    e10, p10, _ = a_err_after(10)
    e_end, p_end, d_end = a_err_after(10**9)
    lines = [
        # The path below is the module's name when catalog/eop.csv was made (now src/sky/earth.rs);
        # kept so that the script still reproduces the committed file byte for byte.
        "# Earth orientation for gpustar (src/streaks/sky.rs), made by scripts/make_eop.py",
        f"# source: IERS 20 C04 (daily, 0h UTC) file {os.path.basename(path)} bundled in "
        f"PyPI astropy-iers-data {version}",
        f"# range: {mjd_to_date(mjd[keep[0]])} (MJD {mjd[keep[0]]:.0f}) to "
        f"{mjd_to_date(mjd[keep[-1]])} (MJD {mjd[keep[-1]]:.0f}), every {step} days, "
        f"last C04 day and last IERS-A day kept",
        f"# IERS-A from MJD {a_row0:.0f} ({mjd_to_date(a_row0)}) on: after the last C04 day "
        f"(MJD {c04_end:.0f}), bulletin-A UT1-UTC and polar motion from "
        f"{os.path.basename(a_path)} (same package); predictions from MJD {pred_mjd:.0f} "
        f"({mjd_to_date(pred_mjd)}; first predicted row MJD {pred_row0:.0f}), "
        f"UT1-UTC error ~{e10 * 1e3:.0f} ms after 10 days, ~{e_end * 1e3:.0f} ms after "
        f"{d_end:.0f} days (polar motion ~{p10 * 1e3:.0f} mas, ~{p_end * 1e3:.0f} mas; IERS)",
        "# interpolate linearly in UT1-TAI (no leap-second steps), not in UT1-UTC",
        "mjd,ut1_minus_utc_s,xp_arcsec,yp_arcsec",
    ]
    for i in keep:
        lines.append(f"{mjd[i]:.0f},{dut1[i]:.7f},{xp[i]:.6f},{yp[i]:.6f}")
    with open(out, "w") as f:
        f.write("\n".join(lines) + "\n")
    print(f"wrote {out}: {len(keep)} rows ({len(keep) - len(a_keep)} C04, {len(a_keep)} IERS-A), "
          f"{os.path.getsize(out)} bytes, {mjd_to_date(mjd[keep[0]])} .. {mjd_to_date(mjd[keep[-1]])}")
    print("C04 part:")
    check(mjd[:n_c04], dut1[:n_c04], xp[:n_c04], yp[:n_c04], keep[:len(keep) - len(a_keep)])
    print("IERS-A part (from the last C04 row on):")
    base = n_c04 - 1
    check(mjd[base:], dut1[base:], xp[base:], yp[base:], [i - base for i in [base] + a_keep],
          full=False)
    check_astropy(out)


def table_dut1(rows, utc_mjd):
    """UT1-UTC (s) at a UTC MJD from (mjd, dut1) rows, as src/sky/earth.rs's earth_orientation does."""
    day = math.floor(utc_mjd)
    dat = tai_minus_utc(day)
    t = day + (utc_mjd - day) + dat / 86400.0  # no leap second inside the checked instants
    pts = [(m + tai_minus_utc(m) / 86400.0, d - tai_minus_utc(m)) for m, d in rows]
    for (ta, ua), (tb, ub) in zip(pts, pts[1:]):
        if ta <= t <= tb:
            return ua + (t - ta) / (tb - ta) * (ub - ua) + dat
    return None


def check_astropy(out, dates=("2026-10-01", "2026-11-01", "2026-12-01", "2027-03-01",
                              "2027-06-01", "2027-10-01")):
    """The table's interpolated UT1-UTC against astropy's Time.delta_ut1_utc (IERS_Auto with
    auto_download off: the bundled IERS-A, with IERS-B substituted where it has values)."""
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    rows = []
    with open(out) as f:
        for line in f:
            if line[0].isdigit():
                m, d, _, _ = line.split(",")
                rows.append((float(m), float(d)))
    print("table vs astropy Time.delta_ut1_utc (bundled IERS-A, no download):")
    for date in dates:
        t = Time(date, scale="utc")
        ours = table_dut1(rows, float(t.mjd))
        theirs = float(t.delta_ut1_utc)
        print(f"  {date}: table {ours:+.7f} s, astropy {theirs:+.7f} s, "
              f"diff {(ours - theirs) * 1e3:+.4f} ms")


def check(mjd, dut1, xp, yp, keep, full=True):
    """Linear interpolation between kept rows (in UT1-TAI over TAI, as src/sky/earth.rs does) against
    every daily row from the first kept one on. full: also the since-2000 and linear-in-UT1-UTC
    figures (for the C04 part, which spans the leap seconds)."""
    dat = {m: tai_minus_utc(m) for m in mjd[keep[0]:]}
    worst = (0.0, None)
    worst_naive = (0.0, None)
    worst_pm = 0.0
    worst_2000 = 0.0  # from 2000-01-01 (MJD 51544) on
    worst_pm_2000 = 0.0
    sq = 0.0
    n = 0
    for a, b in zip(keep, keep[1:]):
        ta = mjd[a] + dat[mjd[a]] / 86400.0
        tb = mjd[b] + dat[mjd[b]] / 86400.0
        ua = dut1[a] - dat[mjd[a]]
        ub = dut1[b] - dat[mjd[b]]
        for i in range(a + 1, b):
            t = mjd[i] + dat[mjd[i]] / 86400.0
            w = (t - ta) / (tb - ta)
            est = ua + w * (ub - ua) + dat[mjd[i]]
            err = est - dut1[i]
            sq += err * err
            n += 1
            if abs(err) > worst[0]:
                worst = (abs(err), mjd[i])
            if mjd[i] >= 51544:
                worst_2000 = max(worst_2000, abs(err))
            naive = dut1[a] + (mjd[i] - mjd[a]) / (mjd[b] - mjd[a]) * (dut1[b] - dut1[a])
            if abs(naive - dut1[i]) > worst_naive[0]:
                worst_naive = (abs(naive - dut1[i]), mjd[i])
            for arr in (xp, yp):
                e = abs(arr[a] + w * (arr[b] - arr[a]) - arr[i])
                worst_pm = max(worst_pm, e)
                if mjd[i] >= 51544:
                    worst_pm_2000 = max(worst_pm_2000, e)
    rms = math.sqrt(sq / n)
    print(f"interpolation check over {n} daily rows between kept ones:")
    print(f"  UT1-UTC, linear in UT1-TAI: max {worst[0] * 1e3:.3f} ms (at {mjd_to_date(worst[1])}), "
          f"rms {rms * 1e3:.3f} ms; max costs {worst[0] * 15.041:.4f} arcsec of Earth rotation"
          + (f"; since 2000 max {worst_2000 * 1e3:.3f} ms" if full else ""))
    if full:
        print(f"  (linear in UT1-UTC instead: max {worst_naive[0] * 1e3:.1f} ms, "
              f"at {mjd_to_date(worst_naive[1])}, across a leap second)")
    print(f"  polar motion x/y: max {worst_pm * 1e3:.3f} mas"
          + (f", since 2000 {worst_pm_2000 * 1e3:.3f} mas" if full else ""))


def astropy_cases():
    import numpy as np
    from astropy import units as u
    from astropy.coordinates import AltAz, EarthLocation, SkyCoord
    from astropy.coordinates.builtin_frames.utils import get_polar_motion
    from astropy.time import Time
    from astropy.utils import iers

    iers.conf.auto_download = False
    iers.conf.auto_max_age = None
    print("    // (label, lat, lon, height_m, utc, ra_deg, dec_deg, az_deg, el_deg, dut1_s, xp_rad, yp_rad)")
    for label, lat, lon, h, utc, az0, el0 in CASES:
        loc = EarthLocation.from_geodetic(lon * u.deg, lat * u.deg, h * u.m, ellipsoid="WGS84")
        t = Time(utc, scale="utc")
        frame = AltAz(obstime=t, location=loc, pressure=0 * u.hPa)
        icrs = SkyCoord(az=az0 * u.deg, alt=el0 * u.deg, frame=frame).icrs
        ra = round(float(icrs.ra.deg), 7)
        dec = round(float(icrs.dec.deg), 7)
        aa = SkyCoord(ra=ra * u.deg, dec=dec * u.deg, frame="icrs").transform_to(frame)
        dut1 = float(t.delta_ut1_utc)
        xp, yp = (float(v) for v in get_polar_motion(t))
        print(f'    ("{label}", {lat}, {lon}, {h}, "{utc}", {ra!r}, {dec!r}, '
              f"{float(aa.az.deg)!r}, {float(aa.alt.deg)!r}, {dut1!r}, {xp!r}, {yp!r}),")
    lat, lon, h = SEED_STATION
    loc = EarthLocation.from_geodetic(lon * u.deg, lat * u.deg, h * u.m, ellipsoid="WGS84")
    print("    // seed 004 at Tehran: (ra, dec, utc, az_deg, el_deg)")
    for ra, dec, utc in SEED:
        t = Time(utc, scale="utc")
        c = SkyCoord(ra, dec, unit=(u.hourangle, u.deg), frame="icrs")
        aa = c.transform_to(AltAz(obstime=t, location=loc, pressure=0 * u.hPa))
        print(f'    ("{ra}", "{dec}", "{utc}", {float(aa.az.deg)!r}, {float(aa.alt.deg)!r}),')
    import astropy
    import astropy_iers_data
    print(f"    // astropy {astropy.__version__}, astropy-iers-data {astropy_iers_data.__version__}, "
          f"numpy {np.__version__}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", default=os.path.join(repo_root(), "catalog", "eop.csv"))
    ap.add_argument("--step", type=int, default=STEP_DAYS)
    ap.add_argument("--astropy-cases", action="store_true")
    args = ap.parse_args()
    if args.astropy_cases:
        astropy_cases()
    else:
        make_table(args.out, args.step)
    return 0


if __name__ == "__main__":
    sys.exit(main())
