"""Issue 47, items 1 and 2, read by their real readers: frames compressed by astropy
(CompImageHDU, CFITSIO's code) and gzip give the records of the plain files; astropy reads the
`--new-fits` header's WCS (the matched stars' residuals to 0.01 arcsec), the `--corr` and
`--axy` tables (scripts/check_astrometry_products.py); the package's WCS equals the .new's.
"""

import gzip
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import gpustar
from test_gpustar import FOV, REPO, cli

fits = pytest.importorskip("astropy.io.fits", reason="astropy is in the [test] extra")


@pytest.fixture(scope="module")
def sky(tmp_path_factory):
    """Three simulated 16-bit frames, written by astropy as plain, RICE-compressed and
    gzipped FITS (the first with a date in its header)."""
    root = tmp_path_factory.mktemp("sky")
    sims = gpustar.simulate(3, size=(512, 384), fov_deg=FOV, seed=11, bits=16)
    for kind in ("plain", "fz", "gz"):
        (root / kind).mkdir()
    for i, (image, _) in enumerate(sims):
        header = fits.Header()
        if i == 0:
            header["DATE-OBS"] = "2024-07-30T22:44:36"
        plain = root / "plain" / f"f{i}.fits"
        fits.PrimaryHDU(image.astype(np.uint16), header=header).writeto(plain)
        fits.HDUList([fits.PrimaryHDU(),
                      fits.CompImageHDU(image.astype(np.uint16), header=header,
                                        compression_type="RICE_1")]).writeto(
            root / "fz" / f"f{i}.fits.fz")
        (root / "gz" / f"f{i}.fits.gz").write_bytes(gzip.compress(plain.read_bytes()))
    return root


def batch(folder, *more):
    p = subprocess.run([cli(), "batch", str(folder), "--fov-deg", str(FOV), "--backend", "cpu",
                        "-q", *map(str, more)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    return [json.loads(line) for line in p.stdout.splitlines()]


def test_compressed_frames_give_the_plain_frames_records(sky):
    def keyed(records, suffix):
        out = {}
        for r in records:
            name = r.pop("file")
            r.pop("timing_ms")
            assert name.endswith(suffix)
            out[name[: len(name) - len(suffix)]] = r
        return out

    plain = keyed(batch(sky / "plain"), ".fits")
    assert [r["status"] for r in plain.values()] == ["solved"] * 3
    assert plain["f0"]["epoch"] != plain["f1"]["epoch"]  # DATE-OBS read
    assert keyed(batch(sky / "fz"), ".fits.fz") == plain
    assert keyed(batch(sky / "gz"), ".fits.gz") == plain


def test_new_fits_corr_and_axy_read_by_astropy(sky, tmp_path):
    out = tmp_path / "run.jsonl"
    dirs = [tmp_path / d for d in ("new", "corr", "axy")]
    batch(sky / "fz", "-o", out, "--new-fits", dirs[0], "--corr", dirs[1], "--axy", dirs[2])
    p = subprocess.run([sys.executable, str(REPO / "scripts/check_astrometry_products.py"),
                        str(out), *map(str, dirs)], capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "3 solved frames" in p.stdout
    # The .new keeps the frame's data as stored and its header (less its old WCS).
    with fits.open(sky / "plain" / "f0.fits") as a, fits.open(dirs[0] / "f0.fits.fits") as b:
        assert np.array_equal(a[0].data, b[0].data)
        assert b[0].header["DATE-OBS"] == "2024-07-30T22:44:36"
        assert b[0].header["CTYPE1"] == "RA---TAN"
    # The package's WCS of the same frame (one without a date: the epoch is the run's) is
    # the .new's.
    wcs = pytest.importorskip("astropy.wcs")
    image = fits.getdata(sky / "plain" / "f1.fits")
    result = gpustar.Solver(fov_deg=FOV, backend="cpu").solve(image.astype(np.uint16))
    new = wcs.WCS(fits.getheader(dirs[0] / "f1.fits.fits"))
    xy = np.array([[0.0, 0.0], [511.0, 383.0], [100.5, 250.25]])
    assert np.allclose(result.wcs().all_pix2world(xy, 0), new.all_pix2world(xy, 0),
                       rtol=0, atol=1e-9)


def test_stvid_cubes_are_read_as_their_mean_plane(sky, tmp_path):
    """stvid writes each 100-frame buffer as a float32 cube of four planes (mean, spread,
    maximum, the maximum's frame number: np.array([zavg, zstd, zmax, znum]))."""
    mean = fits.getdata(sky / "plain" / "f1.fits").astype(np.float32)
    rng = np.random.default_rng(5)
    cube = np.array([mean, np.sqrt(mean) + 1, mean * 1.3 + 50,
                     rng.integers(0, 100, mean.shape)]).astype(np.float32)
    d = tmp_path / "stvid"
    d.mkdir()
    fits.PrimaryHDU(cube).writeto(d / "2024-07-30T22:44:36.123.fits")
    [r] = batch(d)
    [plain] = [x for x in batch(sky / "plain") if x["file"] == "f1.fits"]
    assert r["status"] == "solved", r
    assert any("cube" in w and "first plane" in w for w in r["warnings"]), r["warnings"]
    assert abs(r["ra_deg"] - plain["ra_deg"]) < 1e-3 and abs(r["dec_deg"] - plain["dec_deg"]) < 1e-3
