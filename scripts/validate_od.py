#!/usr/bin/env python3
"""Read gpustar's --tdm and --iod files with the readers orbit-determination users run.

    python3 scripts/validate_od.py [--trusat DIR] [--tle FILE] TDM IOD

* TDM: ccsds-ndm-py (PyPI `ccsds-ndm-py`, module `ccsds_ndm`; `pip install ccsds-ndm-py`):
  `Tdm.from_file(path).validate(strict=True)`, its strict CCSDS 503.0-B-2 validation. (PyPI's
  `ccsds-ndm` 3.x installs a module of the same name without this validator; keep them in
  separate environments.) A TDM path that does not exist is reported, not an error: gpustar
  writes no TDM for a run without a timed streak (TDM 2.0 requires a segment).
* IOD: TruSat's parser (PyPI `trusat` 0.9.0, `trusat/iod.py`): `format_test_iod` (its regex)
  and `parse_iod_lines` on every line. The sdist does not build (it needs Cython, numpy and a
  requirements.txt it lacks), so get its sources with
  `pip download trusat --no-deps --no-build-isolation --no-clean` (the unpacked tree stays in
  pip's temporary directory when metadata fails) and pass the folder holding `trusat/` with
  --trusat. Its `iod.py` imports `trusat.tle_util`, which needs numpy and sgp4 (`sgp4.ext`)
  and imports the `spacetrack` client for downloads it never makes here (stubbed when absent).
* IOD: sattools' `decode_iod_observation` (cbassa/sattools, src/satfit.c; C, not packaged):
  its column rules, as tests/it/common/formats.rs ports them (`sattools_decode`), are checked
  here again: at least 64 characters, `+`/`-` in column 55, digits in the MX columns 42-43
  and 63-64 (read with `%1d%1d`, which skip blanks), a designation in columns 7-15, a 4-digit
  station that is not 9999.

* Objects (tracklets, --tle): every TDM RADEC segment names its own object (PARTICIPANT_2)
  and is in time order; in the IOD lines an object number goes with one designation and a
  designation with one number. With --tle FILE (the elements the run was given), every
  object the lines name with a designation that is not stvid's unidentified scheme (day of
  year + 500) must be in the file with that NORAD id and its international designator.

Exit status 0 when every reader accepts every line (and the TDM), 1 otherwise.
"""
import argparse
import os
import sys


def check_tdm(path):
    if not os.path.exists(path):
        print(f"TDM {path}: no file (gpustar writes none for a run without a timed streak)")
        return True
    try:
        from ccsds_ndm import Tdm
    except ImportError:
        print("TDM: ccsds-ndm-py is not installed (pip install ccsds-ndm-py)")
        return False
    if not hasattr(Tdm, "validate"):
        print("TDM: this ccsds_ndm module is not ccsds-ndm-py's (no Tdm.validate)")
        return False
    try:
        tdm = Tdm.from_file(path)
        tdm.validate(strict=True)
    except Exception as e:  # the reader's own error, shown as it says it
        print(f"TDM {path}: REFUSED by ccsds-ndm-py: {e}")
        return False
    segs = tdm.body.segments if hasattr(tdm, "body") else tdm.segments
    n = len(segs)
    print(f"TDM {path}: ccsds-ndm-py strict validation passed ({n} segments)")
    return True


def sattools_rules(line):
    """What decode_iod_observation (satfit.c) needs to keep a line: the reasons it drops or
    misreads one, None when it keeps it."""
    if len(line) < 64:
        return f"{len(line)} characters (< 64: flag 0, skipped)"
    if line[54] not in "+-":
        return "column 55 is not + or - (skipped)"
    for cols, what in (((41, 42), "time uncertainty (42-43)"),
                       ((62, 63), "position uncertainty (63-64)")):
        if not all(line[c].isdigit() for c in cols):
            return f"{what} not two digits (%1d%1d shifts into the next columns)"
    if not line[44].isdigit() or not line[45].isdigit():
        return "angle format / epoch (45-46) not digits"
    if line[6:15].split() == []:
        return "no designation in columns 7-15 (%s %s reads the station instead)"
    if not line[16:20].isdigit():
        return "station (17-20) not 4 digits"
    if line[16:20] == "9999":
        return "station 9999 is no COSPAR site (get_site fails: flag 0)"
    return None


def check_iod(path, trusat_dir):
    with open(path, encoding="ascii") as f:
        text = f.read()
    lines = [l for l in text.split("\n") if l]
    ok = True
    if text and not text.endswith("\n"):
        # satfit.c strips the last character of every line as its newline.
        print(f"IOD {path}: last line has no newline (sattools would cut its last column)")
        ok = False
    bad = [(l, r) for l in lines if (r := sattools_rules(l))]
    for l, r in bad[:5]:
        print(f"IOD sattools rules: REFUSED {l!r}: {r}")
    print(f"IOD {path}: sattools rules: {len(lines) - len(bad)}/{len(lines)} lines kept")
    ok &= not bad
    if trusat_dir is None:
        print("IOD: TruSat not given (--trusat DIR): its check skipped")
        return False
    sys.path.insert(0, trusat_dir)
    import logging
    import types
    import warnings
    logging.disable(logging.CRITICAL)
    warnings.filterwarnings("ignore", category=SyntaxWarning)
    try:
        import spacetrack  # noqa: F401
    except ImportError:
        # tle_util imports spacetrack's client for its downloads only; the IOD parser
        # never calls it.
        sys.modules["spacetrack"] = types.SimpleNamespace(SpaceTrackClient=None)
    from trusat import iod  # noqa: E402  (also needs numpy and sgp4: pip install sgp4)
    fmt_bad = [l for l in lines if not iod.format_test_iod(l)]
    for l in fmt_bad[:5]:
        print(f"IOD TruSat format_test_iod: REFUSED {l!r}")
    parsed = iod.parse_iod_lines(text) or []
    complete = [p for p in parsed
                if p.InternationalDesignation and p.TimeUncertainty
                and p.PositionUncertainty and getattr(p, "ValidPosition", 0) != -1]
    print(f"IOD {path}: TruSat format_test_iod {len(lines) - len(fmt_bad)}/{len(lines)}; "
          f"parse_iod_lines {len(parsed)} records, {len(complete)} with designation, "
          f"both uncertainties and a valid position")
    for p in parsed[:3]:
        print(f"  {p.ObjectNumber} {p.InternationalDesignation} station {p.Station} "
              f"status {p.StationStatusCode!r} {p.DateTime} time unc {p.TimeUncertainty:g} s "
              f"RA {p.RA:.5f} Dec {p.DEC:.5f} pos unc {p.PositionUncertainty:g} deg")
    ok &= not fmt_bad and len(parsed) == len(lines) and len(complete) == len(lines)
    return ok


def check_objects(tdm_path, iod_path, tle_path):
    ok = True
    if os.path.exists(tdm_path):
        segs, cur = [], None
        for line in open(tdm_path, encoding="ascii"):
            k, _, v = line.partition("=")
            k, v = k.strip(), v.strip()
            if k == "META_START" or line.startswith("META_START"):
                cur = {"epochs": []}
                segs.append(cur)
            elif k in ("PARTICIPANT_2", "ANGLE_TYPE") and cur is not None:
                cur[k] = v
            elif k == "ANGLE_1" and cur is not None:
                cur["epochs"].append(v.split()[0])
        radec = [s for s in segs if s.get("ANGLE_TYPE") == "RADEC"]
        names = [s["PARTICIPANT_2"] for s in radec]
        dup = len(names) - len(set(names))
        unordered = sum(1 for s in radec if s["epochs"] != sorted(s["epochs"]))
        multi = sum(1 for s in radec if len(s["epochs"]) > 1)
        print(f"TDM objects: {len(radec)} RADEC segments, {len(set(names))} distinct objects "
              f"({dup} repeated), {multi} with more than one observation, {unordered} out of time order")
        ok &= dup == 0 and unordered == 0
    lines = [l for l in open(iod_path, encoding="ascii").read().split("\n") if l]
    by_num, by_des = {}, {}
    for l in lines:
        by_num.setdefault(l[0:5], set()).add(l[6:15].strip())
        by_des.setdefault(l[6:15].strip(), set()).add(l[0:5])
    clash = [n for n, d in by_num.items() if len(d) > 1] + [d for d, n in by_des.items() if len(n) > 1]
    print(f"IOD objects: {len(by_num)} object numbers, {len(clash)} numbers or designations shared")
    ok &= not clash
    if tle_path:
        tle = {}
        for l in open(tle_path, encoding="ascii"):
            if l.startswith("1 ") and len(l) >= 17:
                d = l[9:17].strip()
                tle[l[2:7].strip().zfill(5)] = f"{d[:2]} {d[2:]}"
        named = {n: d for n, ds in by_num.items() for d in ds if not (d[3:6].isdigit() and int(d[3:6]) >= 500)}
        wrong = {n: d for n, d in named.items() if tle.get(n) != d}
        print(f"IOD objects: {len(named)} named from the elements, {len(wrong)} not in {tle_path} as named"
              + (f" e.g. {list(wrong.items())[:3]}" if wrong else ""))
        ok &= not wrong
    return ok


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("tdm")
    ap.add_argument("iod")
    ap.add_argument("--trusat", help="folder holding TruSat's trusat/ package sources")
    ap.add_argument("--tle", help="the elements the run was given (--tle): named objects checked")
    a = ap.parse_args()
    ok = check_tdm(a.tdm)
    ok &= check_iod(a.iod, a.trusat)
    ok &= check_objects(a.tdm, a.iod, a.tle)
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
