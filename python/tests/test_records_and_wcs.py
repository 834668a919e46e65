"""Issue 47, items 5 and 6: every record the command line and the package write fits the
record's JSON Schema (docs/record.schema.json); a Result's WCS is the file `--wcs-dir` writes
for the same frame, and its pixel_to_sky / sky_to_pixel are the plate solution;
gpustar.read_records reads output files.

The CLI is found as test_gpustar.py finds it (GPUSTAR_BIN, else this clone's target/).
"""

import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

import gpustar
from test_gpustar import FOV, REPO, cli, write_fits

SCHEMA = REPO / "docs/record.schema.json"

# A camera with an off-centre principal point and radial distortion: its WCS is TAN-SIP.
DISTORTED = """width = 640
height = 480
fov_x_deg = 12.0
cx_px = 330.0
cy_px = 236.5
k1 = -0.08
k2 = 0.01
"""


@pytest.fixture(scope="module")
def validator():
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads(SCHEMA.read_text())
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def problems(validator, record: dict) -> list:
    return [f"{'/'.join(map(str, e.absolute_path))}: {e.message[:300]}"
            for e in validator.iter_errors(record)]


def run(*args, status: int = 0):
    """The CLI with these arguments; `status` its exit status (1: a run with error records)."""
    p = subprocess.run([cli(), *map(str, args)], capture_output=True, text=True)
    assert p.returncode == status, f"{args}: exit {p.returncode}: {p.stderr}"
    return p


def separation_deg(ra1, dec1, ra2, dec2):
    """The angle between directions (degrees), accurate at every angle (atan2 of the cross
    and dot products, where arccos of the dot loses small angles below ~1e-8 rad)."""
    def unit(ra, dec):
        ra, dec = np.radians(ra), np.radians(dec)
        return np.stack([np.cos(dec) * np.cos(ra), np.cos(dec) * np.sin(ra), np.sin(dec)], -1)

    a, b = unit(ra1, dec1), unit(ra2, dec2)
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b), axis=-1), np.sum(a * b, -1)))


def lines(path: pathlib.Path) -> list:
    return [json.loads(line) for line in path.read_text().splitlines()]


def blank_png(path: pathlib.Path) -> None:
    from PIL import Image

    Image.fromarray(np.full((512, 512), 20, np.uint8)).save(path)


def undated(fits: pathlib.Path) -> None:
    """The FITS file with its DATE-OBS, DATE-BEG and DATE-END values made unreadable."""
    raw = fits.read_bytes()
    for key in (b"DATE-OBS", b"DATE-BEG", b"DATE-END"):
        at = raw.find(key + b"= ")
        if at >= 0:
            value = raw[at + 10:at + 80].split(b"/")[0]
            raw = raw[:at + 10] + b"'not a date'".ljust(len(value)) + raw[at + 10 + len(value):]
    fits.write_bytes(raw)


def test_every_record_the_cli_writes_fits_the_schema(tmp_path, validator):
    """Solved, unsolved and error records (with a hint from the header, ML centroids,
    warnings), a sequence run (tracking, particles) and a streak run (streaks, tracklets)."""
    frames = tmp_path / "frames"
    run("simulate", "--out", frames, "-n", "2", "--size", "512x512", "--fov-deg", FOV,
        "--hint-offset-deg", "1", "--seed", "3", "--mag-limit", "7.5")
    blank_png(frames / "blank.png")
    (frames / "broken.png").write_bytes(b"\x89PNG not really" * 20)
    seq = tmp_path / "seq"
    run("simulate", "--out", seq, "--sequence", "--sequences", "1", "-n", "3", "--size", "512x512",
        "--fov-deg", FOV, "--mag-limit", "7.5")
    streaks = tmp_path / "streaks"
    run("simulate", "--out", streaks, "--streaks", "-n", "2")
    # A frame whose dates cannot be read: its record has warnings, its streak ends no times.
    undated(streaks / "sim_00001.fits")
    outs = {
        "frames": ["batch", frames, "--fov-deg", FOV, "--hint", "header,5", "--centroid", "ml"],
        "seq": ["batch", seq, "-r", "--sequence", "--fov-deg", FOV],
        "streaks": ["batch", streaks, "--camera", streaks / "camera.toml", "--streaks"],
    }
    records = {}
    for name, args in outs.items():
        out = tmp_path / f"{name}.jsonl"
        run(*args, "--backend", "cpu", "-q", "-o", out, status=1 if name == "frames" else 0)
        records[name] = lines(out)
    for name, recs in records.items():
        for r in recs:
            assert not problems(validator, r), (name, r["file"], problems(validator, r))
    every = [r for recs in records.values() for r in recs]
    assert {r["status"] for r in every} == {"solved", "unsolved", "error"}
    seen = {k for r in every for k in r}
    assert {"hint", "warnings", "sigma_floor_px", "attitude_sigma_arcsec", "mirrored", "epoch",
            "sequence_mode", "particles", "streaks"} <= seen, seen
    assert "tracking" in {r.get("sequence_mode") for r in records["seq"]}
    assert any(r["particles"] for r in records["seq"])
    assert any(s.get("tracklet") for r in records["streaks"] for s in r["streaks"])
    assert any(e["time_utc"] is None for r in records["streaks"] for s in r["streaks"] for e in s["ends"])
    assert any("sigma_px" in m for r in records["frames"] for m in r["matches"] or [])

    # The schema is not vacuous: a record off it in any of these ways is refused.
    solved = next(r for r in every if r["status"] == "solved" and r.get("streaks"))
    unsolved = next(r for r in every if r["status"] == "unsolved")
    bad = [
        dict(solved, ra="typo"),
        dict(solved, ra_deg=None),
        dict(solved, status="done"),
        dict(solved, quaternion=[1, 0, 0]),
        dict(unsolved, reason="no_idea"),
        dict(unsolved, ra_deg=1.0),
        dict(solved, matches=[dict(solved["matches"][0], extra=1)]),
        dict(solved, streaks=[dict(solved["streaks"][0], mid={**solved["streaks"][0]["ends"][0]})]),
        {k: v for k, v in solved.items() if k != "backend"},
    ]
    for b in bad:
        assert problems(validator, b), b


def test_the_packages_results_fit_the_schema(validator):
    """Result.to_dict() is a record: solve (solved, unsolved, error), solve_centroids, and a
    Sequence's frames."""
    (image, truth), = gpustar.simulate(1, size=(512, 512), fov_deg=FOV, seed=7, bits=16)
    solver = gpustar.Solver(fov_deg=FOV, backend="cpu")
    stars = truth["stars"][:30]
    results = [solver.solve(image), solver.solve(np.full((64, 64), 9, np.uint16)),
               solver.solve(np.zeros((8, 8), np.uint16)),
               solver.solve_centroids(np.array([[s["x"], s["y"]] for s in stars]), (512, 512),
                                      10 ** (-0.4 * np.array([s["mag"] for s in stars])))]
    seq = gpustar.Sequence(solver, frame_interval_s=1.0)
    results += [seq.add(image) for _ in range(2)]
    assert [r.status for r in results] == ["solved", "unsolved", "error", "solved", "solved", "solved"]
    for r in results:
        assert not problems(validator, r.to_dict()), problems(validator, r.to_dict())


def astropy_wcs(text: str):
    """astropy's WCS of a .wcs file's text (header-only: NAXIS = 0, so astropy warns)."""
    import warnings

    from astropy.io import fits
    from astropy.wcs import WCS, FITSFixedWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", FITSFixedWarning)
        return WCS(fits.Header.fromstring(text))


def sample_pixels(width: int, height: int) -> tuple:
    """Corners, edges' midpoints, the centre and points between, in gpustar's pixels."""
    xs = np.array([-0.5, 0.0, 0.3 * width, (width - 1) / 2, width - 1.0, width - 0.5, 17.25])
    ys = np.array([-0.5, height - 1.0, 0.7 * height, (height - 1) / 2, 0.0, height - 0.5, 3.5])
    return xs, ys


def check_the_solution(result, wcs_file: pathlib.Path, size: tuple, sip: bool) -> None:
    """result's WCS against the --wcs-dir file of the same frame; its pixel_to_sky against
    the matches and against sky_to_pixel."""
    astropy = pytest.importorskip("astropy")  # noqa: F841
    want = wcs_file.read_text()
    got = result.wcs_header()
    assert got == want, (got, want)
    card = lambda text, i: text[80 * i:80 * i + 80]  # noqa: E731
    assert [card(got, i) for i in range(len(got) // 80)] == [card(want, i) for i in range(len(want) // 80)]
    assert ("-SIP'" in got) == sip
    w = result.wcs()
    assert w.pixel_shape == size and w.has_distortion == sip
    from_file = astropy_wcs(want)
    xs, ys = sample_pixels(*size)
    ra, dec = w.pixel_to_world_values(xs, ys)
    ra_f, dec_f = from_file.pixel_to_world_values(xs, ys)
    assert np.max(np.abs((ra - ra_f + 180) % 360 - 180) * np.cos(np.radians(dec))) < 1e-9
    assert np.max(np.abs(dec - dec_f)) < 1e-9

    # The camera model itself: astropy's A/B fit is within 0.005 px of it (TAN: exact).
    r_deg, d_deg = result.pixel_to_sky(xs, ys)
    scale = result.fov_x_deg / size[0]
    sep = separation_deg(ra, dec, r_deg, d_deg)
    assert np.max(sep) / scale < (0.01 if sip else 1e-6), np.max(sep) / scale
    # Inverse to 1e-6 px, over the image and for arrays of any shape.
    x2, y2 = result.sky_to_pixel(r_deg, d_deg)
    assert np.max(np.hypot(x2 - xs, y2 - ys)) < 1e-6
    grid = np.meshgrid(np.linspace(-0.5, size[0] - 0.5, 9), np.linspace(-0.5, size[1] - 0.5, 7))
    g_ra, g_dec = result.pixel_to_sky(*grid)
    assert g_ra.shape == (7, 9)
    gx, gy = result.sky_to_pixel(g_ra, g_dec)
    assert np.max(np.hypot(gx - grid[0], gy - grid[1])) < 1e-6

    # The matches' pixels land on their catalog stars to the record's residuals.
    m = result.matches
    m_ra, m_dec = result.pixel_to_sky(m.x, m.y)
    off = separation_deg(m_ra, m_dec, m.ra_deg, m.dec_deg) * 3600
    assert len(m) >= 5 and np.max(np.abs(off - m.residual_arcsec)) < 1e-6, (off, m.residual_arcsec)
    # Numbers give numbers.
    x0, y0 = result.sky_to_pixel(*result.pixel_to_sky(10, 20))
    assert isinstance(x0, float) and abs(x0 - 10) < 1e-6 and abs(y0 - 20) < 1e-6


def test_wcs_is_the_wcs_dirs_for_a_pinhole_camera(tmp_path):
    """`gpustar solve --fov-deg --wcs-dir` and Solver.solve_file on the same PNG: the same
    TAN header, card for card."""
    from PIL import Image

    image, _ = gpustar.simulate(1, fov_deg=FOV, seed=4)[0]
    png = tmp_path / "frame.png"
    Image.fromarray(image).save(png)
    run("solve", png, "--fov-deg", FOV, "--backend", "cpu", "--wcs-dir", tmp_path / "wcs")
    wcs_file, = (tmp_path / "wcs").rglob("*.wcs")
    result = gpustar.Solver(fov_deg=FOV, backend="cpu").solve_file(png)
    assert result.solved
    check_the_solution(result, wcs_file, (1024, 1024), sip=False)


def test_wcs_is_the_wcs_dirs_for_a_distorted_camera(tmp_path):
    """`gpustar batch --camera --wcs-dir` and gpustar.batch on frames of a camera with an
    off-centre principal point and k1, k2: the same TAN-SIP header, card for card; the same
    through Solver.solve on the decoded frame."""
    cam = tmp_path / "cam.toml"
    cam.write_text(DISTORTED)
    d = tmp_path / "frames"
    run("simulate", "--camera", cam, "--out", d, "-n", "2", "--mag-limit", "7.5", "--seed", "5")
    run("batch", d, "--camera", cam, "--backend", "cpu", "-q", "--wcs-dir", tmp_path / "wcs")
    results = list(gpustar.batch(d, camera=cam, backend="cpu"))
    assert [r.status for r in results] == ["solved", "solved"]
    for r in results:
        check_the_solution(r, tmp_path / "wcs" / r.file.replace(".png", ".wcs"), (640, 480), sip=True)
    from PIL import Image

    image = np.asarray(Image.open(d / results[0].file))
    again = gpustar.Solver(camera=cam, backend="cpu").solve(image, name=results[0].file)
    assert again.wcs_header() == results[0].wcs_header()


def test_wcs_without_astropy_and_for_results_without_a_solution(monkeypatch):
    """Without astropy, wcs() is the header's keywords; an unsolved result has no WCS and its
    pixel_to_sky raises; a record read back from JSON does not carry the camera model."""
    image, _ = gpustar.simulate(1, fov_deg=FOV, seed=4)[0]
    solver = gpustar.Solver(fov_deg=FOV, backend="cpu")
    r = solver.solve(image)
    monkeypatch.setitem(sys.modules, "astropy.wcs", None)
    cards = r.wcs()
    assert isinstance(cards, dict)
    assert cards["CTYPE1"] == "RA---TAN" and cards["CTYPE2"] == "DEC--TAN" and cards["SIMPLE"] is True
    assert cards["NAXIS"] == 0 and cards["IMAGEW"] == 1024 and cards["RADESYS"] == "ICRS"
    assert cards["CRPIX1"] == 512.5 and abs(cards["CD1_1"]) < 1 and "COMMENT" not in cards
    ra, dec = r.pixel_to_sky(511.5, 511.5)
    assert abs(dec - r.dec_deg) < 1e-9 and abs((ra - r.ra_deg + 180) % 360 - 180) < 1e-9
    monkeypatch.undo()

    unsolved = solver.solve(np.full((64, 64), 9, np.uint16), name="flat")
    assert unsolved.status == "unsolved" and unsolved.wcs() is None and unsolved.wcs_header() is None
    with pytest.raises(ValueError, match="'flat' is unsolved"):
        unsolved.pixel_to_sky(1.0, 2.0)
    read_back = gpustar.Result(r.to_json())
    assert read_back.ra_deg == r.ra_deg
    with pytest.raises(ValueError, match="does not carry the camera model"):
        read_back.wcs()
    with pytest.raises(gpustar.InputError, match="3 x and 2 y"):
        r._source.pixel_to_sky(np.zeros(3), np.zeros(2))


def test_read_records_reads_jsonl_and_csv(tmp_path, frames_dir, monkeypatch):
    pandas = pytest.importorskip("pandas")
    out = tmp_path / "out.jsonl"
    run("batch", frames_dir, "--fov-deg", FOV, "--backend", "cpu", "-q", "-o", out, status=1)
    want = lines(out)
    df = gpustar.read_records(out)
    assert isinstance(df, pandas.DataFrame) and len(df) == len(want) == 3
    assert list(df["file"]) == [r["file"] for r in want]
    assert list(df["status"]) == [r["status"] for r in want]
    solved = df[df["status"] == "solved"]
    assert len(solved) == 2 and solved["ra_deg"].dtype == np.float64
    assert [len(m) for m in solved["matches"]] == list(solved["stars_matched"])

    csv = tmp_path / "out.csv"
    run("batch", frames_dir, "--fov-deg", FOV, "--backend", "cpu", "-q", "-o", csv, "--format", "csv",
        status=1)
    dc = gpustar.read_records(csv)
    assert list(dc["file"]) == list(df["file"]) and list(dc["status"]) == list(df["status"])
    assert np.allclose(dc["ra_deg"].dropna(), solved["ra_deg"])
    assert np.allclose(dc["qw"].dropna(), [r["quaternion"][0] for r in want if r["quaternion"]])

    monkeypatch.setitem(sys.modules, "pandas", None)
    assert gpustar.read_records(out) == want
    rows = gpustar.read_records(csv)
    assert [r["file"] for r in rows] == [r["file"] for r in want]
    assert [r["ra_deg"] for r in rows] == [r["ra_deg"] for r in want]
    assert [r["stars_detected"] for r in rows] == [r["stars_detected"] for r in want]

    torn = tmp_path / "torn.jsonl"
    torn.write_text(out.read_text() + '{"file": "x.png", "sta')
    with pytest.raises(gpustar.InputError, match="line 4: .*did not finish"):
        gpustar.read_records(torn)
    with pytest.raises(gpustar.IoError, match="cannot read records"):
        gpustar.read_records(tmp_path / "absent.jsonl")


@pytest.fixture
def frames_dir(tmp_path):
    """Two solvable FITS frames and an unreadable PNG."""
    d = tmp_path / "frames"
    d.mkdir()
    for k, (image, _) in enumerate(gpustar.simulate(2, size=(512, 512), fov_deg=FOV, seed=7, bits=16)):
        write_fits(d / f"f{k}.fits", image)
    (d / "z_broken.png").write_bytes(b"not a png")
    return d
