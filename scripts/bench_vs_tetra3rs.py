#!/usr/bin/env python3
"""Benchmark gpustar against tetra3rs side by side on the same frames: whole-process CPU and wall time.

    scripts/bench_vs_tetra3rs.py --db DB [--gpustar target/release/gpustar]
        [--t3bench target/release/t3bench] [--rounds 5] [--threads-all N]
        [--known-fov-error 0.01] [--t3-extractor default|fast] [--backend auto|cpu|gpu]
        [--out /tmp/bench_vs_tetra3rs] SET [SET ...]

    SET is DIR (known field: DIR/camera.toml) or DIR:LOW..HIGH (unknown field between LOW and
    HIGH degrees). DIR is a set written by scripts/sim_frames.py (FITS or 16-bit PNG), or
    rewritten by scripts/convert_set.py (8- or 16-bit PNG by PIL or OpenCV, JPEG): images,
    DIR/camera.toml and DIR/truth.jsonl (per frame: file, ra_deg, dec_deg, ...).

Example (the database is built once, outside the repository):

    (cd bench/tetra3rs && cargo build --release)   # into target/ (the repository's .cargo/config.toml)
    target/release/t3bench db --hip2 hip2.dat --min-fov-deg 8 --max-fov-deg 20 \\
        --epoch 2025 -o /tmp/t3_hip_8-20.db
    python3 scripts/sim_frames.py --out /tmp/sets/f18 -n 200 --fov-deg 18 --seed 11
    scripts/bench_vs_tetra3rs.py --db /tmp/t3_hip_8-20.db /tmp/sets/f18 /tmp/sets/f18:8..20

What runs, per set and per thread count (1, and --threads-all, default os.cpu_count()):
  * gpustar: `gpustar batch DIR --camera DIR/camera.toml -j T -q -o OUT` (known field) or
    `gpustar batch DIR --fov-deg LOW..HIGH -j T -q -o OUT` (unknown field), with
    `--backend` (default auto, gpustar's own default: the records name the backend used).
  * tetra3rs: `t3bench solve --db DB --fov-deg F --fov-max-error-deg E --threads T DIR`
    (bench/tetra3rs: tetra3 0.14.0 from crates.io; decode, tetra3's own centroid extractor,
    solve_from_centroids). Known field: F = the camera's fov_x_deg, E = F * --known-fov-error
    (0 leaves E unset: tetra3's default, no FOV filter). Unknown field: F = (LOW+HIGH)/2,
    E = (HIGH-LOW)/2.
  * Before the timed rounds, one untimed warm-up of each on the first frame (gpustar builds
    and caches its distance table then, as on any machine that has solved before; both get
    the frames and database into the page cache).
  * --rounds R rounds, interleaved (gpustar, tetra3rs, gpustar, tetra3rs, ...). Each round
    measures the whole subprocess: process start, catalog or database load, decoding,
    detection, identification, writing the records; its CPU time (user + system, from
    os.times() of the waited-for child) and its wall time (time.perf_counter()). The median
    of the rounds counts, CPU time first: wall time on a shared machine swings 2x while CPU
    time moves little. The records scored are those of the round with the median CPU time.
  * Per stage, from the records of that round: the median over frames of gpustar's
    timing_ms (decode, detect, identify) and of t3bench's decode_ms, extract_ms, solve_ms.

Scoring against DIR/truth.jsonl (the same for both): a frame is solved when gpustar's
`status` is "solved" or t3bench's `solved` is true; a solution is wrong when its boresight
(ra_deg, dec_deg) or its roll (roll_deg, tetra3's convention, as the truth's roll_tetra3_deg)
is more than 0.1 deg from the true one. Availability = solved / frames
(wrong ones included; the wrong column says how many). The median boresight error (arcsec)
is over the solutions that are not wrong.

Prints a markdown table (also written to OUT/report.md, with every record and time in
OUT/results.json): per set and thread count, frames, CPU ms a frame of each and their ratio
(tetra3rs CPU / gpustar CPU; above 1 means gpustar is faster), the same ratio of wall times,
images/s by wall time, availability, wrong solutions and median boresight error of each; then
the per-stage medians. Exits non-zero when a run fails (a solver
exits with an error, or its records do not cover exactly the frames of truth.jsonl).

Uses only the Python standard library.
"""
import argparse
import json
import math
import os
import platform
import re
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from benchlib import cpu_seconds, other_load_note, read_jsonl, roll_diff_deg, sep_deg, tail

TOL_DEG = 0.1  # the same tolerance `gpustar evaluate` and bench_vs_cedar.py use for "correct"
REPO = Path(__file__).resolve().parent.parent


# ---------------------------------------------------------------------------------------------
# Geometry and scoring (standard library only)
# ---------------------------------------------------------------------------------------------


def score(records, truth, is_solved):
    """solved, wrong, median boresight error (arcsec) of the correct ones."""
    solved = wrong = 0
    errors = []
    for r in records:
        if not is_solved(r):
            continue
        solved += 1
        t = truth.get(r.get("file"))
        ra, dec = r.get("ra_deg"), r.get("dec_deg")
        if t is None or ra is None or dec is None:
            wrong += 1
            continue
        d = sep_deg(ra, dec, t["ra_deg"], t["dec_deg"])
        roll = r.get("roll_deg")
        rolled = roll is None or roll_diff_deg(roll, t["roll_tetra3_deg"]) > TOL_DEG
        if d > TOL_DEG or rolled:
            wrong += 1
        else:
            errors.append(d * 3600.0)
    return {"solved": solved, "wrong": wrong,
            "median_err_arcsec": statistics.median(errors) if errors else None}


def gpustar_solved(r):
    return r.get("status") == "solved"


def t3_solved(r):
    return r.get("solved") is True


# ---------------------------------------------------------------------------------------------
# Running
# ---------------------------------------------------------------------------------------------

def children_cpu():
    """CPU-seconds (user + system) of this process's waited-for children so far."""
    t = os.times()
    return t.children_user + t.children_system


def run_timed(cmd, stdout_path=None):
    """Run a command; return (returncode, stderr, wall seconds, CPU-seconds of the child).
    stdout goes to stdout_path (or is discarded): a file, not a pipe, so that reading it costs
    the child nothing."""
    out = open(stdout_path, "w") if stdout_path else subprocess.DEVNULL
    try:
        cpu0 = children_cpu()
        t0 = time.perf_counter()
        p = subprocess.run([str(c) for c in cmd], stdout=out, stderr=subprocess.PIPE, text=True)
        wall = time.perf_counter() - t0
        cpu = children_cpu() - cpu0
    finally:
        if stdout_path:
            out.close()
    return p.returncode, p.stderr, wall, cpu


class RunFailed(Exception):
    pass


STAGES = {"gpustar": (("timing_ms", "decode"), ("timing_ms", "detect"), ("timing_ms", "identify")),
          "tetra3rs": ((None, "decode_ms"), (None, "extract_ms"), (None, "solve_ms"))}


def stage_medians(name, records):
    """Median over frames of each stage's milliseconds: decode, detect/extract, identify/solve."""
    out = []
    for group, key in STAGES[name]:
        vals = [(r.get(group) or {}).get(key) if group else r.get(key) for r in records]
        vals = [v for v in vals if isinstance(v, (int, float))]
        out.append(statistics.median(vals) if vals else None)
    return out


def parse_set(spec):
    """'DIR' -> (DIR, None); 'DIR:LOW..HIGH' -> (DIR, (LOW, HIGH))."""
    m = re.fullmatch(r"(.+):([0-9.]+)\.\.([0-9.]+)", spec)
    if m and not Path(spec).is_dir():
        lo, hi = float(m.group(2)), float(m.group(3))
        if not (0 < lo < hi < 180):
            sys.exit(f"{spec}: need 0 < LOW < HIGH < 180")
        return Path(m.group(1)), (lo, hi)
    return Path(spec), None


def camera_fov(camera_toml):
    """fov_x_deg of a camera.toml (and a list of what tetra3's pinhole model ignores)."""
    text = camera_toml.read_text()
    try:
        import tomllib  # Python 3.11+
        cam = tomllib.loads(text)
    except ImportError:
        cam = {}
        for line in text.splitlines():
            m = re.match(r"\s*(\w+)\s*=\s*([^#]+)", line)
            if m:
                v = m.group(2).strip()
                try:
                    cam[m.group(1)] = float(v)
                except ValueError:
                    cam[m.group(1)] = v.strip('"')
    ignored = [k for k in ("fx_px", "fy_px", "cx_px", "cy_px", "k1", "k2") if cam.get(k)]
    if cam.get("mirrored") in (True, "true"):
        ignored.append("mirrored")
    fov = cam.get("fov_x_deg")
    if fov is None:
        fx, w = cam.get("fx_px"), cam.get("width")
        if fx and w:
            fov = math.degrees(2 * math.atan((w / 2) / fx))
    if fov is None:
        raise RunFailed(f"{camera_toml}: no fov_x_deg (nor fx_px and width)")
    return float(fov), ignored


def field_args(args, frames, field):
    """(gpustar field options, t3bench field options, a description)."""
    if field is None:
        fov, ignored = camera_fov(frames / "camera.toml")
        g = ["--camera", frames / "camera.toml"]
        t = ["--fov-deg", repr(fov)]
        desc = f"known {fov:g}°"
        if args.known_fov_error > 0:
            t += ["--fov-max-error-deg", repr(fov * args.known_fov_error)]
        if ignored:
            desc += f" (tetra3 ignores {', '.join(ignored)})"
        return g, t, desc
    lo, hi = field
    g = ["--fov-deg", f"{lo:g}..{hi:g}"]
    t = ["--fov-deg", repr((lo + hi) / 2), "--fov-max-error-deg", repr((hi - lo) / 2)]
    return g, t, f"unknown {lo:g}..{hi:g}°"


def check_records(name, records, truth_files):
    files = [r.get("file") for r in records]
    if sorted(files) != sorted(truth_files):
        missing = sorted(set(truth_files) - set(files))[:5]
        extra = sorted(set(files) - set(truth_files))[:5]
        raise RunFailed(f"{name}: {len(files)} records for {len(truth_files)} frames "
                        f"(missing {missing}, not in truth {extra})")


def bench_set(args, frames, field, threads, work):
    truth_list = read_jsonl(frames / "truth.jsonl")
    truth = {t["file"]: t for t in truth_list}
    truth_files = [t["file"] for t in truth_list]
    first = frames / sorted(truth_files)[0]
    g_field, t_field, desc = field_args(args, frames, field)
    g_common = [*g_field, "--backend", args.backend]
    t_common = ["--db", args.db, *t_field, "--extractor", args.t3_extractor]

    # Warm-up, untimed: gpustar's distance-table cache, the page cache for both.
    rc, err, _, _ = run_timed([args.gpustar, "solve", first, *g_common, "-q"])
    if rc not in (0, 1, 4):  # 4: the frame did not solve, which a warm-up may not
        raise RunFailed(f"gpustar solve (warm-up) exited {rc}:\n{tail(err)}")
    rc, err, _, _ = run_timed([args.t3bench, "solve", *t_common, "--limit", "1", frames])
    if rc != 0:
        raise RunFailed(f"t3bench solve (warm-up) exited {rc}:\n{tail(err)}")

    rows = []
    for T in threads:
        runs = {"gpustar": [], "tetra3rs": []}
        for rnd in range(args.rounds):
            tag = f"{work.name}_j{T}_r{rnd}"
            g_out = work / f"gpustar_{tag}.jsonl"
            if g_out.exists():
                g_out.unlink()
            g_cmd = [args.gpustar, "batch", frames, *g_common, "-j", T, "-q", "-o", g_out]
            rc, err, wall, cpu = run_timed(g_cmd)
            # gpustar batch exits 1 when some frames got error records: still a run, those
            # frames count as unsolved. Anything else is a failed run.
            if rc not in (0, 1) or not g_out.exists():
                raise RunFailed(f"gpustar batch exited {rc}: {' '.join(map(str, g_cmd))}\n{tail(err)}")
            g_rec = read_jsonl(g_out)
            check_records("gpustar", g_rec, truth_files)
            runs["gpustar"].append({"wall_s": wall, "cpu_s": cpu, "records": g_rec, "rc": rc,
                                    "out": str(g_out)})
            print(f"  {desc}, {T} thread(s), round {rnd + 1}: gpustar {wall:.3f} s", end="", flush=True)

            t_out = work / f"tetra3rs_{tag}.jsonl"
            t_cmd = [args.t3bench, "solve", *t_common, "--threads", T, frames]
            rc, err, wall, cpu = run_timed(t_cmd, t_out)
            if rc != 0:
                raise RunFailed(f"t3bench solve exited {rc}: {' '.join(map(str, t_cmd))}\n{tail(err)}")
            t_rec = read_jsonl(t_out)
            check_records("t3bench", t_rec, truth_files)
            summary = next((l for l in err.splitlines() if l.startswith("t3bench:")), "").strip()
            runs["tetra3rs"].append({"wall_s": wall, "cpu_s": cpu, "records": t_rec, "out": str(t_out),
                                     "summary": summary})
            print(f", tetra3rs {wall:.3f} s", flush=True)

        row = {"set": str(frames), "field": desc, "threads": T, "frames": len(truth_files)}
        n = len(truth_files)
        for name, solved_fn in (("gpustar", gpustar_solved), ("tetra3rs", t3_solved)):
            # The round with the median CPU time (the lower middle one for an even count).
            by_cpu = sorted(runs[name], key=lambda r: r["cpu_s"])
            mid = by_cpu[(len(by_cpu) - 1) // 2]
            wall = statistics.median(r["wall_s"] for r in runs[name])
            cpu = statistics.median(r["cpu_s"] for r in runs[name])
            s = score(mid["records"], truth, solved_fn)
            availabilities = sorted({score(r["records"], truth, solved_fn)["solved"] for r in runs[name]})
            row[name] = {
                "wall_s": wall, "walls_s": [r["wall_s"] for r in runs[name]],
                "cpu_s": cpu, "cpus_s": [r["cpu_s"] for r in runs[name]],
                "cpu_ms_per_frame": 1e3 * cpu / n, "wall_ms_per_frame": 1e3 * wall / n,
                "images_per_s": n / wall,
                "availability": s["solved"] / n, **s,
                "stages_ms": stage_medians(name, mid["records"]),
                "solved_counts_over_rounds": availabilities, "records_file": mid["out"],
            }
            if name == "gpustar":
                row[name]["backends"] = sorted({str(r.get("backend")) for r in mid["records"]})
            else:
                row[name]["summary"] = mid["summary"]
        row["ratio_cpu"] = row["tetra3rs"]["cpu_s"] / row["gpustar"]["cpu_s"]
        row["ratio"] = row["tetra3rs"]["wall_s"] / row["gpustar"]["wall_s"]
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# Report
# ---------------------------------------------------------------------------------------------

def fmt_err(v):
    return "–" if v is None else f"{v:.1f}"


def report(args, rows, notes):
    lines = [f"## gpustar vs tetra3rs: whole process, median of {args.rounds} interleaved "
             f"round(s)", ""]
    lines += ["| set | field | threads | frames | gpustar CPU ms/frame | tetra3rs CPU ms/frame | "
              "CPU ratio | wall ratio | gpustar img/s | tetra3rs img/s | "
              "gpustar avail | tetra3rs avail | gpustar wrong | tetra3rs wrong | "
              "gpustar median err \" | tetra3rs median err \" |",
              "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in rows:
        g, t = r["gpustar"], r["tetra3rs"]
        lines.append(
            f"| {Path(r['set']).name} | {r['field']} | {r['threads']} | {r['frames']} "
            f"| {g['cpu_ms_per_frame']:.2f} | {t['cpu_ms_per_frame']:.2f} | {r['ratio_cpu']:.2f}x "
            f"| {r['ratio']:.2f}x | {g['images_per_s']:.1f} | {t['images_per_s']:.1f} "
            f"| {100 * g['availability']:.1f}% | {100 * t['availability']:.1f}% "
            f"| {g['wrong']} | {t['wrong']} | {fmt_err(g['median_err_arcsec'])} "
            f"| {fmt_err(t['median_err_arcsec'])} |")
    ms = lambda v: "–" if v is None else f"{v:.2f}"
    lines += ["", "Per stage, ms a frame (median over the frames of the median round): gpustar decode / "
              "detect / identify; tetra3rs decode / extract / solve.", "",
              "| set | threads | gpustar | tetra3rs |", "|---|---:|---|---|"]
    for r in rows:
        g, t = r["gpustar"]["stages_ms"], r["tetra3rs"]["stages_ms"]
        lines.append(f"| {Path(r['set']).name} | {r['threads']} | {' / '.join(map(ms, g))} "
                     f"| {' / '.join(map(ms, t))} |")
    lines += ["", "CPU ratio = tetra3rs CPU time ÷ gpustar CPU time, wall ratio the same of wall "
              "time (above 1: gpustar faster); img/s by median wall time. "
              f"avail = solved / frames; wrong = solved with the boresight or the roll more than "
              f"{TOL_DEG}° from truth; median err = median boresight error of the solutions that are not "
              "wrong.", "", "Notes:"]
    lines += [f"- {n}" for n in notes]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter,
                                 epilog="See the module docstring (head of this file) for details.")
    ap.add_argument("sets", nargs="+", metavar="SET",
                    help="DIR (known field, DIR/camera.toml) or DIR:LOW..HIGH (unknown field, deg)")
    ap.add_argument("--gpustar", type=Path, default=REPO / "target/release/gpustar",
                    help="gpustar binary (cargo build --release)")
    ap.add_argument("--t3bench", type=Path, default=REPO / "target/release/t3bench",
                    help="t3bench binary (cd bench/tetra3rs && cargo build --release)")
    ap.add_argument("--db", type=Path, required=True, help="tetra3 database (t3bench db ...)")
    ap.add_argument("--rounds", type=int, default=5, help="interleaved rounds; the median counts (5)")
    ap.add_argument("--threads-all", type=int, default=os.cpu_count() or 1,
                    help="the 'all threads' count (default os.cpu_count())")
    ap.add_argument("--known-fov-error", type=float, default=0.01,
                    help="known field: tetra3's fov_max_error as a fraction of the FOV (0.01); "
                         "0 leaves it unset (tetra3's default: no FOV filter)")
    ap.add_argument("--t3-extractor", choices=("default", "fast"), default="default",
                    help="tetra3's centroid extractor: default = CentroidExtractor with "
                         "CentroidExtractionConfig::default() (the default), fast = "
                         "extract_centroids_fast with FastCentroidConfig::default()")
    ap.add_argument("--backend", choices=("auto", "cpu", "gpu"), default="auto",
                    help="gpustar --backend (auto, gpustar's default)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_vs_tetra3rs"),
                    help="work directory: binary copies, records, report")
    args = ap.parse_args()
    if args.rounds < 1 or args.threads_all < 1:
        sys.exit("--rounds and --threads-all must be at least 1")

    for name, path, how in (("gpustar", args.gpustar, "cargo build --release"),
                            ("t3bench", args.t3bench, "cd bench/tetra3rs && cargo build --release")):
        if not path.exists():
            sys.exit(f"{path} not found: build it with `{how}`, or pass --{name}")
    if not args.db.exists():
        sys.exit(f"{args.db} not found: build it with `t3bench db --hip2 hip2.dat --min-fov-deg A "
                 "--max-fov-deg B --epoch YEAR -o DB`")
    sets = [parse_set(s) for s in args.sets]
    for frames, _ in sets:
        if not (frames / "truth.jsonl").exists():
            sys.exit(f"{frames}/truth.jsonl not found: make the set with scripts/sim_frames.py")

    os.environ.setdefault("XDG_RUNTIME_DIR", "/tmp/xdg")  # quiets the Vulkan loader / lavapipe
    Path(os.environ["XDG_RUNTIME_DIR"]).mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    # Run private copies of the binaries: a rebuild during the run cannot mix two versions.
    sources = {}
    for attr in ("gpustar", "t3bench"):
        src = getattr(args, attr)
        built = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(src.stat().st_mtime))
        snap = args.out / attr
        shutil.copy2(src, snap)
        sources[attr] = (src, built)
        setattr(args, attr, snap)
    args.db = args.db.resolve()

    threads = [1] if args.threads_all == 1 else [1, args.threads_all]
    cpu_before, wall_before = cpu_seconds(), time.perf_counter()
    rows, failed = [], []
    for i, (frames, field) in enumerate(sets):
        work = args.out / f"set{i}"
        work.mkdir(exist_ok=True)
        print(f"{frames} ({'known field' if field is None else f'{field[0]:g}..{field[1]:g} deg'}) ...",
              flush=True)
        try:
            rows += bench_set(args, frames, field, threads, work)
        except (RunFailed, OSError, ValueError, KeyError) as e:
            print(f"\n  FAILED: {e}", file=sys.stderr, flush=True)
            failed.append(f"{frames}{'' if field is None else f':{field[0]:g}..{field[1]:g}'}: {e}")

    notes = []
    load = other_load_note(cpu_before, cpu_seconds(), time.perf_counter() - wall_before)
    if load:
        notes.append(load)
    notes.append(f"Machine: {os.cpu_count()} logical CPUs, {platform.platform()}; threads: 1 and "
                 f"{args.threads_all} (gpustar -j, t3bench --threads: frames spread over threads).")
    for attr in ("gpustar", "t3bench"):
        src, built = sources[attr]
        notes.append(f"{attr} binary: copy of {src} (built {built}).")
    backends = sorted({b for r in rows for b in r["gpustar"]["backends"]})
    notes.append(f"gpustar: `batch` with --backend {args.backend} (records' backend: "
                 f"{', '.join(backends) or '–'}); known field: --camera DIR/camera.toml; unknown: "
                 "--fov-deg LOW..HIGH; all else its defaults. Warm-up: one untimed `gpustar solve` "
                 "of the first frame per set (distance-table cache).")
    known_err = (f"fov_max_error = {args.known_fov_error:g} × FOV" if args.known_fov_error > 0
                 else "fov_max_error unset (tetra3's default)")
    notes.append(f"tetra3rs: tetra3 0.14.0 (crates.io) through bench/tetra3rs (t3bench), database "
                 f"{args.db}; extractor: "
                 + ("CentroidExtractor with CentroidExtractionConfig::default()"
                    if args.t3_extractor == "default" else "extract_centroids_fast with FastCentroidConfig::default()")
                 + f"; SolveConfig::new(FOV, width, height) (tetra3's defaults: match_radius 0.01, "
                 f"match_threshold 1e-5, solve_timeout 5000 ms, 24 pattern stars), known field: "
                 f"{known_err}; unknown field: the middle of the range ± half of it. Warm-up: one "
                 "untimed frame per set.")
    if rows:
        notes.append(f"t3bench's own summary (first row): {rows[0]['tetra3rs']['summary']}")
    for r in rows:
        g, t = r["gpustar"], r["tetra3rs"]
        for name, x in (("gpustar", g), ("tetra3rs", t)):
            if len(x["solved_counts_over_rounds"]) > 1:
                notes.append(f"{Path(r['set']).name} {r['field']} {r['threads']} thread(s): {name}'s "
                             f"solved count differed between rounds: {x['solved_counts_over_rounds']}.")
        notes.append(f"{Path(r['set']).name} {r['field']} {r['threads']} thread(s): wall seconds per "
                     f"round gpustar {', '.join(f'{w:.3f}' for w in g['walls_s'])}, tetra3rs "
                     f"{', '.join(f'{w:.3f}' for w in t['walls_s'])}; CPU seconds per round "
                     f"gpustar {', '.join(f'{c:.3f}' for c in g['cpus_s'])}, tetra3rs "
                     f"{', '.join(f'{c:.3f}' for c in t['cpus_s'])}.")
    for f in failed:
        notes.append(f"**FAILED**: {f}".replace("\n", "\n  "))

    text = report(args, rows, notes)
    (args.out / "report.md").write_text(text + "\n")
    (args.out / "results.json").write_text(json.dumps(
        {"args": {k: str(v) for k, v in vars(args).items()}, "rows": rows, "failed": failed},
        indent=1) + "\n")
    print()
    print(text)
    print(f"\n(records, report.md and results.json in {args.out})")
    if failed:
        sys.exit(1)


if __name__ == "__main__":
    main()
