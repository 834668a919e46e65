#!/usr/bin/env python3
"""Reproductions of issue 22 (reliability), for comparing gpustar before and after the fixes.

Runs each reproduction of the issue against the gpustar binary given by --bin and prints one line
per case, `case_id | what happened`, with the numbers that tell the behaviours apart (bytes before
and after, exit codes, record counts, seconds). With --json OUT the same lines are written as a
JSON object {case_id: text}.

The input frames are always made by the binary given by --sim-bin (default: this checkout's release
build), so two runs of this script with different --bin see identical inputs and only the binary
under test differs. Every case works in a fresh temporary directory; GPUSTAR_CACHE_DIR points at a
temporary directory per run of the script (case 2 uses its own), XDG_RUNTIME_DIR at /tmp/xdg.
Every subprocess runs in its own process group under a timeout: on timeout the group is killed and
the case reports "hung (killed after N s)".

    python3 scripts/reliability_repro.py --bin /tmp/old-target/release/gpustar --json old.json
    python3 scripts/reliability_repro.py --bin target/release/gpustar --json new.json

Standard library only.
"""

import argparse
import csv
import io
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import time
import zlib

HERE = os.path.dirname(os.path.abspath(__file__))
DEFAULT_SIM_BIN = os.path.join(os.path.dirname(HERE), "target", "release", "gpustar")

BIN = None  # the binary under test (set in main)
SIM_BIN = None  # the binary that makes the inputs
ENV = None  # environment of every gpustar process
FIX = None  # fixtures directory (inputs shared by the cases, read-only by convention)
WORK = None  # scratch root of this run

# Solving options of the 256x256 PNG sets.
PNG_OPTS = ["--fov-deg", "18", "--mag-limit", "6", "--backend", "cpu"]


# --------------------------------------------------------------------------------------------
# Running processes


class Result:
    def __init__(self, rc, out, err, secs, hung, timeout):
        self.rc, self.out, self.err, self.secs, self.hung, self.timeout = rc, out, err, secs, hung, timeout

    def status(self):
        """`rc=N` or `hung (killed after N s)` or `killed by SIGx`."""
        if self.hung:
            return "hung (killed after %d s)" % self.timeout
        if self.rc < 0:
            return "killed by %s" % signal.Signals(-self.rc).name
        return "rc=%d" % self.rc


class Proc:
    """A gpustar process in its own process group; stdout and stderr go to temporary files."""

    def __init__(self, argv, cwd=None):
        self.out = tempfile.TemporaryFile(dir=WORK)
        self.err = tempfile.TemporaryFile(dir=WORK)
        self.t0 = time.monotonic()
        self.p = subprocess.Popen(argv, cwd=cwd, env=ENV, stdin=subprocess.DEVNULL, stdout=self.out,
                                  stderr=self.err, start_new_session=True)

    def wait(self, timeout):
        """Waits at most `timeout` seconds from now; kills the process group if still running."""
        hung = False
        try:
            rc = self.p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            hung = True
            kill_group(self.p)
            rc = self.p.wait()
        secs = time.monotonic() - self.t0
        self.out.seek(0)
        self.err.seek(0)
        out = self.out.read().decode("utf-8", "replace")
        err = self.err.read().decode("utf-8", "replace")
        self.out.close()
        self.err.close()
        return Result(rc, out, err, secs, hung, timeout)


def kill_group(p):
    try:
        os.killpg(p.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass


def run(argv, timeout=60, cwd=None):
    return Proc(argv, cwd).wait(timeout)


def gp(*args, timeout=60, cwd=None):
    """Runs the binary under test."""
    return run([BIN] + list(args), timeout=timeout, cwd=cwd)


def simulate(out, *args):
    r = run([SIM_BIN, "simulate", "--out", out] + list(args), timeout=120)
    if r.rc != 0:
        raise RuntimeError("simulate failed: %s %s" % (r.status(), r.err[-300:]))


# --------------------------------------------------------------------------------------------
# Small helpers


def tail(text, n=1, width=220):
    """The last n non-empty stderr lines (progress-bar carriage returns dropped), shortened."""
    lines = []
    for line in text.splitlines():
        line = line.split("\r")[-1].strip()
        if line:
            lines.append(line)
    s = " / ".join(lines[-n:]) if lines else "(empty)"
    return s if len(s) <= width else s[: width - 3] + "..."


def grep(text, word, width=220):
    """The stderr lines that contain `word`, joined; '(none)' if none."""
    hits = [l.split("\r")[-1].strip() for l in text.splitlines() if word in l]
    s = " / ".join(hits) if hits else "(none)"
    return s if len(s) <= width else s[: width - 3] + "..."


def short(s, width=160):
    s = str(s)
    return s if len(s) <= width else s[: width - 3] + "..."


def case_dir(name):
    d = os.path.join(WORK, name)
    os.makedirs(d)
    return d


def copy_frames(src, dst, names):
    os.makedirs(dst, exist_ok=True)
    for n in names:
        shutil.copy(os.path.join(src, n), os.path.join(dst, n))


def png_frames(k):
    return ["sim_%05d.png" % i for i in range(k)]


def png_set(dst, k):
    """A directory with the first k frames of the 256x256 PNG set."""
    copy_frames(os.path.join(FIX, "png"), dst, png_frames(k))
    return dst


def size(path):
    return os.path.getsize(path) if os.path.exists(path) else None


def read_records(path):
    """JSON Lines records of `path`; lines that do not parse are counted, not returned."""
    recs, bad = [], 0
    if not os.path.exists(path):
        return recs, bad
    with open(path, "rb") as f:
        for line in f.read().split(b"\n"):
            if not line.strip():
                continue
            try:
                recs.append(json.loads(line))
            except ValueError:
                bad += 1
    return recs, bad


def count_lines(path):
    if not os.path.exists(path):
        return 0
    with open(path, "rb") as f:
        return f.read().count(b"\n")


def per_file(files):
    """{name: count} of a list of names."""
    c = {}
    for f in files:
        c[f] = c.get(f, 0) + 1
    return c


def rec_summary(r, warnings=False):
    s = "%s %s" % (r.get("file"), r.get("status"))
    if r.get("error"):
        s += " (error: %s)" % short(r["error"], 120)
    if warnings and r.get("warnings"):
        s += " warnings=[%s]" % ", ".join(short(w, 100) for w in r["warnings"])
    return s


def first_error(text, width=220):
    """The first stderr line that says error (clap's or gpustar's; with the next line when it ends
    with a colon), else the last line."""
    lines = [l.split("\r")[-1].strip() for l in text.splitlines()]
    lines = [l for l in lines if l]
    for i, line in enumerate(lines):
        if "error" in line:
            if line.endswith(":") and i + 1 < len(lines):
                line += " " + lines[i + 1]
            return short(line, width)
    return tail(text)


# --------------------------------------------------------------------------------------------
# FITS and PNG


def fits_read(path):
    """(cards without END, data bytes) of a single-HDU FITS file."""
    with open(path, "rb") as f:
        raw = f.read()
    cards, off = [], 0
    while True:
        block = raw[off: off + 2880]
        off += 2880
        done = False
        for i in range(0, 2880, 80):
            c = block[i: i + 80].decode("ascii")
            if c[:8].strip() == "END":
                done = True
                break
            if c.strip():
                cards.append(c)
        if done:
            return cards, raw[off:]


def fits_card(key, value):
    if isinstance(value, str):
        v = "'%-8s'" % value.replace("'", "''")
    elif isinstance(value, bool):
        v = "%20s" % ("T" if value else "F")
    else:
        v = "%20s" % (repr(value) if isinstance(value, float) else str(value))
    return ("%-8s= %s" % (key, v)).ljust(80)[:80]


def fits_raw_card(key, value_text):
    """A card whose value is written exactly as given (e.g. '1E10')."""
    return ("%-8s= %20s" % (key, value_text)).ljust(80)[:80]


def fits_edit(cards, set_=None, remove=()):
    """Cards with `remove` keys dropped and `set_` {key: value or raw card} replacing or appended."""
    set_ = set_ or {}
    drop = set(remove) | set(set_)
    out = [c for c in cards if c[:8].strip() not in drop]
    for k, v in set_.items():
        out.append(v if isinstance(v, str) and len(v) == 80 and v.startswith(k) else fits_card(k, v))
    return out


def fits_write(path, cards, data):
    head = "".join(cards) + "END".ljust(80)
    head += " " * (-len(head) % 2880)
    data = data + b"\0" * (-len(data) % 2880)
    with open(path, "wb") as f:
        f.write(head.encode("ascii"))
        f.write(data)


def fits_rewrite(src, dst, set_=None, remove=()):
    cards, data = fits_read(src)
    fits_write(dst, fits_edit(cards, set_, remove), data)


def fits_to_float(src, dst, hot=None):
    """The u16 FITS `src` as BITPIX -32; hot = (x, y, value) sets one pixel."""
    cards, data = fits_read(src)
    get = {c[:8].strip(): c[10:].split("/")[0].strip() for c in cards}
    w, h = int(get["NAXIS1"]), int(get["NAXIS2"])
    bzero = float(get.get("BZERO", "0"))
    vals = struct.unpack(">%dh" % (w * h), data[: 2 * w * h])
    fl = [v + bzero for v in vals]
    if hot:
        x, y, v = hot
        fl[y * w + x] = v
    out = struct.pack(">%df" % (w * h), *fl)
    fits_write(dst, fits_edit(cards, {"BITPIX": -32}, remove=("BZERO", "BSCALE")), out)


def png_chunk(kind, data):
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data) & 0xFFFFFFFF)


def write_black_png(path, w, h):
    """An all-zero 8-bit grey PNG, compressed row by row (never the whole image in memory)."""
    c = zlib.compressobj(1)
    row = b"\0" * (w + 1)
    parts = [c.compress(row) for _ in range(h)]
    parts.append(c.flush())
    with open(path, "wb") as f:
        f.write(b"\x89PNG\r\n\x1a\n")
        f.write(png_chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)))
        f.write(png_chunk(b"IDAT", b"".join(parts)))
        f.write(png_chunk(b"IEND", b""))


# --------------------------------------------------------------------------------------------
# Fixtures (made once per run by --sim-bin)


def make_fixtures():
    simulate(os.path.join(FIX, "png"), "-n", "150", "--fov-deg", "18", "--size", "256x256", "--seed", "9")
    simulate(os.path.join(FIX, "streaks"), "--streaks", "-n", "3", "--size", "512x512", "--fov-deg", "12",
             "--mag-limit", "7.5")
    simulate(os.path.join(FIX, "seq"), "--sequence", "--sequences", "2", "-n", "12", "--seed", "5")
    simulate(os.path.join(FIX, "big"), "-n", "60", "--fov-deg", "18", "--size", "1024x1024", "--seed", "9")
    write_black_png(os.path.join(FIX, "huge.png"), 30000, 30000)


def streak_frame(i):
    return os.path.join(FIX, "streaks", "sim_%05d.fits" % i)


def streak_camera():
    return os.path.join(FIX, "streaks", "camera.toml")


def streak_opts():
    return ["--streaks", "--camera", streak_camera(), "--backend", "cpu"]


NOTES = b"observing log\n2024-03-15 clear, seeing 2\"\nflat fields taken at dusk\n"


# --------------------------------------------------------------------------------------------
# Cases: 1 outputs that are not gpustar's


def case_1a():
    d = case_dir("1a")
    inp = png_set(os.path.join(d, "in"), 4)
    out = os.path.join(d, "notes.txt")
    open(out, "wb").write(NOTES)
    before = size(out)
    r = gp("batch", inp, *PNG_OPTS, "-o", out, "--resume")
    intact = open(out, "rb").read().startswith(NOTES)
    return "notes.txt -o --resume: %d bytes before, %s after, notes intact: %s; %s; stderr: %s" % (
        before, size(out), intact, r.status(), tail(r.err))


def case_1b():
    d = case_dir("1b")
    inp = png_set(os.path.join(d, "in"), 4)
    out = os.path.join(inp, "sim_00001.png")
    before = size(out)
    orig = open(out, "rb").read()
    r = gp("batch", inp, *PNG_OPTS, "-o", out, "--resume")
    intact = open(out, "rb").read() == orig
    return "input PNG as -o --resume: %d bytes before, %s after, PNG intact: %s; %s; stderr: %s" % (
        before, size(out), intact, r.status(), tail(r.err))


def csv_rows(path):
    """Data rows of a gpustar CSV (header lines and JSON lines not counted) and JSON lines."""
    text = open(path, "rb").read().decode("utf-8", "replace")
    rows, js = [], 0
    for line in text.splitlines():
        if line.startswith("{"):
            js += 1
    for row in csv.reader(io.StringIO("\n".join(l for l in text.splitlines() if not l.startswith("{")))):
        if row and row[0] != "file":
            rows.append(row)
    return rows, js


def case_1c():
    d = case_dir("1c")
    inp = png_set(os.path.join(d, "in"), 4)
    out = os.path.join(d, "out.csv")
    r1 = gp("batch", inp, *PNG_OPTS, "--format", "csv", "-o", out, "-q")
    rows0, _ = csv_rows(out)
    lines0 = count_lines(out)
    r = gp("batch", inp, *PNG_OPTS, "-o", out, "--resume")
    rows1, js1 = csv_rows(out)
    return ("CSV (%s) resumed as jsonl: %d lines/%d CSV rows before, %d lines after (%d CSV rows, %d JSON lines); "
            "%s; stderr: %s" % (r1.status(), lines0, len(rows0), count_lines(out), len(rows1), js1, r.status(),
                                tail(r.err)))


def case_1d():
    d = case_dir("1d")
    inp = png_set(os.path.join(d, "in"), 4)
    out = os.path.join(d, "out.jsonl")
    gp("batch", inp, *PNG_OPTS, "-o", out, "-q")
    lines0 = count_lines(out)
    r = gp("batch", inp, *PNG_OPTS, "--format", "csv", "-o", out, "--resume")
    recs, _ = read_records(out)
    rows, _ = csv_rows(out)
    counts = per_file([x["file"] for x in recs] + [row[0] for row in rows])
    return ("JSONL resumed with --format csv: %d lines before, %d after; records per input %s; %s; stderr: %s" % (
        lines0, count_lines(out), sorted(set(counts.values())) if len(counts) == 4 else counts, r.status(),
        tail(r.err)))


def case_1e():
    d = case_dir("1e")
    inp = png_set(os.path.join(d, "in"), 4)
    out = os.path.join(d, "notes.txt")
    open(out, "wb").write(NOTES)
    before = size(out)
    r = gp("batch", inp, *PNG_OPTS, "-o", out)
    intact = open(out, "rb").read().startswith(NOTES)
    return "notes.txt -o (no --resume): %d bytes before, %s after, notes intact: %s; %s; stderr: %s" % (
        before, size(out), intact, r.status(), tail(r.err))


# --------------------------------------------------------------------------------------------
# Case 2: a corrupted distance-table cache


def case_2():
    d = case_dir("2")
    inp = png_set(os.path.join(d, "in"), 4)
    cache = os.path.join(d, "cache")
    os.makedirs(cache)
    global ENV
    env_saved = ENV
    ENV = dict(ENV, GPUSTAR_CACHE_DIR=cache)
    try:
        r1 = gp("batch", inp, *PNG_OPTS, "-o", os.path.join(d, "a.jsonl"), "-q")
        tables = sorted((f for f in os.listdir(cache) if f.startswith("table-") and f.endswith(".bin")),
                        key=lambda f: size(os.path.join(cache, f)))
        if not tables:
            return "first run %s wrote no table-*.bin (cache dir: %s)" % (r1.status(), os.listdir(cache))
        path = os.path.join(cache, tables[-1])
        n = size(path)
        with open(path, "r+b") as f:
            f.seek(n // 2)
            f.write(b"\xff" * 64)
        out = os.path.join(d, "b.jsonl")
        r = gp("batch", inp, *PNG_OPTS, "-o", out)
        recs, _ = read_records(out)
        with open(path, "rb") as f:
            f.seek(n // 2)
            still = f.read(64) == b"\xff" * 64 if os.path.exists(path) else False
        statuses = [x["status"] for x in recs]
        errs = sorted(set(short(x["error"], 80) for x in recs if x.get("error")))
        return ("table %s (%d bytes), 64 bytes 0xFF at the middle; 2nd run %s, statuses %s%s; cache still corrupt "
                "after: %s; stderr: %s" % (tables[-1][:16] + "...", n, r.status(), statuses,
                                           (", errors %s" % errs) if errs else "", still, tail(r.err, 2)))
    finally:
        ENV = env_saved


# --------------------------------------------------------------------------------------------
# Case 3: a huge SIP order


def case_3():
    d = case_dir("3")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    fits_rewrite(streak_frame(0), os.path.join(inp, "sip.fits"), {
        "CTYPE1": "RA---TAN-SIP", "CTYPE2": "DEC--TAN-SIP", "CRPIX1": 256, "CRPIX2": 256,
        "CRVAL1": 10, "CRVAL2": 20, "CD1_1": 0.0234, "CD1_2": 0, "CD2_1": 0, "CD2_2": 0.0234,
        "A_ORDER": 2147483647, "B_ORDER": 2})
    args = ["batch", inp, "--streaks", "--astrometry", "header", "--backend", "cpu"]
    out = os.path.join(d, "a.jsonl")
    r = gp(*args, "-o", out, timeout=30)
    recs, _ = read_records(out)
    first = "%s in %.1f s, record: %s" % (r.status(), r.secs, rec_summary(recs[0], True) if recs else "none")
    # Again, with one SIGTERM after 2 s.
    p = Proc([BIN] + args + ["-o", os.path.join(d, "b.jsonl")])
    try:
        p.p.wait(timeout=2)
        second = "exited before the SIGTERM (after %.1f s, rc=%d)" % (time.monotonic() - p.t0, p.p.returncode)
        p.wait(1)
    except subprocess.TimeoutExpired:
        t_sig = time.monotonic()
        os.kill(p.p.pid, signal.SIGTERM)
        r2 = p.wait(30)
        after = time.monotonic() - t_sig
        second = "SIGTERM at 2 s: %s, %.1f s from signal to exit" % (
            r2.status() if not r2.hung else "hung (killed 30 s after the signal)", after)
    return "A_ORDER=2147483647, --astrometry header: %s; %s" % (first, second)


# --------------------------------------------------------------------------------------------
# Case 4: two --resume processes on one output


def case_4():
    d = case_dir("4")
    inp = png_set(os.path.join(d, "in"), 150)
    out = os.path.join(d, "out.jsonl")
    argv = [BIN, "batch", inp, *PNG_OPTS, "-j", "1", "-o", out, "--resume", "-q"]
    a = Proc(argv)
    b = Proc(argv)
    ra, rb = a.wait(120), b.wait(120)
    recs, bad = read_records(out)
    counts = per_file(x["file"] for x in recs)
    twice = sum(1 for v in counts.values() if v >= 2)
    return ("two --resume at once, 150 frames: %s / %s; %d lines (%d torn), %d inputs with a record, %d with two or "
            "more; stderr: %s | %s" % (ra.status(), rb.status(), count_lines(out), bad, len(counts), twice,
                                       tail(ra.err), tail(rb.err)))


# --------------------------------------------------------------------------------------------
# Case 5: absurd exposure times


def case_5():
    d = case_dir("5")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    shutil.copy(streak_frame(0), os.path.join(inp, "sim_00000.fits"))
    for i, exp in ((1, "1E10"), (2, "1E300")):
        fits_rewrite(streak_frame(i), os.path.join(inp, "sim_%05d.fits" % i),
                     {"DATE-OBS": "2024-03-15T20:00:00", "EXPTIME": fits_raw_card("EXPTIME", exp),
                      "OBSGEO-B": 35.7, "OBSGEO-L": 51.4, "OBSGEO-H": 1200},
                     remove=("DATE-BEG", "DATE-END"))
    out, tdm, iod = (os.path.join(d, n) for n in ("out.jsonl", "t.tdm", "t.iod"))
    r = gp("batch", inp, *streak_opts(), "--tdm", tdm, "--iod", iod, "-o", out)
    recs, _ = read_records(out)
    longest = 0
    for x in recs:
        for s in x.get("streaks") or []:
            for e in s.get("ends") or []:
                if e.get("time_utc"):
                    longest = max(longest, len(e["time_utc"]))
    panic = "panicked" in r.err or any("internal error" in (x.get("error") or "") for x in recs)
    return ("EXPTIME 1E10 / 1E300: %s; records: %s; longest streak-end time_utc %d chars; TDM %s bytes, IOD %s bytes; "
            "panic/internal error: %s; stderr: %s" % (r.status(), "; ".join(rec_summary(x, True) for x in recs), longest,
                                                     size(tdm), size(iod), panic, tail(r.err)))


# --------------------------------------------------------------------------------------------
# Case 6: dates far off or in the wrong unit


def epoch_summary(x):
    w = x.get("warnings") or []
    return "%s %s epoch=%s warnings=%s" % (x.get("file"), x.get("status"), x.get("epoch"),
                                          [short(s, 100) for s in w] if w else "[]")


def case_6():
    d = case_dir("6")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    shutil.copy(streak_frame(0), os.path.join(inp, "a_unmodified.fits"))
    fits_rewrite(streak_frame(0), os.path.join(inp, "b_date9999.fits"), {"DATE-OBS": "9999-12-31"},
                 remove=("DATE-BEG", "DATE-END"))
    fits_rewrite(streak_frame(0), os.path.join(inp, "c_mjd_is_jd.fits"), {"MJD-OBS": 2460000.5},
                 remove=("DATE-OBS", "DATE-BEG", "DATE-END"))
    out = os.path.join(d, "out.jsonl")
    r = gp("batch", inp, "--camera", streak_camera(), "--backend", "cpu", "-o", out)
    recs, _ = read_records(out)
    return "%s; %s" % (r.status(), "; ".join(epoch_summary(x) for x in recs))


# --------------------------------------------------------------------------------------------
# Case 7: names that are not UTF-8


def case_7():
    d = case_dir("7")
    inp = png_set(os.path.join(d, "in"), 1)
    good = os.path.join(inp, "sim_00000.png")
    for name in (b"\xff.png", b"\xfe.png"):
        shutil.copy(os.fsencode(good), os.path.join(os.fsencode(inp), name))
    out = os.path.join(d, "out.jsonl")
    r1 = gp("batch", inp, *PNG_OPTS, "-o", out, "-q")
    recs, _ = read_records(out)
    files1 = [x["file"] for x in recs]
    data = open(out, "rb").read()
    lines = data.split(b"\n")[:-1]
    open(out, "wb").write(b"\n".join(lines[:-1]) + b"\n")
    r2 = gp("batch", inp, *PNG_OPTS, "-o", out, "--resume")
    recs2, _ = read_records(out)
    counts = per_file(x["file"] for x in recs2)
    return ("first run %s, file fields %s (%d distinct for 3 inputs); after deleting the last line, --resume %s: "
            "records per file field {%s}; stderr: %s" % (r1.status(), "[%s]" % ", ".join(ascii(f) for f in files1),
                                                       len(set(files1)), r2.status(),
                                                       ", ".join("%s: %d" % (ascii(k), v) for k, v in counts.items()),
                                                     grep(r2.err, "already have")))


# --------------------------------------------------------------------------------------------
# Case 8: merge without a directory, and a torn part


def case_8():
    d = case_dir("8")
    inp = png_set(os.path.join(d, "in"), 8)
    parts = []
    for k in (0, 1):
        p = os.path.join(d, "part%d.jsonl" % k)
        gp("batch", inp, *PNG_OPTS, "--shard", "%d/2" % k, "-o", p, "-q")
        parts.append(p)
    n0, n1 = count_lines(parts[0]), count_lines(parts[1])
    m1 = os.path.join(d, "m1.jsonl")
    r1 = gp("merge", parts[0], "-o", m1)
    m2 = os.path.join(d, "m2.jsonl")
    r2 = gp("merge", parts[0], "--dir", inp, "-o", m2)
    cut = os.path.join(d, "part1cut.jsonl")
    data = open(parts[1], "rb").read()
    open(cut, "wb").write(data[:-20])
    m3 = os.path.join(d, "m3.jsonl")
    r3 = gp("merge", parts[0], cut, "--dir", inp, "-o", m3)
    return ("parts %d+%d lines; merge part 0 alone, no --dir: %s, %d records out (stderr: %s); part 0 alone with "
            "--dir: %s (stderr: %s); part 1 cut by 20 bytes, --dir: %s, %d lines out (%d whole records), stderr: %s"
            % (n0, n1, r1.status(), count_lines(m1), first_error(r1.err), r2.status(), first_error(r2.err), r3.status(),
               count_lines(m3), len(read_records(m3)[0]), first_error(r3.err)))


# --------------------------------------------------------------------------------------------
# Case 9: error records and --resume's exit status


def case_9():
    d = case_dir("9")
    inp = png_set(os.path.join(d, "in"), 3)
    open(os.path.join(inp, "sim_00001.png"), "wb").write(b"not a png")
    out = os.path.join(d, "out.jsonl")
    r1 = gp("batch", inp, *PNG_OPTS, "-o", out)
    r2 = gp("batch", inp, *PNG_OPTS, "-o", out, "--resume")
    return "garbage sim_00001.png: first run %s; --resume %s, %d lines; resume stderr: %s" % (
        r1.status(), r2.status(), count_lines(out), tail(r2.err, 2))


# --------------------------------------------------------------------------------------------
# Case 10: resuming a sequence


def case_10():
    d = case_dir("10")
    inp = os.path.join(d, "seq")
    shutil.copytree(os.path.join(FIX, "seq"), inp)
    args = ["batch", inp, "-r", "--sequence", "--backend", "cpu", "--camera", os.path.join(inp, "camera.toml")]
    clean = os.path.join(d, "clean.jsonl")
    r1 = gp(*args, "-o", clean, "-q")
    lines = open(clean, "rb").read().split(b"\n")
    resumed = os.path.join(d, "resumed.jsonl")
    open(resumed, "wb").write(b"\n".join(lines[:11]) + b"\n")
    r2 = gp(*args, "-o", resumed, "--resume")
    a, _ = read_records(clean)
    b, _ = read_records(resumed)
    strip = lambda x: {k: v for k, v in x.items() if k != "timing_ms"}
    ca = {x["file"]: strip(x) for x in a}
    cb = {x["file"]: strip(x) for x in b}
    differ = sum(1 for f in ca if cb.get(f) != ca[f])
    changed = [f for f in ca if f in cb and cb[f].get("status") != ca[f].get("status")]
    return ("clean %s (%d records, %d solved); resumed after 11 lines %s (%d records): %d records differ from clean "
            "(timing_ms ignored), status changed for %d frames%s; resume stderr: %s" % (
                r1.status(), len(a), sum(x["status"] == "solved" for x in a), r2.status(), len(b), differ,
                len(changed), (" " + str(changed)) if changed else "", tail(r2.err)))


# --------------------------------------------------------------------------------------------
# Case 11: a float FITS with one absurd pixel


def case_11():
    d = case_dir("11")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    shutil.copy(streak_frame(0), os.path.join(inp, "a_u16.fits"))
    fits_to_float(streak_frame(0), os.path.join(inp, "b_float.fits"))
    fits_to_float(streak_frame(0), os.path.join(inp, "c_float_1e9.fits"), hot=(100, 100, 1e9))
    out = os.path.join(d, "out.jsonl")
    r = gp("batch", inp, "--camera", streak_camera(), "--backend", "cpu", "-o", out, "-q")
    recs, _ = read_records(out)
    return "%s; %s" % (r.status(), "; ".join(
        "%s %s stars_detected=%s" % (x["file"], x["status"], x.get("stars_detected")) for x in recs))


# --------------------------------------------------------------------------------------------
# Cases S1-S9


def case_S1():
    d = case_dir("S1")
    inp = png_set(os.path.join(d, "in"), 2)
    os.mkfifo(os.path.join(inp, "fifo.png"))
    out = os.path.join(d, "out.jsonl")
    r = gp("batch", inp, *PNG_OPTS, "-o", out, timeout=20)
    recs, _ = read_records(out)
    fifo = [x for x in recs if x["file"] == "fifo.png"]
    return "FIFO fifo.png + 2 frames: %s in %.1f s; %d records; fifo.png has a record: %s%s" % (
        r.status(), r.secs, len(recs), bool(fifo), (" (%s)" % rec_summary(fifo[0])) if fifo else "")


def case_S2():
    d = case_dir("S2")
    inp = os.path.join(FIX, "big")
    out = os.path.join(d, "out.jsonl")
    p = Proc([BIN, "batch", inp, *PNG_OPTS, "-j", "1", "-o", out])
    t_sig = None
    while p.p.poll() is None and time.monotonic() - p.t0 < 60:
        if count_lines(out) >= 1:
            t_sig = time.monotonic()
            os.kill(p.p.pid, signal.SIGTERM)
            break
        time.sleep(0.002)
    r = p.wait(30 if t_sig else 1)
    recs, bad = read_records(out)
    if t_sig is None:
        return "run ended before a line appeared (%s)" % r.status()
    return ("SIGTERM after the first line (%.2f s in): %s, %.2f s from signal to exit; %d whole records of 60, "
            "torn last line: %s; stderr: %s" % (t_sig - p.t0, r.status() if not r.hung else
                                                "hung (killed 30 s after the signal)", time.monotonic() - t_sig
                                                if r.hung else r.secs - (t_sig - p.t0), len(recs), bad > 0,
                                                tail(r.err)))


def case_S3():
    d = case_dir("S3")
    inp = png_set(os.path.join(d, "in"), 1)
    parts = []
    for i, opt in enumerate((["--pair-tol-px=1e9"], ["--sigma=nan"], ["--match-radius-px=-1"])):
        out = os.path.join(d, "o%d.jsonl" % i)
        r = gp("batch", inp, *PNG_OPTS, *opt, "-o", out, timeout=30)
        recs, _ = read_records(out)
        parts.append("%s: %s in %.1f s%s%s" % (" ".join(opt), r.status(), r.secs,
                                              (", record " + rec_summary(recs[0])) if recs else ", no record",
                                              (", stderr: " + first_error(r.err)) if r.rc != 0 else ""))
    return "; ".join(parts)


def case_S4():
    d = case_dir("S4")
    inp = os.path.join(d, "in")
    copy_frames(os.path.join(FIX, "streaks"), inp, ["sim_%05d.fits" % i for i in range(3)])
    out = os.path.join(d, "out.jsonl")
    r = gp("batch", inp, *streak_opts(), "--tdm", "/nonexistent-dir/x.tdm", "-o", out)
    return "--tdm /nonexistent-dir/x.tdm: %s in %.1f s; %d output lines; stderr: %s" % (
        r.status(), r.secs, count_lines(out), tail(r.err))


def case_S5():
    d = case_dir("S5")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    open(os.path.join(inp, "bad.fits"), "wb").write(b"hello world")
    out = os.path.join(d, "out.jsonl")
    r = gp("batch", inp, *PNG_OPTS, "-o", out)
    recs, _ = read_records(out)
    return "bad.fits = b'hello world': %s; error: %s" % (
        r.status(), ascii(recs[0].get("error")) if recs else "no record")


def case_S6():
    d = case_dir("S6")
    inp = png_set(os.path.join(d, "in"), 3)
    r = gp("batch", inp, *PNG_OPTS, "-o", "/dev/full")
    return "-o /dev/full: %s; stderr: %s" % (r.status(), tail(r.err))


def case_S7():
    d = case_dir("S7")
    inp = png_set(os.path.join(d, "in"), 2)
    shutil.copy(os.path.join(inp, "sim_00000.png"), os.path.join(inp, "a\nb.png"))
    out = os.path.join(d, "out.csv")
    r1 = gp("batch", inp, *PNG_OPTS, "--format", "csv", "-o", out)
    rows1, _ = csv_rows(out)
    r2 = gp("batch", inp, *PNG_OPTS, "--format", "csv", "-o", out, "--resume")
    rows2, _ = csv_rows(out)
    return ("name with a newline, CSV: first run %s, %d data rows; --resume %s, %d data rows (%d raw lines), files %s; "
            "stderr: %s" % (r1.status(), len(rows1), r2.status(), len(rows2), count_lines(out),
                            "[%s]" % ", ".join(ascii(r[0]) for r in rows2), grep(r2.err, "already have")))


def peak_rss_run(argv, timeout):
    """(Result, peak RSS in MiB or None): /usr/bin/time -v when present, else polling VmHWM."""
    if os.path.exists("/usr/bin/time"):
        r = run(["/usr/bin/time", "-v"] + argv, timeout=timeout)
        kb = None
        for line in r.err.splitlines():
            if "Maximum resident set size" in line:
                kb = int(line.split(":")[-1])
        return r, (kb / 1024 if kb is not None else None)
    p = Proc(argv)
    hwm = 0
    while p.p.poll() is None and time.monotonic() - p.t0 < timeout:
        try:
            for line in open("/proc/%d/status" % p.p.pid):
                if line.startswith("VmHWM:"):
                    hwm = max(hwm, int(line.split()[1]))
        except OSError:
            pass
        time.sleep(0.05)
    return p.wait(max(0.1, timeout - (time.monotonic() - p.t0))), hwm / 1024


def case_S8():
    d = case_dir("S8")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    shutil.copy(os.path.join(FIX, "huge.png"), os.path.join(inp, "huge.png"))
    out = os.path.join(d, "out.jsonl")
    r, mib = peak_rss_run([BIN, "batch", inp, "--camera", os.path.join(FIX, "png", "camera.toml"),
                           "--backend", "cpu", "-o", out], 60)
    recs, _ = read_records(out)
    return "30000x30000 zero PNG (%d bytes) with a 256x256 camera: %s in %.1f s, peak RSS %s MiB; record: %s" % (
        size(os.path.join(FIX, "huge.png")), r.status(), r.secs, "%.0f" % mib if mib is not None else "?",
        rec_summary(recs[0]) if recs else "none")


def case_S9():
    d = case_dir("S9")
    inp = os.path.join(d, "in")
    os.makedirs(inp)
    fits_rewrite(streak_frame(0), os.path.join(inp, "date_beg_only.fits"), remove=("DATE-OBS", "DATE-END", "MJD-OBS"))
    out = os.path.join(d, "out.jsonl")
    r = gp("batch", inp, "--camera", streak_camera(), "--backend", "cpu", "-o", out, "-q")
    recs, _ = read_records(out)
    return "DATE-BEG 2024-03-15T20:00:00 only: %s; %s" % (r.status(), epoch_summary(recs[0]) if recs else "no record")


CASES = [("1a", case_1a), ("1b", case_1b), ("1c", case_1c), ("1d", case_1d), ("1e", case_1e), ("2", case_2),
         ("3", case_3), ("4", case_4), ("5", case_5), ("6", case_6), ("7", case_7), ("8", case_8), ("9", case_9),
         ("10", case_10), ("11", case_11), ("S1", case_S1), ("S2", case_S2), ("S3", case_S3), ("S4", case_S4),
         ("S5", case_S5), ("S6", case_S6), ("S7", case_S7), ("S8", case_S8), ("S9", case_S9)]


def main():
    global BIN, SIM_BIN, ENV, FIX, WORK
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", required=True, help="the gpustar binary under test")
    ap.add_argument("--sim-bin", default=DEFAULT_SIM_BIN, help="the gpustar that makes the input frames")
    ap.add_argument("--json", help="also write {case_id: text} here")
    ap.add_argument("--only", help="comma-separated case ids to run (default: all)")
    ap.add_argument("--keep", action="store_true", help="keep the scratch directory")
    a = ap.parse_args()
    BIN, SIM_BIN = os.path.abspath(a.bin), os.path.abspath(a.sim_bin)
    WORK = tempfile.mkdtemp(prefix="repro-", dir="/tmp")
    FIX = os.path.join(WORK, "fixtures")
    os.makedirs("/tmp/xdg", exist_ok=True)
    cache = os.path.join(WORK, "cache")
    os.makedirs(cache)
    ENV = dict(os.environ, GPUSTAR_CACHE_DIR=cache, XDG_RUNTIME_DIR="/tmp/xdg")
    ENV.pop("RUST_LOG", None)
    only = set(a.only.split(",")) if a.only else None
    results = {}
    try:
        t0 = time.monotonic()
        make_fixtures()
        print("# gpustar under test: %s (inputs by %s; fixtures %.0f s)" % (BIN, SIM_BIN, time.monotonic() - t0),
              flush=True)
        for cid, fn in CASES:
            if only and cid not in only:
                continue
            t = time.monotonic()
            try:
                text = fn()
            except Exception as e:  # a broken case must not stop the others
                text = "script error: %s: %s" % (type(e).__name__, e)
            text = text.replace("\n", "\\n")
            results[cid] = text
            print("%s | %s" % (cid, text), flush=True)
            print("#   (%s took %.1f s)" % (cid, time.monotonic() - t), file=sys.stderr, flush=True)
    finally:
        if a.json:
            with open(a.json, "w") as f:
                json.dump(results, f, indent=1, ensure_ascii=True)
        if a.keep:
            print("# scratch kept in %s" % WORK, file=sys.stderr)
        else:
            shutil.rmtree(WORK, ignore_errors=True)


if __name__ == "__main__":
    main()
