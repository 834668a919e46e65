"""Solve the real frames of ../shared/data/real/esa-tetra3 from numpy arrays and compare each
attitude with the set's truth (astrometry.net's). Needs Pillow to read the TIFFs.

    python examples/python/solve_real.py [DATA_DIR]

Exits 0 with a printed reason when the frames are not there (and 1 if any frame is wrong).
"""
import json, pathlib, sys
import numpy as np
import gpustar

repo = pathlib.Path(__file__).resolve().parents[2]
data = pathlib.Path(sys.argv[1]) if len(sys.argv) > 1 else repo.parent / "shared/data/real/esa-tetra3"
if not (data / "truth.jsonl").exists():
    sys.exit(print(f"SKIPPED solve_real.py: no real frames at {data}") or 0)
from PIL import Image  # noqa: E402  (only needed when the frames are there)

truth = {t["file"]: t for t in map(json.loads, open(data / "truth.jsonl"))}
solver = gpustar.Solver(camera=repo / "scripts/cameras/esa-tetra3.toml", epoch=2019.58, backend="cpu")
names = sorted(truth)
images = [np.array(Image.open(data / n)) for n in names]          # uint16, 768 x 1024
wrong = 0
for r in solver.solve_many(images, names=names):
    t = truth[r.file]
    if not r.solved:
        print(f"{r.file}: {r.status} ({r.reason or r.error})"); wrong += 1; continue
    # Angle between the solved and the true boresight (third row of ICRS->camera), by chord.
    chord = np.linalg.norm(r.rotation_matrix[2] - np.array(t["rotation_matrix"])[2])
    off = np.degrees(2 * np.arcsin(chord / 2)) * 3600
    wrong += off > 600
    print(f"{r.file}: ra {r.ra_deg:9.4f} dec {r.dec_deg:8.4f} roll {r.roll_deg:8.3f}  "
          f"{len(r.matches)} stars, {off:5.1f}\" from truth")
print(f"{len(names) - wrong} of {len(names)} frames solved within 10' of the truth")
sys.exit(1 if wrong else 0)
