#!/usr/bin/env python3
"""Write tests/data/fz/: small tile-compressed FITS images (astropy's CompImageHDU, which
compresses with CFITSIO's own code) beside the plain FITS image astropy reads back from each,
for the Rust tests of src/io/fits/tiled.rs. Independent of gpustar: its own star field model
(Moffat profiles, Poisson and read noise).

    python3 scripts/make_fz_fixtures.py [OUTDIR]
"""
import sys
from pathlib import Path

import numpy as np
from astropy.io import fits

out = Path(sys.argv[1] if len(sys.argv) > 1 else Path(__file__).parent.parent / "tests/data/fz")
out.mkdir(parents=True, exist_ok=True)
rng = np.random.default_rng(2026)
h, w = 40, 48
yy, xx = np.mgrid[0:h, 0:w]
sky = np.full((h, w), 800.0)
for _ in range(12):
    x0, y0, flux = rng.uniform(0, w), rng.uniform(0, h), rng.uniform(2e3, 4e5)
    r2 = (xx - x0) ** 2 + (yy - y0) ** 2
    sky += flux * (1 + r2 / 2.0**2) ** -2.5 * 1.5 / (np.pi * 4.0)
frame = rng.poisson(sky) + rng.normal(0, 8, sky.shape)
u16 = np.clip(frame, 0, 65535).astype(np.uint16)
cases = [
    ("u16_rice", u16, dict(compression_type="RICE_1")),
    ("u16_rice_tiles", u16, dict(compression_type="RICE_1", tile_shape=(16, 20))),
    ("u16_gzip1", u16, dict(compression_type="GZIP_1")),
    ("u16_gzip2", u16, dict(compression_type="GZIP_2")),
    ("i32_rice", (frame * 7 - 3000).astype(np.int32), dict(compression_type="RICE_1")),
    ("u8_rice", np.clip(frame / 40, 0, 255).astype(np.uint8), dict(compression_type="RICE_1")),
    ("f32_dither1", frame.astype(np.float32),
     dict(compression_type="RICE_1", quantize_method=1, quantize_level=16, dither_seed=7)),
    ("f32_dither2", np.where(u16 < 790, 0, frame).astype(np.float32),
     dict(compression_type="RICE_1", quantize_method=2, quantize_level=16, dither_seed=3)),
    ("f64_nodither_gzip", frame.astype(np.float64),
     dict(compression_type="GZIP_2", quantize_method=-1, quantize_level=16)),
    ("f32_lossless", frame.astype(np.float32), dict(compression_type="GZIP_1", quantize_level=0)),
    ("u16_hcompress", u16, dict(compression_type="HCOMPRESS_1")),
]
for name, data, kw in cases:
    hdr = fits.Header()
    hdr["DATE-OBS"] = "2024-07-30T22:44:36"
    hdr["EXPTIME"] = 10.0
    fz = out / f"{name}.fits.fz"
    fits.HDUList([fits.PrimaryHDU(), fits.CompImageHDU(data, header=hdr, **kw)]).writeto(fz, overwrite=True)
    if kw["compression_type"] == "HCOMPRESS_1":
        continue  # gpustar refuses it: no plain twin needed
    with fits.open(fz) as f:
        back = f[1].data
        fits.PrimaryHDU(back, header=hdr).writeto(out / f"{name}.fits", overwrite=True)
    print(fz.name, data.dtype, kw)

# The same frames through fpack itself (Debian's libcfitsio-bin), and back through funpack.
import shutil
import subprocess

if shutil.which("fpack") and shutil.which("funpack"):
    for name, src, opts in [
        ("fpack_u16", "u16_rice.fits", []),
        ("fpack_f32", "f32_lossless.fits", ["-q", "4"]),
        ("fpack_f32_dither2", "f32_lossless.fits", ["-qz", "4"]),
    ]:
        fz = out / f"{name}.fits.fz"
        fz.unlink(missing_ok=True)
        subprocess.run(["fpack", *opts, "-O", str(fz), str(out / src)], check=True)
        plain = out / f"{name}.fits"
        plain.unlink(missing_ok=True)
        subprocess.run(["funpack", "-O", str(plain), str(fz)], check=True)
        print(fz.name, "fpack", opts)
else:
    print("fpack/funpack not found (apt-get install libcfitsio-bin): fpack cases not written")
