//! One run configuration: `--config run.toml` sets the options the command line would (the same
//! records), the command line wins over it, bad files are refused before any work, and the
//! configuration kept beside `-o` (`OUTPUT.run.toml`) lets `--resume` go on only with the same
//! options and catalog.

use crate::common;

use common::gpustar;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// The records of a file less their timings.
fn records(path: &Path) -> Vec<Value> {
    std::fs::read_to_string(path)
        .unwrap()
        .lines()
        .map(|l| {
            let mut v: Value = serde_json::from_str(l).unwrap();
            v["timing_ms"] = Value::Null;
            v
        })
        .collect()
}

fn run(args: &[&str]) -> std::process::Output {
    gpustar().args(args).output().unwrap()
}

fn set_up(n: usize) -> (tempfile::TempDir, PathBuf) {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, n);
    (tmp, dir)
}

#[test]
fn a_config_file_gives_the_command_line_s_records_and_the_command_line_wins() {
    let (tmp, dir) = set_up(6);
    let d = dir.to_str().unwrap();
    let by_options = tmp.path().join("options.jsonl");
    let o = run(&[
        "batch",
        d,
        "--fov-deg",
        "18",
        "--mag-limit",
        "6",
        "--sigma",
        "6",
        "--vote-stars",
        "30",
        "--backend",
        "cpu",
        "-q",
        "-o",
        by_options.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    let cfg = tmp.path().join("run.toml");
    std::fs::write(
        &cfg,
        "fov_deg = 18\nmag_limit = 6\nsigma = 6\nvote_stars = 30\nbackend = \"cpu\"\n",
    )
    .unwrap();
    let by_file = tmp.path().join("file.jsonl");
    let c = cfg.to_str().unwrap();
    let o = run(&[
        "batch",
        d,
        "--config",
        c,
        "-q",
        "-o",
        by_file.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    assert_eq!(records(&by_options), records(&by_file));
    assert!(records(&by_file).iter().all(|r| r["status"] == "solved"));

    // The command line wins: a camera given there replaces the file's field of view, and its
    // --sigma the file's (the sidecar says what the run used).
    let cam = dir.join("camera.toml");
    let mixed = tmp.path().join("mixed.jsonl");
    let o = run(&[
        "batch",
        d,
        "--config",
        c,
        "--camera",
        cam.to_str().unwrap(),
        "--sigma",
        "5",
        "-q",
        "-o",
        mixed.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", common::stderr(&o));
    let side = std::fs::read_to_string(tmp.path().join("mixed.jsonl.run.toml")).unwrap();
    assert!(side.starts_with("# gpustar run configuration"), "{side}");
    assert!(
        side.contains("sigma = 5.0") && side.contains("vote_stars = 30"),
        "{side}"
    );
    assert!(
        side.contains("camera = ") && !side.contains("fov_deg"),
        "{side}"
    );

    // Refused before any work, exit 2, naming the option: an unknown name, a value out of
    // range, a missing file.
    for (text, says) in [
        ("sigmaa = 5", "unknown field `sigmaa`"),
        ("sigma = 1000", "sigma: 1000 is outside 0.5 to 100"),
        ("method = \"guess\"", "is not one of vote, radial, triangle"),
    ] {
        std::fs::write(&cfg, text).unwrap();
        let out = tmp.path().join("bad.jsonl");
        let o = run(&["batch", d, "--config", c, "-q", "-o", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{text}");
        assert!(
            common::stderr(&o).contains(says),
            "{text}: {}",
            common::stderr(&o)
        );
        assert!(!out.exists(), "{text}: nothing written");
    }
    let o = run(&["batch", d, "--config", "/nonexistent/run.toml", "-q"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(common::stderr(&o).contains("/nonexistent/run.toml"));
}

#[test]
fn resume_goes_on_only_with_the_options_and_catalog_the_records_were_made_with() {
    let (tmp, dir) = set_up(4);
    let d = dir.to_str().unwrap();
    let out = tmp.path().join("r.jsonl");
    let o_ = out.to_str().unwrap();
    let base = [
        "batch",
        d,
        "--fov-deg",
        "18",
        "--mag-limit",
        "6",
        "-q",
        "-o",
        o_,
    ];
    let o = run(&[&base[..], &["--backend", "cpu"]].concat());
    assert!(o.status.success(), "{}", common::stderr(&o));
    let side = tmp.path().join("r.jsonl.run.toml");
    let text = std::fs::read_to_string(&side).unwrap();
    for part in [
        "gpustar = ",
        "[catalog]",
        "builtin:hip2_hp9.csv",
        "[config]",
        "fov_deg = 18.0",
    ] {
        assert!(text.contains(part), "{part}: {text}");
    }
    // Another --sigma, another catalog: refused, the records untouched.
    let before = std::fs::read(&out).unwrap();
    let o = run(&[&base[..], &["--resume", "--sigma", "7"]].concat());
    assert_eq!(o.status.code(), Some(2));
    let e = common::stderr(&o);
    assert!(
        e.contains("another configuration") && e.contains("sigma: 5.0 then, 7.0 now"),
        "{e}"
    );
    assert_eq!(std::fs::read(&out).unwrap(), before);
    // The same options (another backend and batch size do not change a record): it goes on.
    let o = run(&[
        &base[..],
        &["--resume", "--backend", "cpu", "--batch-size", "8"],
    ]
    .concat());
    assert!(o.status.success(), "{}", common::stderr(&o));
    assert_eq!(records(&out).len(), 4);
    // A file at the sidecar's path that gpustar did not write is refused, and kept.
    std::fs::write(&side, "my notes\n").unwrap();
    let o = run(&[&base[..], &["--resume"]].concat());
    assert_eq!(o.status.code(), Some(2));
    assert!(
        common::stderr(&o).contains("run.toml"),
        "{}",
        common::stderr(&o)
    );
    assert_eq!(std::fs::read_to_string(&side).unwrap(), "my notes\n");
    // Records from before gpustar kept a sidecar resume as before.
    std::fs::remove_file(&side).unwrap();
    let o = run(&[&base[..], &["--resume", "--sigma", "7"]].concat());
    assert!(o.status.success(), "{}", common::stderr(&o));
}
