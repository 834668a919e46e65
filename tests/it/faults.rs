//! Faults and mistakes that once lost data, hung a batch or silently changed an answer
//! (issue 22), each run through the real binary: outputs that are not gpustar's, a second
//! writer, error records on resume, merge's checks, a stop request while a frame is stuck,
//! implausible times, SIP orders, float sentinels. Every run here is bounded in time.
//!
//! Size: about 800 lines, one test per reproduction of the issue, each with the inputs it
//! makes; they share the kill-on-growth and full-disk helpers here.

use crate::common;

use common::{gpustar, kill_until_done, run_within as run, simulate, stderr};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// `batch DIR` on the CPU into `out`, with `args`.
fn cpu_batch(dir: &Path, out: &Path, args: &[&str]) -> Command {
    let mut c = gpustar();
    c.args(["batch", dir.to_str().unwrap(), "--backend", "cpu"])
        .args(["-o", out.to_str().unwrap()])
        .args(args);
    c
}

/// [`common::batch18_args`] with `more`.
fn batch(dir: &Path, out: &Path, more: &[&str]) -> Command {
    let mut c = gpustar();
    c.args(common::batch18_args(dir, out)).args(more);
    c
}

/// The JSON records of a file, in file order.
fn records(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).expect("a whole record"))
        .collect()
}

fn names(records: &[Value]) -> Vec<String> {
    records
        .iter()
        .map(|r| r["file"].as_str().unwrap().to_string())
        .collect()
}

/// Records without their timings, for comparing runs.
fn without_timing(mut records: Vec<Value>) -> Vec<Value> {
    for r in &mut records {
        r["timing_ms"] = Value::Null;
    }
    records
}

struct Set {
    _tmp: tempfile::TempDir,
    root: PathBuf,
    dir: PathBuf,
}

fn set(n: usize) -> Set {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_path_buf();
    let dir = root.join("frames");
    common::simulate_small(&dir, n);
    Set {
        _tmp: tmp,
        root,
        dir,
    }
}

/// Item 1: `-o` naming a file gpustar did not write, with or without --resume, and results of
/// the other format, are refused (exit 2) and left byte for byte; a torn last CSV row is cut
/// and the run completed.
#[test]
fn outputs_gpustar_did_not_write_are_never_cut() {
    let s = set(4);
    let png = s.dir.join("sim_00000.png");
    let notes = s.root.join("notes.txt");
    std::fs::write(&notes, "observing log\nclouds at 02:10\n").unwrap();
    let one_line = s.root.join("one_line.txt");
    std::fs::write(&one_line, "no newline at all").unwrap();
    for target in [&notes, &one_line, &png] {
        let before = std::fs::read(target).unwrap();
        for resume in [true, false] {
            let more: &[&str] = if resume { &["--resume"] } else { &[] };
            let o = run(batch(&s.dir, target, more), 60);
            assert_eq!(
                o.status.code(),
                Some(2),
                "{}: {}",
                target.display(),
                stderr(&o)
            );
            assert!(stderr(&o).contains("not"), "{}", stderr(&o));
            assert_eq!(
                std::fs::read(target).unwrap(),
                before,
                "{} changed",
                target.display()
            );
        }
    }
    // The two formats, each resumed as the other.
    let jsonl = s.root.join("r.jsonl");
    let csv = s.root.join("r.csv");
    assert!(run(batch(&s.dir, &jsonl, &[]), 60).status.success());
    assert!(
        run(batch(&s.dir, &csv, &["--format", "csv"]), 60)
            .status
            .success()
    );
    for (file, more, hint) in [
        (&csv, &["--resume"][..], "--format csv"),
        (
            &jsonl,
            &["--resume", "--format", "csv"][..],
            "leave out --format csv",
        ),
    ] {
        let before = std::fs::read(file).unwrap();
        let o = run(batch(&s.dir, file, more), 60);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(hint), "{}", stderr(&o));
        assert_eq!(std::fs::read(file).unwrap(), before);
    }
    // A CSV cut in the middle of its third row: the torn row is cut, the rest done once.
    let whole = std::fs::read_to_string(&csv).unwrap();
    let rows: Vec<&str> = whole.lines().collect();
    let torn = format!("{}\n{}\n{}\n{}", rows[0], rows[1], rows[2], &rows[3][..10]);
    std::fs::write(&csv, torn).unwrap();
    let o = run(batch(&s.dir, &csv, &["--resume", "--format", "csv"]), 60);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("cut an incomplete last record"),
        "{}",
        stderr(&o)
    );
    let again: Vec<String> = std::fs::read_to_string(&csv)
        .unwrap()
        .lines()
        .map(|l| l.split(',').next().unwrap().to_string())
        .collect();
    assert_eq!(again.len(), 5, "{again:?}");
    let mut files = again[1..].to_vec();
    files.sort();
    files.dedup();
    assert_eq!(files.len(), 4, "each input once: {again:?}");
}

/// Item 4: while a process holds the output (a scheduler's retry of a job still alive), a
/// second run on it refuses to start and touches nothing.
#[test]
fn a_second_writer_on_the_same_output_is_refused() {
    let s = set(3);
    let out = s.root.join("r.jsonl");
    assert!(run(batch(&s.dir, &out, &[]), 60).status.success());
    let before = std::fs::read(&out).unwrap();
    // Hold the lock as a running gpustar does.
    let held = std::fs::OpenOptions::new().write(true).open(&out).unwrap();
    held.lock().unwrap();
    for more in [&["--resume"][..], &[][..]] {
        let o = run(batch(&s.dir, &out, more), 60);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(
            stderr(&o).contains("another gpustar process"),
            "{}",
            stderr(&o)
        );
        assert_eq!(std::fs::read(&out).unwrap(), before);
    }
    drop(held);
    // Two real processes at once: one refuses or finds nothing left; no record twice.
    let frames = s.root.join("more");
    common::simulate_small(&frames, 150);
    let out2 = s.root.join("r2.jsonl");
    let spawn = || {
        batch(&frames, &out2, &["--resume", "-j", "1"])
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (spawn(), spawn());
    let (a, b) = (a.wait_with_output().unwrap(), b.wait_with_output().unwrap());
    let refused = [&a, &b]
        .iter()
        .filter(|o| o.status.code() == Some(2))
        .count();
    let mut got = names(&records(&out2));
    assert_eq!(got.len(), 150, "{} / {}", stderr(&a), stderr(&b));
    got.dedup();
    assert_eq!(got.len(), 150, "a record written twice");
    println!("two writers at once: {refused} refused");
}

/// Item 9: error records already in the file count in a resumed run's exit status;
/// --retry-errors takes them out and tries their inputs again.
#[test]
fn resume_counts_earlier_errors_and_retry_errors_redoes_them() {
    let s = set(3);
    let bad = s.dir.join("sim_00001.png");
    let good = std::fs::read(&bad).unwrap();
    std::fs::write(&bad, b"not a png").unwrap();
    let out = s.root.join("r.jsonl");
    let first = run(batch(&s.dir, &out, &[]), 60);
    assert_eq!(first.status.code(), Some(1), "{}", stderr(&first));
    let again = run(batch(&s.dir, &out, &["--resume"]), 60);
    assert_eq!(again.status.code(), Some(1), "{}", stderr(&again));
    assert!(
        stderr(&again).contains("1 of them errors"),
        "{}",
        stderr(&again)
    );
    std::fs::write(&bad, good).unwrap();
    let retried = run(batch(&s.dir, &out, &["--resume", "--retry-errors"]), 60);
    assert!(retried.status.success(), "{}", stderr(&retried));
    // In input order, the redone record in its place (issue 45: it once came last).
    let r = records(&out);
    assert_eq!(
        names(&r),
        ["sim_00000.png", "sim_00001.png", "sim_00002.png"]
    );
    assert!(r.iter().all(|r| r["status"] != "error"), "{r:?}");
}

/// Item 8: merge checks every input of the directory by default, and a part whose last
/// record is torn is an error, not a record dropped.
#[test]
fn merge_checks_by_default_and_refuses_torn_parts() {
    let s = set(8);
    let mut parts = Vec::new();
    for k in 0..2 {
        let part = s.root.join(format!("part-{k}.jsonl"));
        let o = run(batch(&s.dir, &part, &["--shard", &format!("{k}/2")]), 60);
        assert!(o.status.success(), "{}", stderr(&o));
        parts.push(part);
    }
    let merge = |parts: &[&PathBuf], more: &[&str]| {
        let mut c = gpustar();
        c.arg("merge").args(parts).args(more);
        run(c, 60)
    };
    let dir = s.dir.to_str().unwrap();
    // One shard missing: without --dir (once exit 0) and with it.
    for more in [&[][..], &["--dir", dir][..]] {
        let o = merge(&[&parts[0]], more);
        assert_eq!(o.status.code(), Some(2), "{more:?}: {}", stderr(&o));
    }
    let o = merge(&[&parts[0], &parts[1]], &["--dir", dir]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(String::from_utf8_lossy(&o.stdout).lines().count(), 8);
    // --no-check combines without the directory.
    let o = merge(&[&parts[0], &parts[1]], &["--no-check"]);
    assert!(o.status.success(), "{}", stderr(&o));
    // A torn last line: refused, naming the part.
    let text = std::fs::read_to_string(&parts[1]).unwrap();
    std::fs::write(&parts[1], &text[..text.len() - 20]).unwrap();
    let o = merge(&[&parts[0], &parts[1]], &["--dir", dir]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("incomplete record"), "{}", stderr(&o));
}

/// Item 3 and the queued frames: a stop request (SIGTERM) ends the run within seconds even
/// while a frame never finishes; every record written is whole, queued inputs are left for
/// --resume, and the resumed file equals an uninterrupted run's.
#[test]
fn a_stop_request_ends_the_run_in_seconds_whatever_a_frame_is_doing() {
    let s = set(40);
    let clean = s.root.join("clean.jsonl");
    assert!(
        run(batch(&s.dir, &clean, &["-j", "1"]), 120)
            .status
            .success()
    );
    let out = s.root.join("r.jsonl");
    let mut child = batch(&s.dir, &out, &["-j", "2"])
        .env("GPUSTAR_FAULT_STALL", "sim_00005.png")
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // Wait for the records before the stuck frame.
    let t0 = Instant::now();
    while std::fs::read_to_string(&out).map_or(0, |t| t.lines().count()) < 5 {
        assert!(t0.elapsed() < Duration::from_secs(60), "no records came");
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_millis(300));
    let signalled = Instant::now();
    assert!(
        Command::new("kill")
            .args(["-TERM", &child.id().to_string()])
            .status()
            .unwrap()
            .success()
    );
    while child.try_wait().unwrap().is_none() {
        assert!(
            signalled.elapsed() < Duration::from_secs(15),
            "still running 15 s after SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
    let took = signalled.elapsed().as_secs_f64();
    let status = child.wait().unwrap();
    assert_eq!(status.code(), Some(130));
    let partial = records(&out);
    assert!(partial.len() < 40, "queued inputs were still done");
    println!(
        "stopped {took:.1} s after SIGTERM with {} records",
        partial.len()
    );
    let o = run(batch(&s.dir, &out, &["--resume", "-j", "1"]), 120);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        without_timing(records(&out)),
        without_timing(records(&clean))
    );
}

/// `batch DIR -r --sequence` on the CPU with DIR's camera file, into `out`.
fn sequence_batch(dir: &Path, out: &Path, more: &[&str]) -> Command {
    let camera = dir.join("camera.toml");
    let mut c = cpu_batch(
        dir,
        out,
        &["-r", "--sequence", "--camera", camera.to_str().unwrap()],
    );
    c.args(more);
    c
}

/// `n` simulated 512² streak frames of 12° (FITS with times and a station) in `dir`.
fn streak_set(dir: &Path, n: usize) {
    let n = n.to_string();
    let size = ["--size", "512x512", "--fov-deg", "12", "--mag-limit", "7.5"];
    simulate(dir, &[&["--streaks", "-n", &n][..], &size].concat());
}

/// A FITS file of one BITPIX −32 image with these cards.
fn fits_f32(w: u32, h: u32, pixels: &[f32], cards: &[String]) -> Vec<u8> {
    let card = gpustar::io::fits::card;
    let mut head = vec![
        card("SIMPLE", "T"),
        card("BITPIX", "-32"),
        card("NAXIS", "2"),
        card("NAXIS1", &w.to_string()),
        card("NAXIS2", &h.to_string()),
    ];
    head.extend(cards.iter().cloned());
    head.push(gpustar::io::fits::card_end());
    let mut b: Vec<u8> = head.concat().into_bytes();
    b.resize(b.len().div_ceil(2880) * 2880, b' ');
    for v in pixels {
        b.extend_from_slice(&v.to_be_bytes());
    }
    b.resize(b.len().div_ceil(2880) * 2880, 0);
    b
}

/// Items 6 and 11: a solvable frame keeps its solution when its header holds an implausible
/// epoch (9999-12-31, a JD in MJD-OBS) or its float data a bad-pixel sentinel; each record
/// says what was passed over.
#[test]
fn implausible_epochs_and_float_sentinels_do_not_cost_the_solution() {
    let s = set(1);
    let f = gpustar::io::frame::Frame::read(&s.dir.join("sim_00000.png")).unwrap();
    let fits = s.root.join("fits");
    std::fs::create_dir(&fits).unwrap();
    let q = |v: &str| format!("'{v}'");
    let card = gpustar::io::fits::card;
    let write16 = |name: &str, cards: &[String]| {
        std::fs::write(
            fits.join(name),
            gpustar::io::fits::encode_u16(f.width, f.height, &f.pixels, cards),
        )
        .unwrap();
    };
    write16("a_plain.fits", &[]);
    write16("b_year_9999.fits", &[card("DATE-OBS", &q("9999-12-31"))]);
    write16("c_jd_in_mjd.fits", &[card("MJD-OBS", "2460000.5")]);
    let mut floats: Vec<f32> = f.pixels.iter().map(|&p| p as f32).collect();
    floats[1000] = 1e9;
    floats[2000] = -1e30;
    std::fs::write(
        fits.join("d_sentinel.fits"),
        fits_f32(f.width, f.height, &floats, &[]),
    )
    .unwrap();
    let out = s.root.join("r.jsonl");
    let o = run(batch(&fits, &out, &[]), 60);
    assert!(o.status.success(), "{}", stderr(&o));
    let r = records(&out);
    assert_eq!(r.len(), 4);
    let plain = &r[0];
    assert_eq!(plain["status"], "solved");
    for (rec, warned) in r[1..].iter().zip(["DATE-OBS", "MJD-OBS", "sentinel"]) {
        assert_eq!(rec["status"], "solved", "{rec}");
        let w = rec["warnings"].to_string();
        assert!(w.contains(warned), "{}: {w}", rec["file"]);
        let dra = rec["ra_deg"].as_f64().unwrap() - plain["ra_deg"].as_f64().unwrap();
        assert!(dra.abs() < 0.01, "{}: {dra}", rec["file"]);
    }
}

/// Item 5 and 3: an exposure length beyond any calendar (EXPTIME 1E10, 1E300) and a SIP order
/// of 2^31 − 1 cost their frame's times or header astrometry, never its stars, another frame's
/// output or the exports; nothing hangs.
#[test]
fn absurd_times_and_sip_orders_cost_only_their_own_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    streak_set(&dir, 3);
    let card = gpustar::io::fits::card;
    let q = |v: &str| format!("'{v}'");
    let station = [
        card("OBSGEO-B", "35.7"),
        card("OBSGEO-L", "51.4"),
        card("OBSGEO-H", "1200"),
    ];
    for (k, exptime) in [(1, "1E10"), (2, "1E300")] {
        let path = dir.join(format!("sim_{k:05}.fits"));
        let f = gpustar::io::frame::Frame::read(&path).unwrap();
        let mut cards = vec![
            card("DATE-OBS", &q("2024-03-15T20:00:00")),
            card("EXPTIME", exptime),
        ];
        cards.extend(station.iter().cloned());
        if k == 2 {
            // A TAN-SIP header WCS with an absurd order (read with --astrometry header).
            for (key, v) in [
                ("CTYPE1", q("RA---TAN-SIP")),
                ("CTYPE2", q("DEC--TAN-SIP")),
                ("CRPIX1", "256".into()),
                ("CRPIX2", "256".into()),
                ("CRVAL1", "10".into()),
                ("CRVAL2", "20".into()),
                ("CD1_1", "0.0234".into()),
                ("CD2_2", "0.0234".into()),
                ("A_ORDER", "2147483647".into()),
                ("B_ORDER", "2".into()),
            ] {
                cards.push(card(key, &v));
            }
        }
        std::fs::write(
            &path,
            gpustar::io::fits::encode_u16(f.width, f.height, &f.pixels, &cards),
        )
        .unwrap();
    }
    let tdm = tmp.path().join("obs.tdm");
    let iod = tmp.path().join("obs.iod");
    let camera = dir.join("camera.toml");
    for astrometry in ["solve", "header"] {
        let out = tmp.path().join(format!("{astrometry}.jsonl"));
        let mut c = cpu_batch(
            &dir,
            &out,
            &[
                "--streaks",
                "--astrometry",
                astrometry,
                "--tdm",
                tdm.to_str().unwrap(),
                "--iod",
                iod.to_str().unwrap(),
            ],
        );
        if astrometry == "solve" {
            c.args(["--camera", camera.to_str().unwrap()]);
        }
        let o = run(c, 120);
        let r = records(&out);
        assert_eq!(r.len(), 3, "{}", stderr(&o));
        assert!(
            o.status.code() == Some(0) || o.status.code() == Some(1),
            "{}",
            stderr(&o)
        );
        // A TDM, or none when no streak has a timed midpoint (TDM 2.0 requires a segment).
        let text = std::fs::read_to_string(&tdm).unwrap_or_default();
        assert!(
            text.starts_with("CCSDS_TDM_VERS")
                || !tdm.exists() && astrometry == "header" && stderr(&o).contains("no TDM"),
            "{astrometry}: TDM {text:?}: {}",
            stderr(&o)
        );
        if astrometry == "solve" {
            assert!(r.iter().all(|r| r["status"] == "solved"), "{r:?}");
            assert!(
                text.contains("sim_00000.fits"),
                "the good frame's streak is exported"
            );
            for bad in &r[1..] {
                let w = bad["warnings"].to_string();
                assert!(w.contains("EXPTIME"), "{w}");
                for s in bad["streaks"].as_array().unwrap() {
                    for end in s["ends"].as_array().unwrap() {
                        assert!(end["time_utc"].is_null(), "{end}");
                    }
                }
            }
        } else {
            assert!(r[2].to_string().contains("A_ORDER"), "{}", r[2]);
        }
    }
}

/// Issue 45, items 8 and 9: a header WCS no telescope has (CRVAL2 = 95) gives its frame's
/// streaks no RA/Dec and a warning naming it, and nothing of that frame reaches the TDM or
/// IOD; an exposure from 2099-12-31T18:00 ending in 2100 (past SOFA's Earth ephemeris, where
/// sofars panicked and the frame's record became an internal error) gives its streak ends no
/// time, with a warning, and keeps the star solution.
#[test]
fn nonsensical_header_wcs_and_exposures_past_2100_cost_only_their_own_frame() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    streak_set(&dir, 4);
    let card = gpustar::io::fits::card;
    let q = |v: &str| format!("'{v}'");
    // Frame: (DATE-OBS, EXPTIME, CRVAL2).
    let frames = [
        ("2024-03-15T20:00:00", "4", "20"),
        ("2024-03-15T20:01:00", "4", "95"),
        ("2099-12-31T18:00:00", "43200", "20"),
        ("2099-12-31T18:00:00", "72000", "20"),
    ];
    for (k, (date, exptime, crval2)) in frames.into_iter().enumerate() {
        let path = dir.join(format!("sim_{k:05}.fits"));
        let f = gpustar::io::frame::Frame::read(&path).unwrap();
        let mut cards = vec![
            card("DATE-OBS", &q(date)),
            card("EXPTIME", exptime),
            card("OBSGEO-B", "35.7"),
            card("OBSGEO-L", "51.4"),
            card("OBSGEO-H", "1200"),
        ];
        for (key, v) in [
            ("CTYPE1", q("RA---TAN")),
            ("CTYPE2", q("DEC--TAN")),
            ("CRPIX1", "256".into()),
            ("CRPIX2", "256".into()),
            ("CRVAL1", "10".into()),
            ("CRVAL2", crval2.into()),
            ("CD1_1", "0.0234".into()),
            ("CD2_2", "0.0234".into()),
        ] {
            cards.push(card(key, &v));
        }
        std::fs::write(
            &path,
            gpustar::io::fits::encode_u16(f.width, f.height, &f.pixels, &cards),
        )
        .unwrap();
    }
    let (tdm, iod) = (tmp.path().join("obs.tdm"), tmp.path().join("obs.iod"));
    let camera = dir.join("camera.toml");
    for astrometry in ["solve", "header"] {
        let out = tmp.path().join(format!("{astrometry}.jsonl"));
        let c = cpu_batch(
            &dir,
            &out,
            &[
                "--streaks",
                "--astrometry",
                astrometry,
                "--camera",
                camera.to_str().unwrap(),
                "--tdm",
                tdm.to_str().unwrap(),
                "--iod",
                iod.to_str().unwrap(),
            ],
        );
        let o = run(c, 120);
        assert!(o.status.success(), "{astrometry}: {}", stderr(&o));
        let r = records(&out);
        assert_eq!(r.len(), 4, "{}", stderr(&o));
        assert!(r.iter().all(|r| r["status"] == "solved"), "{r:?}");
        let text = std::fs::read_to_string(&tdm).unwrap();
        let iod_text = std::fs::read_to_string(&iod).unwrap();
        assert!(text.contains("sim_00000.fits"), "{astrometry}: {text}");
        assert!(!iod_text.is_empty());
        // Ends, midpoints and the reversed ends of every streak of a record.
        let ends = |rec: &Value| -> Vec<Value> {
            let mut v = Vec::new();
            for s in rec["streaks"].as_array().unwrap() {
                v.extend(s["ends"].as_array().unwrap().iter().cloned());
                v.extend(s["reversed"].as_array().into_iter().flatten().cloned());
                v.extend(Some(s["mid"].clone()).filter(|m| !m.is_null()));
            }
            v
        };
        for late in &r[2..] {
            let w = late["warnings"].to_string();
            assert!(
                w.contains("ends at 2100-01-01") && w.contains("EXPTIME"),
                "{w}"
            );
            assert!(!ends(late).is_empty());
            for end in ends(late) {
                assert!(
                    end["time_utc"].is_null() && end["az_deg"].is_null(),
                    "{end}"
                );
            }
            let name = late["file"].as_str().unwrap();
            assert!(!text.contains(name), "{name} in the TDM");
        }
        // By time too (a tracklet is named for its first frame).
        assert!(
            !text.contains("2099-12-31") && !text.contains("2100-01-01"),
            "{text}"
        );
        assert!(!iod_text.contains("20991231") && !iod_text.contains("21000101"));
        if astrometry == "header" {
            let bad = &r[1];
            let w = bad["warnings"].to_string();
            assert!(w.contains("CRVAL2 = 95"), "{w}");
            assert!(!ends(bad).is_empty());
            for end in ends(bad) {
                assert!(end["ra_deg"].is_null() && end["dec_deg"].is_null(), "{end}");
            }
            assert!(!text.contains("sim_00001.fits"), "{text}");
            assert!(!text.contains("2024-03-15T20:01:0"), "{text}");
            assert!(!iod_text.contains("2024031520010"), "{iod_text}");
            assert!(ends(&r[0]).iter().all(|e| e["ra_deg"].is_number()));
        }
    }
}

/// Item 10: a `--sequence` run resumed in the middle of a sequence gives the records of an
/// uninterrupted run (tracking once started cold at the first frame without a record).
#[test]
fn a_resumed_sequence_gives_the_uninterrupted_run_s_records() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    simulate(
        &dir,
        &["--sequence", "--sequences", "2", "-n", "12", "--seed", "5"],
    );
    let seq = |out: &Path, more: &[&str]| run(sequence_batch(&dir, out, more), 120);
    let clean = tmp.path().join("clean.jsonl");
    assert!(seq(&clean, &[]).status.success());
    let whole = std::fs::read_to_string(&clean).unwrap();
    let lines: Vec<&str> = whole.lines().collect();
    assert_eq!(lines.len(), 24);
    // Stopped inside each sequence in turn (after 11 frames: tracking by then).
    for kept in [11, 17] {
        let out = tmp.path().join(format!("resumed-{kept}.jsonl"));
        std::fs::write(&out, lines[..kept].join("\n") + "\n").unwrap();
        let o = seq(&out, &["--resume"]);
        assert!(o.status.success(), "{}", stderr(&o));
        assert_eq!(
            without_timing(records(&out)),
            without_timing(records(&clean)),
            "resumed after {kept} records"
        );
    }
}

/// Absurd numbers on the command line are refused at once (exit 2), not found out by a run
/// (`--pair-tol-px 1e9` once took 20 s a frame).
#[test]
fn absurd_numeric_options_are_refused_at_once() {
    let s = set(1);
    let out = s.root.join("r.jsonl");
    for (flag, value) in [
        ("--pair-tol-px", "1e9"),
        ("--pair-tol-px", "NaN"),
        ("--sigma", "nan"),
        ("--match-radius-px", "-1"),
        ("--scale-tol", "inf"),
        ("--max-false-prob", "2"),
        ("--vote-stars", "0"),
        ("--batch-size", "0"),
        ("--epoch", "1e300"),
        ("--mag-limit", "NaN"),
        ("--double-star-px", "-3"),
        ("--threads", "0"),
    ] {
        let o = run(batch(&s.dir, &out, &[&format!("{flag}={value}")]), 10);
        assert_eq!(o.status.code(), Some(2), "{flag} {value}: {}", stderr(&o));
        assert!(
            stderr(&o).contains(flag.trim_start_matches('-')),
            "{}",
            stderr(&o)
        );
        assert!(!out.exists(), "{flag} {value}: an output was made");
    }
}

/// A full disk: the run stops with its summary and exit 3 (not 2, "could not start"), the
/// records written are whole, and --resume after room is made gives an uninterrupted run's
/// records. The disk is a 24 KiB tmpfs where this machine lets the test mount one, and
/// /dev/full (every write fails) in any case.
#[test]
fn a_full_disk_stops_with_a_summary_and_resume_completes() {
    let s = set(30);
    let o = run(batch(&s.dir, Path::new("/dev/full"), &[]), 60);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    assert!(stderr(&o).contains("stopped"), "{}", stderr(&o));

    let clean = s.root.join("clean.jsonl");
    assert!(run(batch(&s.dir, &clean, &[]), 60).status.success());
    let disk = s.root.join("disk");
    std::fs::create_dir(&disk).unwrap();
    let mount = |opts: &str| {
        Command::new("mount")
            .args(["-t", "tmpfs", "-o", opts, "tmpfs", disk.to_str().unwrap()])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if !mount("size=24k") {
        eprintln!(
            "SKIPPED a_full_disk (tmpfs part): this machine does not let the test mount a \
             tmpfs (needs root); the /dev/full part ran"
        );
        return;
    }
    struct Unmount(PathBuf);
    impl Drop for Unmount {
        fn drop(&mut self) {
            let _ = Command::new("umount").arg(&self.0).status();
        }
    }
    let _unmount = Unmount(disk.clone());
    let out = disk.join("r.jsonl");
    let o = run(batch(&s.dir, &out, &[]), 60);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let text = std::fs::read(&out).unwrap();
    let whole = text.iter().rposition(|&b| b == b'\n').map_or(0, |i| i + 1);
    println!(
        "full tmpfs: {} whole records, {} bytes of a torn one",
        text[..whole].iter().filter(|&&b| b == b'\n').count(),
        text.len() - whole
    );
    assert!(whole < std::fs::metadata(&clean).unwrap().len() as usize);
    // Room made: the same mount, larger.
    assert!(mount("remount,size=4m"), "cannot grow the tmpfs");
    let o = run(batch(&s.dir, &out, &["--resume"]), 60);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        without_timing(records(&out)),
        without_timing(records(&clean))
    );
}

/// A frame of another size than the camera file's is refused from its header: a 20000² PNG
/// (a few hundred KB of zeros) once took 1.2 GB to decode before the size was compared.
#[test]
fn frames_of_another_size_are_refused_before_decoding() {
    let s = set(1);
    let big = s.root.join("big");
    std::fs::create_dir(&big).unwrap();
    blank_png(&big.join("huge.png"), 20_000);
    let out = s.root.join("r.jsonl");
    let camera = s.dir.join("camera.toml");
    let c = cpu_batch(&big, &out, &["--camera", camera.to_str().unwrap()]);
    let o = run(c, 60);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let r = records(&out);
    assert!(
        r[0]["error"].as_str().unwrap().contains("20000x20000"),
        "{}",
        r[0]
    );
    // With --fov-deg there is no camera size to compare with: 400 megapixels are over
    // --max-megapixels' 300 (issue 45: a 0.9 MB PNG took 2.65 GB).
    let o = run(cpu_batch(&big, &out, &["--fov-deg", "2"]), 60);
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let r = records(&out);
    let e = r[0]["error"].as_str().unwrap();
    assert!(
        e.contains("20000x20000") && e.contains("--max-megapixels"),
        "{e}"
    );
    // The largest child this test process has waited for (all of them small but gpustar's
    // run here, which decoding would have taken past 1 GB).
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes into the struct it is given.
    assert_eq!(
        unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) },
        0
    );
    let peak_mb = usage.ru_maxrss as f64 / 1024.0;
    println!("largest child's peak memory: {peak_mb:.0} MB");
    assert!(peak_mb < 600.0, "{peak_mb:.0} MB");
}

/// A black 8-bit PNG of `side`² pixels: under a megabyte on disk, `side`² bytes decoded.
fn blank_png(path: &Path, side: u32) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut enc = png::Encoder::new(file, side, side);
    enc.set_color(png::ColorType::Grayscale);
    enc.set_depth(png::BitDepth::Eight);
    enc.set_compression(png::Compression::Fast);
    let mut w = enc.write_header().unwrap().into_stream_writer().unwrap();
    let row = vec![0u8; side as usize];
    for _ in 0..side {
        std::io::Write::write_all(&mut w, &row).unwrap();
    }
    w.finish().unwrap();
}

/// Issue 45, item 4: a `--dark` PNG of 20000² pixels with a camera file of another size is
/// refused from its header before the run (it was decoded whole, 1.2 GB, and then every
/// frame's record said the sizes differ).
#[test]
fn a_dark_of_another_size_is_refused_before_decoding() {
    let s = set(1);
    let dark = s.root.join("dark.png");
    blank_png(&dark, 20_000);
    let out = s.root.join("r.jsonl");
    let camera = s.dir.join("camera.toml");
    let c = cpu_batch(
        &s.dir,
        &out,
        &[
            "--camera",
            camera.to_str().unwrap(),
            "--dark",
            dark.to_str().unwrap(),
        ],
    );
    let t0 = Instant::now();
    let o = run(c, 60);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("--dark: the dark frame")
            && e.contains("is 20000x20000 but the camera file says"),
        "{e}"
    );
    println!("refused in {:.2} s", t0.elapsed().as_secs_f64());
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: getrusage writes into the struct it is given.
    assert_eq!(
        unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) },
        0
    );
    let peak_mb = usage.ru_maxrss as f64 / 1024.0;
    assert!(peak_mb < 600.0, "{peak_mb:.0} MB");
}

/// Issue 45, item 3: a FIFO or a directory given as `--catalog`, `--tle`, `--camera`,
/// `--dark` or to `catalog import` is refused before it is opened, naming what it is (a FIFO
/// held the run forever; `/dev/zero` was read until memory ran out).
#[cfg(unix)]
#[test]
fn option_files_that_are_not_regular_files_are_refused_before_reading() {
    let s = set(1);
    let fifo = s.root.join("pipe");
    common::mkfifo(&fifo);
    let camera = s.dir.join("camera.toml");
    let camera = camera.to_str().unwrap();
    let empty = s.root.join("empty-dir");
    std::fs::create_dir(&empty).unwrap();
    let mut k = 0;
    for (path, kind) in [(&fifo, "a FIFO"), (&empty, "a directory")] {
        let path = path.to_str().unwrap();
        for args in [
            vec!["--camera", camera, "--catalog", path],
            vec!["--camera", camera, "--streaks", "--tle", path],
            vec!["--camera", path],
            vec!["--camera", camera, "--dark", path],
        ] {
            k += 1;
            let out = s.root.join(format!("r{k}.jsonl"));
            let o = run(cpu_batch(&s.dir, &out, &args), 30);
            let e = stderr(&o);
            assert_eq!(o.status.code(), Some(2), "{args:?}: {e}");
            assert!(
                e.contains(&format!("not a regular file but {kind}")),
                "{args:?}: {e}"
            );
        }
        let mut c = gpustar();
        c.args(["catalog", "import", path, "-o"])
            .arg(s.root.join("c.gpustarcat"));
        let o = run(c, 30);
        let e = stderr(&o);
        assert!(!o.status.success(), "{e}");
        assert!(e.contains(&format!("not a regular file but {kind}")), "{e}");
    }
}

/// `--tdm` and `--iod` after `--resume` hold the streaks of the whole file, not only of the
/// inputs this run did (they are written whole at the end), in both formats.
#[test]
fn a_resumed_run_exports_the_whole_file_s_streaks() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    streak_set(&dir, 4);
    let camera = dir.join("camera.toml");
    let files = |tag: &str| {
        let p = |ext: &str| tmp.path().join(format!("{tag}.{ext}"));
        (p("out"), p("tdm"), p("iod"))
    };
    let streaks = |out: &Path, tdm: &Path, iod: &Path, more: &[&str]| {
        let mut c = cpu_batch(
            &dir,
            out,
            &[
                "--streaks",
                "--camera",
                camera.to_str().unwrap(),
                "--tdm",
                tdm.to_str().unwrap(),
                "--iod",
                iod.to_str().unwrap(),
            ],
        );
        c.args(more);
        let o = run(c, 120);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    // The TDM without its creation time.
    let tdm_body = |p: &Path| -> Vec<String> {
        std::fs::read_to_string(p)
            .unwrap()
            .lines()
            .filter(|l| !l.starts_with("CREATION_DATE"))
            .map(String::from)
            .collect()
    };
    let (clean, clean_tdm, clean_iod) = files("clean");
    streaks(&clean, &clean_tdm, &clean_iod, &[]);
    assert!(std::fs::read_to_string(&clean_iod).unwrap().lines().count() >= 3);
    for format in ["jsonl", "csv"] {
        let (out, tdm, iod) = files(format);
        streaks(&out, &tdm, &iod, &["--format", format]);
        // Keep the header (CSV) and the first record only.
        let text = std::fs::read_to_string(&out).unwrap();
        let keep = if format == "csv" { 2 } else { 1 };
        let kept: Vec<&str> = text.lines().take(keep).collect();
        std::fs::write(&out, kept.join("\n") + "\n").unwrap();
        streaks(&out, &tdm, &iod, &["--format", format, "--resume"]);
        assert_eq!(tdm_body(&tdm), tdm_body(&clean_tdm), "{format}: TDM");
        assert_eq!(
            std::fs::read_to_string(&iod).unwrap(),
            std::fs::read_to_string(&clean_iod).unwrap(),
            "{format}: IOD"
        );
    }
}

/// kill -9 at pseudo-random moments of a `--sequence` run (3 sequences of 80), each time resumed: the file ends
/// with every input once and the records of an uninterrupted run (tracking state included).
/// Records reach the file 64 at a time (or every 250 ms), and a kill waits for the file to
/// grow: 240 frames leave room for two kills however fast the build.
#[test]
fn sigkill_during_sequences_then_resume_gives_the_uninterrupted_records() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    simulate(
        &dir,
        &["--sequence", "--sequences", "3", "-n", "80", "--seed", "11"],
    );
    let seq = |out: &Path| sequence_batch(&dir, out, &["-q", "--resume", "-j", "1"]);
    let clean = tmp.path().join("clean.jsonl");
    assert!(run(seq(&clean), 120).status.success());
    let out = tmp.path().join("killed.jsonl");
    let full = std::fs::metadata(&clean).unwrap().len();
    let kills = kill_until_done(
        || seq(&out).spawn().unwrap(),
        &out,
        full,
        (0.05, 0.3),
        0x9E3779B9,
    );
    println!("sequences: {kills} kills before the run finished");
    assert!(
        kills >= 2,
        "the test must really interrupt the run ({kills} kills)"
    );
    assert_eq!(
        without_timing(records(&out)),
        without_timing(records(&clean))
    );
}

/// Fields too narrow for a pattern index of the whole sky (`--fov-deg 0.01`, issue 44/45:
/// before, `patterns::lattice` allocated 89 GB and the process aborted with every record):
/// a known scale is voted without the index, a wide range gets one error record per frame
/// saying what would serve; no abort, every input its record, within seconds.
#[test]
fn fields_too_narrow_for_a_pattern_index_cost_no_abort() {
    let s = set(2);
    for (fov, status) in [
        ("0.01", "unsolved"),
        ("0.01..0.03", "error"),
        ("0.1..5", "error"),
    ] {
        let out = s.root.join(format!("narrow-{fov}.jsonl"));
        let o = run(cpu_batch(&s.dir, &out, &["--fov-deg", fov, "-q"]), 120);
        assert!(
            o.status.code() == Some(0) || o.status.code() == Some(1),
            "--fov-deg {fov}: {:?} {}",
            o.status,
            stderr(&o)
        );
        let recs = records(&out);
        assert_eq!(recs.len(), 2, "--fov-deg {fov}");
        for r in &recs {
            assert_eq!(r["status"], status, "--fov-deg {fov}: {r}");
            if status == "error" {
                let e = r["error"].as_str().unwrap();
                assert!(e.contains("pattern index") && e.contains("--hint"), "{e}");
            }
        }
    }
}
