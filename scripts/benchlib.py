"""Helpers shared by the peer benchmarks (bench_vs_cedar.py, bench_vs_tetra3rs.py): sky angles
for scoring against truth, JSON Lines, and CPU accounting. Standard library only."""
import json
import math
import os


def unit(ra_deg, dec_deg):
    ra, dec = math.radians(ra_deg), math.radians(dec_deg)
    return (math.cos(dec) * math.cos(ra), math.cos(dec) * math.sin(ra), math.sin(dec))


def sep_deg(ra1, dec1, ra2, dec2):
    """Angle between two sky directions in degrees. Uses atan2, which stays accurate at
    small angles."""
    a, b = unit(ra1, dec1), unit(ra2, dec2)
    cross = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
    dot = sum(x * y for x, y in zip(a, b))
    return math.degrees(math.atan2(math.sqrt(sum(c * c for c in cross)), dot))


def roll_diff_deg(r1, r2):
    """|r1 - r2| wrapped into [0, 180]."""
    d = (r1 - r2) % 360.0
    return min(d, 360.0 - d)


def read_jsonl(path):
    with open(path) as f:
        return [json.loads(line) for line in f if line.strip()]


def cpu_seconds():
    """(CPU-seconds busy on the whole machine, CPU-seconds of this process and its waited-for
    children), or None where /proc/stat is missing. The difference between two readings is
    what other processes took during the run."""
    try:
        with open("/proc/stat") as f:
            fields = [int(v) for v in f.readline().split()[1:]]
    except OSError:
        return None
    busy = sum(fields) - fields[3] - (fields[4] if len(fields) > 4 else 0)  # minus idle, iowait
    t = os.times()
    return busy / os.sysconf("SC_CLK_TCK"), t.user + t.system + t.children_user + t.children_system


def tail(text, n=15):
    return "\n".join((text or "").strip().splitlines()[-n:])


def other_load_note(cpu_before, cpu_after, wall):
    """A note on what other processes took of the machine during a run (from two
    cpu_seconds() readings), with a warning when it was more than 5 % of one core; None
    where /proc/stat is missing."""
    if not (cpu_before and cpu_after):
        return None
    other = max(0.0, (cpu_after[0] - cpu_before[0]) - (cpu_after[1] - cpu_before[1]))
    busy = other > 0.05 * wall
    return (f"{'**Warning**: ' if busy else ''}other processes used {other:.1f} CPU-seconds "
            f"during the {wall:.0f} s of the run ({100 * other / wall:.0f}% of one core)"
            + ("; the rates are not clean, rerun when the machine is idle." if busy else "."))
