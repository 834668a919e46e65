//! Fixed-pattern removal: frames whose brightest spots are a pattern fixed on the sensor (the
//! same in every frame) do not solve as they are, and solve after `--dark-median` (the median
//! of the directory's frames) or `--dark FILE` (that pattern) is subtracted.

use crate::common;

use gpustar::catalog::Catalog;
use gpustar::simulate::{SimSettings, render};
use std::path::Path;

const SIZE: u32 = 512;

/// 120 bright 3×3 blobs at fixed places, brighter than all but the brightest stars.
fn pattern() -> Vec<u16> {
    let mut p = vec![0u16; (SIZE * SIZE) as usize];
    let mut state = 12345u32;
    for _ in 0..120 {
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
        let x = (state >> 8) % (SIZE - 3);
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
        let y = (state >> 8) % (SIZE - 3);
        for dy in 0..3 {
            for dx in 0..3 {
                p[((y + dy) * SIZE + x + dx) as usize] = 210;
            }
        }
    }
    p
}

fn write_grey(path: &Path, pixels: &[u16]) {
    let buf: Vec<u8> = pixels.iter().map(|&v| v.min(255) as u8).collect();
    image::GrayImage::from_raw(SIZE, SIZE, buf)
        .unwrap()
        .save(path)
        .unwrap();
}

fn solved(dir: &Path, extra: &[&str]) -> usize {
    let out = common::gpustar()
        .arg("batch")
        .arg(dir)
        .args([
            "--fov-deg",
            "15",
            "--mag-limit",
            "6",
            "--backend",
            "cpu",
            "-q",
        ])
        .args(extra)
        .output()
        .unwrap();
    assert!(out.status.code().is_some_and(|c| c <= 1));
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .filter(|l| l.contains("\"status\":\"solved\""))
        .count()
}

#[test]
fn a_fixed_pattern_is_removed_by_a_dark_or_the_directory_median() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    let cat = Catalog::builtin();
    let s = SimSettings {
        width: SIZE,
        height: SIZE,
        fov_x_deg: 15.0,
        seed: 11,
        ..SimSettings::default()
    };
    let fixed = pattern();
    for k in 0..6 {
        let (pixels, _) = render(&cat, &s, k).unwrap();
        let with: Vec<u16> = pixels.iter().zip(&fixed).map(|(p, f)| p + f).collect();
        write_grey(&frames.join(format!("f{k}.png")), &with);
    }
    // The dark: the pattern on the sky level of an empty frame.
    let dark = tmp.path().join("dark.png");
    let sky = render(
        &cat,
        &SimSettings {
            mag_limit: -5.0,
            false_stars: 0,
            hot_pixels: 0,
            ..s.clone()
        },
        0,
    )
    .unwrap()
    .0;
    let dark_px: Vec<u16> = sky.iter().zip(&fixed).map(|(p, f)| p + f).collect();
    write_grey(&dark, &dark_px);

    let plain = solved(&frames, &[]);
    let median = solved(&frames, &["--dark-median"]);
    let with_dark = solved(&frames, &["--dark", dark.to_str().unwrap()]);
    eprintln!("solved of 6: as they are {plain}, --dark-median {median}, --dark {with_dark}");
    assert!(
        plain <= 1,
        "the pattern should defeat the vote, {plain} solved"
    );
    assert!(median >= 5, "--dark-median solved {median} of 6");
    assert!(with_dark >= 5, "--dark solved {with_dark} of 6");
}

#[test]
fn dark_problems_are_error_records_a_person_can_act_on() {
    let tmp = tempfile::tempdir().unwrap();
    let frames = tmp.path().join("frames");
    std::fs::create_dir(&frames).unwrap();
    write_grey(&frames.join("only.png"), &vec![10; (SIZE * SIZE) as usize]);
    let out = common::gpustar()
        .arg("batch")
        .arg(&frames)
        .args(["--fov-deg", "15", "--backend", "cpu", "-q", "--dark-median"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("\"status\":\"error\""), "{text}");
    assert!(text.contains("at least 3"), "{text}");
    // A dark of another size.
    let small = tmp.path().join("small.png");
    image::GrayImage::new(8, 8).save(&small).unwrap();
    let out = common::gpustar()
        .arg("batch")
        .arg(&frames)
        .args(["--fov-deg", "15", "--backend", "cpu", "-q", "--dark"])
        .arg(&small)
        .output()
        .unwrap();
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(text.contains("the dark frame"), "{text}");
}

/// The errors a frame's record carries keep their kind on the way (a library caller or the
/// Python package can tell a missing file from a bad dark or a missing camera).
#[test]
fn frame_errors_keep_their_kind() {
    use gpustar::io::dark::Darks;
    use gpustar::pipeline::Solvers;
    use gpustar::{CameraSource, Catalog, Error, Settings};
    let tmp = tempfile::tempdir().unwrap();
    let mut solvers = Solvers::new(Catalog::builtin(), Settings::default(), CameraSource::None);
    let missing = solvers.decode(&tmp.path().join("missing.png"), "missing.png");
    assert!(
        matches!(&missing.frame, Err(Error::Io { .. })),
        "{:?}",
        missing.frame.err()
    );
    // No camera: the solver of every size is a configuration error.
    let shared = solvers.get(SIZE, SIZE);
    assert!(
        matches!(shared, Err(Error::Config(_))),
        "{:?}",
        shared.err()
    );
    // A directory median of one frame: an input error, the same for each frame there.
    let one = tmp.path().join("one.png");
    write_grey(&one, &vec![10; (SIZE * SIZE) as usize]);
    solvers.darks = Darks::directory_median();
    for _ in 0..2 {
        let d = solvers.decode(&one, "one.png");
        assert!(
            matches!(&d.frame, Err(Error::Input(m)) if m.contains("at least 3")),
            "{:?}",
            d.frame.err()
        );
    }
}
