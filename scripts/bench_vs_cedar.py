#!/usr/bin/env python3
"""Benchmark gpustar against cedar-solve on the same simulated frames, in one run.

    scripts/bench_vs_cedar.py [--frames 200] [--fov 18] [--out /tmp/bench_vs_cedar]
                              [--gpustar target/release/gpustar] [--skip-gpu]
                              [--cedar-python PYTHON]

Steps:
  1. `gpustar simulate` writes OUT/frames (PNG frames, truth.jsonl, camera.toml), unless frames
     with the same count, FOV and seed are already there.
  2. `gpustar batch --backend cpu`, then `--backend gpu` (unless --skip-gpu or `gpustar info`
     finds no adapter). The rate is frames / wall-clock seconds of the whole command; the
     per-stage means come from each record's `timing_ms`. `gpustar evaluate` does the scoring.
  3. cedar-solve (the `tetra3` module of `pip install cedar-solve`) runs in a child process
     started with --cedar-python, because cedar-solve pins numpy<2 and Pillow<9 and so often
     lives in its own venv. The child is this same script in worker mode. It loads the
     package's default database, then for each frame opens the PNG with PIL and calls
     `Tetra3.solve_from_image(image, fov_estimate=FOV)` with all other arguments left at
     their defaults (tetra3's own centroid extractor, not Cedar Detect). The rate is
     frames / wall-clock seconds of that loop, image loading included. Importing the package
     and loading the database happen once, are timed separately and are not counted.
     A cedar solution counts as correct when its image-centre RA/Dec is within 0.1 deg of
     the truth and its Roll within 0.1 deg (mod 360) of the truth's `roll_tetra3_deg`.
  4. Prints a markdown table (and writes it to OUT/report.md): solver, frames, solved,
     correct, wrong, seconds, frames/s, ratio vs cedar; then the mean ms per stage.

Uses only the Python standard library. The cedar child also uses what cedar-solve installs
(numpy, Pillow, scipy). If cedar-solve is missing or fails, the report says why and still
gives the gpustar rows.
"""
import argparse
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

from benchlib import cpu_seconds, other_load_note, read_jsonl, roll_diff_deg, sep_deg, tail

TOL_DEG = 0.1  # the same tolerance `gpustar evaluate` uses for "correct"
STAGES = ("decode", "detect", "identify", "total")


# ---------------------------------------------------------------------------------------------
# Geometry and scoring (standard library only)
# ---------------------------------------------------------------------------------------------


def score_centre_roll(records, truth):
    """Score records that have ra_deg/dec_deg/roll_deg/status. A frame is correct when the
    image-centre direction is within TOL_DEG of the truth and so is the roll (mod 360)."""
    solved = correct = wrong = 0
    worst_correct = 0.0
    for r in records:
        if r.get("status") != "solved":
            continue
        solved += 1
        t = truth.get(r["file"])
        if t is None:
            wrong += 1
            continue
        d_centre = sep_deg(r["ra_deg"], r["dec_deg"], t["ra_deg"], t["dec_deg"])
        d_roll = roll_diff_deg(r["roll_deg"], t["roll_tetra3_deg"])
        if d_centre < TOL_DEG and d_roll < TOL_DEG:
            correct += 1
            worst_correct = max(worst_correct, d_centre, d_roll)
        else:
            wrong += 1
    return {"solved": solved, "correct": correct, "wrong": wrong, "worst_correct_deg": worst_correct}


# ---------------------------------------------------------------------------------------------
# cedar-solve worker (runs under --cedar-python; the only part that imports cedar's packages)
# ---------------------------------------------------------------------------------------------

def cedar_worker(frames_dir, fov, out_path):
    """Solve every frame listed in truth.jsonl with cedar-solve. Writes one JSON line per
    frame, then a final {"summary": ...} line. Exits 3 when the package cannot be used."""
    t_import = time.perf_counter()
    try:
        from importlib import metadata
        cedar_version = metadata.version("cedar-solve")  # ESA's tetra3 also provides `tetra3`
    except Exception as e:  # noqa: BLE001 - we report any reason verbatim
        print(f"cedar-solve is not installed for {sys.executable}: {type(e).__name__}: {e}",
              file=sys.stderr)
        sys.exit(3)
    try:
        import numpy
        import PIL
        import scipy
        from PIL import Image
        import tetra3
    except Exception as e:  # noqa: BLE001
        print(f"cedar-solve {cedar_version} cannot be imported by {sys.executable}: "
              f"{type(e).__name__}: {e}", file=sys.stderr)
        sys.exit(3)
    import logging
    logging.getLogger("tetra3.Tetra3").setLevel(logging.WARNING)  # no per-solve INFO lines
    t_import = time.perf_counter() - t_import

    # Tetra3() loads 'default_database', i.e. tetra3/data/default_database.npz, which is
    # inside the cedar-solve wheel (nothing is downloaded or generated).
    t_db = time.perf_counter()
    t3 = tetra3.Tetra3()
    t_db = time.perf_counter() - t_db
    db_path = Path(tetra3.__file__).parent / "data" / "default_database.npz"
    props = {k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in t3.database_properties.items()}
    props = {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in props.items()}

    status_names = {getattr(tetra3.tetra3, n): n for n in
                    ("MATCH_FOUND", "NO_MATCH", "TIMEOUT", "CANCELLED", "TOO_FEW")}
    files = [json.loads(line)["file"] for line in open(Path(frames_dir) / "truth.jsonl") if line.strip()]
    with open(out_path, "w") as out:
        t_loop = time.perf_counter()
        for name in files:
            t0 = time.perf_counter()
            with Image.open(Path(frames_dir) / name) as image:
                image.load()  # decode now so that decode time is measured on its own
                t_decode = time.perf_counter() - t0
                sol = t3.solve_from_image(image, fov_estimate=fov)
            dt = time.perf_counter() - t0
            found = sol.get("RA") is not None
            rec = {
                "file": name,
                "status": "solved" if found else "unsolved",
                "cedar_status": status_names.get(sol.get("status"), sol.get("status")),
                "ra_deg": sol.get("RA"), "dec_deg": sol.get("Dec"), "roll_deg": sol.get("Roll"),
                "fov_deg": sol.get("FOV"), "matches": sol.get("Matches"), "prob": sol.get("Prob"),
                "timing_ms": {"decode": t_decode * 1e3, "detect": sol.get("T_extract"),
                              "identify": sol.get("T_solve"), "total": dt * 1e3},
            }
            out.write(json.dumps(rec) + "\n")
        t_loop = time.perf_counter() - t_loop
        out.write(json.dumps({"summary": {
            "frames": len(files), "seconds": t_loop, "import_s": t_import, "database_load_s": t_db,
            "database": str(db_path), "database_properties": props,
            "versions": {"cedar-solve": cedar_version, "numpy": numpy.__version__,
                         "Pillow": PIL.__version__, "scipy": scipy.__version__,
                         "python": platform.python_version()},
            "python": sys.executable,
        }}) + "\n")


# ---------------------------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------------------------

def run(cmd, **kw):
    """Run a command and return (returncode, stdout, stderr, wall seconds)."""
    t0 = time.perf_counter()
    p = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kw)
    return p.returncode, p.stdout, p.stderr, time.perf_counter() - t0


def ensure_frames(args, frames):
    """Generate frames with `gpustar simulate` unless a matching set is already there."""
    truth_path = frames / "truth.jsonl"
    stamp = frames / ".bench_params.json"  # what the frames were generated with
    want = {"frames": args.frames, "fov": args.fov, "seed": args.seed}
    if truth_path.exists() and stamp.exists():
        try:
            if json.loads(stamp.read_text()) == want and len(read_jsonl(truth_path)) == args.frames:
                print(f"frames: reusing {args.frames} frames in {frames}")
                return
        except (ValueError, OSError):
            pass
    if frames.exists():
        # `gpustar batch` solves every image in the directory, so stale frames must go.
        # The directory is this script's own (OUT/frames); make sure before deleting.
        ours = all(p.name.startswith("sim_") or p.name in ("truth.jsonl", "camera.toml", stamp.name)
                   for p in frames.iterdir())
        if not ours:
            sys.exit(f"{frames} holds files not written by gpustar simulate; choose another --out")
        shutil.rmtree(frames)
    rc, _, err, dt = run([args.gpustar, "simulate", "--out", frames, "-n", args.frames,
                          "--fov-deg", args.fov, "--seed", args.seed])
    if rc != 0:
        sys.exit(f"gpustar simulate failed (exit {rc}):\n{tail(err)}")
    stamp.write_text(json.dumps(want))
    print(f"frames: generated {args.frames} frames ({args.fov} deg FOV, seed {args.seed}) in {dt:.1f} s")


def gpu_adapter(args):
    """(name, None) for the adapter `gpustar info` would use, or (None, why not)."""
    rc, out, err, _ = run([args.gpustar, "info"])
    for line in (out + err).splitlines():
        if line.startswith("--backend gpu:"):
            chosen = line[len("--backend gpu:"):].strip()
            return (None, chosen) if chosen.startswith("none") else (chosen, None)
    return None, f"`gpustar info` exited {rc} without naming an adapter: {tail(err, 3)}"


def run_gpustar(args, frames, backend, out_dir):
    """One `gpustar batch` over all frames; returns a result dict (or one with 'error')."""
    camera = frames / "camera.toml"
    out = out_dir / f"gpustar_{backend}.jsonl"
    common = ["--camera", camera, "--mag-limit", args.mag_limit, "--backend", backend]
    # Warm-up: one frame, so the distance table is built and cached on disk (as it would be
    # on any machine that has solved before) and the timed run measures solving only.
    run([args.gpustar, "solve", frames / "sim_00000.png", *common, "-q"])
    rc, _, err, wall = run([args.gpustar, "batch", frames, *common, "-o", out])
    summary = next((l for l in err.splitlines() if l.startswith("gpustar:")), "").strip()
    if rc not in (0, 1) or not out.exists():  # 1 = some error records, still a run
        return {"name": f"gpustar {backend}", "error": f"gpustar batch exited {rc}: {tail(err, 5)}"}
    records = read_jsonl(out)
    rc_e, ev_out, ev_err, _ = run([args.gpustar, "evaluate", "--truth", frames / "truth.jsonl", out])
    try:
        ev = json.loads(ev_out)
    except ValueError:
        return {"name": f"gpustar {backend}", "error": f"gpustar evaluate exited {rc_e}: {tail(ev_err, 5)}"}
    return {
        "name": f"gpustar {backend}", "frames": len(records), "solved": ev["solved"],
        "correct": ev["correct"], "wrong": ev["wrong"], "seconds": wall,
        "records": records, "summary_line": summary, "evaluate": ev,
        "backend_name": records[0].get("backend") if records else backend,
    }


def run_cedar(args, frames, out_dir, truth):
    """cedar-solve in a child process (worker mode of this script); returns a result dict."""
    out = out_dir / "cedar.jsonl"
    if out.exists():
        out.unlink()
    cmd = [args.cedar_python, Path(__file__).resolve(), "--cedar-worker",
           "--frames-dir", frames, "--fov", args.fov, "--worker-out", out]
    try:
        rc, _, err, wall = run(cmd)
    except OSError as e:
        return {"name": "cedar-solve", "error": f"cannot start {args.cedar_python}: {e}"}
    if rc != 0:
        why = tail(err, 20) or f"exit {rc}"
        if rc == 3:
            why += (f"\n(install it with `{args.cedar_python} -m pip install cedar-solve`; it pins "
                    "numpy<2 and Pillow<9, so a venv is advisable; then pass --cedar-python)")
        return {"name": "cedar-solve", "error": f"cedar-solve worker failed (exit {rc}):\n{why}"}
    lines = read_jsonl(out)
    summary = lines[-1]["summary"]
    records = lines[:-1]
    score = score_centre_roll(records, truth)
    return {"name": "cedar-solve", "frames": len(records), "seconds": summary["seconds"],
            "records": records, "cedar": summary, "process_wall_s": wall,
            "statuses": count_by(records, "cedar_status"), **score}


def count_by(records, key):
    counts = {}
    for r in records:
        counts[r.get(key)] = counts.get(r.get(key), 0) + 1
    return counts


def stage_means(records):
    """Mean ms per stage over the records that carry timing_ms."""
    means = {}
    for s in STAGES:
        vals = [r["timing_ms"][s] for r in records if r.get("timing_ms") and r["timing_ms"].get(s) is not None]
        means[s] = (sum(vals) / len(vals), sum(vals)) if vals else (None, None)
    return means


def report(args, results, notes):
    cedar = next((r for r in results if r["name"] == "cedar-solve" and "error" not in r), None)
    cedar_fps = cedar["frames"] / cedar["seconds"] if cedar else None
    lines = [f"## gpustar vs cedar-solve: {args.frames} simulated frames, {args.fov} deg FOV, "
             f"1024x1024, seed {args.seed}", ""]
    lines += ["| solver | frames | solved | correct | wrong | seconds | frames/s | ratio vs cedar |",
              "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        if "error" in r:
            lines.append(f"| {r['name']} | – | – | – | – | – | – | failed (below) |")
            continue
        fps = r["frames"] / r["seconds"]
        ratio = f"{fps / cedar_fps:.2f}x" if cedar_fps else "n/a"
        lines.append(f"| {r['name']} | {r['frames']} | {r['solved']} | {r['correct']} | {r['wrong']} "
                     f"| {r['seconds']:.2f} | {fps:.1f} | {ratio} |")
    lines += ["", "Mean ms per frame and stage (gpustar: the records' `timing_ms`; cedar: PIL decode, "
              "`T_extract`, `T_solve`, whole frame):", "",
              "| solver | decode | detect | identify | total | sum of totals, s |",
              "|---|---:|---:|---:|---:|---:|"]
    for r in results:
        if "error" in r:
            continue
        m = stage_means(r["records"])
        cells = " | ".join(f"{m[s][0]:.2f}" if m[s][0] is not None else "–" for s in STAGES)
        total_s = m["total"][1] / 1e3 if m["total"][1] is not None else float("nan")
        lines.append(f"| {r['name']} | {cells} | {total_s:.2f} |")
    lines += ["", "gpustar's `timing_ms` is per frame; when `gpustar batch` works on several frames at once "
              "these overlap, so the sum of totals can exceed the wall-clock seconds above.", "", "Notes:"]
    lines += [f"- {n}" for n in notes]
    for r in results:
        if "error" in r:
            lines.append(f"- **{r['name']} did not run**: " + r["error"].replace("\n", "\n  "))
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=200, help="frames to simulate (200)")
    ap.add_argument("--fov", type=float, default=18.0, help="horizontal FOV, deg (18); cedar's fov_estimate")
    ap.add_argument("--seed", type=int, default=1, help="gpustar simulate seed (1)")
    ap.add_argument("--mag-limit", type=float, default=6.0, help="gpustar --mag-limit (6)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/bench_vs_cedar"), help="work directory")
    ap.add_argument("--gpustar", type=Path, default=Path("/work/main/target/release/gpustar"),
                    help="gpustar binary (cargo build --release)")
    ap.add_argument("--skip-gpu", action="store_true", help="do not run gpustar --backend gpu")
    ap.add_argument("--cedar-python", default=os.environ.get("CEDAR_PYTHON", sys.executable),
                    help="Python that has cedar-solve installed (default: $CEDAR_PYTHON, else this one)")
    # Worker mode, used internally: run under --cedar-python to solve the frames with cedar.
    ap.add_argument("--cedar-worker", action="store_true", help=argparse.SUPPRESS)
    ap.add_argument("--frames-dir", type=Path, help=argparse.SUPPRESS)
    ap.add_argument("--worker-out", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()

    if args.cedar_worker:
        cedar_worker(args.frames_dir, args.fov, args.worker_out)
        return

    if not args.gpustar.exists():
        sys.exit(f"{args.gpustar} not found: build it with `cargo build --release`, or pass --gpustar")
    os.environ.setdefault("XDG_RUNTIME_DIR", "/tmp/xdg")  # quiets the Vulkan loader / lavapipe
    Path(os.environ["XDG_RUNTIME_DIR"]).mkdir(parents=True, exist_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    # Run a private copy of the binary: a rebuild during the run cannot mix two versions.
    built = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(args.gpustar.stat().st_mtime))
    snapshot = args.out / "gpustar"
    shutil.copy2(args.gpustar, snapshot)
    args.gpustar_source, args.gpustar = args.gpustar, snapshot
    cpu_before, wall_before = cpu_seconds(), time.perf_counter()
    frames = args.out / "frames"
    ensure_frames(args, frames)
    truth = {t["file"]: t for t in read_jsonl(frames / "truth.jsonl")}

    results, notes = [], []
    print("gpustar --backend cpu ...", flush=True)
    results.append(run_gpustar(args, frames, "cpu", args.out))
    if args.skip_gpu:
        notes.append("gpustar --backend gpu skipped (--skip-gpu).")
    else:
        adapter, why = gpu_adapter(args)
        if adapter is None:
            notes.append(f"gpustar --backend gpu skipped: {why}")
        else:
            print(f"gpustar --backend gpu ({adapter}) ...", flush=True)
            results.append(run_gpustar(args, frames, "gpu", args.out))
    print(f"cedar-solve ({args.cedar_python}) ...", flush=True)
    results.append(run_cedar(args, frames, args.out, truth))

    # Context for reading the numbers.
    load = other_load_note(cpu_before, cpu_seconds(), time.perf_counter() - wall_before)
    if load:
        notes.append(load)
    notes.append(f"gpustar binary: copy of {args.gpustar_source} (built {built}).")
    notes.append(f"Machine: {os.cpu_count()} logical CPUs, {platform.platform()}. Seconds are wall-clock: "
                 "for gpustar the whole `gpustar batch` command (process start, catalog, cached "
                 "distance table, all frames; it may use every core); for cedar-solve the frame loop of "
                 "one Python process (PIL load + solve_from_image per frame), as its users run it.")
    for r in results:
        if "error" in r or not r["name"].startswith("gpustar"):
            continue
        alt = score_centre_roll(r["records"], truth)
        notes.append(f"{r['name']}: {r['summary_line'] or 'no summary line'}; backend `{r['backend_name']}`; "
                     f"correct by `gpustar evaluate` (attitude within {TOL_DEG} deg); by cedar's criterion "
                     f"(centre and roll within {TOL_DEG} deg): {alt['correct']} correct, {alt['wrong']} wrong; "
                     f"median attitude error {r['evaluate'].get('median_error_arcsec', float('nan')):.1f} arcsec.")
    for r in results:
        if r["name"] != "cedar-solve" or "error" in r:
            continue
        c = r["cedar"]
        p = c["database_properties"]
        versions = ", ".join(f"{k} {v}" for k, v in c["versions"].items())
        notes.append(f"cedar-solve: {versions} ({c['python']}). Database: the package's own "
                     f"`default_database` ({c['database']}; {p.get('star_catalog')}, FOV "
                     f"{p.get('min_fov')}-{p.get('max_fov')} deg, mag <= {float(p.get('star_max_magnitude') or 'nan'):.2f}, "
                     f"{p.get('num_patterns')} patterns, proper motion to {p.get('epoch_proper_motion')}). "
                     f"Not counted in its seconds: import {c['import_s']:.2f} s, database load "
                     f"{c['database_load_s']:.2f} s (whole child process {r['process_wall_s']:.2f} s).")
        notes.append(f"cedar-solve call: solve_from_image(PIL image, fov_estimate={args.fov}), all else "
                     "default: tetra3's own centroid extractor (get_centroids_from_image, sigma 2, "
                     "local_mean background), not Cedar Detect; solve_timeout 5000 ms; distortion 0. "
                     f"Statuses: {r['statuses']}. Correct = image-centre RA/Dec within {TOL_DEG} deg and Roll "
                     f"within {TOL_DEG} deg of truth (among correct frames the largest centre or roll "
                     f"error is {r['worst_correct_deg'] * 3600:.1f} arcsec).")

    text = report(args, results, notes)
    (args.out / "report.md").write_text(text + "\n")
    print()
    print(text)
    print(f"\n(records and report in {args.out})")


if __name__ == "__main__":
    main()
