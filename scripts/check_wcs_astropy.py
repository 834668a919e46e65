#!/usr/bin/env python3
"""Cross-check gpustar .wcs files with astropy.

For every identified star of a solved record, project its catalog RA/Dec through the .wcs
file with astropy and compare with the star's measured pixel (x, y) from the record.

    check_wcs_astropy.py RECORDS.jsonl WCS [--quiet]

WCS is a .wcs file (checked against the record of the matching input: `a/b.png` <->
`.../a/b.wcs`, or the only solved record) or a directory laid out like gpustar's output
(`<dir>/a/b.wcs` for input `a/b.png`), which checks every solved record.

gpustar pixels are 0-based with (0, 0) the centre of the top-left pixel; the .wcs files use
FITS pixel (x + 1, y + 1), so astropy's 0-based pixels (origin 0) compare directly.

Two astropy paths are reported:
  world_to_pixel  astropy's all_world2pix: iteratively inverts CD + A/B (the fitted SIP);
  AP/BP           wcs_world2pix (CD only) then sip_foc2pix: the exact inverse polynomials.
With real detections the differences include the solution's residuals (residual_arcsec).

Needs: pip install astropy numpy
"""

import argparse
import json
import sys
import warnings
from pathlib import Path

import numpy as np
from astropy.io import fits
from astropy.wcs import WCS, FITSFixedWarning


def load_records(path):
    with open(path) as f:
        for n, line in enumerate(f, 1):
            line = line.strip()
            if line:
                try:
                    yield json.loads(line)
                except json.JSONDecodeError as e:
                    sys.exit(f"{path}:{n}: not JSON: {e}")


def unit_vectors(ra_deg, dec_deg):
    ra, dec = np.radians(ra_deg), np.radians(dec_deg)
    return np.column_stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)])


def wcs_path_for(record_file, wcs_dir):
    return wcs_dir / Path(record_file).with_suffix(".wcs")


def pick_record(wcs_file, solved):
    """The solved record whose input path (minus extension) ends the .wcs path."""
    stem = wcs_file.resolve().with_suffix("")
    best = None
    for rec in solved:
        parts = Path(rec["file"]).with_suffix("").parts
        if stem.parts[-len(parts):] == parts and (best is None or len(parts) > best[0]):
            best = (len(parts), rec)
    if best:
        return best[1]
    if len(solved) == 1:
        return solved[0]
    sys.exit(f"no record matches {wcs_file}; give the records file of that frame")


def check(wcs_file, rec, quiet):
    with fits.open(wcs_file) as hdul:
        header = hdul[0].header
    with warnings.catch_warnings():
        # "more axes (2) than the image (0)": expected for a header-only .wcs file.
        warnings.simplefilter("ignore", FITSFixedWarning)
        w = WCS(header)
    m = rec.get("matches") or []
    if not m:
        print(f"{rec['file']}: no matches")
        return np.zeros(0), np.zeros(0), np.zeros(0)
    ra = np.array([s["ra_deg"] for s in m])
    dec = np.array([s["dec_deg"] for s in m])
    x = np.array([s["x"] for s in m])
    y = np.array([s["y"] for s in m])

    ax, ay = w.all_world2pix(ra, dec, 0, tolerance=1e-8, maxiter=100, quiet=True)
    d_a = np.hypot(ax - x, ay - y)
    if w.sip is not None and w.sip.ap is not None:
        # astropy's focal-plane coordinates are offsets from CRPIX; with origin 1 the
        # result is the 1-based pixel.
        fx, fy = w.wcs_world2pix(ra, dec, 1)
        foc = np.column_stack([fx, fy]) - w.wcs.crpix
        px, py = (w.sip_foc2pix(foc, 1) - 1.0).T
    else:
        px, py = w.wcs_world2pix(ra, dec, 0)
    d_p = np.hypot(px - x, py - y)

    # Pixel -> world (A/B then CD): angle between the measured star and its catalog place.
    wra, wdec = w.all_pix2world(x, y, 0)
    a, b = unit_vectors(ra, dec), unit_vectors(wra, wdec)
    sep = np.arctan2(np.linalg.norm(np.cross(a, b), axis=1), np.sum(a * b, axis=1))
    sep_arcsec = np.degrees(sep) * 3600.0

    if not quiet:
        print(f"# {rec['file']}  ({wcs_file})  CTYPE1={header['CTYPE1']}")
        print(f"# {'hip':>7} {'x':>10} {'y':>10} {'dx':>10} {'dy':>10} {'|d| w2p':>10} {'|d| AP/BP':>10}")
        for s, dx, dy, da, dp in zip(m, ax - x, ay - y, d_a, d_p):
            print(f"  {s.get('hip', ''):>7} {s['x']:10.3f} {s['y']:10.3f} "
                  f"{dx:10.2e} {dy:10.2e} {da:10.2e} {dp:10.2e}")
    print(f"{rec['file']}: {len(m)} stars, max |d| world_to_pixel {d_a.max():.3e} px, "
          f"AP/BP {d_p.max():.3e} px, median {np.median(d_a):.3e} px; "
          f"pixel_to_world max {sep_arcsec.max():.3e} arcsec")
    return d_a, d_p, sep_arcsec


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("records", type=Path, help="gpustar JSON-lines records")
    ap.add_argument("wcs", type=Path, help="a .wcs file or the --wcs-dir of the run")
    ap.add_argument("--quiet", action="store_true", help="only the per-frame summary")
    args = ap.parse_args()

    solved = [r for r in load_records(args.records) if r.get("status") == "solved"]
    if args.wcs.is_dir():
        pairs = [(wcs_path_for(r["file"], args.wcs), r) for r in solved]
        missing = [str(p) for p, _ in pairs if not p.exists()]
        if missing:
            print(f"warning: {len(missing)} solved records have no .wcs file, e.g. {missing[0]}",
                  file=sys.stderr)
        pairs = [(p, r) for p, r in pairs if p.exists()]
    elif args.wcs.exists():
        pairs = [(args.wcs, pick_record(args.wcs, solved))]
    else:
        sys.exit(f"{args.wcs} does not exist")
    if not pairs:
        sys.exit("nothing to check")

    results = [check(path, rec, args.quiet) for path, rec in pairs]
    all_a, all_p, all_s = (np.concatenate(r) for r in zip(*results))
    if len(pairs) > 1 and all_a.size:
        print(f"ALL: {len(pairs)} frames, {all_a.size} stars, max |d| world_to_pixel "
              f"{all_a.max():.3e} px, AP/BP {all_p.max():.3e} px; "
              f"pixel_to_world max {all_s.max():.3e} arcsec")


if __name__ == "__main__":
    main()
