//! `batch --streaks` through the real binary: frames of `simulate --streaks`, the records'
//! ends, times and Az/El, the TDM and IOD files read back by their parsers, header astrometry,
//! and frames whose headers lack or garble the time or the station.

use crate::common;

use common::formats::{parse_iod_line, parse_tdm, sattools_decode, trusat_format_test};
use common::{gpustar, run_records, truths};
use gpustar::camera::Camera;
use gpustar::io::frame::Frame;
use nalgebra::Matrix3;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Eight 512² frames of 12° with streaks, in `tmp/sim`.
fn simulated(tmp: &Path) -> PathBuf {
    common::simulated_streaks(tmp, 8)
}

/// `batch DIR --streaks --camera DIR/camera.toml` on `backend`.
fn streaks_cmd(dir: &Path, backend: &str) -> std::process::Command {
    let mut cmd = gpustar();
    cmd.args([
        "batch",
        dir.to_str().unwrap(),
        "--backend",
        backend,
        "--streaks",
    ])
    .args(["--camera", dir.join("camera.toml").to_str().unwrap()]);
    cmd
}

fn batch(dir: &Path, extra: &[&str]) -> Vec<Value> {
    run_records(streaks_cmd(dir, "cpu").args(extra))
}

fn xy(v: &Value) -> (f64, f64) {
    (v["x"].as_f64().unwrap(), v["y"].as_f64().unwrap())
}

fn dist(a: (f64, f64), b: [f64; 2]) -> f64 {
    ((a.0 - b[0]).powi(2) + (a.1 - b[1]).powi(2)).sqrt()
}

#[test]
fn streak_ends_times_azel_and_the_tdm_and_iod_files() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let (tdm, iod) = (tmp.path().join("out.tdm"), tmp.path().join("out.iod"));
    let records = batch(
        &dir,
        &[
            "--tdm",
            tdm.to_str().unwrap(),
            "--iod",
            iod.to_str().unwrap(),
            "--iod-station",
            "4171",
        ],
    );
    let truth = truths(&dir);
    assert_eq!(records.len(), 8);
    let mut mids = Vec::new();
    for (r, t) in records.iter().zip(&truth) {
        assert_eq!(r["status"], "solved", "{r}");
        let found = r["streaks"].as_array().unwrap();
        let want = t["streaks"].as_array().unwrap();
        assert_eq!(
            found.len(),
            want.len(),
            "{}: {found:?} vs {want:?}",
            r["file"]
        );
        for w in want {
            let p = |k: &str| -> [f64; 2] {
                let a = w[k].as_array().unwrap();
                [a[0].as_f64().unwrap(), a[1].as_f64().unwrap()]
            };
            let (p0, p1) = (p("p0"), p("p1"));
            // The record streak on this line, ends in either order.
            let s = found
                .iter()
                .find(|s| {
                    let (a, b) = (xy(&s["ends"][0]), xy(&s["ends"][1]));
                    let on = |q: (f64, f64)| {
                        let (dx, dy) = (p1[0] - p0[0], p1[1] - p0[1]);
                        ((q.0 - p0[0]) * dy - (q.1 - p0[1]) * dx).abs() / dx.hypot(dy) < 1.0
                    };
                    on(a) && on(b)
                })
                .unwrap_or_else(|| panic!("{}: no streak along {w}", r["file"]));
            let edges = [w["edge0"].as_bool().unwrap(), w["edge1"].as_bool().unwrap()];
            let (e0, e1) = (&s["ends"][0], &s["ends"][1]);
            let swap = dist(xy(e0), p0) + dist(xy(e1), p1) > dist(xy(e0), p1) + dist(xy(e1), p0);
            let (near0, near1) = if swap { (e1, e0) } else { (e0, e1) };
            for (end, truth_p, edge) in [(near0, p0, edges[0]), (near1, p1, edges[1])] {
                assert_eq!(end["edge"].as_bool(), Some(edge), "{}: {s}", r["file"]);
                if edge {
                    assert!(end["time_utc"].is_null() && end["az_deg"].is_null());
                } else {
                    assert!(
                        dist(xy(end), truth_p) < 1.0,
                        "{}: {end} vs {truth_p:?}",
                        r["file"]
                    );
                    assert!(
                        end["ra_deg"].is_f64() && end["az_deg"].is_f64() && end["el_deg"].is_f64()
                    );
                    let time = end["time_utc"].as_str().unwrap();
                    assert!(
                        time == t["date_beg_utc"] || time == t["date_end_utc"],
                        "{time}"
                    );
                }
            }
            if !edges[0] && !edges[1] {
                mids.push(s["mid"].clone());
            }
        }
    }
    assert!(!mids.is_empty(), "the set has streaks inside the frame");
    // TDM: a RADEC and an AZEL segment per timed midpoint, the record's values.
    let tdm = parse_tdm(&std::fs::read_to_string(&tdm).unwrap()).unwrap();
    let radec: Vec<_> = tdm
        .segments
        .iter()
        .filter(|s| s.meta_value("ANGLE_TYPE") == Some("RADEC"))
        .collect();
    assert_eq!(radec.len(), mids.len());
    assert_eq!(tdm.segments.len(), 2 * mids.len());
    for (seg, m) in radec.iter().zip(&mids) {
        let ra = seg.values("ANGLE_1")[0];
        assert_eq!(ra.0, m["time_utc"].as_str().unwrap());
        assert!((ra.1 - m["ra_deg"].as_f64().unwrap()).abs() < 1e-8);
        assert!((seg.values("ANGLE_2")[0].1 - m["dec_deg"].as_f64().unwrap()).abs() < 1e-8);
    }
    // IOD: one line per midpoint, to the format's resolution (0.001 min of RA, 0.01′ of Dec).
    let lines: Vec<String> = std::fs::read_to_string(&iod)
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    assert_eq!(lines.len(), mids.len());
    // Each streak its own object; the station named in the TDM (the headers' OBSGEO-B/L/H).
    let mut objects: Vec<_> = lines.iter().map(|l| l[..15].to_string()).collect();
    objects.sort();
    objects.dedup();
    assert_eq!(objects.len(), lines.len(), "{lines:?}");
    for seg in &tdm.segments {
        assert_eq!(
            seg.meta_value("PARTICIPANT_1"),
            Some("station at lat 35.70000 lon 51.40000 h 1200.0 m")
        );
    }
    for (line, m) in lines.iter().zip(&mids) {
        // What sattools and TruSat read.
        let s = sattools_decode(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        assert!(trusat_format_test(line), "{line}");
        assert_eq!(s.site, 4171);
        assert!(s.st > 0.0 && s.sr > 0.0, "{line}");
        let o = parse_iod_line(line).unwrap();
        let dra = (o.ra_deg - m["ra_deg"].as_f64().unwrap()).abs();
        assert!(dra.min(360.0 - dra) < 0.001 / 60.0 * 15.0, "{line}: {m}");
        assert!((o.dec_deg - m["dec_deg"].as_f64().unwrap()).abs() < 0.01 / 60.0);
        assert_eq!(o.time_utc, m["time_utc"].as_str().unwrap());
    }
}

/// Rewrite a FITS frame with other header cards (the pixels kept).
fn rewrite(src: &Path, dst: &Path, cards: &[String]) {
    let f = Frame::read(src).unwrap();
    std::fs::write(
        dst,
        gpustar::io::fits::encode_u16(f.width, f.height, &f.pixels, cards),
    )
    .unwrap();
}

#[test]
fn frames_without_time_or_station_keep_their_ends_and_say_why() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let bad = tmp.path().join("bad");
    std::fs::create_dir(&bad).unwrap();
    std::fs::copy(dir.join("camera.toml"), bad.join("camera.toml")).unwrap();
    let q = |v: &str| format!("'{v}'");
    let src = dir.join("sim_00000.fits");
    let cases: [(&str, Vec<String>); 4] = [
        ("a_none.fits", vec![]),
        (
            "b_y2k.fits",
            vec![
                gpustar::io::fits::card("DATE-OBS", &q("15/03/24")),
                gpustar::io::fits::card("EXPTIME", "5"),
            ],
        ),
        (
            "c_time_only.fits",
            vec![
                gpustar::io::fits::card("TIME-OBS", &q("20:00:00")),
                gpustar::io::fits::card("EXPTIME", "5"),
            ],
        ),
        (
            "d_no_station.fits",
            vec![
                gpustar::io::fits::card("DATE-OBS", &q("2024-03-15T20:00:00")),
                gpustar::io::fits::card("EXPTIME", "5"),
            ],
        ),
    ];
    for (name, cards) in &cases {
        rewrite(&src, &bad.join(name), cards);
    }
    let records = batch(&bad, &[]);
    assert_eq!(records.len(), 4);
    for r in &records {
        let streaks = r["streaks"].as_array().unwrap();
        assert!(!streaks.is_empty(), "{r}");
        let warnings = r["warnings"].to_string();
        for s in streaks {
            for e in s["ends"].as_array().unwrap() {
                assert!(e["x"].is_f64() && e["ra_deg"].is_f64(), "{e}");
                assert!(e["az_deg"].is_null() && e["el_deg"].is_null(), "{e}");
            }
        }
        let file = r["file"].as_str().unwrap();
        match file {
            "d_no_station.fits" => {
                // A time, but no station: times, no Az/El.
                assert!(warnings.contains("--station"), "{warnings}");
                let inside = streaks
                    .iter()
                    .flat_map(|s| s["ends"].as_array().unwrap())
                    .find(|e| e["edge"] == false);
                if let Some(e) = inside {
                    assert!(e["time_utc"].is_string());
                }
            }
            _ => {
                assert!(warnings.contains("no exposure time"), "{file}: {warnings}");
                if file == "b_y2k.fits" {
                    assert!(warnings.contains("15/03/24"), "{warnings}");
                }
                if file == "c_time_only.fits" {
                    assert!(warnings.contains("TIME-OBS"), "{warnings}");
                }
                for s in streaks {
                    for e in s["ends"].as_array().unwrap() {
                        assert!(e["time_utc"].is_null());
                    }
                }
            }
        }
    }
}

#[test]
fn header_astrometry_gives_the_solution_s_ra_dec() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let solved = batch(&dir, &["--astrometry", "solve"]);
    // The first frame with a streak, with a TAN WCS of its true attitude in the header.
    let truth = truths(&dir);
    let k = truth
        .iter()
        .position(|t| !t["streaks"].as_array().unwrap().is_empty())
        .unwrap();
    let t = &truth[k];
    let r: Vec<Vec<f64>> = serde_json::from_value(t["rotation_matrix"].clone()).unwrap();
    let r = Matrix3::from_fn(|i, j| r[i][j]);
    let camera = Camera::from_fov(512, 512, 12.0).unwrap();
    let one = tmp.path().join("one");
    std::fs::create_dir(&one).unwrap();
    std::fs::copy(dir.join("camera.toml"), one.join("camera.toml")).unwrap();
    let name = t["file"].as_str().unwrap();
    rewrite(
        &dir.join(name),
        &one.join(name),
        &gpustar::io::wcs::wcs_header(&camera, &r),
    );
    let header = batch(&one, &["--astrometry", "header"]);
    // Without a camera at all: the stars are not identified, the streaks the same.
    let mut cmd = gpustar();
    cmd.args([
        "batch",
        one.to_str().unwrap(),
        "--streaks",
        "--astrometry",
        "header",
    ]);
    let alone = run_records(&mut cmd);
    assert_eq!(alone[0]["status"], "unsolved");
    assert_eq!(alone[0]["reason"], "no_camera");
    assert_eq!(alone[0]["streaks"], header[0]["streaks"]);
    let (a, b) = (&solved[k]["streaks"], &header[0]["streaks"]);
    assert_eq!(a.as_array().unwrap().len(), b.as_array().unwrap().len());
    for (sa, sb) in a.as_array().unwrap().iter().zip(b.as_array().unwrap()) {
        for e in 0..2 {
            let (ea, eb) = (&sa["ends"][e], &sb["ends"][e]);
            let dra = (ea["ra_deg"].as_f64().unwrap() - eb["ra_deg"].as_f64().unwrap()).abs()
                * eb["dec_deg"].as_f64().unwrap().to_radians().cos();
            let ddec = (ea["dec_deg"].as_f64().unwrap() - eb["dec_deg"].as_f64().unwrap()).abs();
            // The solution's attitude is within a few arcseconds of the truth.
            assert!(dra.hypot(ddec) * 3600.0 < 10.0, "{ea} vs {eb}");
        }
    }
}

/// `batch --streaks --tdm --iod` on `dir`; the process's output.
fn exports_run(dir: &Path, tdm: &Path, iod: &Path, extra: &[&str]) -> std::process::Output {
    streaks_cmd(dir, "cpu")
        .args([
            "--tdm",
            tdm.to_str().unwrap(),
            "--iod",
            iod.to_str().unwrap(),
        ])
        .args(extra)
        .output()
        .unwrap()
}

#[test]
fn exports_without_streaks_with_odd_names_and_after_a_failed_run() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    let truth = truths(&dir);
    let name = |k: usize| truth[k]["file"].as_str().unwrap().to_string();
    let inside = |k: usize| {
        truth[k]["streaks"]
            .as_array()
            .unwrap()
            .iter()
            .any(|w| !w["edge0"].as_bool().unwrap() && !w["edge1"].as_bool().unwrap())
    };
    let (tdm, iod) = (tmp.path().join("o.tdm"), tmp.path().join("o.iod"));

    // 1. No streak: no TDM (an older one gpustar wrote is removed, and stderr says so), an
    //    empty IOD file, and the warning for the default station code.
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    std::fs::copy(dir.join("camera.toml"), empty.join("camera.toml")).unwrap();
    let k = (0..truth.len())
        .find(|&k| truth[k]["streaks"].as_array().unwrap().is_empty())
        .expect("a frame without a streak");
    std::fs::copy(dir.join(name(k)), empty.join(name(k))).unwrap();
    // Another program's TDM is refused before the run, untouched; with --overwrite and
    // nothing to export it is left as it was (issue 45, item 6).
    let theirs = "CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2026-01-01T00:00:00\nORIGINATOR = OTHER\n";
    std::fs::write(&tdm, theirs).unwrap();
    let out = exports_run(&empty, &tdm, &iod, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("does not hold a TDM gpustar wrote"), "{err}");
    let out = exports_run(&empty, &tdm, &iod, &["--overwrite"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("not a TDM gpustar wrote, left as it was"),
        "{err}"
    );
    assert_eq!(std::fs::read_to_string(&tdm).unwrap(), theirs);
    std::fs::write(&tdm, theirs.replace("OTHER", "GPUSTAR")).unwrap();
    let out = exports_run(&empty, &tdm, &iod, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(!tdm.exists(), "{err}");
    assert!(err.contains("no TDM") && err.contains("removed"), "{err}");
    assert!(err.contains("9999") && err.contains("COSPAR"), "{err}");
    assert_eq!(std::fs::read_to_string(&iod).unwrap(), "");

    // 2. A name that is not ASCII, and a header that names the observatory: escaped, not
    //    refused; the IOD line as for any name.
    let odd = tmp.path().join("odd");
    std::fs::create_dir(&odd).unwrap();
    std::fs::copy(dir.join("camera.toml"), odd.join("camera.toml")).unwrap();
    let k = (0..truth.len())
        .find(|&k| inside(k))
        .expect("a streak inside a frame");
    let q = |v: &str| format!("'{v}'");
    let t = &truth[k];
    let cards = [
        gpustar::io::fits::card("DATE-BEG", &q(t["date_beg_utc"].as_str().unwrap())),
        gpustar::io::fits::card("DATE-END", &q(t["date_end_utc"].as_str().unwrap())),
        gpustar::io::fits::card("OBSGEO-B", "35.7"),
        gpustar::io::fits::card("OBSGEO-L", "51.4"),
        gpustar::io::fits::card("OBSGEO-H", "1200"),
        gpustar::io::fits::card("OBSERVAT", &q("Ondrejov")),
    ];
    rewrite(&dir.join(name(k)), &odd.join("café €.fits"), &cards);
    let out = exports_run(&odd, &tdm, &iod, &["--iod-station", "4171"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(!err.contains("9999"), "{err}");
    let text = std::fs::read_to_string(&tdm).unwrap();
    let parsed = parse_tdm(&text).unwrap();
    assert!(!parsed.segments.is_empty());
    for seg in &parsed.segments {
        let object = seg.meta_value("PARTICIPANT_2").unwrap();
        assert!(object.contains("(caf\\u{e9} \\u{20ac}.fits#"), "{object}");
        assert_eq!(
            seg.meta_value("PARTICIPANT_1"),
            Some("Ondrejov (lat 35.70000 lon 51.40000 h 1200.0 m)")
        );
    }
    let lines = std::fs::read_to_string(&iod).unwrap();
    assert_eq!(lines.lines().count(), parsed.segments.len() / 2, "{lines}");
    for line in lines.lines() {
        sattools_decode(line).unwrap_or_else(|e| panic!("{line}: {e}"));
        assert!(trusat_format_test(line), "{line}");
    }

    // 3. A run that fails (its output is a file gpustar did not write) leaves both files as
    //    they were.
    let before = (std::fs::read(&tdm).unwrap(), std::fs::read(&iod).unwrap());
    let foreign = tmp.path().join("notes.txt");
    std::fs::write(&foreign, "my notes\n").unwrap();
    let out = exports_run(&dir, &tdm, &iod, &["-o", foreign.to_str().unwrap()]);
    assert!(!out.status.success());
    assert_eq!(std::fs::read(&tdm).unwrap(), before.0);
    assert_eq!(std::fs::read(&iod).unwrap(), before.1);
    assert_eq!(std::fs::read_to_string(&foreign).unwrap(), "my notes\n");
}

/// Issue 26, item 5: under `--streaks` every record carries `streaks`, error records too
/// (`[]`), on both backends, so that scripts read one shape.
#[test]
fn error_records_carry_an_empty_streak_list() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = simulated(tmp.path());
    std::fs::write(dir.join("zz_broken.fits"), b"SIMPLE  =  not a FITS file").unwrap();
    let gpu = crate::common::gpu("error_records_carry_an_empty_streak_list").is_some();
    let backends: &[&str] = if gpu { &["cpu", "gpu"] } else { &["cpu"] };
    for backend in backends {
        // A run with an error record exits 1 (spec/INTERFACE.md); its records are all there.
        let out = streaks_cmd(&dir, backend).output().unwrap();
        assert_eq!(
            out.status.code(),
            Some(1),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let records: Vec<Value> = String::from_utf8(out.stdout)
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        assert_eq!(records.len(), 9, "{backend}");
        assert!(records.iter().all(|r| r["streaks"].is_array()), "{backend}");
        let broken = records
            .iter()
            .find(|r| r["file"] == "zz_broken.fits")
            .unwrap();
        assert_eq!(broken["status"], "error");
        assert_eq!(broken["streaks"], serde_json::json!([]));
    }
}

/// ASTRiDE's sample frame (tests/data/astride: a 2002 SAAO frame whose one streak brightens
/// and fades along its track and is broken in the middle): one streak with both ends, where
/// an independent fit puts them (scripts/measure_streak.py: a Gaussian profile across the
/// track, a free brightness every 4 px along it, erf ends; (20.55, 337.62) and (338.96,
/// 309.45), ±0.35 px, though a start 5 px off moves its far end by 2 px: a star lies on the
/// track 12 px inside it), and RA/Dec through the header's TAN WCS as astropy reads it.
#[test]
fn astride_long_fits_one_broken_streak_with_both_ends_and_header_ra_dec() {
    use std::io::Read;
    let gz = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/astride/long.fits.gz");
    let tmp = tempfile::tempdir().unwrap();
    let mut fits = Vec::new();
    flate2::read::GzDecoder::new(std::fs::File::open(&gz).unwrap())
        .read_to_end(&mut fits)
        .unwrap();
    assert_eq!(fits.len(), 535_680);
    std::fs::write(tmp.path().join("long.fits"), &fits).unwrap();
    let records = run_records(gpustar().args([
        "batch",
        tmp.path().to_str().unwrap(),
        "--streaks",
        "--astrometry",
        "header",
        "--backend",
        "cpu",
    ]));
    assert_eq!(records.len(), 1);
    let s = records[0]["streaks"].as_array().unwrap();
    assert_eq!(s.len(), 1, "{s:?}");
    let ends = s[0]["ends"].as_array().unwrap();
    let order = if xy(&ends[0]).0 < xy(&ends[1]).0 {
        [0, 1]
    } else {
        [1, 0]
    };
    for (k, px) in order.iter().zip([[20.55, 337.62], [338.96, 309.45]]) {
        let e = &ends[*k];
        assert_eq!(e["edge"], false);
        let d = dist(xy(e), px);
        assert!(d < 1.2, "end {k}: {:?} is {d:.2} px from {px:?}", xy(e));
        // RA/Dec at the record's own pixel end through the header's TAN WCS, worked out
        // here from its cards (astropy gives the same to 1e-9 deg).
        let (ra, dec) = long_fits_tan(xy(e));
        let (r, de) = (
            e["ra_deg"].as_f64().unwrap(),
            e["dec_deg"].as_f64().unwrap(),
        );
        assert!(
            (r - ra).abs() < 1e-6 && (de - dec).abs() < 1e-6,
            "{r} {de} vs {ra} {dec}"
        );
    }
    let len = s[0]["length_px"].as_f64().unwrap();
    assert!((len - 319.7).abs() < 2.0, "{len}");
}

/// long.fits's header WCS (RA---TAN/DEC--TAN, CRPIX, CRVAL, CD) at a 0-based pixel: the
/// gnomonic projection inverted (Calabretta & Greisen 2002), in degrees.
fn long_fits_tan((x, y): (f64, f64)) -> (f64, f64) {
    let (crpix1, crpix2) = (-511.5, 256.5);
    let (ra0, dec0) = (232.2755534f64.to_radians(), 0.09632738913f64.to_radians());
    let cd = [
        [8.44440778984850e-4, -2.4880646061637e-6],
        [2.48806460616369e-6, 8.44440778984850e-4],
    ];
    let (u, v) = (x + 1.0 - crpix1, y + 1.0 - crpix2);
    let xi = (cd[0][0] * u + cd[0][1] * v).to_radians();
    let eta = (cd[1][0] * u + cd[1][1] * v).to_radians();
    let den = dec0.cos() - eta * dec0.sin();
    let ra = ra0 + xi.atan2(den);
    let dec = (dec0.sin() + eta * dec0.cos()).atan2((xi * xi + den * den).sqrt());
    (ra.to_degrees().rem_euclid(360.0), dec.to_degrees())
}
