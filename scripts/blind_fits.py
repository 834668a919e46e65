#!/usr/bin/env python3
"""Copy FITS frames with their pointing and WCS keywords removed, so that a solver cannot read
the answer from the header (../shared/data/narrow_real/README.md names the keywords).

    python3 scripts/blind_fits.py [--keep-scale] OUT_DIR FRAME.fits [FRAME.fits ...]

Every HDU's header is cleaned; pixel data are copied unchanged (astropy, no scaling applied).
--keep-scale keeps what states the pixel scale (CD, PC, CDELT, CTYPE, CUNIT, PIXSCALE, SECPIX,
PLTSCALE) and removes only the pointing (CRVAL, CRPIX, RA/DEC, OBJCTRA/OBJCTDEC, ...): a frame
as an observer's software leaves it, for solving from the header's scale (issue 47).
"""
import re
import sys
from pathlib import Path

from astropy.io import fits

# Exact names and prefixes of the keywords that give away where the frame points.
EXACT = {"RA", "DEC", "OBJCTRA", "OBJCTDEC", "TELRA", "TELDEC", "RA_OBJ", "DEC_OBJ", "EQUINOX",
         "RADESYS", "RADECSYS", "LONPOLE", "LATPOLE", "WCSAXES", "PLTSCALE", "PIXSCALE",
         "SECPIX", "CRVAL", "OBJCTROT", "PLATERA", "PLATEDEC"}
PREFIX = re.compile(r"^(CTYPE|CRVAL|CRPIX|CD\d|PC\d|CDELT|CROTA|CUNIT|A_|B_|AP_|BP_|AMD|PLT|PPO|"
                    r"XPIXELSZ|YPIXELSZ|DSSORIG|CNPIX|PV\d|ASTAP|ANNOTATE|SIP)")


SCALE = re.compile(r"^(CD\d|PC\d|CDELT|CTYPE|CUNIT|PIXSCALE|SECPIX|PLTSCALE)")


def blind(header, keep_scale=False):
    removed = []
    for key in list(header.keys()):
        k = key.upper()
        if keep_scale and SCALE.match(k):
            continue
        if k in EXACT or PREFIX.match(k) or k.startswith("HIERARCH ASTAP"):
            removed.append(k)
            while key in header:
                del header[key]
    return removed


def main():
    args = sys.argv[1:]
    keep_scale = "--keep-scale" in args
    args = [a for a in args if a != "--keep-scale"]
    if len(args) < 2:
        sys.exit(__doc__)
    out = Path(args[0])
    out.mkdir(parents=True, exist_ok=True)
    for name in args[1:]:
        with fits.open(name, do_not_scale_image_data=True) as hdus:
            removed = sorted({k for h in hdus for k in blind(h.header, keep_scale)})
            hdus.writeto(out / Path(name).name, overwrite=True, output_verify="silentfix")
        print(f"{name}: removed {len(removed)} keywords ({' '.join(removed[:12])}{' ...' if len(removed) > 12 else ''})")


if __name__ == "__main__":
    main()
