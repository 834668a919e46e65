#!/usr/bin/env python3
"""Reproductions of issue 45 (every file gpustar writes guarded; no input aborts a run), for
comparing gpustar before and after the fixes.

Prints one line per case, `case_id | what happened`, with what tells the behaviours apart (bytes
of the files at stake before and after, exit codes, seconds, what was written). Inputs are made
by --sim-bin, so two runs with different --bin see the same inputs. Every process runs in its own
process group under a timeout (the helpers of scripts/reliability_repro.py).

    python3 scripts/reliability45_repro.py --bin /tmp/gpustar-before > before.txt
    python3 scripts/reliability45_repro.py --bin target/debug/gpustar > after.txt

Standard library only. Run as root, the unreadable-folder case runs the binary as `nobody`.
"""

import argparse
import hashlib
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import reliability_repro as rr  # noqa: E402

PNG = ["--fov-deg", "18", "--mag-limit", "6", "--backend", "cpu"]


def digest(path):
    """`N bytes #abcd` of a file, or `absent`, or what it is if not a regular file."""
    if os.path.islink(path) and not os.path.exists(path):
        return "dangling link"
    if not os.path.exists(path):
        return "absent"
    if not os.path.isfile(path):
        return "not a file"
    b = open(path, "rb").read()
    return "%d bytes #%s" % (len(b), hashlib.sha1(b).hexdigest()[:6])


def kept(path, before):
    now = digest(path)
    return "kept (%s)" % now if now == before else "CHANGED %s -> %s" % (before, now)


def err(r):
    return rr.first_error(r.err) if "error" in r.err else rr.tail(r.err)


def frames(d):
    """Three 18° PNG frames and a FITS: x.png and x.fits share a stem."""
    rr.png_set(d, 3)
    os.rename(os.path.join(d, "sim_00000.png"), os.path.join(d, "x.png"))
    r = rr.run([rr.SIM_BIN, "simulate", "--out", d + "_fits", "-n", "1", "--fov-deg", "18", "--size",
                "256x256", "--hint-offset-deg", "1"], timeout=120)
    assert r.rc == 0, r.err
    shutil.move(os.path.join(d + "_fits", "sim_00000.fits"), os.path.join(d, "x.fits"))
    return d


def case_1a():
    d = frames(rr.case_dir("1a") + "/in")
    x = os.path.join(d, "x.png")
    before, listing = digest(x), sorted(os.listdir(d))
    r = rr.gp("batch", d, *PNG, "--annotate-dir", d, "-o", d + "/../r.jsonl")
    added = sorted(set(os.listdir(d)) - set(listing))
    return "%s; input x.png %s; new files in the input folder %s; %s" % (
        r.status(), kept(x, before), added or "none", err(r))


def case_1b():
    d = frames(rr.case_dir("1b") + "/in")
    ann, wcs = d + "/../ann", d + "/../wcs"
    r = rr.gp("batch", d, *PNG, "--annotate-dir", ann, "--wcs-dir", wcs, "-o", d + "/../r.jsonl")
    return "%s; annotations %s; WCS %s" % (
        r.status(), sorted(os.listdir(ann)) if os.path.isdir(ann) else "-",
        sorted(os.listdir(wcs)) if os.path.isdir(wcs) else "-")


def case_2a():
    c = rr.case_dir("2a")
    d = rr.png_set(c + "/in", 2)
    x = c + "/x"
    r = rr.gp("batch", d, *PNG, "--streaks", "--tdm", x, "-o", x)
    head = open(x).read(40).replace("\n", " ") if os.path.exists(x) else "-"
    return "%s; X holds: %r; %s" % (r.status(), head, err(r))


def case_2b():
    c = rr.case_dir("2b")
    r = rr.gp("batch", rr.streak_frame(0).rsplit("/", 1)[0], *rr.streak_opts(), "--tdm", c + "/x",
              "--iod", c + "/./x", "-o", c + "/r.jsonl", timeout=120)
    head = open(c + "/x").read(30).replace("\n", " ") if os.path.exists(c + "/x") else "-"
    return "%s; X holds %r; stderr: %s" % (r.status(), head, rr.grep(r.err, "wrote") if "error" not in r.err
                                           else err(r))


def case_3(name, text):
    c = rr.case_dir(name)
    d = rr.png_set(c + "/in", 2)
    p = c + "/target"
    open(p, "w").write(text)
    before = digest(p)
    r = rr.gp("batch", d, *PNG, "-o", p)
    m = rr.gp("merge", "--no-check", "-o", p)
    return "batch -o: %s, file %s; merge -o: %s, file %s" % (r.status(), kept(p, before), m.status(),
                                                             kept(p, before))


def case_3a():
    return case_3("3a", '{\n  "file": "settings of my own"\n}\n')


def case_3b():
    return case_3("3b", "fix the mount on friday\n")


def case_5():
    c = rr.case_dir("5")
    d = rr.png_set(c + "/in", 3)
    shutil.copy(os.path.join(rr.FIX, "png", "camera.toml"), c + "/cam.toml")
    notes = c + "/notes.toml"
    open(notes, "w").write("# my lens\nfocal = 50\n")
    before = digest(notes)
    out = []
    for target in [notes, c + "/cam.toml", c + "/no/such/dir/cam.toml"]:
        b = digest(target)
        r = rr.gp("calibrate", d, "--camera", c + "/cam.toml", "-o", target, timeout=120)
        out.append("-o %s: %s in %.1f s, %s" % (os.path.relpath(target, c), r.status(), r.secs,
                                                 kept(target, b) if b != "absent" else digest(target)))
    return "; ".join(out) + "; notes %s" % kept(notes, before)


def streak_run(c, *more, timeout=120):
    return rr.gp("batch", os.path.dirname(rr.streak_frame(0)), *rr.streak_opts(), "-o", c + "/r.jsonl",
                 *more, timeout=timeout)


def case_6a():
    c = rr.case_dir("6a")
    p = c + "/theirs.tdm"
    open(p, "w").write("CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2026-01-01T00:00:00\nORIGINATOR = OTHER\n")
    b = digest(p)
    r = streak_run(c, "--tdm", p)
    return "%s; another originator's TDM %s" % (r.status(), kept(p, b))


def case_6b():
    c = rr.case_dir("6b")
    p = c + "/obs.iod"
    open(p, "w").write("25544 98 067A   4353 G 20260101000000000 17 25 0000000+000000 37\n")
    b = digest(p)
    r = streak_run(c, "--iod", p)
    first = kept(p, b)
    r2 = streak_run(c, "--iod", p, "--overwrite")
    after_overwrite = digest(p)
    r3 = streak_run(c, "--iod", p)
    return "%s, sattools' IOD %s; --overwrite: %s (%s); rerun on gpustar's own: %s" % (
        r.status(), first, r2.status(), after_overwrite, r3.status())


def case_6c():
    c = rr.case_dir("6c")
    target, link = c + "/target.tdm", c + "/link.tdm"
    open(target, "w").write("")
    os.symlink(target, link)
    r = streak_run(c, "--tdm", link)
    return "%s; link.tdm is %s; target %s; mode %o" % (
        r.status(), "still a link" if os.path.islink(link) else "a regular file now", digest(target),
        stat.S_IMODE(os.stat(link).st_mode))


def case_7():
    c = rr.case_dir("7")
    d = rr.png_set(c + "/in", 2)
    os.makedirs(d + "/sub")
    shutil.copy(d + "/sim_00000.png", d + "/sub/a.png")
    empty = c + "/empty"
    os.makedirs(empty)
    e = rr.gp("batch", empty, *PNG)
    parts = ["empty folder: %s %s" % (e.status(), rr.tail(e.err))]
    if os.geteuid() == 0:
        # root reads any folder: run the binary as nobody (everything here world-readable).
        for p in [rr.WORK, rr.BIN]:
            os.chmod(p, 0o755)
        subprocess.run(["chmod", "-R", "a+rX", c])
        os.chmod(d + "/sub", 0)
        cache = c + "/cache"
        os.makedirs(cache)
        os.chmod(cache, 0o777)
        base = ["runuser", "-u", "nobody", "--", "env", "GPUSTAR_CACHE_DIR=" + cache, rr.BIN]
    else:
        os.chmod(d + "/sub", 0)
        base = [rr.BIN]
    r = rr.run(base + ["batch", d, "-r"] + PNG)
    records = [l for l in r.out.splitlines() if l.strip()]
    parts.append("unreadable subfolder (-r): %s, %d records (%s)" % (
        r.status(), len(records), rr.short(", ".join(l[:40] for l in records), 140)))
    os.chmod(d + "/sub", 0o755)
    os.chmod(d, 0)
    r = rr.run(base + ["batch", d] + PNG)
    os.chmod(d, 0o755)
    parts.append("unreadable folder: %s %s" % (r.status(), rr.tail(r.err)))
    return "; ".join(parts)


def case_10():
    c = rr.case_dir("10")
    fifo = c + "/f.tdm"
    os.mkfifo(fifo)
    r = streak_run(c, "--tdm", fifo, timeout=20)
    z = streak_run(c, "--tdm", "/dev/zero", timeout=20)
    return "FIFO: %s in %.1f s; /dev/zero: %s in %.1f s, %s" % (r.status(), r.secs, z.status(), z.secs, err(z))


def case_11():
    c = rr.case_dir("11")
    d = rr.png_set(c + "/in", 2)
    os.makedirs(c + "/wcs")
    p = c + "/wcs/sim_00001.wcs"
    open(p, "w").write("%-80s" % "SIMPLE  =                    T / by astrometry.net")
    b = digest(p)
    r = rr.gp("batch", d, *PNG, "--wcs-dir", c + "/wcs", "-o", c + "/r.jsonl")
    return "%s; astrometry.net's sim_00001.wcs %s" % (r.status(), kept(p, b))


def case_low_products_dir():
    c = rr.case_dir("lowdir")
    d = rr.png_set(c + "/in", 3)
    open(c + "/file", "w").write("x")
    r = rr.gp("batch", d, *PNG, "--wcs-dir", c + "/file/wcs", "-o", c + "/r.jsonl")
    return "--wcs-dir under a file: %s, %d warnings; %s" % (r.status(), r.err.count("WARN"), rr.tail(r.err))


def case_low_retry_order():
    c = rr.case_dir("lowretry")
    d = rr.png_set(c + "/in", 3)
    good = open(d + "/sim_00001.png", "rb").read()
    open(d + "/sim_00001.png", "wb").write(b"not a png")
    rr.gp("batch", d, *PNG, "-o", c + "/r.jsonl")
    open(d + "/sim_00001.png", "wb").write(good)
    r = rr.gp("batch", d, *PNG, "-o", c + "/r.jsonl", "--resume", "--retry-errors")
    names = [x["file"] for x in rr.read_records(c + "/r.jsonl")[0]]
    return "%s; record order %s" % (r.status(), names)


def case_low_output_in_dir():
    c = rr.case_dir("lowoutdir")
    d = rr.png_set(c + "/in", 2)
    r = rr.gp("batch", d, *PNG, "-o", d + "/results.png")
    r2 = rr.gp("batch", d, *PNG, "-o", d + "/results.png", "--resume")
    return "first: %s; --resume: %s, %s" % (r.status(), r2.status(), rr.tail(r2.err))


def case_low_cache_dir():
    c = rr.case_dir("lowcache")
    d = rr.png_set(c + "/in", 1)
    work = c + "/work"
    os.makedirs(work)
    env = dict(rr.ENV, GPUSTAR_CACHE_DIR="", XDG_CACHE_HOME=c + "/xdg")
    t0 = time.monotonic()
    p = subprocess.run([rr.BIN, "batch", d] + PNG, cwd=work, env=env, capture_output=True, timeout=60)
    return "rc=%d in %.1f s; files left in the working directory: %s" % (
        p.returncode, time.monotonic() - t0, sorted(os.listdir(work)) or "none")


def case_low_escape():
    c = rr.case_dir("lowescape")
    d = c + "/in"
    os.makedirs(d)
    good = open(os.path.join(rr.FIX, "png", "sim_00000.png"), "rb").read()
    for name in [b"\xff.png", b"\\xff.png"]:
        open(os.path.join(d.encode(), name), "wb").write(good)
    r = rr.gp("batch", d, *PNG, "-o", c + "/r.jsonl")
    names = [x["file"] for x in rr.read_records(c + "/r.jsonl")[0]] if os.path.exists(c + "/r.jsonl") else []
    return "%s; records %s; %s" % (r.status(), names, rr.tail(r.err))


CASES = [
    ("1a", case_1a), ("1b", case_1b), ("2a", case_2a), ("2b", case_2b), ("3a", case_3a), ("3b", case_3b),
    ("5", case_5), ("6a", case_6a), ("6b", case_6b), ("6c", case_6c), ("7", case_7), ("10", case_10),
    ("11", case_11), ("low-dirs", case_low_products_dir), ("low-retry", case_low_retry_order),
    ("low-out-in-dir", case_low_output_in_dir), ("low-cache", case_low_cache_dir), ("low-escape", case_low_escape),
]


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--bin", required=True, help="the gpustar binary under test")
    ap.add_argument("--sim-bin", default=rr.DEFAULT_SIM_BIN, help="the gpustar that makes the input frames")
    ap.add_argument("--only", help="comma-separated case ids to run (default: all)")
    a = ap.parse_args()
    rr.BIN, rr.SIM_BIN = os.path.abspath(a.bin), os.path.abspath(a.sim_bin)
    rr.WORK = tempfile.mkdtemp(prefix="repro45-", dir="/tmp")
    rr.FIX = os.path.join(rr.WORK, "fixtures")
    os.makedirs("/tmp/xdg", exist_ok=True)
    cache = os.path.join(rr.WORK, "cache")
    os.makedirs(cache)
    rr.ENV = dict(os.environ, GPUSTAR_CACHE_DIR=cache, XDG_RUNTIME_DIR="/tmp/xdg")
    rr.ENV.pop("RUST_LOG", None)
    only = set(a.only.split(",")) if a.only else None
    try:
        rr.simulate(os.path.join(rr.FIX, "png"), "-n", "3", "--fov-deg", "18", "--size", "256x256", "--seed", "9")
        rr.simulate(os.path.join(rr.FIX, "streaks"), "--streaks", "-n", "2", "--size", "512x512", "--fov-deg",
                    "12", "--mag-limit", "7.5")
        print("# gpustar under test: %s (inputs by %s)" % (rr.BIN, rr.SIM_BIN), flush=True)
        for cid, fn in CASES:
            if only and cid not in only:
                continue
            try:
                text = fn()
            except Exception as e:  # a broken case must not stop the others
                text = "script error: %s: %s" % (type(e).__name__, e)
            print("%s | %s" % (cid, text.replace("\n", "\\n")), flush=True)
    finally:
        shutil.rmtree(rr.WORK, ignore_errors=True)


if __name__ == "__main__":
    main()
