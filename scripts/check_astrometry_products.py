#!/usr/bin/env python3
"""Read what `gpustar batch --new-fits N --corr C --axy A -o run.jsonl` wrote with astropy, as
astrometry.net's users would read solve-field's .new/.corr/.axy, and compare with the records:

- the .new header's WCS (astropy.wcs, SIP included) at each matched detection gives a
  direction whose angle to the matched catalog star equals the record's residual_arcsec;
- the .corr's field_ra/field_dec are astropy's WCS at field_x/field_y (1-based), and its
  index_x/index_y are astropy's WCS at index_ra/index_dec;
- the .axy holds the record's stars_detected rows, and the .new holds the frame's pixels.

    python3 scripts/check_astrometry_products.py run.jsonl NEW_DIR CORR_DIR AXY_DIR [FRAMES_DIR]

Prints one line per solved frame and the worst figures; exits 1 when a figure is off the mark
(0.01 arcsec, 0.001 px).
"""
import json
import sys
import warnings
from pathlib import Path

import numpy as np
from astropy.io import fits
from astropy.table import Table
from astropy.wcs import WCS, FITSFixedWarning

warnings.simplefilter("ignore", FITSFixedWarning)
run, new_dir, corr_dir, axy_dir = (Path(a) for a in sys.argv[1:5])
frames = Path(sys.argv[5]) if len(sys.argv) > 5 else None


def unit(ra, dec):
    ra, dec = np.radians(ra), np.radians(dec)
    return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], -1)


def angle_arcsec(a, b):
    # atan2 of cross and dot: exact at small angles.
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), (a * b).sum(-1))) * 3600


def product(d, name, ext):
    return d / (name.rsplit(".", 1)[0] + ext)


worst = dict(residual=0.0, field=0.0, index=0.0)
solved = 0
for line in open(run):
    r = json.loads(line)
    if r["status"] == "error":
        continue
    axy = Table.read(product(axy_dir, r["file"], ".axy"))
    assert len(axy) == r["stars_detected"], (r["file"], len(axy), r["stars_detected"])
    assert list(axy.colnames[:3]) == ["X", "Y", "FLUX"]
    if r["status"] != "solved":
        continue
    solved += 1
    new = product(new_dir, r["file"], ".fits")
    with fits.open(new) as f:
        w = WCS(f[0].header)
        data = f[0].data
    m = r["matches"]
    x = np.array([s["x"] for s in m])
    y = np.array([s["y"] for s in m])
    ra, dec = w.all_pix2world(x, y, 0)  # origin 0: gpustar's pixels
    sep = angle_arcsec(unit(ra, dec), unit([s["ra_deg"] for s in m], [s["dec_deg"] for s in m]))
    d_res = np.abs(sep - np.array([s["residual_arcsec"] for s in m])).max()
    corr = Table.read(product(corr_dir, r["file"], ".corr"))
    assert len(corr) == len(m)
    fra, fdec = w.all_pix2world(corr["field_x"], corr["field_y"], 1)
    d_field = angle_arcsec(unit(fra, fdec), unit(corr["field_ra"], corr["field_dec"])).max()
    ix, iy = w.all_world2pix(corr["index_ra"], corr["index_dec"], 1)
    d_index = max(np.abs(ix - corr["index_x"]).max(), np.abs(iy - corr["index_y"]).max())
    worst.update(residual=max(worst["residual"], d_res), field=max(worst["field"], d_field),
                 index=max(worst["index"], d_index))
    print(f"{r['file']}: {len(m)} matches, {len(axy)} detections, .new {data.shape} {data.dtype}"
          f" {'SIP' if w.sip is not None else 'TAN'}; |astropy angle - residual| {d_res:.1e}\","
          f" corr field {d_field:.1e}\", index {d_index:.1e} px")
print(f"{solved} solved frames; worst: residual {worst['residual']:.2e}\", field radec "
      f"{worst['field']:.2e}\", index xy {worst['index']:.2e} px")
ok = solved > 0 and worst["residual"] < 0.01 and worst["field"] < 0.01 and worst["index"] < 0.001
sys.exit(0 if ok else 1)
