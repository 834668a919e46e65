//! Every file gpustar writes is claimed before any work (issue 45): products never land on an
//! input or on each other, two outputs never share a path, files other programs wrote are not
//! replaced (without --overwrite), only regular files are, links stay links, and a batch that
//! reads nothing does not exit 0. Each case runs the real binary, bounded in time.

use crate::common;

use common::{gpustar, run_within as run, stderr};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

/// `batch DIR` of 18° frames on the CPU, with `more`.
fn batch(dir: &Path, more: &[&str]) -> Command {
    let mut c = gpustar();
    c.args(["batch", dir.to_str().unwrap()])
        .args(["--fov-deg", "18", "--mag-limit", "6", "--backend", "cpu"])
        .args(more);
    c
}

/// Refused before any work: exit 2, the message holds `says`, and `files` are byte for byte
/// as they were.
fn assert_refused(o: &Output, says: &str, files: &[(&Path, Option<Vec<u8>>)]) {
    assert_eq!(o.status.code(), Some(2), "{}", stderr(o));
    assert!(
        stderr(o).contains(says),
        "wanted {says:?} in: {}",
        stderr(o)
    );
    for (f, before) in files {
        assert_eq!(&std::fs::read(f).ok(), before, "{} changed", f.display());
    }
}

fn bytes(p: &Path) -> (&Path, Option<Vec<u8>>) {
    (p, std::fs::read(p).ok())
}

/// A directory of three 18° frames, `x.png` and `x.fits` among them (one stem, two images).
fn frames(root: &Path) -> PathBuf {
    let dir = root.join("frames");
    common::simulate_small(&dir, 3);
    std::fs::rename(dir.join("sim_00000.png"), dir.join("x.png")).unwrap();
    let f = gpustar::io::frame::Frame::read(&dir.join("sim_00001.png")).unwrap();
    std::fs::write(
        dir.join("x.fits"),
        gpustar::io::fits::encode_u16(f.width, f.height, &f.pixels, &[]),
    )
    .unwrap();
    std::fs::remove_file(dir.join("sim_00001.png")).unwrap();
    dir
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// Items 1 and 11: annotations into the input folder are refused (they would replace an input,
/// or be read as frames by the next run); `x.fits` and `x.png` get products of their own;
/// astrometry.net's `.wcs` files are replaced only with --overwrite; gpustar's own products
/// are replaced by a rerun.
#[test]
fn products_never_land_on_inputs_or_on_each_other() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = frames(tmp.path());
    let x_png = dir.join("x.png");
    let before = listing(&dir);
    for (annotate, more, says) in [
        (&dir, &[][..], "an input of this run"),
        (&dir.join("ann"), &["-r"][..], "where the frames are read"),
    ] {
        let mut c = batch(&dir, &["--annotate-dir", annotate.to_str().unwrap()]);
        c.args(more);
        let o = run(c, 60);
        assert_refused(&o, says, &[bytes(&x_png)]);
        assert_eq!(
            listing(&dir),
            before,
            "nothing written into the input folder"
        );
    }
    // Records named like an image inside the input folder: the next run's frame.
    let o = run(
        batch(&dir, &["-o", dir.join("out.png").to_str().unwrap()]),
        60,
    );
    assert_refused(&o, "where the frames are read", &[]);
    assert!(!dir.join("out.png").exists());

    let (ann, wcs) = (tmp.path().join("ann"), tmp.path().join("wcs"));
    let products = |more: &[&str]| {
        let mut c = batch(
            &dir,
            &[
                "--annotate-dir",
                ann.to_str().unwrap(),
                "--wcs-dir",
                wcs.to_str().unwrap(),
                "-o",
                tmp.path().join("r.jsonl").to_str().unwrap(),
            ],
        );
        c.args(more);
        run(c, 120)
    };
    let o = products(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        listing(&ann),
        ["sim_00002.png", "x.fits.png", "x.png.png"],
        "x.fits and x.png each annotated"
    );
    assert_eq!(listing(&wcs), ["sim_00002.wcs", "x.fits.wcs", "x.png.wcs"]);
    let (a, b) = (
        std::fs::read(ann.join("x.fits.png")).unwrap(),
        std::fs::read(ann.join("x.png.png")).unwrap(),
    );
    assert_ne!(a, b, "two frames, two annotations");
    // A rerun replaces gpustar's own products.
    let o = products(&[]);
    assert!(o.status.success(), "{}", stderr(&o));
    // astrometry.net's WCS beside the frames: kept, unless --overwrite.
    let theirs = wcs.join("sim_00002.wcs");
    std::fs::write(
        &theirs,
        format!(
            "{:<80}",
            "SIMPLE  =                    T / by astrometry.net"
        ),
    )
    .unwrap();
    let o = products(&[]);
    assert_refused(
        &o,
        "does not hold a WCS header gpustar wrote",
        &[bytes(&theirs)],
    );
    let o = products(&["--overwrite"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        String::from_utf8_lossy(&std::fs::read(&theirs).unwrap()).contains("WCS by gpustar."),
        "replaced with --overwrite"
    );
    // An image of someone else's at an annotation's path: kept.
    std::fs::copy(&x_png, ann.join("x.png.png")).unwrap();
    let kept = ann.join("x.png.png");
    let o = products(&[]);
    assert_refused(
        &o,
        "does not hold an image gpustar annotated",
        &[bytes(&kept)],
    );
}

/// Items 2, 6 and 10: two outputs on one path, an output that is an input or standard output,
/// a FIFO or a device at an export path: refused before any work, every file as it was; an
/// export through a link replaces the link's target and leaves the link.
#[test]
fn outputs_on_one_path_inputs_fifos_and_devices_are_refused_at_once() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = frames(tmp.path());
    let rec = tmp.path().join("r.jsonl");
    let o = run(batch(&dir, &["-o", rec.to_str().unwrap()]), 60);
    assert!(o.status.success(), "{}", stderr(&o));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let tdm = tmp.path().join("t.tdm");
    let fifo = tmp.path().join("f.tdm");
    common::mkfifo(&fifo);
    let x_png = dir.join("x.png");
    let cases: Vec<(Vec<String>, &str)> = vec![
        (
            vec!["--tdm".into(), s(&rec), "-o".into(), s(&rec)],
            "is also -o",
        ),
        (
            vec![
                "--tdm".into(),
                s(&tdm),
                "--iod".into(),
                format!("{}/./t.tdm", s(tmp.path())),
            ],
            "is also --tdm",
        ),
        (vec!["--iod".into(), s(&x_png)], "an input of this run"),
        (vec!["--tdm".into(), s(&fifo)], "it is a FIFO"),
        (vec!["--tdm".into(), "/dev/zero".into()], "it is a device"),
        // Standard output here is a pipe: the records' output and a FIFO.
        (
            vec!["--tdm".into(), "/dev/stdout".into()],
            "standard output",
        ),
    ];
    for (args, says) in cases {
        let mut c = batch(&dir, &["--streaks"]);
        c.args(&args);
        if !args.contains(&"-o".to_string()) && args[1] != "/dev/stdout" {
            c.args(["-o", rec.to_str().unwrap()]);
        }
        let t = Instant::now();
        let o = run(c, 30);
        assert_refused(&o, says, &[bytes(&rec), bytes(&x_png), bytes(&tdm)]);
        assert!(
            t.elapsed() < Duration::from_secs(20),
            "{args:?}: refused at once"
        );
    }

    // A link at --iod: the link stays, its target takes the lines.
    let target = tmp.path().join("target.iod");
    std::fs::write(&target, "").unwrap();
    let link = tmp.path().join("link.iod");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    let o = run(
        batch(
            &dir,
            &[
                "--streaks",
                "--iod",
                s(&link).as_str(),
                "-o",
                s(&rec).as_str(),
            ],
        ),
        120,
    );
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        std::fs::symlink_metadata(&link)
            .unwrap()
            .file_type()
            .is_symlink()
    );
}

/// Item 6: IOD lines carry no mark of their writer. A file another program wrote is kept
/// (replaced with --overwrite); one gpustar wrote is replaced by the next run, until another
/// program changes it.
#[test]
fn iod_files_other_programs_wrote_are_kept() {
    let tmp = tempfile::tempdir().unwrap();
    // Streak frames (FITS with times and a station), so that gpustar's IOD file has lines.
    let dir = common::simulated_streaks(tmp.path(), 2);
    let iod = tmp.path().join("obs.iod");
    let theirs = "25544 98 067A   4353 G 20260101000000000 17 25 0000000+000000 37\n";
    std::fs::write(&iod, theirs).unwrap();
    let rec = tmp.path().join("r.jsonl");
    let go = |more: &[&str]| {
        let mut c = gpustar();
        c.args([
            "batch",
            dir.to_str().unwrap(),
            "--backend",
            "cpu",
            "--streaks",
        ])
        .arg("--camera")
        .arg(dir.join("camera.toml"))
        .args(["--iod", iod.to_str().unwrap(), "-o", rec.to_str().unwrap()])
        .args(more);
        run(c, 120)
    };
    assert_refused(&go(&[]), "does not hold IOD lines", &[bytes(&iod)]);
    let o = go(&["--overwrite"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let ours = std::fs::read_to_string(&iod).unwrap();
    assert!(ours.lines().count() >= 1 && ours != theirs, "{ours:?}");
    let o = go(&[]);
    assert!(o.status.success(), "gpustar's own IOD file: {}", stderr(&o));
    // Another program appends: the file is no longer as gpustar wrote it.
    let mut now = std::fs::read_to_string(&iod).unwrap();
    now.push_str(theirs);
    std::fs::write(&iod, &now).unwrap();
    assert_refused(&go(&[]), "does not hold IOD lines", &[bytes(&iod)]);
}

/// Item 3: `-o` (batch and merge) refuses a pretty-printed JSON file and a text that starts
/// with `f` (once taken for the start of a record or of the CSV header), untouched; merge
/// refuses writing over one of its parts.
#[test]
fn record_outputs_must_hold_whole_records_to_be_replaced() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = frames(tmp.path());
    let pretty = tmp.path().join("settings.json");
    std::fs::write(&pretty, "{\n  \"file\": \"mine\"\n}\n").unwrap();
    let text = tmp.path().join("todo.txt");
    std::fs::write(&text, "fix the mount\n").unwrap();
    let torn = tmp.path().join("f");
    std::fs::write(&torn, "f").unwrap();
    for target in [&pretty, &text, &torn] {
        for more in [&[][..], &["--format", "csv"][..]] {
            let mut c = batch(&dir, &["-o", target.to_str().unwrap()]);
            c.args(more);
            assert_refused(
                &run(c, 60),
                "does not hold gpustar results",
                &[bytes(target)],
            );
        }
        let mut c = gpustar();
        c.args(["merge", "--no-check", "-o", target.to_str().unwrap()]);
        assert_refused(
            &run(c, 30),
            "does not hold gpustar results",
            &[bytes(target)],
        );
    }
    let part = tmp.path().join("part.jsonl");
    assert!(
        run(batch(&dir, &["-o", part.to_str().unwrap()]), 60)
            .status
            .success()
    );
    let mut c = gpustar();
    c.args([
        "merge",
        "--no-check",
        part.to_str().unwrap(),
        "-o",
        part.to_str().unwrap(),
    ]);
    assert_refused(&run(c, 30), "a part to merge", &[bytes(&part)]);
}

/// Item 5: `calibrate -o` is checked before the fit: a file it did not write, its own
/// --camera file, a folder that does not exist.
#[test]
fn calibrate_checks_its_output_before_the_fit() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 3);
    let camera = dir.join("camera.toml");
    let notes = tmp.path().join("notes.toml");
    std::fs::write(&notes, "# my lens\nfocal = 50\n").unwrap();
    let missing = tmp.path().join("no/such/dir/cam.toml");
    for (out, says) in [
        (
            &notes,
            "does not hold a camera file gpustar calibrate wrote",
        ),
        (&camera, "an input of this run"),
        (&missing, "is not a directory"),
    ] {
        let mut c = gpustar();
        c.args(["calibrate", dir.to_str().unwrap(), "--camera"])
            .arg(&camera)
            .arg("-o")
            .arg(out);
        let t = Instant::now();
        let o = run(c, 60);
        assert_refused(&o, says, &[bytes(&notes), bytes(&camera)]);
        assert!(t.elapsed() < Duration::from_secs(5), "before the fit");
    }
}

/// Item 7: a batch never exits 0 having read nothing: an empty folder and an unreadable one
/// are refused; an unreadable subfolder gets an error record (exit 1).
#[test]
fn folders_that_give_nothing_to_read_do_not_exit_0() {
    let tmp = tempfile::tempdir().unwrap();
    let empty = tmp.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let o = run(batch(&empty, &[]), 30);
    assert_refused(&o, "holds no image files", &[]);

    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 2);
    let sub = dir.join("sub");
    std::fs::create_dir(&sub).unwrap();
    std::fs::copy(dir.join("sim_00000.png"), sub.join("a.png")).unwrap();
    use std::os::unix::fs::PermissionsExt;
    std::fs::set_permissions(&sub, std::fs::Permissions::from_mode(0o000)).unwrap();
    if std::fs::read_dir(&sub).is_ok() {
        // root reads every folder whatever its mode.
        eprintln!("SKIPPED unreadable folders: this user (root) reads a mode-000 folder");
        std::fs::set_permissions(&sub, std::fs::Permissions::from_mode(0o755)).unwrap();
        return;
    }
    let o = run(batch(&dir, &["-r"]), 60);
    std::fs::set_permissions(&sub, std::fs::Permissions::from_mode(0o755)).unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let out = String::from_utf8_lossy(&o.stdout);
    assert!(
        out.lines()
            .any(|l| l.contains("\"file\":\"sub\"") && l.contains("cannot read the directory")),
        "{out}"
    );
}

/// Low: `GPUSTAR_CACHE_DIR=""` is unset, not the working directory.
#[test]
fn an_empty_cache_dir_variable_writes_nothing_into_the_working_directory() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 1);
    let work = tmp.path().join("work");
    std::fs::create_dir(&work).unwrap();
    let mut c = batch(&dir, &[]);
    c.env("GPUSTAR_CACHE_DIR", "")
        .env("XDG_CACHE_HOME", tmp.path().join("xdg"))
        .current_dir(&work);
    let o = run(c, 60);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(listing(&work).is_empty(), "{:?}", listing(&work));
}
