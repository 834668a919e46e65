#!/usr/bin/env python3
"""cedar-solve on every frame of ../shared/data/real, scored like `gpustar evaluate` scores
gpustar's records, for the side-by-side count per set.

    PYTHON_WITH_CEDAR scripts/cedar_real_sets.py [REAL_DIR] [--out results.jsonl]

Runs under a Python that has cedar-solve (`pip install cedar-solve`; it pins numpy<2 and
Pillow<9, so a venv of its own is easiest). Each frame gets `Tetra3().solve_from_image(image,
fov_estimate=FOV)` with FOV from the set's truth.jsonl (what a user who knows the camera would
pass) and every other argument at its default. A solution is correct when its RA/Dec is within
0.1 deg of the truth's and its Roll within 0.1 deg of the truth's `roll_tetra3_deg`; otherwise
it is wrong. Prints one line per set: frames, solved, correct, wrong, median centre error.
"""
import json
import logging
import math
import statistics
import sys
from pathlib import Path


def unit(ra, dec):
    ra, dec = math.radians(ra), math.radians(dec)
    return (math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec))


def sep_deg(a, b):
    u, v = unit(*a), unit(*b)
    dot = max(-1.0, min(1.0, sum(x * y for x, y in zip(u, v))))
    return math.degrees(math.acos(dot))


def main():
    args = sys.argv[1:]
    out = None
    if "--out" in args:
        i = args.index("--out")
        out = Path(args[i + 1])
        del args[i : i + 2]
    here = Path(__file__).resolve().parent
    real = Path(args[0]) if args else here / ".." / ".." / "shared" / "data" / "real"
    import tetra3
    from PIL import Image

    logging.getLogger("tetra3.Tetra3").setLevel(logging.WARNING)
    t3 = tetra3.Tetra3()
    lines = []
    total = {"frames": 0, "solved": 0, "correct": 0, "wrong": 0}
    for set_dir in sorted(p for p in real.iterdir() if (p / "truth.jsonl").exists()):
        n = solved = correct = wrong = 0
        errors = []
        for line in (set_dir / "truth.jsonl").read_text().splitlines():
            t = json.loads(line)
            n += 1
            with Image.open(set_dir / t["file"]) as img:
                sol = t3.solve_from_image(img.convert("L"), fov_estimate=t["fov_x_deg"])
            rec = {"set": set_dir.name, "file": t["file"], "status": "unsolved"}
            if sol.get("RA") is not None:
                solved += 1
                err = sep_deg((sol["RA"], sol["Dec"]), (t["ra_deg"], t["dec_deg"]))
                d_roll = abs((sol["Roll"] - t["roll_tetra3_deg"] + 180.0) % 360.0 - 180.0)
                ok = err <= 0.1 and d_roll <= 0.1
                correct += ok
                wrong += not ok
                if ok:
                    errors.append(err * 3600.0)
                rec.update(status="correct" if ok else "wrong", centre_error_arcsec=err * 3600,
                           roll_error_deg=d_roll, fov=sol.get("FOV"), t_solve_ms=sol.get("T_solve"))
            lines.append(rec)
        med = f"{statistics.median(errors):.1f}" if errors else "-"
        print(f"{set_dir.name}: {n} frames, {solved} solved, {correct} correct, {wrong} wrong, "
              f"median centre error {med} arcsec", flush=True)
        for k, v in (("frames", n), ("solved", solved), ("correct", correct), ("wrong", wrong)):
            total[k] += v
    print(f"all: {total['frames']} frames, {total['solved']} solved, {total['correct']} correct, "
          f"{total['wrong']} wrong")
    if out:
        out.write_text("".join(json.dumps(r) + "\n" for r in lines))


if __name__ == "__main__":
    main()
