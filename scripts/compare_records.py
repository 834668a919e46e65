#!/usr/bin/env python3
"""Compare two result files record by record, as the GPU = CPU check does: the same status,
the same HIP ids at the same centroids, and the attitude difference (arcsec).
   scripts/compare_records.py A.jsonl B.jsonl [--position-tolerance PX]
With --centroid ml the GPU's f32 fits differ from the CPU's f64 ones by ~1e-6 px: give the
tolerance (e.g. 1e-5) to compare centroids within it; exact otherwise."""
import json, math, sys

def star_key(s):
    """A star's identity in records and truth files: its catalog_id ("HIP 27989", "Gaia DR3 ...")
    where written, else its HIP (truth files of the Python simulators, older records)."""
    return s.get("catalog_id") or f"HIP {s['hip']}"


def records(path):
    return [json.loads(l) for l in open(path) if l.strip()]

args = [x for x in sys.argv[1:] if not x.startswith("--")]
tol = 0.0
if "--position-tolerance" in sys.argv:
    tol = float(sys.argv[sys.argv.index("--position-tolerance") + 1])
    args.remove(str(sys.argv[sys.argv.index("--position-tolerance") + 1]))
a, b = records(args[0]), records(args[1])
assert len(a) == len(b), f"{len(a)} vs {len(b)} records"
worst, differ = 0.0, 0
for x, y in zip(a, b):
    same = x["file"] == y["file"] and x["status"] == y["status"]
    mx = [(star_key(m), m["x"], m["y"]) for m in x["matches"] or []]
    my = [(star_key(m), m["x"], m["y"]) for m in y["matches"] or []]
    same = same and len(mx) == len(my) and all(
        p[0] == q[0] and abs(p[1] - q[1]) <= tol and abs(p[2] - q[2]) <= tol for p, q in zip(mx, my)
    )
    if x["rotation_matrix"] and y["rotation_matrix"]:
        r, s = x["rotation_matrix"], y["rotation_matrix"]
        # |R - S|_F = 2 sqrt(2) sin(angle / 2): accurate for tiny angles, unlike acos(trace).
        frob = math.sqrt(sum((r[i][k] - s[i][k]) ** 2 for i in range(3) for k in range(3)))
        angle = 2 * math.asin(min(1.0, frob / (2 * math.sqrt(2))))
        worst = max(worst, math.degrees(angle) * 3600)
    if not same:
        differ += 1
        print("differs:", x["file"])
print(f"{len(a)} records, {differ} differ in status or identified stars; "
      f"largest attitude difference {worst:.6f} arcsec; backends: {a[0]['backend']!r} vs {b[0]['backend']!r}")
sys.exit(1 if differ else 0)
