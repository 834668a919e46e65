#!/usr/bin/env python3
"""gpustar against astrometry.net's solve-field on real frames with known pointing: solved,
wrong and whole-process time a frame, the same frames and the same scale range for both.

    python3 scripts/bench_vs_astrometry.py --catalog tycho2.cat SET_DIR [SET_DIR ...]

Each SET_DIR holds frames and a truth.jsonl in ../shared/data/narrow_real's conventions (file,
ra_deg/dec_deg of the centre pixel ((W-1)/2, (H-1)/2), fov_x_deg). FITS frames are blinded first
(scripts/blind_fits.py: WCS and pointing keywords removed); other formats are used as they are.
Both tools get the field width as a range, truth × (1 ± --scale-rel) unless --fov-deg gives one,
and one core (taskset) each; gpustar gets --catalog, solve-field the index files its config
names (Debian: /etc/astrometry.cfg, /usr/share/astrometry). A solution is right when its
centre pixel lies within --tol-frac of the field's width (default 1 %) of the truth's; any other
solution is wrong. Time is the whole process, wall and CPU (user + system), measured for each
frame separately: a per-frame run of each tool, caches warm (one untimed run first with --warm).

Writes a Markdown table to stdout and appends every frame's figures, as it is done, as JSON
Lines to --out (--report FILE... prints the table of such files again).
"""
import argparse
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import read_jsonl, sep_deg  # noqa: E402
from blind_fits import blind  # noqa: E402

FITS_EXT = {".fits", ".fit", ".fts"}


def run_timed(cmd, timeout):
    """(returncode, wall s, CPU s of the process and its children, stdout, stderr). On timeout
    the whole process group is killed (solve-field runs astrometry-engine as a child), and the
    CPU time then covers only what was waited for."""
    t0 = time.perf_counter()
    before = os.times()
    p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                         start_new_session=True)
    try:
        out, err = p.communicate(timeout=timeout)
        rc = p.returncode
    except subprocess.TimeoutExpired:
        os.killpg(p.pid, signal.SIGKILL)
        out, err = p.communicate()
        rc = "timeout"
    wall = time.perf_counter() - t0
    after = os.times()
    cpu = (after.children_user - before.children_user) + (after.children_system - before.children_system)
    return rc, wall, cpu, out or "", err or ""


def blinded_copy(src, dst_dir):
    dst = dst_dir / src.name
    if src.suffix.lower() in FITS_EXT:
        from astropy.io import fits

        with fits.open(src, do_not_scale_image_data=True) as hdus:
            for h in hdus:
                blind(h.header)
            hdus.writeto(dst, overwrite=True, output_verify="silentfix")
    else:
        shutil.copy(src, dst)
    return dst


def pin(cmd, core):
    return (["taskset", "-c", str(core)] + cmd) if shutil.which("taskset") and core is not None else cmd


def gpustar_solve(args, frame, lo, hi):
    cmd = [args.gpustar, "solve", str(frame), "--fov-deg", f"{lo:.6f}..{hi:.6f}", "--backend", "cpu"]
    if args.catalog:
        cmd += ["--catalog", args.catalog]
    cmd += args.gpustar_arg
    rc, wall, cpu, out, err = run_timed(pin(cmd, args.core), args.timeout)
    sol = None
    try:
        rec = json.loads(out)
        if rec.get("status") == "solved":
            sol = (rec["ra_deg"], rec["dec_deg"], rec.get("fov_x_deg"))
        detail = rec.get("reason") or rec.get("error") or f"{rec.get('stars_matched')} matched"
    except (json.JSONDecodeError, TypeError):
        detail = f"rc {rc}: {err.strip().splitlines()[-1] if err.strip() else 'no output'}"
    return sol, wall, cpu, detail


def astrometry_solve(args, frame, lo, hi, work):
    from astropy.io import fits
    from astropy.wcs import WCS

    out_dir = work / f"an_{frame.stem}"
    shutil.rmtree(out_dir, ignore_errors=True)
    out_dir.mkdir()
    wcs_path = out_dir / "out.wcs"
    cmd = ["solve-field", str(frame), "--dir", str(out_dir), "--no-plots", "--overwrite",
           "--scale-units", "degwidth", "--scale-low", f"{lo:.6f}", "--scale-high", f"{hi:.6f}",
           "--cpulimit", str(args.timeout), "--wcs", str(wcs_path), "--new-fits", "none",
           "--temp-axy", "--index-xyls", "none", "--rdls", "none", "--match", "none",
           "--corr", "none", "--solved", "none"] + args.an_arg
    rc, wall, cpu, out, err = run_timed(pin(cmd, args.core), args.timeout + 30)
    if not wcs_path.exists():
        return None, wall, cpu, f"rc {rc}, no solution"
    header = fits.getheader(wcs_path)
    w = WCS(header)
    width, height = header["IMAGEW"], header["IMAGEH"]
    ra, dec = w.all_pix2world([[(width - 1) / 2, (height - 1) / 2]], 0)[0]
    return (float(ra), float(dec), None), wall, cpu, "solved"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("sets", nargs="*", type=Path, help="folders with frames and truth.jsonl")
    ap.add_argument("--catalog", help="gpustar --catalog file (default: the built-in Hipparcos)")
    ap.add_argument("--gpustar", default=str(Path(__file__).resolve().parent.parent / "target/release/gpustar"))
    ap.add_argument("--scale-rel", type=float, default=0.10, help="field width range: truth × (1 ± this)")
    ap.add_argument("--fov-deg", help="LOW..HIGH instead of --scale-rel, the same for every frame")
    ap.add_argument("--scale-per-set", action="store_true",
                    help="one range per group of a set's frames whose widths lie within --scale-rel "
                         "of each other: the group's median width × (1 ± --scale-rel), as a user gives "
                         "a camera's scale (gpustar's cached pattern index then serves the group)")
    ap.add_argument("--report", nargs="+", type=Path, metavar="JSONL",
                    help="only print the table of rows saved by earlier runs' --out; a frame's row in a "
                         "later file replaces the tools it holds (one run's astrometry beside another's gpustar)")
    ap.add_argument("--tol-frac", type=float, default=0.01, help="right: centre within this fraction of the width")
    ap.add_argument("--timeout", type=int, default=300, help="seconds a frame for each tool")
    ap.add_argument("--core", type=int, default=0, help="the core both tools are pinned to (taskset)")
    ap.add_argument("--warm", action="store_true", help="one untimed run of each tool per frame first")
    ap.add_argument("--tools", default="gpustar,astrometry", help="comma-separated: gpustar, astrometry")
    ap.add_argument("--gpustar-arg", action="append", default=[], help="extra argument for gpustar (repeat)")
    ap.add_argument("--an-arg", action="append", default=[], help="extra argument for solve-field (repeat)")
    ap.add_argument("--out", type=Path, help="JSON Lines of every frame's figures")
    args = ap.parse_args()
    tools = args.tools.split(",")
    if args.report:
        merged = {}
        for p in args.report:
            for r in read_jsonl(p):
                merged.setdefault((r["set"], r["file"]), {}).update(r)
        report([r for r in merged.values() if all(t in r for t in tools)], tools)
        return
    work = Path(tempfile.mkdtemp(prefix="bench_an_"))
    rows = []
    try:
        for set_dir in args.sets:
            blind_dir = work / set_dir.name
            blind_dir.mkdir()
            truths = read_jsonl(set_dir / "truth.jsonl")
            # One range per group: the frames of a set (truth's "set" where a folder holds
            # several) whose widths lie within --scale-rel of the group's narrowest.
            centre = {}
            for name in {t.get("set") for t in truths}:
                frames = sorted((t for t in truths if t.get("set") == name), key=lambda t: t["fov_x_deg"])
                group = []
                for t in frames + [None]:
                    if group and (t is None or t["fov_x_deg"] > group[0]["fov_x_deg"] * (1 + args.scale_rel)):
                        m = group[len(group) // 2]["fov_x_deg"]
                        for g in group:
                            centre[g["file"]] = m
                        group = []
                    if t is not None:
                        group.append(t)
            for t in truths:
                frame = blinded_copy(set_dir / t["file"], blind_dir)
                if args.fov_deg:
                    lo, hi = (float(v) for v in args.fov_deg.split(".."))
                elif args.scale_per_set:
                    m = centre[t["file"]]
                    lo, hi = m * (1 - args.scale_rel), m * (1 + args.scale_rel)
                    if not lo <= t["fov_x_deg"] <= hi:
                        print(f"{t['file']}: width {t['fov_x_deg']:.4f} outside the set's range", file=sys.stderr)
                else:
                    lo, hi = t["fov_x_deg"] * (1 - args.scale_rel), t["fov_x_deg"] * (1 + args.scale_rel)
                row = {"set": set_dir.name, "file": t["file"], "fov_range": [lo, hi]}
                for tool in tools:
                    solve = (lambda: gpustar_solve(args, frame, lo, hi)) if tool == "gpustar" else \
                        (lambda: astrometry_solve(args, frame, lo, hi, work))
                    if args.warm:
                        solve()
                    sol, wall, cpu, detail = solve()
                    verdict = "unsolved"
                    err = None
                    if sol:
                        err = sep_deg(sol[0], sol[1], t["ra_deg"], t["dec_deg"])
                        verdict = "right" if err <= args.tol_frac * t["fov_x_deg"] else "wrong"
                    row[tool] = {"verdict": verdict, "wall_s": wall, "cpu_s": cpu, "detail": detail,
                                 "centre_err_arcsec": None if err is None else err * 3600}
                    print(f"{set_dir.name}/{t['file']}: {tool} {verdict} ({detail}) "
                          f"{wall:.2f} s wall, {cpu:.2f} s CPU", file=sys.stderr)
                rows.append(row)
                if args.out:
                    with open(args.out, "a") as f:
                        f.write(json.dumps(row) + "\n")
    finally:
        shutil.rmtree(work, ignore_errors=True)
    report(rows, tools)


def report(rows, tools):
    print("| set | frame | " + " | ".join(f"{t} | {t} wall / CPU s" for t in tools) + " |")
    print("|---|---|" + "---|---|" * len(tools))
    for r in rows:
        cells = []
        for t in tools:
            x = r[t]
            e = "" if x["centre_err_arcsec"] is None else f" ({x['centre_err_arcsec']:.1f}″)"
            cells += [x["verdict"] + e, f"{x['wall_s']:.2f} / {x['cpu_s']:.2f}"]
        print(f"| {r['set']} | {r['file']} | " + " | ".join(cells) + " |")
    print()
    for t in tools:
        xs = [r[t] for r in rows]
        right = sum(x["verdict"] == "right" for x in xs)
        wrong = sum(x["verdict"] == "wrong" for x in xs)
        walls = sorted(x["wall_s"] for x in xs)
        cpus = sorted(x["cpu_s"] for x in xs)
        med = lambda v: v[len(v) // 2] if v else float("nan")  # noqa: E731
        print(f"- {t}: {right}/{len(xs)} right, {wrong} wrong; median {med(walls):.2f} s wall, "
              f"{med(cpus):.2f} s CPU a frame; total {sum(walls):.1f} s wall, {sum(cpus):.1f} s CPU")
    if len(tools) == 2:
        a, b = tools
        ratio = sorted(r[b]["cpu_s"] / max(r[a]["cpu_s"], 1e-9) for r in rows)
        print(f"- CPU time {b} / {a} a frame: median {ratio[len(ratio) // 2]:.1f}×, least {ratio[0]:.1f}×")


if __name__ == "__main__":
    main()
