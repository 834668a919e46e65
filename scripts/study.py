#!/usr/bin/env python3
"""Accuracy and robustness study of gpustar, with cedar-solve on the same frames (issue 6).

    python3 scripts/study.py --out DIR [--gpustar BIN] [--cedar-python PY]
                             [--headline-frames 10000] [--sweep-frames 1000] [--cedar-frames N]
                             [--only NAMES] [--quick] [--keep-frames] [--report-only] [--redo-gpustar]
                             [--variant NAME="ARGS" ...]

What it does, set by set (each set lives in DIR/<set>/):
  1. `gpustar simulate` writes the frames, truth.jsonl and camera.toml into DIR/<set>/frames.
  2. `gpustar batch --backend cpu -q` solves them (timed: frames / wall seconds of the whole
     command, after a one-frame warm-up `gpustar solve` that builds the distance table cache);
     `gpustar evaluate --per-frame` scores them. Once per series: the default settings
     ("gpustar"), each --variant, and on base18 and headline10 also `--double-stars drop` and
     `--double-stars keep`.
  3. cedar-solve solves the first --cedar-frames frames of the same files, in two worker
     processes in parallel under --cedar-python (cedar pins numpy<2 and Pillow<9, so it usually
     lives in its own venv; the workers are this script in worker mode and use only stdlib +
     cedar's own packages). This script scores cedar itself, with the same criteria.
  4. The PNGs are deleted (unless --keep-frames); truth, records and scores stay.
Then DIR/report.md, DIR/results.json (every number of the report) and the PNG charts in DIR.

Sets (1024x1024; base: 18 deg FOV, Hp <= 6, 3 false stars, 5 hot pixels, no centroid noise):
  headline10      10 deg FOV, --headline-frames frames
  headline18f20   18 deg, 20 false stars, 20 hot pixels, --headline-frames frames
  base18          the base, --sweep-frames frames (the shared point of every sweep)
  false_stars_K, centroid_noise_S, mag_limit_M, fov_F   sweep points, --sweep-frames frames
Names for --only: set names, sweep names (false_stars, centroid_noise, mag_limit, fov; a sweep
includes base18) or "headline" (both headline sets). --only limits what is computed; the report
always shows everything found in DIR.

Reuse: a set whose DIR/<set>/ already holds truth, records, scores and cedar results for the
requested counts is not recomputed, so rerunning only redraws the report (--report-only never
runs gpustar or cedar, and shows every variant found in DIR). Changing a set's frame count or
parameters recomputes that set. --redo-gpustar solves the selected sets again with the current
binary and keeps cedar's results (frames are regenerated from their seed when they were
deleted; if the simulator's output changed, the set's old results are dropped). The gpustar
binary is copied to DIR/gpustar-snapshot first, so a rebuild during the run cannot mix two
versions.

Run time on 2 idle cores (measured with --quick; DIR/report.md ends with the ms per frame of
each step): simulate ~35 ms/frame (43,000 frames: ~25 min), gpustar batch ~3-5 ms/frame per
series (~5 min in all, each --variant ~3 min more), cedar-solve 30-50 ms/frame at the base
point but 0.3-0.5 s at 20 false stars and 1.5-2.3 s at 40-50 (its 5 s timeouts): with cedar on
every frame about 3-3.5 h in all, with --cedar-frames 1000 about 2 h. 10000 PNG frames take
about 4 GB while a set is being worked on.

The driver uses the standard library and matplotlib (Agg) only; the helpers shared with
scripts/bench_vs_cedar.py are imported from it.
"""
import argparse
import hashlib
import json
import math
import os
import platform
import re
import shlex
import shutil
import subprocess
import sys
import time
import zlib
from pathlib import Path

SCRIPTS = Path(__file__).resolve().parent
REPO = SCRIPTS.parent
sys.path.insert(0, str(SCRIPTS))
import bench_vs_cedar as bvc  # noqa: E402  (stdlib only: read_jsonl, sep_deg, roll_diff_deg, tail)

TOL_DEG = 0.1       # attitude within this of the truth = correct (as `gpustar evaluate`)
ID_TOL_PX = 3.0     # a star ID is false when the star is not within this of its true place


def star_key(s):
    """A star's identity in records and truth files: its catalog_id ("HIP 27989", "Gaia DR3 ...")
    where written, else its HIP (truth files of the Python simulators, older records)."""
    return s.get("catalog_id") or f"HIP {s['hip']}"


def tolerances(params):
    """(attitude tolerance deg, ID tolerance px) of a set. With centroid noise sigma the stars
    are drawn off their true places (the truth keeps those), so a correct ID can be 3 sigma away
    and a correct attitude's roll off by a few hundred arcseconds: the ID tolerance grows by
    5 sigma and the attitude tolerance to 0.1 deg x max(1, 4 sigma/px)."""
    sigma = params.get("noise", 0.0)
    return TOL_DEG * max(1.0, 4.0 * sigma), ID_TOL_PX + 5.0 * sigma
BASE = {"fov": 18.0, "mag": 6.0, "false": 3, "hot": 5, "noise": 0.0}
# sweep name: (parameter, values, axis label)
SWEEPS = {
    "false_stars": ("false", [0, 10, 20, 30, 40, 50], "false stars per frame"),
    "centroid_noise": ("noise", [0, 0.25, 0.5, 0.75, 1.0, 1.5], "centroid noise sigma (px)"),
    "mag_limit": ("mag", [4.5, 5, 5.5, 6, 6.5, 7], "limiting magnitude (Hp)"),
    "fov": ("fov", [8, 10, 12, 15, 18, 20, 25], "horizontal field of view (deg)"),
}
DOUBLE_STARS = {"ds_drop": ["--double-stars", "drop"], "ds_keep": ["--double-stars", "keep"]}
SEED000 = {"stars18": "22–30", "stars10": "6–13", "no_false_before": 94.38, "no_false_after": 99.98}
CEDAR = "cedar-solve"
T0 = time.perf_counter()


# ---------------------------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------------------------

def log(msg):
    print(f"[{time.perf_counter() - T0:8.1f} s] {msg}", file=sys.stderr, flush=True)


def run(cmd):
    """(returncode, stdout, stderr, wall seconds) of a command."""
    t0 = time.perf_counter()
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True)
    return p.returncode, p.stdout, p.stderr, time.perf_counter() - t0


def read_json(path, default=None):
    try:
        return json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return default


def write_json(path, obj):
    tmp = Path(str(path) + ".part")
    tmp.write_text(json.dumps(obj, indent=1, default=float) + "\n")
    tmp.replace(path)


def count_lines(path):
    try:
        with open(path) as f:
            return sum(1 for line in f if line.strip())
    except OSError:
        return 0


def quantile(sorted_vals, q):
    """The quantile `gpustar evaluate` uses: the element at round((n - 1) q)."""
    if not sorted_vals:
        return None
    return sorted_vals[round((len(sorted_vals) - 1) * q)]


def pct(num, den):
    return 100.0 * num / den if den else None


def fmt(v, spec=".1f", unit=""):
    return "–" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:{spec}}{unit}"


# ---------------------------------------------------------------------------------------------
# Geometry (standard library; used for cedar and for checking the roll convention)
# ---------------------------------------------------------------------------------------------

def unit(ra_deg, dec_deg):
    return bvc.unit(ra_deg, dec_deg)


def rotation_from_radec_roll(ra_deg, dec_deg, roll_deg):
    """ICRS -> camera rotation (rows: camera +X right, +Y down, +Z boresight in ICRS) from the
    image-centre RA/Dec and tetra3's Roll (angle from image up to celestial north, counter-
    clockwise as displayed), for an unmirrored pinhole camera centred on the image."""
    ra, dec, roll = (math.radians(a) for a in (ra_deg, dec_deg, roll_deg))
    z = unit(ra_deg, dec_deg)
    north = (-math.sin(dec) * math.cos(ra), -math.sin(dec) * math.sin(ra), math.cos(dec))
    east = (-math.sin(ra), math.cos(ra), 0.0)
    s, c = math.sin(roll), math.cos(roll)
    # On the image, north = (-sin r, -cos r) and east = (-cos r, sin r) in (x, y).
    x = tuple(-s * n - c * e for n, e in zip(north, east))
    y = tuple(-c * n + s * e for n, e in zip(north, east))
    return [list(x), list(y), list(z)]


def matmul_vec(m, v):
    return [sum(m[i][k] * v[k] for k in range(3)) for i in range(3)]


def attitude_error_deg(r1, r2):
    """Angle of the rotation r1 r2^T (degrees), by atan2 (accurate at small angles)."""
    m = [[sum(r1[i][k] * r2[j][k] for k in range(3)) for j in range(3)] for i in range(3)]
    skew = (m[2][1] - m[1][2], m[0][2] - m[2][0], m[1][0] - m[0][1])
    return math.degrees(math.atan2(math.sqrt(sum(v * v for v in skew)), m[0][0] + m[1][1] + m[2][2] - 1))


def project(truth, ra_deg, dec_deg):
    """Pixel (x, y) of a sky direction under the truth attitude and the truth's pinhole
    camera (centre pixel = principal point), or None when behind the camera."""
    v = matmul_vec(truth["rotation_matrix"], unit(ra_deg, dec_deg))
    if v[2] <= 0:
        return None
    w, h = truth["width"], truth["height"]
    fx = w / 2 / math.tan(math.radians(truth["fov_x_deg"]) / 2)
    fy = h / 2 / math.tan(math.radians(truth.get("fov_y_deg") or truth["fov_x_deg"]) / 2)
    return ((w - 1) / 2 + fx * v[0] / v[2], (h - 1) / 2 + fy * v[1] / v[2])


def check_roll_convention(truths):
    """Largest element difference between truth's rotation_matrix and the rotation built
    from its own ra/dec/roll_tetra3 (the function cedar's answers go through)."""
    worst = 0.0
    for t in truths:
        r = rotation_from_radec_roll(t["ra_deg"], t["dec_deg"], t["roll_tetra3_deg"])
        worst = max(worst, max(abs(r[i][j] - t["rotation_matrix"][i][j]) for i in range(3) for j in range(3)))
    return worst


# ---------------------------------------------------------------------------------------------
# cedar-solve worker (runs under --cedar-python; the only code that imports cedar's packages)
# ---------------------------------------------------------------------------------------------

def cedar_versions():
    from importlib import metadata
    out = {"python": platform.python_version(), "executable": sys.executable}
    for pkg in ("cedar-solve", "numpy", "Pillow", "scipy"):
        try:
            out[pkg] = metadata.version(pkg)
        except Exception:  # noqa: BLE001
            out[pkg] = None
    return out


def cedar_probe():
    """Print cedar's versions as JSON; exit 3 when tetra3 cannot be imported."""
    v = cedar_versions()
    try:
        import tetra3  # noqa: F401
    except Exception as e:  # noqa: BLE001
        print(f"{sys.executable} cannot import tetra3 (cedar-solve): {type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(3)
    if v["cedar-solve"] is None:
        print(f"{sys.executable}: tetra3 is importable but the cedar-solve distribution is missing "
              "(ESA's tetra3?)", file=sys.stderr)
        sys.exit(3)
    print(json.dumps(v))


def cedar_worker(frames_dir, files_list, fov, out_path):
    """Solve the listed frames with cedar-solve: one JSON line per frame, then {"summary": ...}.
    Centroids are converted to gpustar's pixel convention ((0, 0) = centre of the top-left
    pixel; tetra3 puts it at (0.5, 0.5))."""
    import logging
    import tetra3
    from PIL import Image
    logging.getLogger("tetra3.Tetra3").setLevel(logging.WARNING)
    t_db = time.perf_counter()
    t3 = tetra3.Tetra3()  # the wheel's default_database (hip_main, 10-30 deg FOV)
    t_db = time.perf_counter() - t_db
    props = {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in t3.database_properties.items()}
    props = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in props.items()}
    status_names = {getattr(tetra3.tetra3, n): n for n in
                    ("MATCH_FOUND", "NO_MATCH", "TIMEOUT", "CANCELLED", "TOO_FEW")}
    files = Path(files_list).read_text().split()

    def num(v):
        return None if v is None else float(v)

    with open(out_path, "w") as out:
        start, t_loop = time.time(), time.perf_counter()
        for name in files:
            t0 = time.perf_counter()
            with Image.open(Path(frames_dir) / name) as image:
                image.load()
                sol = t3.solve_from_image(image, fov_estimate=fov, return_matches=True)
            dt = time.perf_counter() - t0
            ids = []
            for cat, (cy, cx), star in zip(sol.get("matched_catID") or [], sol.get("matched_centroids") or [],
                                           sol.get("matched_stars") or []):
                ids.append({"hip": int(cat), "x": float(cx) - 0.5, "y": float(cy) - 0.5,
                            "ra_deg": float(star[0]), "dec_deg": float(star[1])})
            out.write(json.dumps({
                "file": name, "status": "solved" if sol.get("RA") is not None else "unsolved",
                "cedar_status": status_names.get(sol.get("status"), sol.get("status")),
                "ra_deg": num(sol.get("RA")), "dec_deg": num(sol.get("Dec")), "roll_deg": num(sol.get("Roll")),
                "fov_deg": num(sol.get("FOV")), "prob": num(sol.get("Prob")),
                "t_extract_ms": num(sol.get("T_extract")), "t_solve_ms": num(sol.get("T_solve")),
                "total_ms": dt * 1e3, "matches": ids}) + "\n")
        seconds = time.perf_counter() - t_loop
        out.write(json.dumps({"summary": {
            "frames": len(files), "seconds": seconds, "start": start, "end": start + seconds,
            "database_load_s": t_db, "database_properties": props, "versions": cedar_versions()}}) + "\n")


# ---------------------------------------------------------------------------------------------
# The plan: which sets, with which parameters
# ---------------------------------------------------------------------------------------------

def point_name(sweep, value):
    return f"{sweep}_{value:g}"


def plan_sets(args):
    """{set name: spec} in run order. A spec holds params, frames, seed and its sweeps."""
    def spec(name, frames, **over):
        params = dict(BASE, **over)
        # A stable seed per set, different for every set.
        return {"name": name, "params": params, "frames": frames,
                "seed": 1 + zlib.crc32(name.encode()) % 1_000_000, "sweeps": {}}
    sets = {
        "headline10": spec("headline10", args.headline_frames, fov=10.0),
        "headline18f20": spec("headline18f20", args.headline_frames, false=20, hot=20),
        "base18": spec("base18", args.sweep_frames),
    }
    for sweep, (param, values, _) in SWEEPS.items():
        sets["base18"]["sweeps"][sweep] = BASE[param]  # the base is a point of every sweep
        for v in values:
            if v == BASE[param]:
                continue
            name = point_name(sweep, v)
            sets[name] = spec(name, args.sweep_frames, **{param: v})
            sets[name]["sweeps"][sweep] = v
    return sets


def selected(spec, only):
    if not only:
        return True
    return (spec["name"] in only or any(s in only for s in spec["sweeps"])
            or ("headline" in only and spec["name"].startswith("headline")))


def series_for(spec, variants):
    """[(series name, extra batch args)] for a set."""
    out = [("gpustar", [])] + list(variants.items())
    if spec["name"] in ("base18", "headline10"):
        out += list(DOUBLE_STARS.items())
    return out


# ---------------------------------------------------------------------------------------------
# Computing one set
# ---------------------------------------------------------------------------------------------

class SetRunner:
    """Makes sure DIR/<set>/ holds frames' truth, gpustar records and scores for every series,
    and cedar results, computing only what is missing."""

    def __init__(self, ctx, spec):
        self.ctx, self.spec = ctx, spec
        self.dir = ctx.out / spec["name"]
        self.frames = self.dir / "frames"
        self.stamp_path = self.dir / "set.json"
        self.name = spec["name"]

    # -- state ----------------------------------------------------------------------------------
    def wanted_stamp(self):
        return {"params": self.spec["params"], "frames": self.spec["frames"], "seed": self.spec["seed"]}

    def stamp(self):
        return read_json(self.stamp_path, {})

    def frame_files(self):
        return [json.loads(l)["file"] for l in open(self.frames / "truth.jsonl") if l.strip()]

    def pngs_complete(self):
        if count_lines(self.frames / "truth.jsonl") != self.spec["frames"]:
            return False
        return all((self.frames / f).exists() for f in self.frame_files())

    def series_done(self, series, extra):
        meta = read_json(self.dir / f"{series}.meta.json", {})
        return (meta.get("extra_args") == extra and meta.get("frames") == self.spec["frames"]
                and count_lines(self.dir / f"{series}.jsonl") == self.spec["frames"])

    def cedar_wanted(self):
        n = self.spec["frames"]
        return min(self.ctx.args.cedar_frames, n) if self.ctx.args.cedar_frames else n

    def cedar_done(self):
        meta = read_json(self.dir / "cedar.meta.json", {})
        return meta.get("frames", 0) >= self.cedar_wanted() and count_lines(self.dir / "cedar.jsonl") == meta["frames"]

    # -- steps ----------------------------------------------------------------------------------
    def run(self):
        self.dir.mkdir(parents=True, exist_ok=True)
        if {k: self.stamp().get(k) for k in ("params", "frames", "seed")} != self.wanted_stamp():
            if any(self.dir.iterdir()):
                log(f"{self.name}: parameters or frame count changed; starting the set afresh")
            self.wipe()
        todo = [(s, e) for s, e in series_for(self.spec, self.ctx.variants)
                if self.ctx.args.redo_gpustar or not self.series_done(s, e)]
        need_cedar = self.ctx.cedar_python is not None and not self.cedar_done()
        if not todo and not need_cedar:
            log(f"{self.name}: complete, reusing")
            self.score_missing()
            return False
        if not self.pngs_complete() and not self.simulate():
            return True
        for series, extra in todo:
            self.batch(series, extra)
        self.score_missing()
        if need_cedar:
            self.cedar()
        if not self.ctx.args.keep_frames:
            for p in self.frames.glob("sim_*.png"):
                p.unlink()
        return True

    def wipe(self):
        # The directory is this script's own (DIR/<set>); remove only what it writes.
        for p in self.dir.iterdir():
            if p.is_dir() and p.name == "frames":
                shutil.rmtree(p)
            elif p.suffix in (".json", ".jsonl", ".part", ".txt") or p.name.startswith("cedar_"):
                p.unlink()
        write_json(self.stamp_path, self.wanted_stamp())

    def simulate(self):
        p, n = self.spec["params"], self.spec["frames"]
        cmd = [self.ctx.gpustar, "simulate", "--out", self.frames, "-n", n, "--fov-deg", p["fov"],
               "--mag-limit", p["mag"], "--false-stars", p["false"], "--hot-pixels", p["hot"],
               "--seed", self.spec["seed"]]
        if p["noise"] > 0:
            cmd += ["--centroid-noise-px", p["noise"]]
        log(f"{self.name}: simulate {n} frames (FOV {p['fov']:g} deg, Hp <= {p['mag']:g}, "
            f"{p['false']} false stars, {p['hot']} hot pixels, noise {p['noise']:g} px, seed {self.spec['seed']})")
        if self.frames.exists():
            for q in self.frames.glob("sim_*.png"):
                q.unlink()
        rc, _, err, dt = run(cmd)
        if rc != 0:
            why = bvc.tail(err, 5)
            if "--centroid-noise-px" in err:
                why = ("this gpustar binary has no `simulate --centroid-noise-px` yet: rebuild gpustar "
                       f"and rerun with `--only centroid_noise` ({why})")
            (self.dir / "error.txt").write_text(f"gpustar simulate failed (exit {rc}): {why}\n")
            log(f"{self.name}: FAILED: gpustar simulate exit {rc}: {why}")
            return False
        (self.dir / "error.txt").unlink(missing_ok=True)
        digest = hashlib.sha256((self.frames / "truth.jsonl").read_bytes()).hexdigest()
        stamp = self.stamp()
        if stamp.get("truth_sha256") not in (None, digest):
            # The simulator changed since the stored results: they are about other frames.
            log(f"{self.name}: regenerated frames differ from the stored truth; dropping old results")
            for q in self.dir.glob("*.jsonl"):
                q.unlink()
            for q in self.dir.glob("*.meta.json"):
                q.unlink()
        stamp.update(truth_sha256=digest, simulate_s=dt)
        write_json(self.stamp_path, stamp)
        log(f"{self.name}: simulate done in {dt:.1f} s ({1e3 * dt / n:.1f} ms/frame)")
        return True

    def batch_args(self, extra):
        camera = self.frames / "camera.toml"
        args = ["--camera", camera, "--backend", "cpu", "-q"]
        if "mag_limit" not in camera.read_text() and "--mag-limit" not in extra:
            args += ["--mag-limit", self.spec["params"]["mag"]]  # older binaries: no mag_limit there
        return args + extra

    def batch(self, series, extra):
        out = self.dir / f"{series}.jsonl"
        args = self.batch_args(extra)
        first = self.frames / self.frame_files()[0]
        run([self.ctx.gpustar, "solve", first, *args])  # warm-up: builds the distance-table cache
        log(f"{self.name}: gpustar batch [{series}] {' '.join(extra)}")
        part = Path(str(out) + ".part")
        rc, _, err, wall = run([self.ctx.gpustar, "batch", self.frames, *args, "-o", part])
        if rc not in (0, 1) or count_lines(part) != self.spec["frames"]:
            msg = f"gpustar batch [{series}] exited {rc}: {bvc.tail(err, 5)}"
            (self.dir / f"{series}.error.txt").write_text(msg + "\n")
            log(f"{self.name}: FAILED: {msg}")
            return
        part.replace(out)
        (self.dir / f"{series}.error.txt").unlink(missing_ok=True)
        (self.dir / f"{series}.eval.json").unlink(missing_ok=True)
        write_json(self.dir / f"{series}.meta.json", {
            "extra_args": extra, "frames": self.spec["frames"], "wall_s": wall, "exit": rc,
            "command": " ".join(shlex.quote(str(a)) for a in ["gpustar", "batch", "DIR", *args, "-o", out.name])})
        n = self.spec["frames"]
        log(f"{self.name}: batch [{series}] done in {wall:.1f} s ({n / wall:.1f} frames/s)")

    def score_missing(self):
        """`gpustar evaluate --per-frame` for every series whose scores are missing."""
        for series, _ in series_for(self.spec, self.ctx.variants):
            rec, ev = self.dir / f"{series}.jsonl", self.dir / f"{series}.eval.json"
            if rec.exists() and not ev.exists():
                evaluate(self.ctx.gpustar, self.frames / "truth.jsonl", rec, ev, self.spec["params"])

    def cedar(self):
        n = self.cedar_wanted()
        files = self.frame_files()[:n]
        workers = min(2, n)
        log(f"{self.name}: cedar-solve on {n} frames, {workers} workers")
        procs = []
        for k in range(workers):
            lst, part = self.dir / f"cedar_files_{k}.txt", self.dir / f"cedar_part_{k}.jsonl"
            lst.write_text("\n".join(files[k::workers]) + "\n")
            cmd = [self.ctx.cedar_python, Path(__file__).resolve(), "--cedar-worker", "--frames-dir", self.frames,
                   "--files-list", lst, "--fov", self.spec["params"]["fov"], "--worker-out", part]
            procs.append(subprocess.Popen([str(c) for c in cmd], stdout=subprocess.DEVNULL,
                                          stderr=subprocess.PIPE, text=True))
        t0 = time.perf_counter()
        errs = [(p.wait(), p.stderr.read()) for p in procs]
        wall = time.perf_counter() - t0
        if any(rc != 0 for rc, _ in errs):
            msg = "; ".join(f"worker {k} exit {rc}: {bvc.tail(e, 5)}" for k, (rc, e) in enumerate(errs) if rc)
            (self.dir / "cedar.error.txt").write_text(msg + "\n")
            log(f"{self.name}: FAILED: cedar-solve: {msg}")
            return
        records, summaries = {}, []
        for k in range(workers):
            lines = bvc.read_jsonl(self.dir / f"cedar_part_{k}.jsonl")
            summaries.append(lines[-1]["summary"])
            records.update((r["file"], r) for r in lines[:-1])
        with open(self.dir / "cedar.jsonl", "w") as f:
            for name in files:
                f.write(json.dumps(records[name]) + "\n")
        for k in range(workers):
            (self.dir / f"cedar_part_{k}.jsonl").unlink()
            (self.dir / f"cedar_files_{k}.txt").unlink()
        (self.dir / "cedar.error.txt").unlink(missing_ok=True)
        loop_s = max(s["end"] for s in summaries) - min(s["start"] for s in summaries)
        write_json(self.dir / "cedar.meta.json", {
            "frames": n, "workers": workers, "loop_s": loop_s, "process_wall_s": wall,
            "worker_summaries": summaries})
        log(f"{self.name}: cedar done: loop {loop_s:.1f} s ({n / loop_s:.2f} frames/s), process wall {wall:.1f} s")


def evaluate(gpustar, truth_path, records_path, out_path, params):
    """Run `gpustar evaluate --per-frame` with the set's tolerances; store {"frames": [...],
    "summary": {...}}."""
    tol_deg, id_tol = tolerances(params)
    rc, out, err, _ = run([gpustar, "evaluate", "--truth", truth_path, records_path, "--per-frame",
                           "--tolerance-deg", tol_deg, "--id-tolerance-px", id_tol])
    if rc != 0:
        log(f"FAILED: gpustar evaluate {records_path}: exit {rc}: {bvc.tail(err, 3)}")
        return
    frames, rest = [], []
    for line in out.splitlines():
        (frames if line.startswith('{"file"') else rest).append(line)
    write_json(out_path, {"frames": [json.loads(l) for l in frames], "summary": json.loads("\n".join(rest))})


# ---------------------------------------------------------------------------------------------
# Scoring: per-frame rows and metrics (the same for gpustar and cedar)
# ---------------------------------------------------------------------------------------------

def gpustar_rows(set_dir, series, truth):
    """Per-frame rows from evaluate's per-frame lines (correct_ids / identify_ms filled in from
    the records when this evaluate does not print them)."""
    ev = read_json(set_dir / f"{series}.eval.json")
    if ev is None:
        return None
    recs = {r["file"]: r for r in bvc.read_jsonl(set_dir / f"{series}.jsonl")}
    rows = []
    for v in ev["frames"]:
        r = recs.get(v["file"], {})
        n_matches = len(r.get("matches") or [])
        rows.append({
            "file": v["file"], "stars_in_view": v.get("stars_in_view", len(truth[v["file"]]["stars"])),
            "solved": v["status"] == "solved", "correct": bool(v["correct"]),
            "error_arcsec": v.get("error_arcsec"), "false_ids": v.get("false_ids", 0),
            "correct_ids": v.get("correct_ids", n_matches - v.get("false_ids", 0)),
            "identify_ms": v.get("identify_ms", (r.get("timing_ms") or {}).get("identify"))})
    return rows


def cedar_id_ok(m, t, id_tol):
    """The criterion of `gpustar evaluate`: a star of the truth list must be within ID_TOL_PX of
    its true place; another star must be within ID_TOL_PX of where the truth attitude puts its
    catalog position."""
    ts = next((s for s in t["stars"] if star_key(s) == star_key(m)), None)
    if ts is not None:
        return math.hypot(ts["x"] - m["x"], ts["y"] - m["y"]) <= id_tol
    p = project(t, m["ra_deg"], m["dec_deg"])
    return p is not None and math.hypot(p[0] - m["x"], p[1] - m["y"]) <= id_tol


def cedar_rows(set_dir, truth, params):
    tol_deg, id_tol = tolerances(params)
    path = set_dir / "cedar.jsonl"
    if not path.exists():
        return None
    rows = []
    for r in bvc.read_jsonl(path):
        t = truth[r["file"]]
        row = {"file": r["file"], "stars_in_view": len(t["stars"]), "solved": r["status"] == "solved",
               "correct": False, "error_arcsec": None, "false_ids": 0, "correct_ids": 0,
               "identify_ms": r.get("t_solve_ms"), "centre_roll_ok": False}
        if row["solved"]:
            rot = rotation_from_radec_roll(r["ra_deg"], r["dec_deg"], r["roll_deg"])
            err = attitude_error_deg(rot, t["rotation_matrix"])
            row["error_arcsec"] = err * 3600
            row["correct"] = err <= tol_deg
            # bench_vs_cedar.py's criterion, as a cross-check: centre and roll within TOL_DEG.
            row["centre_roll_ok"] = (bvc.sep_deg(r["ra_deg"], r["dec_deg"], t["ra_deg"], t["dec_deg"]) < TOL_DEG
                                     and bvc.roll_diff_deg(r["roll_deg"], t["roll_tetra3_deg"]) < TOL_DEG)
            for m in r["matches"]:
                if cedar_id_ok(m, t, id_tol):
                    row["correct_ids"] += 1
                else:
                    row["false_ids"] += 1
        rows.append(row)
    return rows


def metrics(rows, seconds):
    """Every number a chart or table shows, from per-frame rows."""
    n = len(rows)
    avail = sum(r["correct"] and r["correct_ids"] >= 2 and r["false_ids"] == 0 for r in rows)
    wrong = sum(r["solved"] and not r["correct"] for r in rows)
    errs = sorted(r["error_arcsec"] for r in rows if r["correct"])
    hist = [sum(min(r["false_ids"], 3) == k for r in rows) for k in range(4)]
    frac = [r["correct_ids"] / r["stars_in_view"] for r in rows if r["stars_in_view"] > 0]
    return {
        "frames": n, "solved": sum(r["solved"] for r in rows), "correct": sum(r["correct"] for r in rows),
        "available": avail, "availability_pct": pct(avail, n), "wrong": wrong, "wrong_pct": pct(wrong, n),
        "frames_with_false_ids": n - hist[0], "frames_with_false_ids_pct": pct(n - hist[0], n),
        "false_id_hist": {"0": hist[0], "1": hist[1], "2": hist[2], "3+": hist[3]},
        "false_id_hist_pct": {k: pct(v, n) for k, v in zip(("0", "1", "2", "3+"), hist)},
        "median_error_arcsec": quantile(errs, 0.5), "p90_error_arcsec": quantile(errs, 0.9),
        "mean_fraction_identified": sum(frac) / len(frac) if frac else None,
        "seconds": seconds, "frames_per_s": n / seconds if seconds else None,
    }


def stars_in_view_stats(truths):
    counts = sorted(len(t["stars"]) for t in truths)
    n = len(counts)
    return {"frames": n, "mean": sum(counts) / n, "p10": quantile(counts, 0.1), "median": quantile(counts, 0.5),
            "p90": quantile(counts, 0.9), "min": counts[0], "max": counts[-1],
            "ge4_pct": pct(sum(c >= 4 for c in counts), n), "counts": counts}


BINS = [0, 4, 6, 8, 10, 12, 14, 16, 18, 20, 23, 26, 30, 35, 40, 45, 50, 60, 80, 1000]


def binned(rows, value, min_count=3):
    """[(mean stars in view, mean value, median value, p90 value, frames)] per stars-in-view bin."""
    out = []
    for lo, hi in zip(BINS, BINS[1:]):
        sel = [r for r in rows if lo <= r["stars_in_view"] < hi and value(r) is not None]
        if len(sel) < min_count:
            continue
        vals = sorted(value(r) for r in sel)
        out.append({"stars_in_view": sum(r["stars_in_view"] for r in sel) / len(sel), "bin": [lo, hi - 1],
                    "mean": sum(vals) / len(vals), "median": quantile(vals, 0.5), "p90": quantile(vals, 0.9),
                    "frames": len(sel)})
    return out


def collect(ctx, plan):
    """Score every set found in DIR: {set: {...}} with metrics per series."""
    sets = {}
    for name, spec in plan.items():
        d = ctx.out / name
        truth_path = d / "frames" / "truth.jsonl"
        entry = {"params": spec["params"], "frames_planned": spec["frames"], "seed": spec["seed"],
                 "sweeps": spec["sweeps"], "series": {}, "errors": []}
        sets[name] = entry
        for err in sorted(d.glob("*error.txt")) if d.exists() else []:
            entry["errors"].append(err.read_text().strip())
        stamp = read_json(d / "set.json", {})
        # Report what the directory holds for these parameters, whatever its frame count.
        if not truth_path.exists() or stamp.get("params") != spec["params"]:
            continue
        entry["frames_planned"] = stamp.get("frames")
        truths = bvc.read_jsonl(truth_path)
        truth = {t["file"]: t for t in truths}
        entry["stars_in_view"] = stars_in_view_stats(truths)
        entry["roll_check_max_abs"] = check_roll_convention(truths)
        entry["simulate_s"] = stamp.get("simulate_s")
        entry["rows"] = {}
        for series, _ in series_for(spec, ctx.variants):
            rows = gpustar_rows(d, series, truth)
            if rows is None:
                continue
            meta = read_json(d / f"{series}.meta.json", {})
            entry["series"][series] = metrics(rows, meta.get("wall_s"))
            entry["series"][series]["command"] = meta.get("command")
            entry["rows"][series] = rows
        rows = cedar_rows(d, truth, spec["params"])
        if rows is not None:
            meta = read_json(d / "cedar.meta.json", {})
            m = metrics(rows, meta.get("loop_s"))
            m["workers"] = meta.get("workers")
            m["process_wall_s"] = meta.get("process_wall_s")
            m["centre_roll_disagreements"] = sum(r["correct"] != r["centre_roll_ok"] for r in rows)
            summaries = meta.get("worker_summaries") or [{}]
            m["versions"] = summaries[0].get("versions")
            m["database_properties"] = summaries[0].get("database_properties")
            m["statuses"] = {}
            for r in bvc.read_jsonl(d / "cedar.jsonl"):
                m["statuses"][r["cedar_status"]] = m["statuses"].get(r["cedar_status"], 0) + 1
            entry["series"][CEDAR] = m
            entry["rows"][CEDAR] = rows
    return sets


def series_order(ctx):
    return ["gpustar"] + list(ctx.variants) + [CEDAR]


def sweep_points(sets, sweep):
    """[(x, set name)] sorted by x, for the sets of a sweep that have results."""
    pts = [(s["sweeps"][sweep], name) for name, s in sets.items() if sweep in s["sweeps"] and s["series"]]
    return sorted(pts)


# ---------------------------------------------------------------------------------------------
# Charts (matplotlib, Agg)
# ---------------------------------------------------------------------------------------------

STYLE = {"gpustar": dict(color="C0", marker="o", linestyle="-"),
         CEDAR: dict(color="C1", marker="s", linestyle="--")}


def style(series, k=0):
    return STYLE.get(series, dict(color=f"C{(k + 2) % 10}", marker="^v<>Dp*"[k % 7], linestyle="-."))


def plt():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as pyplot
    pyplot.rcParams.update({"figure.dpi": 110, "axes.grid": True, "grid.alpha": 0.3, "font.size": 9})
    return pyplot


def save_chart(p, fig, path):
    """Lay out, write and close a finished chart."""
    fig.tight_layout()
    fig.savefig(path)
    p.close(fig)
    return True


def finish_chart(p, fig, ax, drawn, path, xlabel, ylabel, title, legend_size):
    """Label, write and close a one-panel chart; False (nothing written) when nothing was drawn."""
    if not drawn:
        p.close(fig)
        return False
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=legend_size)
    return save_chart(p, fig, path)


def chart_stars_in_view(sets, path):
    p = plt()
    fig, ax = p.subplots(figsize=(7, 3.6))
    drawn = False
    for name, fov, color, seed_range in (("headline10", 10, "C2", (6, 13)), ("base18", 18, "C0", (22, 30))):
        s = sets.get(name, {}).get("stars_in_view")
        if not s:
            continue
        counts = s["counts"]
        ax.hist(counts, bins=range(0, max(counts) + 2), alpha=0.55, color=color, density=True,
                label=f"{fov}° FOV ({s['frames']} frames; median {s['median']})")
        ax.axvspan(seed_range[0], seed_range[1] + 1, color=color, alpha=0.12,
                   label=f"seed 000 Fig. 6 at {fov}°: {seed_range[0]}–{seed_range[1]}")
        drawn = True
    return finish_chart(p, fig, ax, drawn, path,
                        "catalog stars in view (Hp ≤ 6, centre on the 1024×1024 frame)",
                        "fraction of frames", "Stars in view", 8)


def chart_sweep(ctx, sets, sweep, path):
    param, _, label = SWEEPS[sweep]
    pts = sweep_points(sets, sweep)
    if not pts:
        return False
    p = plt()
    fig, axes = p.subplots(2, 2, figsize=(10, 7))
    panels = [(axes[0][0], "availability_pct", "availability (%)", None),
              (axes[0][1], "wrong_pct", "wrong attitude (%, solid); frames with ≥1 false ID (%, dotted)",
               "frames_with_false_ids_pct"),
              (axes[1][0], "median_error_arcsec", "attitude error of correct frames (arcsec): median, p90 dotted",
               "p90_error_arcsec"),
              (axes[1][1], "frames_per_s", "frames/s (log; gpustar: 2 cores, cedar: 2 workers)", None)]
    for k, series in enumerate(series_order(ctx)):
        xs = [(x, sets[n]["series"][series]) for x, n in pts if series in sets[n]["series"]]
        if not xs:
            continue
        st = style(series, k)
        n_label = sorted({m["frames"] for _, m in xs})
        lab = f"{series_label(series)} ({'/'.join(map(str, n_label))} frames per point)"
        for ax, key, _, second in panels:
            data = [(x, m[key]) for x, m in xs if m[key] is not None]
            if data:
                ax.plot(*zip(*data), label=lab, **st)
            if second:
                data2 = [(x, m[second]) for x, m in xs if m[second] is not None]
                if data2:
                    ax.plot(*zip(*data2), color=st["color"], marker=st["marker"], linestyle=":",
                            markersize=3, alpha=0.8)
    for ax, key, title, _ in panels:
        ax.set_xlabel(label)
        ax.set_title(title, fontsize=9)
        if key == "frames_per_s":
            ax.set_yscale("log")
        elif key.endswith("_pct"):
            ax.set_ylim(bottom=0, top=101 if key == "availability_pct" else None)
        else:
            ax.set_ylim(bottom=0)
    axes[0][0].legend(fontsize=8, loc="lower left")
    fig.suptitle(f"Sweep of {label} (base: 18° FOV, Hp ≤ 6, 3 false stars, 5 hot pixels, no centroid noise)")
    return save_chart(p, fig, path)


def id_sets(sets):
    return [(name, lab) for name, lab in (("headline10", "10°"), ("base18", "18°")) if sets.get(name, {}).get("rows")]


def binned_lines(ctx, sets, select, value):
    """Per (set at 10° and 18°, series) with rows: (set label, series, rows, bins of `value` by
    stars in view, plot style: open markers at 10°). `select` filters the rows first."""
    for name, lab in id_sets(sets):
        for k, series in enumerate(series_order(ctx)):
            rows = sets[name]["rows"].get(series)
            if not rows:
                continue
            b = binned([r for r in rows if select(r)], value)
            if not b:
                continue
            st = dict(style(series, k))
            if lab == "10°":
                st["markerfacecolor"] = "white"
            yield lab, series, rows, b, st


def chart_identified(ctx, sets, path):
    p = plt()
    fig, ax = p.subplots(figsize=(7.5, 4))
    drawn = False
    lines = binned_lines(ctx, sets, lambda r: r["stars_in_view"] > 0,
                         lambda r: r["correct_ids"] / r["stars_in_view"])
    for lab, series, rows, b, st in lines:
        ax.plot([x["stars_in_view"] for x in b], [100 * x["mean"] for x in b],
                label=f"{series_label(series)}, {lab} ({len(rows)} frames)", **st)
        drawn = True
    ax.set_ylim(0, 105)
    return finish_chart(p, fig, ax, drawn, path, "catalog stars in view (bin mean)",
                        "stars identified correctly / stars in view (%, bin mean)",
                        "Fraction of the stars in view identified (cf. seed 000 Fig. 12); "
                        "open markers: 10° FOV", 8)


def chart_identify_time(ctx, sets, path):
    p = plt()
    fig, ax = p.subplots(figsize=(7.5, 4))
    drawn = False
    for lab, series, _, b, st in binned_lines(ctx, sets, lambda r: True, lambda r: r["identify_ms"]):
        what = "T_solve" if series == CEDAR else "identify"
        xs = [x["stars_in_view"] for x in b]
        ax.plot(xs, [x["median"] for x in b], label=f"{series_label(series)} {what}, {lab} (median; p90 dotted)", **st)
        ax.plot(xs, [x["p90"] for x in b], color=st["color"], linestyle=":", alpha=0.8)
        drawn = True
    ax.set_yscale("log")
    return finish_chart(p, fig, ax, drawn, path, "catalog stars in view (bin mean)",
                        "identification time per frame (ms, log)",
                        "Identification time vs stars in view (cf. seed 000 Fig. 9); "
                        "open markers: 10° FOV", 7)


def false_id_groups(sets):
    """[(set label, [(handling label, metrics)])] for the double-star chart and table."""
    out = []
    for name, lab in (("base18", "18° base"), ("headline10", "10° headline")):
        s = sets.get(name, {}).get("series", {})
        bars = [(h, s[k]) for h, k in (("merge (default)", "gpustar"), ("drop", "ds_drop"), ("keep", "ds_keep"),
                                        (CEDAR, CEDAR)) if k in s]
        if bars:
            out.append((lab, bars))
    return out


def chart_false_ids(sets, path):
    groups = false_id_groups(sets)
    if not groups:
        return False
    p = plt()
    fig, axes = p.subplots(1, len(groups), figsize=(5 * len(groups), 3.8), squeeze=False)
    for ax, (lab, bars) in zip(axes[0], groups):
        bottom = [0.0] * len(bars)
        for k, color in (("1", "C1"), ("2", "C3"), ("3+", "C4")):
            vals = [m["false_id_hist_pct"][k] for _, m in bars]
            ax.bar(range(len(bars)), vals, bottom=bottom, color=color, label=f"{k} false ID{'' if k == '1' else 's'}")
            bottom = [b + v for b, v in zip(bottom, vals)]
        for i, (_, m) in enumerate(bars):
            ax.text(i, bottom[i], f"{m['false_id_hist_pct']['0']:.2f} %\nwithout", ha="center", va="bottom", fontsize=7)
        ax.set_xticks(range(len(bars)))
        ax.set_xticklabels([f"{h}\n{m['frames']} frames" for h, m in bars], fontsize=8)
        ax.set_ylabel("frames with false IDs (% of all frames)")
        ax.set_ylim(0, max(bottom + [0.1]) * 1.35)
        ax.set_title(f"{lab}: double-star handling", fontsize=9)
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle("Frames with 1, 2, 3+ false star IDs\n(label: share without; seed 000: 94.38 % → 99.98 %)",
                 fontsize=9)
    return save_chart(p, fig, path)


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------

def environment(ctx):
    """Where and with what this invocation ran (a computing run appends it to DIR/runs.jsonl)."""
    def git(*a):
        rc, out, _, _ = run(["git", "-C", REPO, *a])
        return out.strip() if rc == 0 else None
    version = None
    if ctx.gpustar and Path(ctx.gpustar).exists():
        version = run([ctx.gpustar, "--version"])[1].strip()
    dirty = git("status", "--porcelain", "--untracked-files=no")
    src = Path(ctx.args.gpustar)
    return {
        "command": " ".join(shlex.quote(a) for a in [sys.executable, *sys.argv]),
        "date": time.strftime("%Y-%m-%d %H:%M:%S %z"),
        "cpus": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(),
        "gpustar_version": version, "gpustar_binary": str(src.resolve()),
        "gpustar_built": time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(src.stat().st_mtime)) if src.exists() else None,
        "git_commit": git("rev-parse", "--short", "HEAD"),
        "git_dirty": None if dirty is None else bool(dirty),
        "cedar": ctx.cedar_versions, "cedar_note": ctx.cedar_note, "other_cpu_note": ctx.other_cpu_note,
        "only": ctx.args.only or None,
    }


def run_line(e):
    """One computing run, for the report header."""
    c = e.get("cedar")
    cedar = (f"cedar-solve {c.get('cedar-solve')} (numpy {c.get('numpy')}, Pillow {c.get('Pillow')}, scipy "
             f"{c.get('scipy')}, Python {c.get('python')}, {c.get('executable')})" if c else
             f"cedar-solve {e.get('cedar_note') or 'not run'}")
    return (f"- {e['date']}: `{e['command']}`  \n  {e['gpustar_version'] or 'gpustar ?'} (copy of "
            f"{e['gpustar_binary']}, built {e['gpustar_built']}), git {e['git_commit']}"
            f"{' + uncommitted changes' if e['git_dirty'] else ''}; {cedar}"
            + (f"; {e['other_cpu_note']}" if e.get("other_cpu_note") else ""))


def series_label(series):
    return {"gpustar": "gpustar", CEDAR: "cedar-solve"}.get(series, f"gpustar [{series}]")


def headline_rows(ctx, sets):
    """[(what, {series: text}, seed 000)] for the headline table."""
    cols = series_order(ctx)
    h10, h18, b18 = (sets.get(n, {}) for n in ("headline10", "headline18f20", "base18"))
    s18 = b18.get("stars_in_view") or h18.get("stars_in_view")

    def per(entry, fn):
        return {c: fn(entry["series"][c]) for c in cols if c in entry.get("series", {})}

    rows = []
    if h10.get("stars_in_view"):
        s = h10["stars_in_view"]
        rows.append(("10°: frames with ≥ 4 catalog stars in view",
                     {"truth": f"{s['ge4_pct']:.2f} % ({s['frames']})"}, "–"))
        rows.append(("10°: stars in view, p10–p90 (median)", {"truth": f"{s['p10']}–{s['p90']} ({s['median']})"},
                     SEED000["stars10"]))
    if s18:
        rows.append(("18°: stars in view, p10–p90 (median)", {"truth": f"{s18['p10']}–{s18['p90']} ({s18['median']})"},
                     SEED000["stars18"]))
    if h10.get("series"):
        rows.append(("10°: availability", per(h10, lambda m: f"{m['availability_pct']:.2f} % ({m['frames']})"), "–"))
        rows.append(("10°: wrong attitude", per(h10, lambda m: f"{m['wrong_pct']:.2f} % ({m['wrong']})"), "–"))
        rows.append(("10°: frames with ≥ 1 false ID",
                     per(h10, lambda m: f"{m['frames_with_false_ids_pct']:.2f} %"), "–"))
    if h18.get("series"):
        rows.append(("18°, 20 false stars, 20 hot pixels: availability",
                     per(h18, lambda m: f"{m['availability_pct']:.2f} % ({m['frames']})"), "–"))
        rows.append(("18°, 20 false + 20 hot: wrong attitude",
                     per(h18, lambda m: f"{m['wrong_pct']:.2f} % ({m['wrong']})"), "–"))
        rows.append(("18°, 20 false + 20 hot: median attitude error (target ≤ 5″)",
                     per(h18, lambda m: f"{fmt(m['median_error_arcsec'], '.2f', '″')} (p90 "
                                        f"{fmt(m['p90_error_arcsec'], '.1f', '″')})"), "–"))
    for lab, bars in false_id_groups(sets):
        for h, m in bars:
            if h == CEDAR:
                continue
            rows.append((f"{lab}: frames without a false ID, double stars {h}",
                         {"gpustar": f"{m['false_id_hist_pct']['0']:.2f} %"},
                         {"merge (default)": f"{SEED000['no_false_after']} % (handled)",
                          "drop": f"{SEED000['no_false_after']} % (seed 000 drops)",
                          "keep": f"{SEED000['no_false_before']} % (not handled)"}[h]))
        if any(h == CEDAR for h, _ in bars):
            m = dict(bars)[CEDAR]
            rows.append((f"{lab}: frames without a false ID", {CEDAR: f"{m['false_id_hist_pct']['0']:.2f} %"}, "–"))
    return rows


def md_table(header, rows, align=None):
    align = align or ["---"] + ["---:"] * (len(header) - 1)
    out = ["| " + " | ".join(header) + " |", "|" + "|".join(align) + "|"]
    out += ["| " + " | ".join(str(c) for c in r) + " |" for r in rows]
    return out


def sweep_table(ctx, sets, sweep):
    pts = sweep_points(sets, sweep)
    cols = [c for c in series_order(ctx) if any(c in sets[n]["series"] for _, n in pts)]
    header = [SWEEPS[sweep][2]]
    for c in cols:
        short = series_label(c)
        header += [f"{short} avail.", "wrong", "false-ID frames", "median / p90 ″", "frames/s"]
    rows = []
    for x, n in pts:
        row = [f"{x:g}"]
        for c in cols:
            m = sets[n]["series"].get(c)
            if m is None:
                row += ["–"] * 5
                continue
            row += [f"{m['availability_pct']:.1f} % ({m['frames']})", f"{m['wrong_pct']:.1f} %",
                    f"{m['frames_with_false_ids_pct']:.1f} %",
                    f"{fmt(m['median_error_arcsec'], '.2f')} / {fmt(m['p90_error_arcsec'], '.1f')}",
                    fmt(m["frames_per_s"], ".1f")]
        rows.append(row)
    return md_table(header, rows)


def binned_table(ctx, sets, value, fmt_fn):
    lines = []
    for name, lab in id_sets(sets):
        for series in series_order(ctx):
            rows = sets[name]["rows"].get(series)
            if not rows:
                continue
            b = binned([r for r in rows if r["stars_in_view"] > 0], value)
            cells = ", ".join(f"{x['bin'][0]}–{x['bin'][1]}: {fmt_fn(x)} ({x['frames']})" for x in b)
            lines.append(f"- {series_label(series)}, {lab}: {cells}")
    return lines


def report(ctx, env, sets, charts):
    L = ["# gpustar accuracy and robustness study (issue 6)", ""]
    L += [f"- This report: `{env['command']}`, {env['date']}",
          f"- Machine: {env['cpus']} logical CPUs, {env['platform']}, Python {env['python']}",
          "", "Runs that computed the results in this directory (`runs.jsonl`; the last 10):", ""]
    runs = bvc.read_jsonl(ctx.out / "runs.jsonl") if (ctx.out / "runs.jsonl").exists() else []
    L += [run_line(e) for e in runs[-10:]] or ["- none"]
    L += ["", "## Definitions", "",
          f"- **availability**: the frame is solved, its attitude is within {TOL_DEG}° of the truth, it has ≥ 2 "
          "correct star IDs and no false ID.",
          f"- **wrong**: a solution is returned whose attitude is not within {TOL_DEG}° of the truth (share of all "
          "frames). Separately, **false-ID frames**: frames (of all) with ≥ 1 false star ID.",
          f"- **false ID**: an identified star that is not within {ID_TOL_PX:g} px of where the truth puts it (a "
          "star of the truth list: its drawn place; any other star: its catalog position under the true "
          "attitude). gpustar: `gpustar evaluate`; cedar-solve: the same test in this script on "
          "`matched_catID` (Hipparcos numbers, cedar's default database is `hip_main`), `matched_stars` and "
          "`matched_centroids` (moved by −0.5 px: tetra3 puts the top-left pixel centre at (0.5, 0.5)).",
          "- **centroid-noise sets**: the stars are drawn σ px off the places the truth keeps, so there a false ID "
          "is one more than 3 + 5σ px away and a correct attitude is within 0.1° × max(1, 4σ/px) (a correct "
          "solution's roll moves with the noise); the same for both solvers.",
          "- **attitude error**: the angle of the rotation between solved and true attitude (arcsec); median and "
          "p90 over correct frames. cedar's attitude is the rotation built from its RA, Dec, Roll with tetra3's "
          "roll convention; the same function rebuilt every truth rotation matrix from the truth's "
          f"ra/dec/roll_tetra3 to within {max((s.get('roll_check_max_abs') or 0) for s in sets.values()):.1e} "
          "(largest element difference over all frames).",
          "- **stars in view**: catalog stars (Hp ≤ the set's limit) whose centre is on the frame (truth.jsonl).",
          "- **frames/s**: gpustar = frames / wall seconds of the whole `gpustar batch --backend cpu` command (both "
          "cores; a one-frame `gpustar solve` before it builds the distance-table cache and is not counted); "
          "cedar-solve = frames / seconds of its frame loop (PIL load + `solve_from_image`), run as 2 worker "
          "processes in parallel (first loop start to last loop end), database load not counted.",
          "- cedar-solve call: `solve_from_image(image, fov_estimate=FOV, return_matches=True)`, all else default "
          "(tetra3's own centroiding, solve_timeout 5 s, database for 10–30° FOV: below 10° it is expected to fail). "
          "cedar solves the first frames of each set only when --cedar-frames says so; every table gives the "
          "frames each number rests on.",
          "- Sets: 1024×1024 frames of `gpustar simulate`, a different seed per set; base 18° FOV, Hp ≤ 6, 3 false "
          "stars, 5 hot pixels, no centroid noise; `gpustar batch` with the set's camera.toml (its `mag_limit` "
          "follows the simulated limit).", ""]
    # headline
    cols = series_order(ctx)
    L += ["## Headline", ""]
    hrows = headline_rows(ctx, sets)
    truth_rows = [[w, v["truth"], seed] for w, v, seed in hrows if "truth" in v]
    solver_rows = [[w, *(v.get(c, "–") for c in cols), seed] for w, v, seed in hrows if "truth" not in v]
    if truth_rows:
        L += md_table(["frames (from truth.jsonl)", "this study", "seed 000"], truth_rows) + [""]
    if solver_rows:
        L += md_table(["", *map(series_label, cols), "seed 000"], solver_rows)
    if not hrows:
        L.append("(no headline set has results yet)")
    L += ["", "Percentages are of all frames of the set; the number in parentheses is the frames (or count) "
          "it rests on. Stars in view: 10th–90th percentile (median).", ""]
    # stars in view
    if charts.get("stars_in_view"):
        L += ["## Stars in view", "", f"![stars in view]({charts['stars_in_view']})", ""]
        rows = []
        for n in ("headline10", "base18", "headline18f20"):
            v = sets.get(n, {}).get("stars_in_view")
            if v:
                rows.append([n, f"{sets[n]['params']['fov']:g}°", v["frames"], f"{v['mean']:.1f}",
                             f"{v['p10']}–{v['p90']}", f"{v['min']}–{v['max']}", f"{v['ge4_pct']:.2f} %"])
        L += md_table(["set", "FOV", "frames", "mean", "p10–p90", "min–max", "≥ 4 stars"], rows) + [""]
    # sweeps
    for sweep in SWEEPS:
        key = f"sweep_{sweep}"
        L += [f"## Sweep: {SWEEPS[sweep][2]}", ""]
        if not charts.get(key):
            L += ["(no results yet)", ""]
            continue
        L += [f"![{sweep}]({charts[key]})", ""] + sweep_table(ctx, sets, sweep)
        L += ["", "avail. = availability (frames it rests on); wrong = wrong attitude; false-ID frames = frames "
              "with ≥ 1 false ID; median / p90 ″ = attitude error of correct frames (arcsec).", ""]
        if sweep == "centroid_noise":
            L += ["At high centroid noise the 3 px ID test also flags right stars: the truth keeps the true "
                  "places, and a star drawn with Gaussian noise σ per axis lands more than 3 px away with "
                  "probability exp(−4.5/σ²) (1.1 % at σ = 1 px, 13.5 % at 1.5 px), which counts as a false ID "
                  "and makes the frame unavailable.", ""]
    # identification
    L += ["## Fraction of stars identified vs stars in view", ""]
    if charts.get("identified"):
        L += [f"![identified]({charts['identified']})", "",
              "Mean over the frames of each stars-in-view bin of correct IDs / stars in view (unsolved frames "
              "count 0); bin: mean (frames):", ""]
        L += binned_table(ctx, sets, lambda r: r["correct_ids"] / r["stars_in_view"], lambda x: f"{100 * x['mean']:.1f} %")
    else:
        L.append("(no results yet)")
    L += ["", "## Identification time vs stars in view", ""]
    if charts.get("identify_time"):
        L += [f"![identify time]({charts['identify_time']})", "",
              "gpustar: `timing_ms.identify` of each record (vote, verification, attitude and refinement, one "
              "thread, after detection); cedar-solve: its `T_solve` (pattern search and verification, after "
              "centroiding). Bin: median ms / p90 ms (frames):", ""]
        L += binned_table(ctx, sets, lambda r: r["identify_ms"], lambda x: f"{x['median']:.2f} / {x['p90']:.2f}")
    else:
        L.append("(no results yet)")
    L += ["", "## False IDs and double-star handling", ""]
    groups = false_id_groups(sets)
    if charts.get("false_ids"):
        L += [f"![false ids]({charts['false_ids']})", "",
              "`gpustar batch --double-stars merge` (default: catalog stars closer than 2 px become one at their "
              "photocentre), `drop` (seed 000's choice: both removed) and `keep`; share of all frames with 0, 1, 2, "
              "3+ false IDs (seed 000 Figs. 13/16: 94.38 % → 99.98 % frames without a false ID):", ""]
        rows = [[lab, h, m["frames"], *(f"{m['false_id_hist_pct'][k]:.2f} %" for k in ("0", "1", "2", "3+")),
                 f"{m['availability_pct']:.2f} %"] for lab, bars in groups for h, m in bars]
        L += md_table(["set", "handling", "frames", "0", "1", "2", "3+", "availability"], rows)
    else:
        L.append("(no results yet)")
    L += ["", "## Run time per step", "",
          "Seconds per frame, for estimating a full run (simulate: `gpustar simulate`, all cores; batch: one "
          "`gpustar batch` series; cedar: wall seconds of the 2 workers incl. process start and database load):", ""]
    rows = []
    for n, s in sets.items():
        if not s["series"] and not s.get("simulate_s"):
            continue
        g = s["series"].get("gpustar", {})
        cd = s["series"].get(CEDAR, {})
        sim_ms = 1e3 * s["simulate_s"] / s["frames_planned"] if s.get("simulate_s") else None
        rows.append([n, s["frames_planned"], fmt(sim_ms, ".1f"),
                     fmt(1e3 * g["seconds"] / g["frames"] if g.get("seconds") else None, ".2f"),
                     cd.get("frames", "–"),
                     fmt(1e3 * cd["process_wall_s"] / cd["frames"] if cd.get("process_wall_s") else None, ".1f")])
    L += md_table(["set", "frames", "simulate ms/frame", "batch ms/frame", "cedar frames", "cedar ms/frame"], rows)
    # notes
    notes = []
    for n, s in sets.items():
        notes += [f"{n}: {e}" for e in s["errors"]]
        m = s["series"].get(CEDAR)
        if m and m.get("centre_roll_disagreements"):
            notes.append(f"{n}: cedar-solve: {m['centre_roll_disagreements']} frames where the full-rotation "
                         "criterion and bench_vs_cedar.py's centre+roll criterion disagree")
    statuses = {n: s["series"][CEDAR]["statuses"] for n, s in sets.items() if CEDAR in s["series"]}
    if statuses:
        notes.append("cedar-solve statuses per set: " + "; ".join(
            f"{n} " + ", ".join(f"{k} {v}" for k, v in st.items()) for n, st in statuses.items()))
    worst = max((s.get("roll_check_max_abs") or 0) for s in sets.values())
    if worst > 1e-9:
        notes.append(f"**the roll conversion does not reproduce the truth's rotation matrices** (largest "
                     f"element difference {worst:.1e} > 1e-9): cedar's attitude errors are not trustworthy")
    missing = [n for n, s in sets.items() if not s["series"]]
    if missing:
        notes.append("sets without results in this directory: " + ", ".join(missing))
    for name, extra in ctx.variants.items():
        notes.append(f"variant {name}: `gpustar batch ... {' '.join(extra)}`")
    if notes:
        L += ["", "## Notes", ""] + [f"- {x}" for x in notes]
    return "\n".join(L) + "\n"


def write_outputs(ctx, plan, env):
    sets = collect(ctx, plan)
    charts = {}
    jobs = [("stars_in_view", lambda p: chart_stars_in_view(sets, p)),
            *[(f"sweep_{s}", (lambda s: lambda p: chart_sweep(ctx, sets, s, p))(s)) for s in SWEEPS],
            ("identified", lambda p: chart_identified(ctx, sets, p)),
            ("identify_time", lambda p: chart_identify_time(ctx, sets, p)),
            ("false_ids", lambda p: chart_false_ids(sets, p))]
    for key, fn in jobs:
        name = f"fig_{key}.png"
        if fn(ctx.out / name):
            charts[key] = name
    (ctx.out / "report.md").write_text(report(ctx, env, sets, charts))
    slim = {n: {k: v for k, v in s.items() if k != "rows"} for n, s in sets.items()}
    for s in slim.values():
        if "stars_in_view" in s:
            counts = s["stars_in_view"]["counts"]
            s["stars_in_view"] = {k: v for k, v in s["stars_in_view"].items() if k != "counts"}
            s["stars_in_view"]["histogram"] = {str(c): counts.count(c) for c in sorted(set(counts))}
    extra = {
        "fraction_identified": {f"{n}/{series}": binned([r for r in s["rows"][series] if r["stars_in_view"] > 0],
                                                         lambda r: r["correct_ids"] / r["stars_in_view"])
                                for n, s in sets.items() if n in ("headline10", "base18") for series in s.get("rows", {})},
        "identify_ms": {f"{n}/{series}": binned(s["rows"][series], lambda r: r["identify_ms"])
                        for n, s in sets.items() if n in ("headline10", "base18") for series in s.get("rows", {})},
        "headline": [{"what": w, "values": v, "seed000": s} for w, v, s in headline_rows(ctx, sets)],
    }
    write_json(ctx.out / "results.json", {"environment": env, "definitions": {
        "tolerance_deg": TOL_DEG, "id_tolerance_px": ID_TOL_PX}, "variants": ctx.variants, "charts": charts,
        "sets": slim, **extra})
    log(f"wrote {ctx.out / 'report.md'}, {ctx.out / 'results.json'} and {len(charts)} charts")


# ---------------------------------------------------------------------------------------------
# Main
# ---------------------------------------------------------------------------------------------

def parse_variants(specs):
    out = {}
    for s in specs:
        name, sep, rest = s.partition("=")
        if not sep or not re.fullmatch(r"[A-Za-z0-9_.-]+", name) or name in ("gpustar", "cedar", *DOUBLE_STARS):
            sys.exit(f"--variant {s!r}: expected NAME=ARGS with NAME of letters, digits, _ . - "
                     "(not gpustar, cedar, ds_drop, ds_keep)")
        out[name] = shlex.split(rest)
    return out


class Ctx:
    pass


def stored_variants(out):
    """{name: extra args} of the variant series found in DIR (for --report-only)."""
    found = {}
    for meta in sorted(out.glob("*/*.meta.json")):
        series = meta.name[: -len(".meta.json")]
        if series not in ("gpustar", "cedar", *DOUBLE_STARS):
            found.setdefault(series, read_json(meta, {}).get("extra_args", []))
    return found


def setup_cedar(ctx):
    """Probe --cedar-python; sets ctx.cedar_python (None = skip) and a note for the report."""
    ctx.cedar_versions, ctx.cedar_note, ctx.cedar_python = None, None, None
    py = ctx.args.cedar_python
    if not py:
        ctx.cedar_note = ("not run in this invocation: no --cedar-python and no $CEDAR_PYTHON (results already "
                          "in the directory are still shown)")
        return
    try:
        rc, out, err, _ = run([py, Path(__file__).resolve(), "--cedar-probe"])
    except OSError as e:
        rc, out, err = -1, "", str(e)
    if rc != 0:
        ctx.cedar_note = f"not run: {py} cannot run cedar-solve: {bvc.tail(err, 3)}"
        log(ctx.cedar_note)
        return
    ctx.cedar_versions = json.loads(out)
    ctx.cedar_python = py


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter, epilog=__doc__)
    ap.add_argument("--out", type=Path, help="study directory (required)")
    ap.add_argument("--gpustar", type=Path, default=REPO / "target" / "release" / "gpustar")
    ap.add_argument("--cedar-python", default=os.environ.get("CEDAR_PYTHON"),
                    help="Python with cedar-solve installed (default $CEDAR_PYTHON; else cedar is skipped)")
    ap.add_argument("--headline-frames", type=int, default=10000)
    ap.add_argument("--sweep-frames", type=int, default=1000)
    ap.add_argument("--cedar-frames", type=int, default=None, help="cedar solves the first N frames of each set")
    ap.add_argument("--only", default="", help="comma list of sets / sweeps / 'headline' to compute")
    ap.add_argument("--quick", action="store_true", help="20 frames everywhere (smoke test)")
    ap.add_argument("--keep-frames", action="store_true", help="keep the PNG frames")
    ap.add_argument("--report-only", action="store_true", help="only redraw report, charts and results.json")
    ap.add_argument("--redo-gpustar", action="store_true",
                    help="solve the selected sets again (new gpustar build); keep cedar's results")
    ap.add_argument("--variant", action="append", default=[], metavar="NAME=ARGS",
                    help='another gpustar batch series with extra args, e.g. vote30="--vote-stars 30"')
    # worker mode (internal)
    ap.add_argument("--cedar-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--cedar-probe", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--frames-dir", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--files-list", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--fov", type=float, help=argparse.SUPPRESS)
    ap.add_argument("--worker-out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.cedar_probe:
        return cedar_probe()
    if args.cedar_worker:
        return cedar_worker(args.frames_dir, args.files_list, args.fov, args.worker_out)

    if args.out is None:
        ap.error("--out DIR is required")
    if args.quick:
        args.headline_frames = args.sweep_frames = 20
    ctx = Ctx()
    ctx.args, ctx.out, ctx.variants = args, args.out.resolve(), parse_variants(args.variant)
    ctx.out.mkdir(parents=True, exist_ok=True)
    ctx.other_cpu_note = None
    plan = plan_sets(args)
    only = {s.strip() for s in args.only.split(",") if s.strip()}
    unknown = only - set(plan) - set(SWEEPS) - {"headline"}
    if unknown:
        sys.exit(f"--only: unknown names {sorted(unknown)}; sets: {', '.join(plan)}; sweeps: {', '.join(SWEEPS)}")

    snapshot = ctx.out / "gpustar-snapshot"
    if args.report_only:
        ctx.variants.update((k, v) for k, v in stored_variants(ctx.out).items() if k not in ctx.variants)
        ctx.gpustar = snapshot if snapshot.exists() else None
        ctx.cedar_versions, ctx.cedar_python = None, None
        ctx.cedar_note, ctx.other_cpu_note = None, None
        return write_outputs(ctx, plan, environment(ctx))

    if not args.gpustar.exists():
        sys.exit(f"{args.gpustar} not found: build it with `cargo build --release`, or pass --gpustar")
    shutil.copy2(args.gpustar, snapshot)  # a rebuild during the run cannot mix two versions
    ctx.gpustar = snapshot
    setup_cedar(ctx)
    cpu_before, t_before = bvc.cpu_seconds(), time.perf_counter()
    computed = False
    for name, spec in plan.items():
        if selected(spec, only):
            computed |= SetRunner(ctx, spec).run()
    cpu_after, wall = bvc.cpu_seconds(), time.perf_counter() - t_before
    if cpu_before and cpu_after and wall > 0:
        other = max(0.0, (cpu_after[0] - cpu_before[0]) - (cpu_after[1] - cpu_before[1]))
        busy = other > 0.05 * wall
        ctx.other_cpu_note = (f"{'**Warning**: ' if busy else ''}other processes used {other:.0f} CPU-seconds during "
                              f"the {wall:.0f} s of this invocation ({100 * other / wall:.0f} % of one core)"
                              + ("; rates are not clean." if busy else "."))
    env = environment(ctx)
    if computed:
        with open(ctx.out / "runs.jsonl", "a") as f:
            f.write(json.dumps(env) + "\n")
    write_outputs(ctx, plan, env)


if __name__ == "__main__":
    main()
