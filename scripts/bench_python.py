#!/usr/bin/env python3
"""What the Python package costs, and gpustar beside cedar-solve in one Python process.

    python scripts/bench_python.py FRAMES_DIR [--cli PATH] [--reps 30] [--pairs N] [--cedar N]

FRAMES_DIR is a set of scripts/sim_frames.py (FITS frames, truth.jsonl, camera.toml), e.g.
`python3 scripts/sim_frames.py --out /tmp/sim300 -n 300 --size 1024 --fov-deg 10`. Run it with
the Python of a virtual environment where gpustar is installed (`pip install ./python`), and
cedar-solve too for --cedar. Everything is the CPU backend, default threads (all cores).

1. Throughput: `gpustar batch FRAMES_DIR` (the CLI at --cli, files on disk), gpustar.batch()
   (the same from Python), Solver.solve_many() on the frames already in memory (numpy uint16,
   read here by a FITS reader of this script's own, with each frame's DATE-OBS as its epoch):
   images/s = frames / wall seconds of the call (the distance table is cached on disk before).
   With --pairs N: N pairs run back to back (CLI, solve_many, solve_many, CLI), each giving two
   ratios solve_many img/s / CLI img/s: on a shared machine whose load moves, the ratios of
   runs made together say more than any single rate.
2. Latency: Solver.solve() of one frame from Python, --reps times, against the library's own
   call (Solvers::solve_cpu on the frame made beforehand, timed in Rust, the same name and
   epoch), interleaved: the difference is what the binding adds (array to frame, a Result;
   with a field read, the record to JSON and parsed).
3. With --cedar N: the first N frames solved by cedar-solve (tetra3.Tetra3().solve_from_image
   on the same arrays as PIL images, which it requires, fov_estimate from camera.toml, other arguments at their defaults) and by
   gpustar in this one process; correct = boresight and roll within 0.1 deg of the truth.
"""

import argparse
import datetime as dt
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from benchlib import roll_diff_deg, sep_deg  # noqa: E402

import gpustar  # noqa: E402

TOL_DEG = 0.1


def read_fits(path):
    """(uint16 array, header dict) of a simple 2-D FITS file (BITPIX 16 with BZERO 32768, or
    8), the way sim_frames.py writes them."""
    raw = Path(path).read_bytes()
    header, pos = {}, 0
    while True:
        card = raw[pos:pos + 80].decode("ascii")
        pos += 80
        key = card[:8].strip()
        if key == "END":
            break
        if card[8:10] == "= ":
            value = card[10:].split("/")[0].strip().strip("'").strip()
            header[key] = value
    pos = (pos + 2879) // 2880 * 2880
    w, h, bitpix = int(header["NAXIS1"]), int(header["NAXIS2"]), int(header["BITPIX"])
    if bitpix == 16:
        data = np.frombuffer(raw, ">i2", w * h, pos).astype(np.int32)
        data = data * float(header.get("BSCALE", 1)) + float(header.get("BZERO", 0))
        return data.reshape(h, w).astype(np.uint16), header
    if bitpix == 8:
        return np.frombuffer(raw, np.uint8, w * h, pos).reshape(h, w).copy(), header
    raise SystemExit(f"{path}: BITPIX {bitpix} not read here")


def julian_year(date_obs):
    t = dt.datetime.fromisoformat(date_obs.replace("Z", ""))
    j2000 = dt.datetime(2000, 1, 1, 12)
    return 2000.0 + (t - j2000).total_seconds() / 86400.0 / 365.25


def score(records, truth):
    solved = correct = 0
    for r in records:
        if r.get("status") != "solved":
            continue
        solved += 1
        t = truth[r["file"]]
        if (sep_deg(r["ra_deg"], r["dec_deg"], t["ra_deg"], t["dec_deg"]) < TOL_DEG
                and roll_diff_deg(r["roll_deg"], t["roll_tetra3_deg"]) < TOL_DEG):
            correct += 1
    return {"frames": len(records), "solved": solved, "correct": correct, "wrong": solved - correct}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("frames", type=Path)
    ap.add_argument("--cli", default="target/release/gpustar")
    ap.add_argument("--reps", type=int, default=30)
    ap.add_argument("--cedar", type=int, default=0)
    ap.add_argument("--pairs", type=int, default=0,
                    help="also N back-to-back pairs (CLI, solve_many, solve_many, CLI): ratios")
    a = ap.parse_args()

    truth = {t["file"]: t for t in map(json.loads, open(a.frames / "truth.jsonl"))}
    names = sorted(truth)
    camera = a.frames / "camera.toml"
    fov = float([ln for ln in camera.read_text().splitlines() if ln.startswith("fov_x_deg")][0].split("=")[1])
    t0 = time.perf_counter()
    loaded = [read_fits(a.frames / n) for n in names]
    images = [im for im, _ in loaded]
    epochs = [julian_year(h["DATE-OBS"]) if "DATE-OBS" in h else None for _, h in loaded]
    print(f"read {len(images)} frames {images[0].shape} into memory in {time.perf_counter() - t0:.1f} s")

    solver = gpustar.Solver(camera=camera, backend="cpu")
    solver.solve(images[0], name=names[0], epoch=epochs[0])  # table built or read from the cache
    out = {}

    # 1. Throughput.
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        p = subprocess.run([a.cli, "batch", str(a.frames), "--camera", str(camera), "--backend", "cpu",
                            "-q", "-o", f"{tmp}/cli.jsonl"], capture_output=True, text=True)
        cli_s = time.perf_counter() - t0
        assert p.returncode in (0, 1), p.stderr
        cli = [json.loads(x) for x in open(f"{tmp}/cli.jsonl")]
    t0 = time.perf_counter()
    py_batch = [r.to_dict() for r in gpustar.batch(a.frames, camera=camera, backend="cpu")]
    batch_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    many = [r.to_dict() for r in solver.solve_many(images, names=names, epochs=epochs)]
    many_s = time.perf_counter() - t0
    same = sum({k: v for k, v in x.items() if k != "timing_ms"} == {k: v for k, v in y.items() if k != "timing_ms"}
               for x, y in zip(many, cli))
    n = len(names)
    out["throughput"] = {
        "cli_batch_disk": {"s": round(cli_s, 2), "img_s": round(n / cli_s, 1), **score(cli, truth)},
        "py_batch_disk": {"s": round(batch_s, 2), "img_s": round(n / batch_s, 1), **score(py_batch, truth)},
        "py_solve_many_memory": {"s": round(many_s, 2), "img_s": round(n / many_s, 1), **score(many, truth)},
        "solve_many_records_equal_to_cli": f"{same} of {n}",
    }

    # 1b. Pairs run back to back, for a machine whose load moves: each gives two ratios
    # solve_many img/s / CLI img/s (CLI, solve_many, solve_many, CLI cancels a drift).
    if a.pairs:
        def cli_rate():
            with tempfile.TemporaryDirectory() as tmp:
                t0 = time.perf_counter()
                subprocess.run([a.cli, "batch", str(a.frames), "--camera", str(camera), "--backend", "cpu",
                                "-q", "-o", f"{tmp}/cli.jsonl"], capture_output=True, check=False)
                return n / (time.perf_counter() - t0)

        def many_rate():
            t0 = time.perf_counter()
            for r in solver.solve_many(images, names=names, epochs=epochs):
                r.to_dict()
            return n / (time.perf_counter() - t0)

        pairs = []
        for _ in range(a.pairs):
            c1, m1, m2, c2 = cli_rate(), many_rate(), many_rate(), cli_rate()
            pairs.append({"cli_img_s": [round(c1, 1), round(c2, 1)], "many_img_s": [round(m1, 1), round(m2, 1)],
                          "ratio": [round(m1 / c1, 3), round(m2 / c2, 3)]})
        ratios = sorted(x for p in pairs for x in p["ratio"])
        out["pairs"] = {"runs": pairs, "ratio_median": round(statistics.median(ratios), 3),
                        "ratio_range": [ratios[0], ratios[-1]]}

    # 2. Latency of one call: solve() from Python against the library's own call on a frame
    # made beforehand (Solver._library_call_ms: the same compiled code, the same name and
    # epoch, no Python), each repeated --reps times, interleaved so that both see the same
    # machine load. solve() builds its Result lazily; "solve_and_read" also reads one field
    # (ra_deg), which turns the record into its JSON line and parses it once.
    # Two frames: the first solved one, and the solved frame of median solve time.
    def library_ms(k):
        try:
            return solver._inner._library_call_ms(images[k], 1, names[k], epochs[k])
        except TypeError:  # a binding from before _library_call_ms took the name and epoch
            return solver._inner._library_call_ms(images[k], 1)

    solved = [i for i, r in enumerate(many) if r["status"] == "solved"]
    by_time = sorted(solved, key=lambda i: many[i]["timing_ms"]["total"])
    out["latency_one_frame"] = []
    for k in (solved[0], by_time[len(by_time) // 2]):
        py_ms, read_ms, rust_ms = [], [], []
        for _ in range(a.reps):
            t0 = time.perf_counter()
            solver.solve(images[k], name=names[k], epoch=epochs[k])
            py_ms.append((time.perf_counter() - t0) * 1e3)
            t0 = time.perf_counter()
            solver.solve(images[k], name=names[k], epoch=epochs[k]).ra_deg
            read_ms.append((time.perf_counter() - t0) * 1e3)
            rust_ms += library_ms(k)
        stat = {"median": statistics.median, "min": min}
        out["latency_one_frame"].append({"frame": names[k], "reps": a.reps, **{
            f"{name}_ms": {"python_solve": round(f(py_ms), 3), "python_solve_and_read": round(f(read_ms), 3),
                           "rust_library": round(f(rust_ms), 3),
                           "overhead_ms": round(f(py_ms) - f(rust_ms), 3),
                           "overhead_pct": round(100 * (f(py_ms) / f(rust_ms) - 1), 2),
                           "overhead_read_pct": round(100 * (f(read_ms) / f(rust_ms) - 1), 2)}
            for name, f in stat.items()}})

    # 3. cedar-solve beside gpustar, in this process.
    if a.cedar:
        import logging

        import tetra3
        from importlib import metadata

        from PIL import Image
        logging.getLogger("tetra3.Tetra3").setLevel(logging.WARNING)
        t3 = tetra3.Tetra3()
        sub = names[:a.cedar]
        ced, gs = [], []
        t_c = t_g = 0.0
        for name, im, ep in zip(sub, images, epochs):
            t0 = time.perf_counter()
            s = t3.solve_from_image(Image.fromarray(im), fov_estimate=fov)  # it takes PIL images
            t_c += time.perf_counter() - t0
            ok = s.get("RA") is not None
            ced.append({"file": name, "status": "solved" if ok else "unsolved",
                        "ra_deg": s.get("RA"), "dec_deg": s.get("Dec"), "roll_deg": s.get("Roll")})
            t0 = time.perf_counter()
            gs.append(solver.solve(im, name=name, epoch=ep).to_dict())
            t_g += time.perf_counter() - t0
        m = len(sub)
        out["vs_cedar_one_process"] = {
            "cedar-solve " + metadata.version("cedar-solve"): {**score(ced, truth), "ms_per_frame": round(1e3 * t_c / m, 1)},
            "gpustar " + gpustar.__version__ + " solve()": {**score(gs, truth), "ms_per_frame": round(1e3 * t_g / m, 1)},
        }
    out["machine"] = {"cores": os.cpu_count(), "load_1min": os.getloadavg()[0]}
    print(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
