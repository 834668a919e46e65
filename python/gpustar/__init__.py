"""gpustar: lost-in-space star identification and attitude for sky frames, from numpy.

A thin layer over the gpustar Rust crate (the same code as the ``gpustar`` command line):
every result is the command line's JSON Lines record, field for field.

    import numpy as np, gpustar
    solver = gpustar.Solver(fov_deg=10.0)          # built once: catalog, tables, GPU
    result = solver.solve(image)                   # 2-D uint8, uint16 or float32
    if result.solved:
        print(result.ra_deg, result.dec_deg, result.roll_deg, result.quaternion)
        print(result.matches.hip, result.matches.x, result.matches.y)
    record = result.to_dict()                      # exactly the JSONL record
    ra, dec = result.pixel_to_sky(100.0, 200.0)    # the plate solution, distortion included
    wcs = result.wcs()                             # astropy.wcs.WCS: what --wcs-dir writes
    df = gpustar.read_records("out.jsonl")         # a pandas DataFrame (a list without pandas)

``Solver`` is safe to share between threads; solving releases the GIL. The records follow
the JSON Schema docs/record.schema.json of the repository.
"""

from __future__ import annotations

import datetime as _dt
import json
import os
from typing import Any, Callable, Iterable, Iterator, Optional, Sequence as _Seq, Tuple, Union

import numpy as np


def _give_the_driver_a_runtime_dir() -> None:
    """Mesa's Vulkan drivers print "error: XDG_RUNTIME_DIR is invalid or not set in the
    environment." on stderr where the environment has no runtime directory (containers, batch
    jobs, cron): give them one of gpustar's own in the temp directory, as the command line
    does. Done at import, before the extension makes a GPU instance."""
    current = os.environ.get("XDG_RUNTIME_DIR")
    if current and os.path.isdir(current):
        return
    import tempfile

    path = os.path.join(tempfile.gettempdir(), "gpustar-runtime")
    try:
        os.makedirs(path, mode=0o700, exist_ok=True)
    except OSError:
        return
    os.environ["XDG_RUNTIME_DIR"] = path


_give_the_driver_a_runtime_dir()

from . import _gpustar  # noqa: E402
from ._gpustar import (  # noqa: E402
    CatalogError,
    ConfigError,
    Error,
    GpuError,
    InputError,
    IoError,
    OutputError,
    __version__,
)

_RECORD_FIELDS = frozenset(_gpustar.RECORD_FIELDS)

__all__ = [
    "Solver",
    "Result",
    "Matches",
    "Sequence",
    "Batch",
    "batch",
    "simulate",
    "calibrate",
    "read_records",
    "Error",
    "InputError",
    "CatalogError",
    "ConfigError",
    "OutputError",
    "GpuError",
    "IoError",
    "__version__",
]

PathLike = Union[str, "os.PathLike[str]"]
Progress = Union[Callable[[int, Optional[int]], Any], Any]


class Matches:
    """The identified stars of a result, as arrays (one entry per star, brightest first).

    ``x``, ``y``: centroid (pixels; x = column, y = row, (0, 0) the centre of the top-left
    pixel); ``hip``: Hipparcos number (-1 where the star has none); ``catalog_id``: the id in
    its catalog ("HIP 71683", "Gaia DR3 ..."); ``ra_deg``, ``dec_deg``: catalog position at the
    epoch; ``mag``; ``flux``; ``residual_arcsec``; ``sigma_px``: the centroid's 1-sigma (NaN
    for a centre of gravity).
    """

    __slots__ = ("x", "y", "hip", "catalog_id", "ra_deg", "dec_deg", "mag", "flux",
                 "residual_arcsec", "sigma_px")

    def __init__(self, matches: list):
        def col(key: str, dtype=np.float64, missing=np.nan) -> np.ndarray:
            return np.array([missing if m.get(key) is None else m[key] for m in matches],
                            dtype=dtype)

        self.x = col("x")
        self.y = col("y")
        self.hip = col("hip", np.int64, -1)
        self.catalog_id = [m.get("catalog_id") for m in matches]
        self.ra_deg = col("ra_deg")
        self.dec_deg = col("dec_deg")
        self.mag = col("mag")
        self.flux = col("flux")
        self.residual_arcsec = col("residual_arcsec")
        self.sigma_px = col("sigma_px")

    def __len__(self) -> int:
        return len(self.x)

    def __repr__(self) -> str:
        return f"Matches({len(self)} stars)"


class Result:
    """One frame's result: the fields of its JSON Lines record as attributes.

    ``status`` is "solved", "unsolved" (see ``reason``) or "error" (see ``error``).
    ``quaternion`` ([w, x, y, z], w >= 0) and ``rotation_matrix`` (3x3, ICRS into the camera
    frame) are numpy arrays; ``matches`` is a :class:`Matches` of arrays. Every other record
    field (``ra_deg``, ``dec_deg``, ``roll_deg``, ``fov_x_deg``, ``false_match_prob``,
    ``rmse_arcsec``, ``streaks``, ``timing_ms``, ...) is the record's value; a field this
    record does not have is None, and a name that is no record field raises AttributeError.
    :meth:`to_dict` gives the record exactly (docs/record.schema.json describes its fields).

    A solved result also holds its plate solution: :meth:`pixel_to_sky` and
    :meth:`sky_to_pixel` map through its camera model, :meth:`wcs` and :meth:`wcs_header`
    give the FITS WCS ``--wcs-dir`` writes. (A record read back from JSON does not carry the
    camera model: these raise ValueError for it.)
    """

    __slots__ = ("_source", "_text", "_dict")

    def __init__(self, line: Any):
        # A JSON line, or the extension's record handle, turned into its line and parsed only
        # when a field is first read: solve() pays for neither.
        self._source = line
        self._text: Optional[str] = line if isinstance(line, str) else None
        self._dict: Optional[dict] = None

    @property
    def _line(self) -> str:
        if self._text is None:
            self._text = self._source.json()
        return self._text

    @property
    def _record(self) -> dict:
        if self._dict is None:
            self._dict = json.loads(self._line)
        return self._dict

    def _field(self, name: str) -> Any:
        # A field alone from the extension's record, until the whole record is parsed.
        if self._dict is None and self._text is None:
            return self._source.get(name)
        return self._record.get(name)

    @property
    def status(self) -> str:
        """"solved", "unsolved" or "error"."""
        if self._dict is None and self._text is None:
            return self._source.status
        return self._record["status"]

    @property
    def solved(self) -> bool:
        return self.status == "solved"

    @property
    def quaternion(self) -> Optional[np.ndarray]:
        q = self._field("quaternion")
        return None if q is None else np.array(q, dtype=np.float64)

    @property
    def rotation_matrix(self) -> Optional[np.ndarray]:
        m = self._field("rotation_matrix")
        return None if m is None else np.array(m, dtype=np.float64)

    @property
    def matches(self) -> Matches:
        return Matches(self._field("matches") or [])

    def __getattr__(self, name: str) -> Any:
        if name.startswith("_") or name not in _RECORD_FIELDS:
            raise AttributeError(f"a gpustar record has no field {name!r} (its fields: "
                                 f"{', '.join(sorted(_RECORD_FIELDS))})")
        return self._field(name)

    def _solution(self, what: str) -> Any:
        """The extension's handle of a solved result (it holds the solution's camera model),
        None for a result that is not solved; ValueError for a solved result read back from a
        JSON line, whose record does not carry the camera model."""
        if not self.solved:
            return None
        if isinstance(self._source, str):
            raise ValueError(
                f"{what}: {self.file!r} is a record read back from JSON, which does not carry the "
                "camera model of its solution; take the result from Solver.solve, solve_file, "
                "solve_many, Sequence.add or gpustar.batch")
        return self._source

    def _solved(self, what: str) -> Any:
        handle = self._solution(what)
        if handle is None:
            raise ValueError(f"{what}: {self.file!r} is {self.status}, so it has no plate solution")
        return handle

    def wcs_header(self) -> Optional[str]:
        """The solution's FITS WCS header exactly as ``--wcs-dir`` writes it: 80-character
        cards, TAN (TAN-SIP when the camera has distortion), ``END`` last, blank-padded to a
        multiple of 2880 characters (the ``.wcs`` file's content). FITS pixel (1, 1) is the
        centre of the top-left pixel (gpustar's (0, 0)). None when the result is not
        solved."""
        handle = self._solution("wcs_header")
        if handle is None:
            return None
        text = "".join(handle.wcs_cards())
        return text + " " * (-len(text) % 2880)

    def wcs(self) -> Any:
        """The solution's FITS WCS (the header of :meth:`wcs_header`, as ``--wcs-dir`` writes
        it): an ``astropy.wcs.WCS`` when astropy is installed (its 0-based pixel coordinates
        are gpustar's: (0, 0) the centre of the top-left pixel; ``pixel_shape`` is the image's
        (width, height)), else a dict of the header's keywords and their values (``CRVAL1``,
        ``CD1_1``, ``A_2_0``, ...; bool, int, float or str). None when the result is not
        solved.

        astropy evaluates the SIP polynomials, whose pixel-to-sky part (A, B) is a fit within
        0.005 px of the camera model; :meth:`pixel_to_sky` and :meth:`sky_to_pixel` use the
        camera model itself."""
        text = self.wcs_header()
        if text is None:
            return None
        try:
            from astropy.io import fits
            from astropy.wcs import WCS
        except ImportError:
            return _header_values(text)
        header = fits.Header.fromstring(text)
        # The image's size as a FITS image header gives it (the .wcs file is header-only):
        # astropy then knows pixel_shape, and does not warn of a 2-axis WCS on no image.
        header["NAXIS"] = 2
        header.set("NAXIS1", header["IMAGEW"], "Image width, in pixels.", after="NAXIS")
        header.set("NAXIS2", header["IMAGEH"], "Image height, in pixels.", after="NAXIS1")
        return WCS(header)

    def pixel_to_sky(self, x: Any, y: Any) -> Tuple[Any, Any]:
        """(ra_deg, dec_deg), ICRS degrees (RA in [0, 360)), of pixel positions (x = column,
        y = row, 0-based, (0, 0) the centre of the top-left pixel) through the solution: its
        rotation and camera model (scale, principal point, distortion, parity), as gpustar
        computes the matches' residuals. Numbers give floats; arrays (broadcast together)
        give arrays of their shape. ValueError when the result is not solved."""
        return _mapped(self._solved("pixel_to_sky").pixel_to_sky, x, y)

    def sky_to_pixel(self, ra_deg: Any, dec_deg: Any) -> Tuple[Any, Any]:
        """(x, y) pixel positions (as :meth:`pixel_to_sky` takes them) of ICRS directions
        (degrees), through the solution; NaN for a direction behind the camera (a position
        off the image is still given). The inverse of :meth:`pixel_to_sky`. ValueError when
        the result is not solved."""
        return _mapped(self._solved("sky_to_pixel").sky_to_pixel, ra_deg, dec_deg)

    def to_dict(self) -> dict:
        """The JSON Lines record, exactly as ``gpustar batch`` writes it (a fresh copy)."""
        return json.loads(self._line)

    def to_json(self) -> str:
        """The record as one JSON line (no newline)."""
        return self._line

    def __repr__(self) -> str:
        r = self._record
        if r["status"] == "solved":
            return (f"Result({r['file']!r}, solved, ra={r['ra_deg']:.4f}, dec={r['dec_deg']:.4f}, "
                    f"roll={r['roll_deg']:.3f}, {r['stars_matched']} stars)")
        return f"Result({r['file']!r}, {r['status']}, {r.get('reason') or r.get('error')!r})"


def _mapped(convert: Callable, a: Any, b: Any) -> Tuple[Any, Any]:
    """``convert`` (the extension's, on two 1-D float64 arrays) of numbers or arrays."""
    a, b = np.broadcast_arrays(np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64))
    shape = a.shape
    p, q = convert(np.ascontiguousarray(a.ravel()), np.ascontiguousarray(b.ravel()))
    if shape == ():
        return float(p[0]), float(q[0])
    return p.reshape(shape), q.reshape(shape)


def _header_values(text: str) -> dict:
    """The keywords of a FITS header (80-character cards) and their values: bool, int, float
    or str (COMMENT and END left out)."""
    values: dict = {}
    for k in range(0, len(text), 80):
        card = text[k:k + 80]
        key = card[:8].strip()
        if card[8:10] != "= " or not key:
            continue
        raw = card[10:].strip()
        if raw.startswith("'"):
            # A string: to the closing quote ('' is a quote), trailing blanks not significant.
            end = 1
            while True:
                end = raw.index("'", end)
                if raw[end + 1:end + 2] == "'":
                    end += 2
                    continue
                break
            values[key] = raw[1:end].replace("''", "'").rstrip()
            continue
        token = raw.split("/")[0].strip()
        if token in ("T", "F"):
            values[key] = token == "T"
        else:
            try:
                values[key] = int(token)
            except ValueError:
                values[key] = float(token.replace("D", "E"))
    return values


def _header(epoch_time: Any, header: Optional[dict]) -> Optional[dict]:
    """FITS-like keywords for a frame: a time (ISO string or datetime) becomes DATE-OBS."""
    h = {str(k): str(v) for k, v in (header or {}).items()}
    if epoch_time is not None:
        if isinstance(epoch_time, _dt.datetime):
            if epoch_time.tzinfo is not None:
                epoch_time = epoch_time.astimezone(_dt.timezone.utc).replace(tzinfo=None)
            epoch_time = epoch_time.isoformat()
        h["DATE-OBS"] = str(epoch_time)
    return h or None


def _tick(progress: Progress, done: int, total: Optional[int]) -> None:
    if progress is None:
        return
    if hasattr(progress, "update"):  # a tqdm bar
        progress.update(1)
    else:
        progress(done, total)


class Solver:
    """A solver built once and reused: the catalog, the distance table of each frame size
    (built on first use, cached on disk) and the GPU context.

    ``camera``: a camera file (TOML, as ``--camera``) or its text; or ``fov_deg``: the
    horizontal field of view in degrees (centred, no distortion, size from each image; square
    pixels unless the option ``pixel_aspect`` gives a pixel's height over its width), or a
    ``(low, high)`` range to search. ``catalog``: a file ``gpustar catalog
    import`` made (default: the built-in Hipparcos-2, Hp <= 9). ``backend``: "auto", "gpu"
    or "cpu", as ``--backend``.

    ``**options`` are the command line's, with ``_`` for ``-``: ``fov_tolerance``, ``fov_walk``, ``fit``
    ("none", "scale", "distortion"), ``parity`` ("either", "camera"), ``mag_limit``, ``epoch``, ``centroid`` ("ml", "cog"),
    ``method`` ("vote", "radial", "triangle"), ``detect_filter`` ("none", "binomial"),
    ``sigma``, ``vote_stars``, ``pair_tol_px``, ``scale_tol``, ``match_radius_px``,
    ``max_false_prob``, ``retry`` (False = ``--no-retry``), ``wide_min_stars``, ``double_stars``,
    ``double_star_px``, ``cache`` (False = ``--no-cache``), ``hint`` ("RA,DEC[,R]" or
    "header[,R]"), ``streaks`` (True = ``--streaks``) with ``station`` ("LAT,LON,HEIGHT_M"),
    ``astrometry``, ``dut1``, ``streak_sigma``, ``tle`` (a TLE or OMM file naming each
    streak's object), ``tle_cross``, ``tle_along``; ``threads`` (CPU solving threads of
    :meth:`solve_many`), ``batch_size`` (frames per GPU batch, 32). Values out of the command
    line's ranges raise :class:`ConfigError` with its message.

    A Solver may be shared between threads: solving releases the GIL, CPU solves run in
    parallel, and GPU batches take turns on the one context.
    """

    def __init__(self, camera: Optional[PathLike] = None, fov_deg: Union[float, Tuple[float, float], None] = None,
                 catalog: Optional[PathLike] = None, backend: str = "auto", **options: Any):
        if camera is not None and not isinstance(camera, str):
            camera = os.fspath(camera)
        self._inner = _gpustar.Solver(camera, fov_deg, None if catalog is None else os.fspath(catalog),
                                      backend, options or None)

    @property
    def backend(self) -> str:
        """The records' ``backend`` field: "cpu" or "gpu: <adapter>"."""
        return self._inner.backend

    def prepare(self, width: int, height: int) -> None:
        """Build the distance table for frames of this size now (else on the first solve)."""
        self._inner.prepare(int(width), int(height))

    def solve(self, image: np.ndarray, *, name: str = "image", epoch: Optional[float] = None,
              time: Any = None, header: Optional[dict] = None) -> Result:
        """Solve one frame: a 2-D numpy array (height, width) of uint8, uint16 or float32.

        A C-contiguous uint16 array is solved where it lies, without a copy (and with the GIL
        released: another thread must not write to it until ``solve`` returns); other dtypes
        are converted, other strides gathered. uint8 and uint16 values are taken as they are
        (as 8- and 16-bit PNGs); float32 values are scaled from their range as a BITPIX -32
        FITS file's. ``name`` is the record's ``file``;
        ``epoch`` (Julian year) moves the catalog stars by proper motion; ``time`` (ISO UTC
        string or datetime) and ``header`` (FITS keywords: EXPTIME, station, ...) serve
        streaks. A bad array raises :class:`InputError`; a frame that cannot be solved is a
        result with status "unsolved" (or "error" when its size has no solver, as a file).
        """
        return Result(self._inner.solve(image, name, epoch, _header(time, header)))

    def solve_file(self, path: PathLike) -> Result:
        """Read and solve one image file (PNG, JPEG, TIFF, FITS, .fits.gz) as ``gpustar solve
        FILE`` does: the same record, its ``file`` the path as given. A file that cannot be
        read is a result with status "error", not an exception; a FITS header's date, station
        and pixel scale are used as the command line uses them."""
        return Result(self._inner.solve_file(os.fspath(path)))

    def solve_many(self, images: Iterable[np.ndarray], *, names: Optional[_Seq[str]] = None,
                   epochs: Optional[_Seq[Optional[float]]] = None, progress: Progress = None,
                   batch_size: Optional[int] = None) -> Iterator[Result]:
        """Solve frames as ``gpustar batch`` solves files: streamed to ``threads`` worker
        threads on the CPU (or the GPU in batches of ``batch_size``), an iterator of results in
        input order, each as soon as it and those before it are done.

        ``images`` may be a list or a generator, read up to a window of frames ahead of the
        results (as ``batch``'s, and at most 256 MiB of pixels beyond two frames per thread or
        one GPU batch), each frame copied as it is handed over; on the GPU, the solver's other
        calls wait until the iteration ends. ``names`` the records'
        ``file`` fields (default "image_00000", ...); ``epochs`` each frame's epoch (Julian
        year, or None), as ``solve``'s ``epoch``. An array refused for its values gives that
        frame an error record rather than losing the others. ``progress`` is called as
        ``progress(done, total)`` (total None for a generator), or ``progress.update(1)`` when
        it has ``update`` (a tqdm bar).
        """
        total = len(images) if hasattr(images, "__len__") else None  # type: ignore[arg-type]
        if total is not None and any(s is not None and len(s) != total for s in (names, epochs)):
            raise InputError(f"{total} images, {len(names or [])} names and {len(epochs or [])} "
                             "epochs: give one of each per image")
        run = self._inner.start_many(None if batch_size is None else int(batch_size))
        window = 1
        put = done = 0
        for im in images:
            for what, given in (("names", names), ("epochs", epochs)):
                if given is not None and put >= len(given):
                    run.close()
                    raise InputError(f"more images than {what} ({len(given)}): give one per image")
            run.put(im, names[put] if names is not None else f"image_{put:05d}",
                    None if epochs is None else epochs[put])
            if put == 0:  # a 2-D array: put takes no other
                window = run.window_for(im.shape[1], im.shape[0])
            put += 1
            # Take the records that are ready; wait for one only when the workers hold a
            # window of frames (so they always have the next ones while Python waits).
            while True:
                handle = run.next_record(put - done >= window)
                if handle is None:
                    break
                done += 1
                _tick(progress, done, total)
                yield Result(handle)
        run.close()
        while True:
            handle = run.next_record(True)
            if handle is None:
                return
            done += 1
            _tick(progress, done, total)
            yield Result(handle)

    def solve_centroids(self, xy: np.ndarray, image_size: Tuple[int, int],
                        fluxes: Optional[np.ndarray] = None, *, name: str = "centroids",
                        epoch: Optional[float] = None) -> Result:
        """Identify stars you detected: ``xy`` an (N, 2) array of (x, y) pixel positions (x =
        column, y = row, (0, 0) the centre of the top-left pixel) in an image of
        ``image_size`` = (width, height); ``fluxes`` their brightness (any linear unit; None:
        ``xy`` is brightest first). The result is the record of a frame with those
        detections."""
        xy = np.asarray(xy, dtype=np.float64)
        if xy.ndim != 2 or xy.shape[1] != 2:
            raise InputError(f"xy has shape {xy.shape}: give an (N, 2) array of x, y")
        f = None if fluxes is None else np.ascontiguousarray(fluxes, dtype=np.float64)
        w, h = (int(v) for v in image_size)
        return Result(self._inner.solve_centroids(np.ascontiguousarray(xy[:, 0]),
                                                  np.ascontiguousarray(xy[:, 1]), w, h, f, name,
                                                  epoch))


class Sequence:
    """A sequence of frames of one camera head, fed frame by frame in time order (as
    ``--sequence`` takes a directory): moving particles are rejected over frames and the
    attitude is tracked from frame to frame. Records carry ``sequence_mode`` and
    ``particles``. Give each frame's ``time`` (ISO UTC or datetime), or
    ``frame_interval_s`` for frames without one."""

    def __init__(self, solver: Solver, frame_interval_s: Optional[float] = None, name: str = "sequence"):
        self._inner = _gpustar.Sequence(solver._inner, frame_interval_s)
        self._name = name
        self._count = 0

    def add(self, image: np.ndarray, time: Any = None, *, header: Optional[dict] = None) -> Result:
        """The next frame's result."""
        name = f"{self._name}/frame_{self._count:05d}"
        self._count += 1
        return Result(self._inner.add(image, name, _header(time, header)))


class Batch:
    """An iterator of the results of a ``gpustar batch`` run, in input order; ``total`` is the
    number of inputs this run solves (after ``shard`` and ``resume``). Leaving the loop
    early stops the run after the frames in flight."""

    def __init__(self, run: Any, progress: Progress):
        self._run = run
        self._progress = progress
        self._done = 0
        self.total: int = run.total

    def __iter__(self) -> "Batch":
        return self

    def __next__(self) -> Result:
        handle = self._run.next_record()
        if handle is None:
            raise StopIteration
        self._done += 1
        _tick(self._progress, self._done, self.total)
        return Result(handle)

    def __len__(self) -> int:
        return self.total

    def close(self) -> None:
        """Start no new input (the run ends after the frames in flight)."""
        self._run.stop()


def batch(directory: PathLike, camera: Optional[PathLike] = None,
          fov_deg: Union[float, Tuple[float, float], None] = None, catalog: Optional[PathLike] = None,
          backend: str = "auto", *, output: Optional[PathLike] = None, format: str = "jsonl",
          resume: bool = False, retry_errors: bool = False, shard: Optional[str] = None,
          recursive: bool = False, sequence: bool = False, frame_interval_s: Optional[float] = None,
          dark: Optional[PathLike] = None, dark_median: bool = False,
          wcs_dir: Optional[PathLike] = None, annotate_dir: Optional[PathLike] = None,
          tdm: Optional[PathLike] = None, iod: Optional[PathLike] = None, iod_station: int = 9999,
          overwrite: bool = False, progress: Progress = None, **options: Any) -> Batch:
    """``gpustar batch DIRECTORY``: every image file of the directory (sorted by path),
    decoded and solved on worker threads (or the GPU in batches), as an iterator of results
    in input order. ``output`` also writes the records to a file, as JSON Lines or
    ``format="csv"``, which ``resume`` continues (and ``retry_errors`` retries the error
    records of); ``shard`` = "K/N" takes one shard; ``sequence`` solves each directory as a
    sequence. ``dark`` (a dark frame's file) or ``dark_median`` (each directory's median frame)
    is subtracted before detection; ``wcs_dir`` gets a FITS WCS header per solved frame,
    ``annotate_dir`` an annotated PNG per frame; with ``streaks=True``, ``tdm`` and ``iod``
    write the streaks as a CCSDS TDM and as IOD lines (``iod_station``: your COSPAR site)
    when the run ends; ``overwrite`` lets those replace files gpustar did not write (never an
    input, never ``output``). Each is the command line's option of that name. ``progress`` as in
    :meth:`Solver.solve_many`; other options as :class:`Solver`'s.
    """
    path = lambda p: None if p is None else os.fspath(p)  # noqa: E731
    run = _gpustar.start_batch(
        os.fspath(directory), path(camera), fov_deg, path(catalog), backend, path(output), resume,
        retry_errors, shard, recursive, sequence, frame_interval_s, options or None, format,
        path(dark), dark_median, path(wcs_dir), path(annotate_dir), path(tdm), path(iod),
        int(iod_station), bool(overwrite))
    return Batch(run, progress)


def simulate(n: int = 1, size: Tuple[int, int] = (1024, 1024), fov_deg: float = 18.0, seed: int = 1,
             *, mag_limit: Optional[float] = None, bits: int = 8, false_stars: Optional[int] = None,
             catalog: Optional[PathLike] = None) -> list:
    """``gpustar simulate``'s frames (its defaults: 1024x1024, 18 degrees, Hp <= 6, 8 bits, 3
    false stars): a list of (image, truth) with image a (height, width) uint8 array (uint16
    for ``bits=16``) and truth the frame's line of truth.jsonl (attitude, the catalog stars on
    the frame with their positions, false stars)."""
    w, h = (int(v) for v in size)
    out = []
    for raw, truth in _gpustar.simulate(int(n), (w, h), float(fov_deg), int(seed), mag_limit, int(bits),
                                        false_stars, None if catalog is None else os.fspath(catalog)):
        image = np.frombuffer(raw, dtype=np.uint16).reshape(h, w)
        if bits == 8:
            image = image.astype(np.uint8)
        out.append((image, json.loads(truth)))
    return out


def calibrate(directory: PathLike, camera: PathLike, *, fov_tolerance: Optional[float] = None,
              recursive: bool = False, catalog: Optional[PathLike] = None, fit_k2: bool = True,
              fixed_centre: bool = False) -> dict:
    """``gpustar calibrate``: fit the camera (fx, fy, cx, cy, k1, k2) to every solvable frame
    of the directory, starting from a camera file (``fit_k2=False`` = ``--no-k2``,
    ``fixed_centre=True`` = ``--fixed-centre``). Returns ``camera_file`` (the TOML
    text to save), ``camera`` (the fitted values), ``sigmas`` (their 1-sigma),
    ``rms_before_px``, ``rms_after_px``, ``stars_used``, ``stars_rejected``, ``frames`` and
    ``records`` (the frames' results with the fitted camera)."""
    d = _gpustar.calibrate(os.fspath(directory), os.fspath(camera), fov_tolerance, recursive,
                           None if catalog is None else os.fspath(catalog), fit_k2, fixed_centre)
    d["records"] = [Result(line) for line in d["records"]]
    return d


# The columns of gpustar's CSV records that hold JSON (an empty cell: none).
_CSV_JSON = frozenset({"streaks", "particles", "warnings", "hint"})


def _csv_value(column: str, text: str) -> Any:
    """A CSV cell as the value it stands for: None (empty), JSON (the JSON columns), a bool,
    an int, a float, or the text."""
    if text == "":
        return None
    if column in _CSV_JSON:
        return json.loads(text)
    if text in ("true", "false"):
        return text == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def read_records(path: PathLike, *, format: Optional[str] = None) -> Any:
    """The records of a gpustar output file: a pandas ``DataFrame`` (one row per record, a
    column per field; nested fields such as ``matches``, ``streaks`` and ``timing_ms`` are
    Python lists and dicts) when pandas is installed, else a list of dicts.

    ``format`` is "jsonl" (one record per line, as ``gpustar batch -o`` writes) or "csv"
    (``--format csv``: its columns, the JSON cells of streaks, particles, warnings and hint
    decoded); by default "csv" for a name ending in .csv, else "jsonl". Blank lines are
    skipped; a line that is not JSON raises :class:`InputError` naming it (a last line
    without its newline is a run that did not finish)."""
    p = os.fspath(path)
    if format is None:
        format = "csv" if p.lower().endswith(".csv") else "jsonl"
    if format not in ("jsonl", "csv"):
        raise ConfigError(f"format: {format!r} is not one of jsonl, csv")
    try:
        f = open(p, encoding="utf-8", newline="" if format == "csv" else None)
    except OSError as e:
        raise IoError(f"cannot read records {p}: {e.strerror or e}") from None
    with f:
        if format == "csv":
            import csv

            rows = [{k: _csv_value(k, v) for k, v in row.items()} for row in csv.DictReader(f)]
        else:
            rows = []
            for n, line in enumerate(f, 1):
                if not line.strip():
                    continue
                try:
                    rows.append(json.loads(line))
                except json.JSONDecodeError as e:
                    torn = "" if line.endswith("\n") else " (its last line is cut off: that run did not finish)"
                    raise InputError(f"{p}: line {n}: not a gpustar record{torn}: {e}") from None
    try:
        import pandas
    except ImportError:
        return rows
    return pandas.DataFrame(rows)
