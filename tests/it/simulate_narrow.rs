//! `gpustar simulate` of narrow fields from a catalog file, with header hints (issue 24,
//! item 5): a user's catalog of one small patch, imported to the binary file, frames pointed
//! at its stars with hints 0.3° off, and `batch --hint header` solving them.

use crate::common::{self, run_ok};
use gpustar::record::{Record, Status};
use gpustar::solve::attitude::attitude_error;
use nalgebra::Matrix3;
use rand::{Rng, SeedableRng};

/// A user CSV of `n` stars (named `N0000`…) uniform in a 2° × 2° patch about RA 150°, Dec 20°,
/// magnitudes 7 to 11 rising to the faint end.
fn patch_csv(n: usize) -> String {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(24);
    let mut text = String::from("id,ra_deg,dec_deg,mag\n");
    let half_ra = 1.0 / 20f64.to_radians().cos();
    for k in 0..n {
        let ra = 150.0 + rng.random_range(-half_ra..half_ra);
        let dec = 20.0 + rng.random_range(-1.0..1.0);
        let mag = 7.0 + 4.0 * rng.random::<f64>().sqrt();
        text.push_str(&format!("N{k:04},{ra:.7},{dec:.7},{mag:.3}\n"));
    }
    text
}

#[test]
fn narrow_frames_of_a_catalog_file_solve_from_their_header_hints() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("patch.csv");
    std::fs::write(&csv, patch_csv(300)).unwrap();
    let cat = dir.path().join("patch.gpustarcat");
    let (csv, cat) = (csv.to_str().unwrap(), cat.to_str().unwrap());
    run_ok(&["catalog", "import", csv, "-o", cat]);
    let sim = dir.path().join("sim");
    let args = [
        "--catalog",
        cat,
        "--fov-deg",
        "0.5",
        "--size",
        "512x512",
        "--mag-limit",
        "11",
        "--limit-snr",
        "8",
        "--hint-offset-deg",
        "0.3",
        "--pointing",
        "catalog",
        "-n",
        "4",
        "--seed",
        "7",
    ];
    common::simulate(&sim, &args);
    // The same seed gives the same files.
    let again = dir.path().join("again");
    common::simulate(&again, &args);
    for name in ["sim_00000.fits", "sim_00003.fits", "truth.jsonl"] {
        assert_eq!(
            std::fs::read(sim.join(name)).unwrap(),
            std::fs::read(again.join(name)).unwrap(),
            "{name}"
        );
    }
    let truth = gpustar::simulate::read_truth(&sim.join("truth.jsonl")).unwrap();
    assert_eq!(truth.len(), 4);
    for t in &truth {
        assert!(t.file.ends_with(".fits"), "{}", t.file);
        let hint = t.hint.as_ref().expect("a hint in the truth");
        assert!((hint.offset_deg - 0.3).abs() < 1e-9, "{hint:?}");
        // Every star of the patch to magnitude 11 is drawn, under its own name.
        assert!(t.stars.len() >= 8, "{}: {} stars", t.file, t.stars.len());
        for s in &t.stars {
            let id = s.catalog_id.as_deref().unwrap();
            assert!(
                s.hip.is_none() && id.starts_with('N') && s.mag <= 11.0,
                "{s:?}"
            );
        }
    }
    let out = dir.path().join("out.jsonl");
    let (simd, out_s) = (sim.to_str().unwrap(), out.to_str().unwrap());
    let camera = sim.join("camera.toml");
    run_ok(&[
        "batch",
        simd,
        "--camera",
        camera.to_str().unwrap(),
        "--catalog",
        cat,
        "--hint",
        "header",
        "--backend",
        "cpu",
        "-q",
        "-o",
        out_s,
    ]);
    let records = gpustar::record::read_jsonl::<Record>(&out, "record").unwrap();
    assert_eq!(records.len(), 4);
    for (r, t) in records.iter().zip(&truth) {
        assert_eq!(r.file, t.file);
        assert_eq!(r.status, Status::Solved, "{r:?}");
        let m = |a: [[f64; 3]; 3]| Matrix3::from_fn(|i, j| a[i][j]);
        let err = attitude_error(&m(r.rotation_matrix.unwrap()), &m(t.rotation_matrix));
        assert!(
            err.to_degrees() < 0.01,
            "{}: off by {}°",
            r.file,
            err.to_degrees()
        );
        let hint = r.hint.as_ref().expect("a hint in the record");
        assert_eq!(hint.source, "OBJCTRA/OBJCTDEC");
        // The sexagesimal cards round the hint by less than 0.2″.
        let offset = hint.offset_deg.unwrap();
        assert!(
            (offset - 0.3).abs() < 1e-3,
            "{}: hint {offset}° off",
            r.file
        );
        // The identifications are the truth's stars, by catalog id.
        let ids: std::collections::HashSet<&str> = t
            .stars
            .iter()
            .filter_map(|s| s.catalog_id.as_deref())
            .collect();
        let matches = r.matches.as_ref().unwrap();
        assert!(matches.len() >= 8, "{}: {} matches", r.file, matches.len());
        for m in matches {
            assert!(ids.contains(m.catalog_id.as_str()), "{}: {m:?}", r.file);
        }
    }
}

#[test]
fn hints_and_pointings_are_refused_where_they_cannot_apply() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("x");
    let run = |args: &[&str]| {
        common::gpustar()
            .args(
                [
                    &["simulate", "--out", out.to_str().unwrap(), "-n", "1"],
                    args,
                ]
                .concat(),
            )
            .output()
            .unwrap()
    };
    for bad in [
        &["--hint-offset-deg", "0.3", "--streaks"][..],
        &["--hint-offset-deg", "0.3", "--sequence"],
        &["--hint-offset-deg", "-1"],
        &["--pointing", "catalog", "--sequence"],
        &["--limit-snr", "0"],
    ] {
        assert_eq!(run(bad).status.code(), Some(2), "{bad:?} accepted");
    }
    // No star to the limit to point at.
    let o = run(&["--pointing", "catalog", "--mag-limit=-3", "--size", "64x64"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("no star to magnitude -3"),
        "{err}"
    );
    // A limit the default zero point leaves in the noise is said.
    let o = run(&["--mag-limit", "10", "--size", "64x64"]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success() && err.contains("--limit-snr"), "{err}");
}
