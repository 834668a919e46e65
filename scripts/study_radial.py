#!/usr/bin/env python3
"""Seed 002's set-up in the accuracy study (issue 17): vote, radial and triangle identification
on narrow deep frames, against uncatalogued faint stars, false stars and positional noise.

    python3 scripts/study_radial.py --out docs/study/radial \\
        --set "base=/tmp/r4" --set "false 0=/tmp/s2/fs0" ... [--noise "pos 1 px=1.0"]

Each set is a directory of scripts/sim_frames.py (frames, truth.jsonl, camera.toml). Every set
is solved with `gpustar batch --backend cpu --method M` for M in vote, radial, triangle (one
thread each, -j 1, so identify times compare), scored with `gpustar evaluate --per-frame`:
available = solved within 0.1 deg of the truth with >= 2 right star IDs and no false one (the
accuracy study's definition); wrong = solved beyond 0.1 deg; on sets drawn with position noise
sigma (px) a false ID is a star more than 3 + 5 sigma px from where the truth puts it and the
attitude tolerance is 0.1 deg x max(1, 4 sigma) (the accuracy study's rules: a right solution's
roll moves with the noise). Table sizes are `gpustar info`'s for the set's camera (the main band):
the distance table (vote, triangle) and the radial features (radial, which are built from the
table). Writes OUT/radial.md, OUT/results.json and OUT/fig_radial.png (matplotlib).
"""
import argparse
import json
import os
import re
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
GPUSTAR = os.environ.get("GPUSTAR", str(HERE.parent / "target" / "release" / "gpustar"))
METHODS = ("vote", "radial", "triangle")


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode not in (0, 1):
        sys.exit(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr[-2000:]}")
    return r.stdout


def table_sizes(camera):
    out = run([GPUSTAR, "info", "--camera", str(camera)])
    table = re.search(r"distance table: \d+ rows, (\d+) bytes", out)
    radial = re.search(r"radial features \(--method radial\): (\d+) bytes", out)
    return int(table.group(1)), int(radial.group(1))


def score(set_dir, method, noise, out):
    records = out / f"{set_dir.name}_{method}.jsonl"
    if not records.exists():
        run([GPUSTAR, "batch", str(set_dir), "--camera", str(set_dir / "camera.toml"),
             "--backend", "cpu", "-j", "1", "--method", method, "-q", "-o", str(records)])
    frames = [json.loads(l) for l in run([
        GPUSTAR, "evaluate", "--truth", str(set_dir / "truth.jsonl"), str(records),
        "--per-frame", "--id-tolerance-px", str(3 + 5 * noise),
        "--tolerance-deg", str(0.1 * max(1.0, 4 * noise))]).splitlines() if l.startswith('{"file"')]
    n = len(frames)
    available = sum(f["correct"] and f["correct_ids"] >= 2 and f["false_ids"] == 0 for f in frames)
    wrong = sum(f["status"] == "solved" and not f["correct"] for f in frames)
    false_frames = sum(f["false_ids"] > 0 for f in frames)
    ms = sorted(f["identify_ms"] for f in frames)
    errs = sorted(f["error_arcsec"] for f in frames if f["correct"])
    return {
        "frames": n,
        "available": available,
        "wrong": wrong,
        "frames_with_false_ids": false_frames,
        "false_ids": sum(f["false_ids"] for f in frames),
        "identify_ms_median": statistics.median(ms),
        "identify_ms_p90": ms[min(len(ms) - 1, int(0.9 * len(ms)))],
        "error_arcsec_median": statistics.median(errs) if errs else None,
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--set", action="append", required=True, help="LABEL=DIR")
    ap.add_argument("--noise", action="append", default=[], help="LABEL=SIGMA_PX (sets drawn with position noise)")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    noise = {k: float(v) for k, v in (x.split("=", 1) for x in args.noise)}
    results = []
    for spec in args.set:
        label, d = spec.split("=", 1)
        d = Path(d)
        table, features = table_sizes(d / "camera.toml")
        row = {"set": label, "dir": str(d), "noise_px": noise.get(label, 0.0),
               "table_bytes": table, "radial_bytes": features}
        for m in METHODS:
            row[m] = score(d, m, row["noise_px"], out)
            print(label, m, row[m], flush=True)
        results.append(row)
    (out / "results.json").write_text(json.dumps(results, indent=1))
    pct = lambda r: 100.0 * r["available"] / max(1, r["frames"])
    lines = [
        "# Seed 002's set-up: vote, radial features and triangles on narrow deep frames",
        "",
        "Made by `scripts/study_radial.py` (" + " ".join(sys.argv[1:]).replace(str(out), "OUT") + ").",
        "Frames of `scripts/sim_frames.py` (independent of `gpustar simulate`): 4° FOV, 4096², 3.52″/px",
        "(seed 002's 9 µm pixels at f ≈ 528 mm), stars rendered to the set's Hp limit (to 9 unless said)",
        "from Hipparcos while gpustar's catalog stops at Hp 8 (uncatalogued faint stars), false stars",
        "(10 unless said), position noise (0 unless said). CPU backend, one thread.",
        "Available: within 0.1° (0.1° × max(1, 4σ/px) with position noise σ) with ≥ 2 right IDs and no",
        "false one (beyond 3 + 5σ px); wrong: solved beyond that angle.",
        "",
        "| set | frames | vote: available, wrong, false-ID frames | radial | triangle | identify ms median (p90): vote / radial / triangle |",
        "|---|---|---|---|---|---|",
    ]
    for r in results:
        cell = lambda m: f"{pct(r[m]):.1f} %, {r[m]['wrong']}, {r[m]['frames_with_false_ids']}"
        t = " / ".join(f"{r[m]['identify_ms_median']:.1f} ({r[m]['identify_ms_p90']:.1f})" for m in METHODS)
        lines.append(f"| {r['set']} | {r['vote']['frames']} | {cell('vote')} | {cell('radial')} | {cell('triangle')} | {t} |")
    lines += ["", "Table memory (main band, `gpustar info`): "
              + "; ".join(sorted({f"{r['table_bytes'] / 1e6:.1f} MB distance table (vote, triangle), "
                                  f"{r['radial_bytes'] / 1e6:.1f} MB radial features" for r in results})) + ".", ""]
    (out / "radial.md").write_text("\n".join(lines) + "\n")
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
        fig, ax = plt.subplots(figsize=(9, 4))
        xs = range(len(results))
        for m, mk in zip(METHODS, ("o-", "s-", "^-")):
            ax.plot(xs, [pct(r[m]) for r in results], mk, label=m)
        ax.set_xticks(list(xs))
        ax.set_xticklabels([r["set"] for r in results], rotation=20)
        ax.set_ylabel("available (%)")
        ax.set_title("4°, 4096²: vote, radial, triangle")
        ax.grid(alpha=0.3)
        ax.legend()
        fig.tight_layout()
        fig.savefig(out / "fig_radial.png", dpi=110)
    except ImportError:
        print("matplotlib not installed: no chart", file=sys.stderr)
    print((out / "radial.md").read_text())


if __name__ == "__main__":
    main()
