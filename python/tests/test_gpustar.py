"""The Python package against the command line: the same frames give the same records (both
backends), every dtype and stride gives the frame a file of those values gives, bad arrays
and options raise gpustar.Error subclasses with the CLI's messages, threads share a Solver.

The CLI is $GPUSTAR_BIN, else target/debug/gpustar or target/release/gpustar of this clone
(scripts/test_python.sh runs after `cargo test`, which builds it). Tests that need it, a GPU
adapter or the real frames print `SKIPPED <test>: <why>` and skip when these are absent; with
CI=true they fail instead.
"""

import csv
import io
import json
import os
import pathlib
import subprocess
import sys
import threading

import numpy as np
import pytest

import gpustar

REPO = pathlib.Path(__file__).resolve().parents[2]
CI = os.environ.get("CI") == "true"
FOV = 10.0


def skip(why: str):
    name = os.environ.get("PYTEST_CURRENT_TEST", "?").split(" ")[0]
    if CI:
        pytest.fail(f"{why} (CI=true: nothing is skipped)")
    print(f"SKIPPED {name}: {why}")
    pytest.skip(why)


def cli() -> str:
    env = os.environ.get("GPUSTAR_BIN")
    if env:
        return env
    for p in (REPO / "target/debug/gpustar", REPO / "target/release/gpustar"):
        if p.exists():
            return str(p)
    skip("no gpustar binary: set GPUSTAR_BIN or run `cargo build` first")


def write_fits(path: pathlib.Path, image: np.ndarray) -> None:
    """A minimal FITS file of the array's values: BITPIX 8 (uint8), 16 with BZERO 32768
    (uint16), -32 (float32). Written here, not by gpustar, so the CLI reads a file it did not
    make."""
    kind = {np.dtype(np.uint8): (8, None), np.dtype(np.uint16): (16, 32768),
            np.dtype(np.float32): (-32, None)}[image.dtype]
    bitpix, bzero = kind
    h, w = image.shape
    cards = ["SIMPLE  =                    T", f"BITPIX  = {bitpix:>20}", "NAXIS   =                    2",
             f"NAXIS1  = {w:>20}", f"NAXIS2  = {h:>20}"]
    if bzero is not None:
        cards += [f"BZERO   = {bzero:>20}", "BSCALE  =                    1"]
    cards.append("END")
    header = "".join(c.ljust(80) for c in cards).encode()
    header += b" " * (-len(header) % 2880)
    if bitpix == 16:
        data = (image.astype(np.int32) - 32768).astype(">i2").tobytes()
    elif bitpix == -32:
        data = image.astype(">f4").tobytes()
    else:
        data = image.tobytes()
    data += b"\0" * (-len(data) % 2880)
    path.write_bytes(header + data)


def read_fits(path: pathlib.Path):
    """(uint16 array, keywords as text) of a 16-bit FITS file with BZERO 32768, as gpustar
    simulate writes them."""
    raw = path.read_bytes()
    header, pos = {}, 0
    while raw[pos:pos + 8].decode().strip() != "END":
        card = raw[pos:pos + 80].decode()
        if card[8:10] == "= ":
            header[card[:8].strip()] = card[10:].split("/")[0].strip().strip("'").strip()
        pos += 80
    pos = (pos + 80 + 2879) // 2880 * 2880
    w, h = int(header["NAXIS1"]), int(header["NAXIS2"])
    data = np.frombuffer(raw, ">i2", w * h, pos).astype(np.int32) + int(header["BZERO"])
    return data.reshape(h, w).astype(np.uint16), header


def comparable(record: dict) -> dict:
    """A record less its timings (which differ between any two runs)."""
    r = dict(record)
    r.pop("timing_ms", None)
    return r


def unlinked(record: dict) -> dict:
    """A record as one frame alone gives it: its streaks without the tracklet fields."""
    r = dict(record)
    r["streaks"] = [{k: v for k, v in s.items() if k not in ("tracklet", "tracklet_index")}
                    for s in record["streaks"]]
    return r


@pytest.fixture(scope="module")
def frames():
    """Four 512x512 simulated frames (gpustar's own simulator: this suite checks the binding,
    not the solver) as uint16, and their truths."""
    return gpustar.simulate(4, size=(512, 512), fov_deg=FOV, seed=7, bits=16)


@pytest.fixture(scope="module")
def cpu_solver():
    return gpustar.Solver(fov_deg=FOV, backend="cpu")


def variants(frames):
    """The frames in the three dtypes, with the names of their FITS files."""
    (a, _), (b, _), (c, _), (d, _) = frames
    f32 = (c.astype(np.float32) * 0.25 - 100.0).astype(np.float32)
    return {"u16.fits": a, "u8.fits": np.clip(b // 64, 0, 255).astype(np.uint8),
            "f32.fits": f32, "u16b.fits": d}


def cli_records(tmp_path, images: dict, backend: str) -> list:
    d = tmp_path / "frames"
    d.mkdir(exist_ok=True)
    for name, im in images.items():
        write_fits(d / name, im)
    out = tmp_path / f"cli-{backend}.jsonl"
    p = subprocess.run([cli(), "batch", str(d), "--fov-deg", str(FOV), "--backend", backend, "-q",
                        "-o", str(out)], capture_output=True, text=True)
    if p.returncode != 0:
        if backend == "gpu" and "adapter" in p.stderr.lower():
            skip(f"no GPU adapter for the CLI: {p.stderr.strip()}")
        raise AssertionError(p.stderr)
    return [json.loads(line) for line in out.read_text().splitlines()]


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_records_equal_the_clis(tmp_path, frames, backend):
    images = variants(frames)
    expected = cli_records(tmp_path, images, backend)
    try:
        solver = gpustar.Solver(fov_deg=FOV, backend=backend)
    except gpustar.GpuError as e:
        skip(f"no GPU adapter: {e}")
    names = sorted(images)
    got = [r.to_dict() for r in solver.solve_many([images[n] for n in names], names=names)]
    assert [comparable(r) for r in got] == [comparable(r) for r in expected]
    assert sum(r["status"] == "solved" for r in got) >= 3, [r["status"] for r in got]
    # One at a time too, and through gpustar.batch on the files.
    assert comparable(solver.solve(images[names[0]], name=names[0]).to_dict()) == comparable(expected[0])
    batched = list(gpustar.batch(tmp_path / "frames", fov_deg=FOV, backend=backend))
    assert [comparable(r.to_dict()) for r in batched] == [comparable(r) for r in expected]


def test_result_fields_are_the_records(cpu_solver, frames):
    image, truth = frames[0]
    r = cpu_solver.solve(image, name="a")
    # Fields read before the record is parsed (taken from the record one by one) are those of
    # its JSON line.
    fresh = cpu_solver.solve(image, name="a")
    assert fresh.solved and fresh.status == "solved"
    assert comparable({k: fresh._field(k) for k in r.to_dict()}) == comparable(r.to_dict())
    assert fresh._dict is None and fresh._text is None
    d = r.to_dict()
    assert r.solved and d["status"] == "solved"
    assert r.rotation_matrix.shape == (3, 3) and r.quaternion.shape == (4,)
    assert np.allclose(r.rotation_matrix, d["rotation_matrix"])
    assert len(r.matches) == d["stars_matched"] == len(d["matches"])
    assert list(r.matches.hip) == [m["hip"] for m in d["matches"]]
    assert r.ra_deg == d["ra_deg"] and r.false_match_prob == d["false_match_prob"]
    chord = np.linalg.norm(r.rotation_matrix[2] - np.array(truth["rotation_matrix"])[2])
    assert np.degrees(2 * np.arcsin(chord / 2)) * 3600 < 30
    assert r.to_json() == json.dumps(d, separators=(",", ":")) or json.loads(r.to_json()) == d


def test_strides_and_layouts_give_the_same_record(cpu_solver, frames):
    image = frames[1][0]
    want = comparable(cpu_solver.solve(image, name="x").to_dict())
    fortran = np.asfortranarray(image)
    assert not fortran.flags.c_contiguous
    padded = np.zeros((image.shape[0] + 6, image.shape[1] * 2), np.uint16)
    padded[3:-3, ::2] = image
    view = padded[3:-3, ::2]
    flipped = np.ascontiguousarray(image[::-1, ::-1])[::-1, ::-1]
    assert view.strides != image.strides and flipped.strides[0] < 0
    for v in (fortran, view, flipped):
        assert comparable(cpu_solver.solve(v, name="x").to_dict()) == want
    # A read-only array is read in place.
    ro = image.copy()
    ro.setflags(write=False)
    assert comparable(cpu_solver.solve(ro, name="x").to_dict()) == want


@pytest.mark.parametrize("bad,message", [
    (np.zeros((4, 4, 3), np.uint16), "3 dimensions"),
    (np.zeros(16, np.uint16), "1 dimensions"),
    (np.zeros((0, 0), np.uint16), "empty"),
    (np.zeros((64, 64), np.float64), "dtype is float64"),
    (np.zeros((64, 64), np.int32), "dtype is int32"),
    (np.full((64, 64), np.nan, np.float32), "NaN or infinite"),
    ([[1, 2], [3, 4]], "got a list"),
])
def test_bad_arrays_are_refused_clearly(cpu_solver, bad, message):
    with pytest.raises(gpustar.InputError, match=message):
        cpu_solver.solve(bad)


def test_small_frame_is_an_error_record_as_on_the_cli(cpu_solver):
    r = cpu_solver.solve(np.zeros((8, 8), np.uint16), name="tiny")
    assert r.status == "error" and "too small" in r.error


def test_options_and_errors_are_the_clis():
    with pytest.raises(gpustar.ConfigError, match="sigma: 1000 is outside 0.5 to 100"):
        gpustar.Solver(fov_deg=FOV, sigma=1000)
    with pytest.raises(gpustar.ConfigError, match="unknown option"):
        gpustar.Solver(fov_deg=FOV, sigmaa=5)
    with pytest.raises(gpustar.ConfigError, match="is not one of"):
        gpustar.Solver(fov_deg=FOV, centroid="best")
    with pytest.raises(gpustar.ConfigError, match="between 0 and 170"):
        gpustar.Solver(fov_deg=400)
    with pytest.raises(gpustar.ConfigError, match="give the camera"):
        gpustar.Solver()
    with pytest.raises(gpustar.ConfigError, match="pixel_aspect: 3 is outside 0.5 to 2"):
        gpustar.Solver(fov_deg=FOV, pixel_aspect=3)
    with pytest.raises(gpustar.ConfigError, match="pixel_aspect goes with fov_deg"):
        gpustar.Solver(camera="width = 64\nheight = 64\nfov_x_deg = 10\n", pixel_aspect=0.9)
    with pytest.raises(gpustar.IoError, match="cannot read /nonexistent/cam.toml"):
        gpustar.Solver(camera="/nonexistent/cam.toml")
    with pytest.raises(gpustar.InputError, match="is not a directory"):
        gpustar.batch("/nonexistent-dir", fov_deg=FOV)
    with pytest.raises(gpustar.ConfigError, match="tle is an option of streaks=True"):
        gpustar.Solver(fov_deg=FOV, tle="objects.tle")
    with pytest.raises(gpustar.Error, match="/nonexistent/objects.tle"):
        gpustar.Solver(fov_deg=FOV, streaks=True, tle="/nonexistent/objects.tle")
    with pytest.raises(gpustar.ConfigError, match="tle_cross: 0 is outside"):
        gpustar.Solver(fov_deg=FOV, streaks=True, tle_cross=0)
    assert issubclass(gpustar.InputError, gpustar.Error) and issubclass(gpustar.Error, Exception)


def test_centroids_solve_as_the_frame(cpu_solver, frames):
    _, truth = frames[0]
    stars = truth["stars"][:30]
    xy = np.array([[s["x"], s["y"]] for s in stars])
    fluxes = 10 ** (-0.4 * np.array([s["mag"] for s in stars]))
    r = cpu_solver.solve_centroids(xy, (512, 512), fluxes)
    assert r.solved, r
    chord = np.linalg.norm(r.rotation_matrix[2] - np.array(truth["rotation_matrix"])[2])
    assert np.degrees(2 * np.arcsin(chord / 2)) * 3600 < 5
    assert set(r.matches.hip) <= {s["hip"] for s in stars}
    with pytest.raises(gpustar.InputError, match="x, y"):
        cpu_solver.solve_centroids(np.zeros((3, 3)), (512, 512))


def test_threads_share_one_solver(cpu_solver, frames):
    images = [f for f, _ in frames]
    want = [comparable(cpu_solver.solve(im, name="t").to_dict()) for im in images]
    got = {}

    def work(k):
        got[k] = [comparable(cpu_solver.solve(im, name="t").to_dict()) for im in images]

    threads = [threading.Thread(target=work, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert all(got[k] == want for k in range(4))


def test_solve_many_streams_in_order(cpu_solver, frames):
    """solve_many over a generator (no length): records in input order, each frame's the one
    solve gives, a bad array an error record that loses no other frame's; leaving the loop
    early ends the run; names and epochs of the wrong length are refused."""
    images = [f for f, _ in frames] * 3
    want = [comparable(cpu_solver.solve(im, name=f"f{k}").to_dict()) for k, im in enumerate(images)]
    seen = []
    got = [comparable(r.to_dict()) for r in cpu_solver.solve_many(
        (im for im in images), names=[f"f{k}" for k in range(len(images))], batch_size=2,
        progress=lambda done, total: seen.append((done, total)))]
    assert got == want
    assert seen == [(k + 1, None) for k in range(len(images))]
    mixed = [images[0], np.full((64, 64), np.nan, np.float32), images[1]]
    rs = list(cpu_solver.solve_many(mixed))
    assert [r.status for r in rs] == ["solved", "error", "solved"]
    assert "NaN" in rs[1].error and rs[2].file == "image_00002"
    for r in cpu_solver.solve_many(images):
        break
    assert r.solved
    with pytest.raises(gpustar.InputError, match="2 images, 1 names"):
        list(cpu_solver.solve_many(images[:2], names=["a"]))
    # A generator has no length to check first: refused when it outruns them.
    with pytest.raises(gpustar.InputError, match=r"more images than epochs \(1\)"):
        list(cpu_solver.solve_many((im for im in images[:2]), epochs=[None]))


def test_batch_shard_resume_and_progress(tmp_path, frames):
    d = tmp_path / "frames"
    d.mkdir()
    for name, im in variants(frames).items():
        write_fits(d / name, im)
    seen = []
    every = [r.file for r in gpustar.batch(d, fov_deg=FOV, backend="cpu",
                                           progress=lambda done, total: seen.append((done, total)))]
    assert every == sorted(every) and len(every) == 4
    assert seen == [(i + 1, 4) for i in range(4)]
    shards = [[r.file for r in gpustar.batch(d, fov_deg=FOV, backend="cpu", shard=f"{k}/2")] for k in range(2)]
    assert sorted(shards[0] + shards[1]) == every
    out = tmp_path / "out.jsonl"
    first = gpustar.batch(d, fov_deg=FOV, backend="cpu", output=out, shard="0/2")
    assert [r.file for r in first] == shards[0]
    rest = gpustar.batch(d, fov_deg=FOV, backend="cpu", output=out, resume=True)
    assert rest.total == len(shards[1]) and [r.file for r in rest] == shards[1]
    assert sorted(json.loads(line)["file"] for line in out.read_text().splitlines()) == every
    with pytest.raises(gpustar.ConfigError, match="resume needs output"):
        gpustar.batch(d, fov_deg=FOV, resume=True)


def test_streak_records_equal_the_clis(tmp_path):
    d = tmp_path / "streaks"
    p = subprocess.run([cli(), "simulate", "--streaks", "--out", str(d), "-n", "2"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    out = tmp_path / "cli.jsonl"
    p = subprocess.run([cli(), "batch", str(d), "--camera", str(d / "camera.toml"), "--streaks", "--backend", "cpu",
                        "-q", "-o", str(out)], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    expected = [json.loads(line) for line in out.read_text().splitlines()]
    # The batch links a directory's streaks into tracklets, as the command line does.
    batched = list(gpustar.batch(d, camera=d / "camera.toml", backend="cpu", streaks=True))
    assert [comparable(r.to_dict()) for r in batched] == [comparable(r) for r in expected]
    # One frame alone cannot be linked to its neighbours: solve() gives the record less the
    # tracklet fields (these frames' streaks are of different objects, so none was turned).
    solver = gpustar.Solver(camera=d / "camera.toml", backend="cpu", streaks=True)
    for want in expected:
        assert all(not s["direction_known"] for s in want["streaks"])
        image, header = read_fits(d / want["file"])
        got = solver.solve(image, name=want["file"], header=header).to_dict()
        assert comparable(got) == comparable(unlinked(want))
    assert sum(len(r["streaks"]) for r in expected) >= 1 and expected[0]["epoch"] is not None


def test_batch_writes_the_clis_files(tmp_path):
    """batch()'s dark, wcs_dir, annotate_dir, CSV output and TDM/IOD exports are the command
    line's: the same files, byte for byte (the TDM's CREATION_DATE aside)."""
    d = tmp_path / "streaks"
    p = subprocess.run([cli(), "simulate", "--streaks", "--out", str(d), "-n", "2"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    frames = sorted(f for f in os.listdir(d) if f.endswith(".fits"))
    dark = tmp_path / "dark.fits"
    write_fits(dark, np.full(read_fits(d / frames[0])[0].shape, 7, np.uint16))
    outs = {}
    for who in ("cli", "py"):
        o = tmp_path / who
        o.mkdir()
        files = dict(output=o / "records.csv", dark=dark, wcs_dir=o / "wcs", annotate_dir=o / "png",
                     tdm=o / "streaks.tdm", iod=o / "streaks.iod")
        if who == "cli":
            args = [cli(), "batch", str(d), "--camera", str(d / "camera.toml"), "--streaks", "--backend", "cpu",
                    "-q", "--format", "csv", "--iod-station", "4171"]
            for k, v in files.items():
                args += [f"--{k.replace('_', '-')}", str(v)]
            p = subprocess.run(args, capture_output=True, text=True)
            assert p.returncode == 0, p.stderr
        else:
            records = list(gpustar.batch(d, camera=d / "camera.toml", backend="cpu", streaks=True, format="csv",
                                         iod_station=4171, **files))
            assert [r.file for r in records] == frames
        outs[who] = {str(f.relative_to(o)): f.read_bytes() for f in sorted(o.rglob("*")) if f.is_file()}
    assert set(outs["py"]) == set(outs["cli"]) and len(outs["py"]) >= 6, sorted(outs["py"])
    for name, want in outs["cli"].items():
        got = outs["py"][name]
        if name.endswith(".tdm"):
            want, got = (b"\n".join(x for x in t.split(b"\n") if not x.startswith(b"CREATION_DATE"))
                         for t in (want, got))
        if name.endswith(".csv"):  # less the timing column
            want, got = ([{k: v for k, v in row.items() if k != "total_ms"}
                          for row in csv.DictReader(io.StringIO(t.decode()))] for t in (want, got))
        assert got == want, name
    assert outs["py"]["records.csv"].startswith(b"file,status")
    with pytest.raises(gpustar.ConfigError, match="tdm is an option of streaks=True"):
        gpustar.batch(d, camera=d / "camera.toml", tdm=tmp_path / "x.tdm")
    with pytest.raises(gpustar.ConfigError, match="dark and dark_median"):
        gpustar.batch(d, camera=d / "camera.toml", dark=dark, dark_median=True)
    with pytest.raises(gpustar.ConfigError, match="give output=FILE"):
        gpustar.batch(d, camera=d / "camera.toml", format="csv")


def test_batch_refuses_outputs_that_are_not_its_own(tmp_path, frames):
    """batch() claims its outputs before any work, as the command line does (issue 45): a
    file that is not gpustar's records, an annotation folder where the frames are read, two
    outputs on one path; each refused with the file as it was."""
    d = tmp_path / "frames"
    d.mkdir()
    write_fits(d / "a.fits", frames[0][0])
    pretty = tmp_path / "settings.json"
    pretty.write_text('{\n  "file": "mine"\n}\n')
    with pytest.raises(gpustar.Error, match="does not hold gpustar results"):
        gpustar.batch(d, fov_deg=FOV, backend="cpu", output=pretty)
    assert pretty.read_text() == '{\n  "file": "mine"\n}\n'
    with pytest.raises(gpustar.Error, match="where the frames are read"):
        gpustar.batch(d, fov_deg=FOV, backend="cpu", annotate_dir=d)
    assert sorted(os.listdir(d)) == ["a.fits"]
    out = tmp_path / "r.jsonl"
    with pytest.raises(gpustar.Error, match="is also -o"):
        gpustar.batch(d, fov_deg=FOV, backend="cpu", output=out, streaks=True, tdm=out)
    assert not out.exists()


def test_sequence_tracks_frames(cpu_solver, frames):
    seq = gpustar.Sequence(cpu_solver, frame_interval_s=1.0)
    image = frames[0][0]
    records = [seq.add(image, time=f"2024-01-01T00:00:{k:02d}") for k in range(3)]
    assert all(r.sequence_mode is not None for r in records), [r.to_dict() for r in records]
    assert records[0].solved and records[0].file == "sequence/frame_00000"


def test_calibrate_writes_the_clis_camera_file(tmp_path):
    data = REPO.parent / "shared/data/real/esa-tetra3"
    if not (data / "truth.jsonl").exists():
        skip(f"no real frames at {data}")
    cam = REPO / "scripts/cameras/esa-tetra3.toml"
    out = tmp_path / "fitted.toml"
    p = subprocess.run([cli(), "calibrate", str(data), "--camera", str(cam), "-o", str(out)],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    fit = gpustar.calibrate(data, cam)
    assert fit["camera_file"] == out.read_text()
    assert fit["frames"] == 8 and fit["rms_after_px"] < fit["rms_before_px"]


def test_example_solves_the_real_frames():
    data = REPO.parent / "shared/data/real/esa-tetra3"
    if not (data / "truth.jsonl").exists():
        skip(f"no real frames at {data}")
    p = subprocess.run([sys.executable, str(REPO / "examples/python/solve_real.py")],
                       capture_output=True, text=True)
    assert p.returncode == 0, p.stdout + p.stderr
    assert "8 of 8 frames solved" in p.stdout, p.stdout


def test_readme_quickstart_runs_as_written(tmp_path, monkeypatch, capsys):
    """The README's Python example, verbatim, in an empty folder (issue 50: it named
    undefined variables)."""
    readme = (REPO / "README.md").read_text()
    section = readme[readme.index("## Python\n"):]
    code = section[section.index("```python\n") + len("```python\n"):]
    code = code[:code.index("```")]
    monkeypatch.chdir(tmp_path)
    exec(compile(code, "README.md", "exec"), {})
    out = capsys.readouterr().out
    assert "8/8" in out, out
    records = [json.loads(line) for line in (tmp_path / "out.jsonl").read_text().splitlines()]
    assert [r["file"] for r in records] == ["frame.png"] and records[0]["status"] == "solved"


def test_a_misspelt_field_raises_and_an_absent_one_is_none():
    """Issue 47: `r.ra` raised nothing and read None; a record field the record lacks is None."""
    image, _ = gpustar.simulate(1, fov_deg=FOV)[0]
    r = gpustar.Solver(fov_deg=FOV, backend="cpu").solve(image)
    assert r.solved and r.reason is None and r.error is None
    with pytest.raises(AttributeError, match="no field 'ra'"):
        r.ra
    assert not hasattr(r, "ra_degrees")
    assert {"ra_deg", "pixel_scale", "matches"} <= set(gpustar._gpustar.RECORD_FIELDS)
    assert set(r.to_dict()) <= set(gpustar._gpustar.RECORD_FIELDS)


def test_solve_file_gives_the_record_gpustar_solve_gives(tmp_path):
    """Issue 47: a file solved from Python is `gpustar solve FILE`'s record (less timing), for
    a PNG and a gzipped FITS; a file that cannot be read is an error result."""
    from PIL import Image

    image, _ = gpustar.simulate(1, fov_deg=FOV, seed=4)[0]
    png = tmp_path / "frame.png"
    Image.fromarray(image).save(png)
    fits = tmp_path / "frame.fits"
    write_fits(fits, image.astype(np.uint16))
    import gzip
    gz = tmp_path / "frame.fits.gz"
    gz.write_bytes(gzip.compress(fits.read_bytes()))
    solver = gpustar.Solver(fov_deg=FOV, backend="cpu")
    for path in (png, gz):
        got = solver.solve_file(path).to_dict()
        p = subprocess.run([cli(), "solve", str(path), "--fov-deg", str(FOV), "--backend", "cpu"],
                           capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        want = json.loads(p.stdout)
        assert got["status"] == "solved" and got["file"] == str(path)
        got.pop("timing_ms"), want.pop("timing_ms")
        assert got == want, path
    missing = solver.solve_file(tmp_path / "absent.png")
    assert missing.status == "error" and "absent.png" in missing.error
