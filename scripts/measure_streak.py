#!/usr/bin/env python3
"""Independent measurement of one streak in a FITS frame (numpy/scipy/astropy only).

Usage:
    python3 scripts/measure_streak.py FRAME.fits X0,Y0,X1,Y1 [--knot-px 4] [--mask X,Y,R] [--json OUT]

X0,Y0,X1,Y1 is a rough guess of the ends (0-based pixel centres, x = column), e.g. read off a
display; a few pixels off is fine. The streak is modelled as an object moving uniformly along
a segment whose brightness may change along it (tumbling, glints, a gap): a Gaussian profile
across the line, a piecewise-linear brightness along it (a knot every --knot-px, each free, >= 0), and
ends where the along-track profile falls to half of the local brightness, i.e.

    m(x, y) = B + exp(-d^2 / 2 s^2) * b(t) * 1/2 [erf((t - t0)/sqrt2 s_a) - erf((t - t1)/sqrt2 s_a)]

fitted by scipy's least_squares (soft-L1 loss, so stars on the track weigh little) on the
pixels within 12 px of the line. s and s_a (across and along the track) are separate: a
frame's PSF need not be round. Prints the ends with 1-sigma errors from the Jacobian, and the
ends' RA/Dec through the header's WCS (astropy) when it has one.

Written for ASTRiDE's sample frame long.fits (broken streak, 2002 SAAO), to have ends that
do not come from gpustar; nothing here is shared with gpustar's fit.
"""
import argparse
import json
import math

import numpy as np
from astropy.io import fits
from astropy.wcs import WCS
from scipy.optimize import least_squares
from scipy.special import erf


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("frame")
    ap.add_argument("guess", help="X0,Y0,X1,Y1 (0-based pixels)")
    ap.add_argument("--knot-px", type=float, default=4.0,
                    help="spacing of the brightness knots along the track (px; default 4)")
    ap.add_argument("--mask", action="append", default=[],
                    help="X,Y,R: leave out the pixels within R of (X, Y) (a star on the track)")
    ap.add_argument("--json", help="write the result here")
    args = ap.parse_args(argv)

    hdu = fits.open(args.frame)[0]
    img = hdu.data.astype(float)
    h, w = img.shape
    x0, y0, x1, y1 = map(float, args.guess.split(","))
    L0 = math.hypot(x1 - x0, y1 - y0)
    ux, uy = (x1 - x0) / L0, (y1 - y0) / L0

    yy, xx = np.mgrid[0:h, 0:w]
    t_all = (xx - x0) * ux + (yy - y0) * uy
    d_all = -(xx - x0) * uy + (yy - y0) * ux
    sel = (np.abs(d_all) <= 12) & (t_all >= -25) & (t_all <= L0 + 25)
    for m in args.mask:
        mx, my, mr = map(float, m.split(","))
        sel &= (xx - mx) ** 2 + (yy - my) ** 2 > mr * mr
    X, Y, V = xx[sel].astype(float), yy[sel].astype(float), img[sel]
    # Background: the median of the band's pixels farther than 6 px from the line.
    bg0 = float(np.median(V[np.abs(d_all[sel]) > 6]))
    # Knots inside the guessed ends: beyond the outer ones the brightness stays constant
    # (np.interp), so the ends are fixed by the erf steps, not by a knot's free amplitude.
    nk = max(int(round((L0 - 6) / args.knot_px)) + 1, 2)
    knots = np.linspace(3, L0 - 3, nk)

    def unpack(p):
        rho, th, t0, t1, s, sa, bg = p[:7]
        return rho, th, t0, t1, s, sa, bg, p[7:]

    def model(p):
        rho, th, t0, t1, s, sa, bg, amp = unpack(p)
        c, sn = math.cos(th), math.sin(th)
        # line through (x0, y0) + rho * normal, direction th
        px, py = x0 - rho * sn, y0 + rho * c
        t = (X - px) * c + (Y - py) * sn
        d = -(X - px) * sn + (Y - py) * c
        b = np.interp(t, knots, amp)
        along = 0.5 * (erf((t - t0) / (math.sqrt(2) * sa)) - erf((t - t1) / (math.sqrt(2) * sa)))
        return bg + np.exp(-d * d / (2 * s * s)) * b * along

    th0 = math.atan2(uy, ux)
    # Start: the brightness at each knot from the pixels near the line.
    on = np.abs(d_all[sel]) <= 1.0
    amp0 = np.array([max(np.median(V[on & (np.abs(t_all[sel] - k) < 10)] - bg0) if np.any(on & (np.abs(t_all[sel] - k) < 10)) else 0.0, 1.0)
                     for k in knots])
    p0 = np.concatenate([[0.0, th0, 0.0, L0, 1.5, 1.5, bg0], amp0])
    lo = np.concatenate([[-6, th0 - 0.1, -20, L0 - 20, 0.4, 0.4, bg0 - 200], np.zeros(nk)])
    hi = np.concatenate([[6, th0 + 0.1, 20, L0 + 20, 6, 6, bg0 + 200], np.full(nk, np.inf)])
    noise = 1.4826 * np.median(np.abs(V - bg0))

    def resid(p):
        return (V - model(p)) / noise

    r = least_squares(resid, p0, bounds=(lo, hi), loss="soft_l1", f_scale=3.0, x_scale="jac")
    rho, th, t0, t1, s, sa, bg, amp = unpack(r.x)
    # 1-sigma from the Jacobian, scaled by the residuals' robust scatter.
    J = r.jac
    scat = 1.4826 * np.median(np.abs(resid(r.x)))
    try:
        cov = np.linalg.inv(J.T @ J) * scat ** 2
        err = np.sqrt(np.diag(cov))
    except np.linalg.LinAlgError:
        err = np.full(len(r.x), np.nan)
    c, sn = math.cos(th), math.sin(th)
    px, py = x0 - rho * sn, y0 + rho * c
    ends = [(px + t0 * c, py + t0 * sn), (px + t1 * c, py + t1 * sn)]
    out = {"frame": args.frame, "ends": [[round(e[0], 3), round(e[1], 3)] for e in ends],
           "end_sigma_px": [round(float(err[2]), 3), round(float(err[3]), 3)],
           "sigma_across_px": round(s, 3), "sigma_along_px": round(sa, 3),
           "length_px": round(t1 - t0, 3), "angle_deg": round(math.degrees(th), 4),
           "brightness_knots": [round(float(a), 1) for a in amp], "noise_adu": round(float(noise), 2),
           "status": r.status, "cost": float(r.cost)}
    # Brightness modulation along the track: the knots' scatter over their median (inner knots).
    inner = amp[(knots > t0 + 10) & (knots < t1 - 10)]
    if inner.size:
        out["brightness_min_median_max"] = [round(float(inner.min()), 1), round(float(np.median(inner)), 1),
                                            round(float(inner.max()), 1)]
    try:
        wcs = WCS(hdu.header)
        if wcs.has_celestial:
            ra, dec = wcs.celestial.wcs_pix2world([e[0] for e in ends], [e[1] for e in ends], 0)
            out["ends_radec_deg"] = [[round(float(a), 6), round(float(b), 6)] for a, b in zip(ra, dec)]
    except Exception as e:  # a header astropy cannot read: say so, keep the pixel result
        out["wcs_error"] = str(e)
    print(json.dumps(out, indent=1))
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=1)


if __name__ == "__main__":
    main()
