//! Bad inputs through the real binary: a directory of broken, hostile and starless files must
//! give exactly one record per image file, in sorted order, `error` records with a message a
//! person can act on for what cannot be read, `unsolved` with a reason for readable frames
//! without a solvable sky, never `solved` for any of them; the run must not panic, hang or
//! allocate gigabytes, and a good frame after the bad ones must still be solved.
//!
//! Linux/Unix only: symbolic links, a FIFO and a file name that is not UTF-8.
#![cfg(unix)]

use crate::common;

use serde_json::Value;
use std::collections::BTreeMap;
use std::ffi::OsStr;
use std::os::unix::ffi::OsStrExt;
use std::os::unix::fs::{PermissionsExt, symlink};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Size of the main frames, and of the camera file.
const W: u32 = 512;
const H: u32 = 384;
/// Longest a run over the corpus may take (a debug build needs a few seconds).
const RUN_LIMIT: Duration = Duration::from_secs(120);

/// What a file must get.
#[derive(Clone, Debug, PartialEq)]
enum Expect {
    /// A good frame: solved.
    Solved,
    /// Readable, but no solvable sky: unsolved with a reason.
    Unsolved,
    /// An error record whose message contains every one of these (case-insensitive).
    Error(Vec<String>),
    /// Not solved, whichever of unsolved or error (used for the --fov-deg run).
    NotSolved,
}

/// One file of the corpus and what its record must be.
#[derive(Clone, Debug)]
struct Case {
    /// The record's `file` (relative path, '/'-separated, lossy UTF-8).
    name: String,
    expect: Expect,
}

struct Corpus {
    /// Kept alive: removed at the end of the test.
    _tmp: tempfile::TempDir,
    root: PathBuf,
    dir: PathBuf,
    camera: PathBuf,
    /// The image files directly in `dir`.
    top: Vec<Case>,
    /// The image files in `dir/sub` (only found with --recursive).
    sub: Vec<Case>,
}

fn error(hints: &[&str]) -> Expect {
    Expect::Error(hints.iter().map(|s| s.to_string()).collect())
}

/// A small deterministic generator (xorshift64*), so the corpus is the same on every run.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| (self.next() >> 56) as u8).collect()
    }
}

fn crc32(data: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in data {
        c ^= b as u32;
        for _ in 0..8 {
            c = if c & 1 != 0 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

fn png_chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
    out.extend_from_slice(&(data.len() as u32).to_be_bytes());
    let start = out.len();
    out.extend_from_slice(kind);
    out.extend_from_slice(data);
    let crc = crc32(&out[start..]);
    out.extend_from_slice(&crc.to_be_bytes());
}

/// A well-formed grey PNG whose header claims `w`×`h` pixels but whose data holds only one
/// short row: what a hostile or corrupted file looks like to a decoder that trusts headers.
fn png_claiming(w: u32, h: u32, bit_depth: u8) -> Vec<u8> {
    let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
    let mut ihdr = Vec::new();
    ihdr.extend_from_slice(&w.to_be_bytes());
    ihdr.extend_from_slice(&h.to_be_bytes());
    ihdr.extend_from_slice(&[bit_depth, 0, 0, 0, 0]); // grey, deflate, no filter, no interlace
    png_chunk(&mut out, b"IHDR", &ihdr);
    // zlib stream with one stored block of 64 zero bytes (filter byte + pixels).
    let data = [0u8; 64];
    let mut z = vec![0x78, 0x01, 0x01];
    z.extend_from_slice(&(data.len() as u16).to_le_bytes());
    z.extend_from_slice(&(!(data.len() as u16)).to_le_bytes());
    z.extend_from_slice(&data);
    let (a, b) = data.iter().fold((1u32, 0u32), |(a, b), &x| {
        let a = (a + x as u32) % 65521;
        (a, (b + a) % 65521)
    });
    z.extend_from_slice(&((b << 16) | a).to_be_bytes());
    png_chunk(&mut out, b"IDAT", &z);
    png_chunk(&mut out, b"IEND", &[]);
    out
}

fn encode(img: &image::DynamicImage, format: image::ImageFormat) -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, format).unwrap();
    buf.into_inner()
}

fn simulate(out: &Path, extra: &[&str]) {
    let size = format!("{W}x{H}");
    let args = ["-n", "1", "--fov-deg", "18", "--size", &size, "--seed", "5"];
    common::simulate(out, &[&args[..], extra].concat());
}

/// Build the corpus: every bad case of the issue, good frames in several formats, files that
/// are not images, and a subdirectory with a directory-link loop.
fn corpus() -> Corpus {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path().to_path_buf();
    let dir = root.join("corpus");
    std::fs::create_dir(&dir).unwrap();
    simulate(&root.join("sim8"), &[]);
    simulate(&root.join("sim16"), &["--bits", "16"]);
    let camera = root.join("camera.toml");
    std::fs::write(
        &camera,
        format!("width = {W}\nheight = {H}\nfov_x_deg = 18\n"),
    )
    .unwrap();
    let good_png = std::fs::read(root.join("sim8/sim_00000.png")).unwrap();
    let good = image::load_from_memory(&good_png).unwrap();
    assert_eq!((good.width(), good.height()), (W, H));
    let grey = good.to_luma8();
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let mut top = Vec::new();
    let mut add = |name: &str, expect: Expect| {
        top.push(Case {
            name: name.to_string(),
            expect,
        })
    };
    let write = |name: &str, bytes: &[u8]| std::fs::write(dir.join(name), bytes).unwrap();

    // Truncated files of each format: the first half of a good frame's file. A decoder
    // that fills the missing part in (JPEG decoders tend to) must still not pass it on.
    write("truncated.png", &good_png[..good_png.len() / 2]);
    add("truncated.png", error(&["truncated.png", "truncated"]));
    let jpeg = encode(&good, image::ImageFormat::Jpeg);
    write("truncated.jpg", &jpeg[..jpeg.len() / 2]);
    add("truncated.jpg", error(&["truncated.jpg", "truncated"]));
    let tiff = encode(&good, image::ImageFormat::Tiff);
    write("truncated.tif", &tiff[..tiff.len() / 2]);
    add("truncated.tif", error(&["truncated.tif", "truncated"]));
    // A zero-byte file: say it is empty.
    write("empty.png", b"");
    add("empty.png", error(&["empty.png", "empty"]));
    // Text named .png.
    write("not_png.png", b"this is a text file, not a picture\n");
    add("not_png.png", error(&["not_png.png", "cannot decode"]));
    // A header claiming 60000x60000: refused from the header, nothing allocated (the
    // memory-limited run below checks the allocation); the message gives the size.
    write("huge_header.png", &png_claiming(60000, 60000, 8));
    add(
        "huge_header.png",
        error(&["huge_header.png", "60000x60000"]),
    );
    // A 1x1 image: not the camera's size.
    let one =
        image::DynamicImage::ImageLuma8(image::GrayImage::from_pixel(1, 1, image::Luma([128])));
    write("one_pixel.png", &encode(&one, image::ImageFormat::Png));
    add("one_pixel.png", error(&["1x1", &format!("{W}x{H}")]));
    // A good star field of the wrong size for the camera file (a crop): error, not a guess.
    let crop = image::DynamicImage::ImageLuma8(
        image::imageops::crop_imm(&grey, 64, 48, W / 2, H / 2).to_image(),
    );
    write("wrong_size.png", &encode(&crop, image::ImageFormat::Png));
    add(
        "wrong_size.png",
        error(&[&format!("{}x{}", W / 2, H / 2), &format!("{W}x{H}")]),
    );
    // Starless frames of the right size: unsolved (too few stars), never solved.
    let flat = |v: u8| {
        image::DynamicImage::ImageLuma8(image::GrayImage::from_pixel(W, H, image::Luma([v])))
    };
    write("black.png", &encode(&flat(0), image::ImageFormat::Png));
    add("black.png", Expect::Unsolved);
    write(
        "saturated.png",
        &encode(&flat(255), image::ImageFormat::Png),
    );
    add("saturated.png", Expect::Unsolved);
    let noise = image::GrayImage::from_raw(W, H, rng.bytes((W * H) as usize)).unwrap();
    write(
        "noise.png",
        &encode(
            &image::DynamicImage::ImageLuma8(noise),
            image::ImageFormat::Png,
        ),
    );
    add("noise.png", Expect::Unsolved);
    // 16-bit noise, roughly Gaussian (sum of 12 uniforms), around 1000 with sigma ~100.
    let noise16: Vec<u16> = (0..W * H)
        .map(|_| {
            let s: u32 = (0..12).map(|_| (rng.next() >> 48) as u32 % 101).sum();
            (s + 400) as u16
        })
        .collect();
    let noise16 = image::ImageBuffer::<image::Luma<u16>, _>::from_raw(W, H, noise16).unwrap();
    write(
        "noise16.png",
        &encode(
            &image::DynamicImage::ImageLuma16(noise16),
            image::ImageFormat::Png,
        ),
    );
    add("noise16.png", Expect::Unsolved);
    // Format variants of good frames must still solve: a 16-bit PNG, and an RGBA PNG whose
    // alpha is 0 everywhere (alpha is ignored).
    std::fs::copy(root.join("sim16/sim_00000.png"), dir.join("good16.png")).unwrap();
    add("good16.png", Expect::Solved);
    let rgba = image::RgbaImage::from_fn(W, H, |x, y| {
        let v = grey.get_pixel(x, y).0[0];
        image::Rgba([v, v, v, 0])
    });
    write(
        "good_rgba.png",
        &encode(
            &image::DynamicImage::ImageRgba8(rgba),
            image::ImageFormat::Png,
        ),
    );
    add("good_rgba.png", Expect::Solved);
    // Files that are not images under an image name: ZIP bytes and random bytes.
    let mut zip = b"PK\x03\x04\x14\x00\x00\x00\x00\x00".to_vec();
    zip.extend_from_slice(&rng.bytes(200));
    zip.extend_from_slice(b"PK\x05\x06\x00\x00\x00\x00\x01\x00\x01\x00");
    write("archive.tiff", &zip);
    add("archive.tiff", error(&["archive.tiff", "cannot decode"]));
    write("random.tif", &rng.bytes(4096));
    add("random.tif", error(&["random.tif", "cannot decode"]));
    // Not image types: no record at all.
    write("notes.txt", b"observing log\n");
    write("data.csv", b"file,exposure\nsim.png,0.1\n");
    // Links: dangling, a two-link loop and a self-loop: "cannot open" with the OS reason.
    symlink("no_such_file.png", dir.join("dangling.png")).unwrap();
    add("dangling.png", error(&["dangling.png", "no such file"]));
    symlink("loop_b.png", dir.join("loop_a.png")).unwrap();
    symlink("loop_a.png", dir.join("loop_b.png")).unwrap();
    add("loop_a.png", error(&["loop_a.png", "symbolic links"]));
    add("loop_b.png", error(&["loop_b.png", "symbolic links"]));
    symlink("self_loop.png", dir.join("self_loop.png")).unwrap();
    add("self_loop.png", error(&["self_loop.png", "symbolic links"]));
    // A link with an image name to a FIFO: opening a FIFO blocks until a writer comes, so
    // reading it would hang the run. It must be refused as not a regular file.
    let fifo = Command::new("mkfifo").arg(dir.join("pipe")).status();
    if fifo.is_ok_and(|s| s.success()) {
        symlink("pipe", dir.join("fifo_link.png")).unwrap();
        add(
            "fifo_link.png",
            error(&["fifo_link.png", "not a regular file"]),
        );
        // A FIFO named as an image gets its record too (it once got none).
        assert!(
            Command::new("mkfifo")
                .arg(dir.join("fifo.png"))
                .status()
                .unwrap()
                .success()
        );
        add("fifo.png", error(&["fifo.png", "not a regular file"]));
    } else {
        eprintln!("bad_input: no mkfifo here; the FIFO cases are left out");
    }
    // An unreadable file: mode 000. Root (or CAP_DAC_OVERRIDE) reads it anyway; then the
    // unreadable case is a dangling link of the same name instead.
    let unreadable = dir.join("unreadable.png");
    std::fs::write(&unreadable, &good_png).unwrap();
    std::fs::set_permissions(&unreadable, std::fs::Permissions::from_mode(0o000)).unwrap();
    if std::fs::File::open(&unreadable).is_ok() {
        std::fs::remove_file(&unreadable).unwrap();
        symlink("gone/away.png", &unreadable).unwrap();
        eprintln!(
            "bad_input: privileged user (mode 000 does not stop reads): unreadable.png is a \
             dangling symlink"
        );
        add("unreadable.png", error(&["unreadable.png", "no such file"]));
    } else {
        eprintln!("bad_input: unreadable.png has mode 000");
        add(
            "unreadable.png",
            error(&["unreadable.png", "permission denied"]),
        );
    }
    // File names that are not UTF-8 and differ only in such a byte (0xFF, 0xFE), holding a
    // good frame: solved, each under its own name, the byte escaped as \xNN (issue 22, item
    // 7: both were once "\u{FFFD}.png").
    // Beside them a UTF-8 name that spells out the first one's escape: its own record, its
    // backslash doubled (issue 45: the two once refused the whole run).
    for (bytes, name) in [
        (&b"\xff.png"[..], "\\xff.png"),
        (&b"\xfe.png"[..], "\\xfe.png"),
        (&b"\\xff.png"[..], "\\\\xff.png"),
    ] {
        std::fs::write(dir.join(OsStr::from_bytes(bytes)), &good_png).unwrap();
        add(name, Expect::Solved);
    }
    // The good frame, sorted after every bad one: the run goes on to it and solves it.
    std::fs::write(dir.join("zz_good.png"), &good_png).unwrap();
    add("zz_good.png", Expect::Solved);

    // A subdirectory (only with --recursive) with a loop back to its parent and to itself,
    // and a link with an image name to it.
    let sub = dir.join("sub");
    std::fs::create_dir(&sub).unwrap();
    symlink("..", sub.join("loop")).unwrap();
    symlink(".", sub.join("here")).unwrap();
    // A link with an image name to a directory: not an input (links to directories are not
    // followed), so no record, with or without --recursive.
    symlink("sub", dir.join("linkdir.png")).unwrap();
    std::fs::write(
        sub.join("black.png"),
        encode(&flat(0), image::ImageFormat::Png),
    )
    .unwrap();
    std::fs::write(sub.join("truncated.png"), &good_png[..good_png.len() / 3]).unwrap();
    std::fs::write(sub.join("zz_good.png"), &good_png).unwrap();
    let sub_cases = vec![
        Case {
            name: "sub/black.png".into(),
            expect: Expect::Unsolved,
        },
        Case {
            name: "sub/truncated.png".into(),
            expect: error(&["sub/truncated.png", "truncated"]),
        },
        Case {
            name: "sub/zz_good.png".into(),
            expect: Expect::Solved,
        },
    ];
    Corpus {
        _tmp: tmp,
        root,
        dir,
        camera,
        top,
        sub: sub_cases,
    }
}

/// Run gpustar with a time limit (a hang fails the test instead of stalling it); returns
/// (exit code, stdout, stderr).
fn run_limited(mut cmd: Command, what: &str) -> (Option<i32>, String, String) {
    let out_dir = tempfile::tempdir().unwrap();
    let (so, se) = (out_dir.path().join("stdout"), out_dir.path().join("stderr"));
    cmd.stdin(Stdio::null())
        .stdout(std::fs::File::create(&so).unwrap())
        .stderr(std::fs::File::create(&se).unwrap());
    let t0 = Instant::now();
    let mut child = cmd.spawn().unwrap();
    let status = loop {
        if let Some(s) = child.try_wait().unwrap() {
            break s;
        }
        if t0.elapsed() > RUN_LIMIT {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{what}: still running after {RUN_LIMIT:?} (hung?); stderr:\n{}",
                std::fs::read_to_string(&se).unwrap_or_default()
            );
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let read = |p: &Path| String::from_utf8_lossy(&std::fs::read(p).unwrap()).into_owned();
    let (stdout, stderr) = (read(&so), read(&se));
    println!(
        "{what}: exit {:?} in {:.1} s; stderr:\n{stderr}",
        status.code(),
        t0.elapsed().as_secs_f64()
    );
    (status.code(), stdout, stderr)
}

/// `gpustar batch` over the corpus; returns the records (checked: exit status 1, stdout
/// empty, no panic and no internal error on stderr).
fn batch(c: &Corpus, tag: &str, args: &[&str], env: &[(&str, &OsStr)]) -> Vec<Value> {
    let out = c.root.join(format!("{tag}.jsonl"));
    let mut cmd = common::gpustar();
    cmd.arg("batch").arg(&c.dir).args(args).arg("-o").arg(&out);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let (code, stdout, stderr) = run_limited(cmd, tag);
    assert!(!stderr.contains("panicked"), "{tag}: a panic:\n{stderr}");
    assert!(
        !stderr.contains("internal error"),
        "{tag}: an internal error:\n{stderr}"
    );
    assert_eq!(
        code,
        Some(1),
        "{tag}: some inputs are errors, so the exit status must be 1; stderr:\n{stderr}"
    );
    assert!(stdout.is_empty(), "{tag}: records go to -o, not stdout");
    std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("{tag}: bad line {l}: {e}")))
        .collect()
}

/// Check records against the cases: one record per case, sorted by name, each as expected.
fn check(tag: &str, records: &[Value], cases: &[Case]) {
    let mut want: Vec<&Case> = cases.iter().collect();
    want.sort_by(|a, b| a.name.cmp(&b.name));
    let got: Vec<&str> = records
        .iter()
        .map(|r| r["file"].as_str().expect("file is a string"))
        .collect();
    let want_names: Vec<&str> = want.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(
        got,
        want_names,
        "{tag}: exactly one record per image file ({} of them), in sorted order, none for \
         other files or links to directories",
        want.len()
    );
    let mut failures = Vec::new();
    for (r, case) in records.iter().zip(&want) {
        let status = r["status"].as_str().unwrap_or("?");
        let message = r["error"].as_str().unwrap_or("");
        let reason = r["reason"].as_str().unwrap_or("");
        println!("{tag}: {:<20} {status:<8} {reason}{message}", case.name);
        let ok = match &case.expect {
            Expect::Solved => status == "solved",
            Expect::Unsolved => {
                status == "unsolved"
                    && ["too_few_stars", "no_consistent_match", "low_confidence"].contains(&reason)
                    && r["error"].is_null()
            }
            Expect::NotSolved => match status {
                "unsolved" => !reason.is_empty(),
                "error" => !message.trim().is_empty(),
                _ => false,
            },
            Expect::Error(hints) => {
                let m = message.to_lowercase();
                status == "error" && hints.iter().all(|h| m.contains(&h.to_lowercase()))
            }
        };
        if !ok {
            failures.push(format!(
                "{}: expected {:?}, got status {status:?} reason {reason:?} error {message:?}",
                case.name, case.expect
            ));
        }
    }
    assert!(
        failures.is_empty(),
        "{tag}: records not as expected:\n{}",
        failures.join("\n")
    );
}

fn camera_args(c: &Corpus) -> Vec<String> {
    vec!["--camera".into(), c.camera.to_str().unwrap().into()]
}

fn args<'a>(v: &'a [String], more: &[&'a str]) -> Vec<&'a str> {
    v.iter()
        .map(|s| s.as_str())
        .chain(more.iter().copied())
        .collect()
}

#[test]
fn bad_inputs_get_one_record_each_and_never_solved() {
    let c = corpus();
    let cam = camera_args(&c);
    let records = batch(&c, "cpu", &args(&cam, &["--backend", "cpu"]), &[]);
    check("cpu", &records, &c.top);
}

#[test]
fn recursive_walk_takes_subdirectories_and_does_not_follow_link_loops() {
    let c = corpus();
    let cam = camera_args(&c);
    let records = batch(
        &c,
        "recursive",
        &args(&cam, &["--backend", "cpu", "--recursive"]),
        &[],
    );
    // sub/ once, never through sub/loop, sub/here or linkdir.png.
    let cases: Vec<Case> = c.top.iter().chain(&c.sub).cloned().collect();
    check("recursive", &records, &cases);
}

/// With --fov-deg every size is accepted, so the 1x1 frame and the wrong-size crop go
/// through detection: no panic, and neither may be solved (the crop is of an 9° field, not
/// 18°). Everything else is as with the camera file.
#[test]
fn bad_inputs_with_fov_deg_are_never_solved() {
    let c = corpus();
    let cases: Vec<Case> = c
        .top
        .iter()
        .map(|k| Case {
            name: k.name.clone(),
            expect: match k.name.as_str() {
                "one_pixel.png" | "wrong_size.png" => Expect::NotSolved,
                _ => k.expect.clone(),
            },
        })
        .collect();
    let records = batch(&c, "fov", &["--fov-deg", "18", "--backend", "cpu"], &[]);
    check("fov", &records, &cases);
}

/// A header claiming a huge image must be refused before anything big is allocated. The run
/// has its address space limited to 1 GiB (`ulimit -v`), so an allocation of gigabytes ends
/// the process (Rust aborts on allocation failure) and fails this test; the frames after
/// the huge headers must still be solved.
#[test]
fn huge_image_headers_are_refused_without_allocating_gigabytes() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("huge");
    std::fs::create_dir(&dir).unwrap();
    simulate(&tmp.path().join("sim"), &[]);
    // Over the side limit: refused from the header.
    std::fs::write(dir.join("a_60000.png"), png_claiming(60000, 60000, 8)).unwrap();
    std::fs::write(dir.join("b_60000x16.png"), png_claiming(60000, 60000, 16)).unwrap();
    // Under the side limit, but 1.8 GB of 16-bit pixels from a 132-byte file.
    std::fs::write(dir.join("c_30000x16.png"), png_claiming(30000, 30000, 16)).unwrap();
    std::fs::copy(tmp.path().join("sim/sim_00000.png"), dir.join("z_good.png")).unwrap();
    let mut cmd = Command::new("sh");
    let bin = common::gpustar();
    cmd.arg("-c")
        .arg("ulimit -v 1048576 && exec \"$0\" \"$@\"")
        .arg(bin.get_program())
        .args(["batch", dir.to_str().unwrap(), "--fov-deg", "18"])
        .args(["--backend", "cpu", "-j", "1"]);
    for (k, v) in bin.get_envs() {
        if let Some(v) = v {
            cmd.env(k, v);
        }
    }
    let t0 = Instant::now();
    let (code, stdout, stderr) = run_limited(cmd, "huge");
    assert!(
        t0.elapsed() < Duration::from_secs(60),
        "huge headers took {:?}",
        t0.elapsed()
    );
    assert!(
        !stderr.contains("memory allocation"),
        "an allocation of gigabytes failed and ended the run:\n{stderr}"
    );
    assert!(!stderr.contains("panicked"), "a panic:\n{stderr}");
    assert_eq!(code, Some(1), "exit status; stderr:\n{stderr}");
    let records: Vec<Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let cases = [
        ("a_60000.png", error(&["a_60000.png", "60000x60000"])),
        ("b_60000x16.png", error(&["b_60000x16.png", "60000x60000"])),
        ("c_30000x16.png", error(&["c_30000x16.png", "30000x30000"])),
        ("z_good.png", Expect::Solved),
    ]
    .map(|(n, e)| Case {
        name: n.into(),
        expect: e,
    });
    check("huge", &records, &cases);
}

/// The GPU backend must give the same statuses, reasons, errors and star counts as the CPU
/// on the same corpus, with the camera file and with --fov-deg (odd sizes reach the kernels).
#[test]
fn bad_inputs_on_the_gpu_match_the_cpu() {
    let Some(g) = common::gpu("bad_inputs_on_the_gpu_match_the_cpu") else {
        return;
    };
    drop(g);
    let c = corpus();
    let xdg = c.root.join("xdg");
    std::fs::create_dir(&xdg).unwrap();
    std::fs::set_permissions(&xdg, std::fs::Permissions::from_mode(0o700)).unwrap();
    let env = [("XDG_RUNTIME_DIR", xdg.as_os_str())];
    let cam = camera_args(&c);
    for (tag, base) in [
        ("camera", cam.clone()),
        ("fov", vec!["--fov-deg".to_string(), "18".to_string()]),
    ] {
        // One worker: frames reach the GPU in input order, so its batches are the same on
        // every run.
        let cpu = batch(
            &c,
            &format!("{tag}-cpu"),
            &args(&base, &["--backend", "cpu", "-j", "1"]),
            &[],
        );
        let gpu = batch(
            &c,
            &format!("{tag}-gpu"),
            &args(&base, &["--backend", "gpu", "-j", "1"]),
            &env,
        );
        assert_eq!(cpu.len(), gpu.len(), "{tag}: record counts");
        let key = |r: &Value| {
            BTreeMap::from([
                ("file", r["file"].clone()),
                ("status", r["status"].clone()),
                ("reason", r["reason"].clone()),
                ("error", r["error"].clone()),
                ("stars_detected", r["stars_detected"].clone()),
                ("stars_matched", r["stars_matched"].clone()),
            ])
        };
        let mut differ = Vec::new();
        for (a, b) in cpu.iter().zip(&gpu) {
            if key(a) != key(b) {
                differ.push(format!("cpu {:?}\ngpu {:?}", key(a), key(b)));
            }
            let backend = b["backend"].as_str().unwrap_or("");
            assert!(
                backend.starts_with("gpu"),
                "{tag}: {} ran on {backend:?}, not the GPU",
                b["file"]
            );
        }
        assert!(
            differ.is_empty(),
            "{tag}: GPU records differ from the CPU's:\n{}",
            differ.join("\n")
        );
        if tag == "camera" {
            check("camera-gpu", &gpu, &c.top);
        }
    }
}
