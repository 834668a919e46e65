//! `gpustar report` through the real binary, on a batch of simulated frames in two folders
//! (one of broken files), run as sequences: the summary's counts are the records', the page
//! is balanced and self-contained, lines that are not records are counted, not fatal, and a
//! page is never written over a file gpustar did not write (nor over a RUN). With Chromium on
//! PATH, the page is drawn by it too.

use crate::common;

use common::{gpustar, run_ok, stderr};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Output;

/// `tmp/run/a`: four simulated 18° frames; `tmp/run/b`: a truncated PNG and a text file
/// named .png. Batched with --sequence into `tmp/run.jsonl`; its records.
fn batched(tmp: &Path) -> (PathBuf, Vec<Value>) {
    let dir = tmp.join("run");
    common::simulate_small(&dir.join("a"), 4);
    let b = dir.join("b");
    std::fs::create_dir_all(&b).unwrap();
    let png = std::fs::read(dir.join("a/sim_00000.png")).unwrap();
    std::fs::write(b.join("torn.png"), &png[..png.len() / 3]).unwrap();
    std::fs::write(b.join("text.png"), "not an image\n").unwrap();
    let out = tmp.join("run.jsonl");
    let mut args = common::batch18_args(&dir, &out);
    args.extend(["-r", "--sequence", "-q"].map(String::from));
    let o = gpustar().args(&args).output().unwrap();
    // 1: the broken files' error records.
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    let records = std::fs::read_to_string(&out)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    (out, records)
}

fn report(args: &[&Path], more: &[&str]) -> Output {
    gpustar()
        .arg("report")
        .args(args)
        .args(more)
        .output()
        .unwrap()
}

/// The number in the summary's line that starts with `label` (after its indent).
fn count(summary: &str, label: &str) -> usize {
    let line = summary
        .lines()
        .find(|l| l.trim_start().starts_with(&format!("{label} ")))
        .unwrap_or_else(|| panic!("no {label:?} line in:\n{summary}"));
    line.split_whitespace()
        .nth(label.split(' ').count())
        .unwrap()
        .parse()
        .unwrap()
}

/// Every element opened is closed (void elements aside), in order.
fn assert_balanced(page: &str) {
    const VOID: [&str; 3] = ["meta", "!DOCTYPE", "br"];
    let mut open: Vec<String> = Vec::new();
    let mut rest = page;
    while let Some(at) = rest.find('<') {
        let end = rest[at..].find('>').expect("a tag left open") + at;
        let tag = &rest[at + 1..end];
        rest = &rest[end + 1..];
        let name: String = tag
            .trim_start_matches('/')
            .chars()
            .take_while(|c| !c.is_whitespace() && *c != '/')
            .collect();
        if VOID.contains(&name.as_str()) || tag.ends_with('/') {
            continue;
        }
        if tag.starts_with('/') {
            assert_eq!(open.pop().as_deref(), Some(name.as_str()), "</{name}>");
        } else {
            open.push(name);
        }
    }
    assert!(open.is_empty(), "never closed: {open:?}");
}

#[test]
fn report_counts_are_the_records_and_the_page_is_whole() {
    let tmp = tempfile::tempdir().unwrap();
    let (run, records) = batched(tmp.path());
    let html = tmp.path().join("page.html");
    let o = report(&[&run], &["--html", html.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = String::from_utf8(o.stdout).unwrap();
    let with = |status: &str, folder: &str| {
        records
            .iter()
            .filter(|r| r["status"] == status && r["file"].as_str().unwrap().starts_with(folder))
            .count()
    };
    assert_eq!(records.len(), 6);
    assert!(
        summary.starts_with(&format!("{}: 6 frames\n", run.display())),
        "{summary}"
    );
    assert_eq!(count(&summary, "solved"), with("solved", ""), "{summary}");
    assert_eq!(count(&summary, "unsolved"), with("unsolved", ""));
    assert_eq!(count(&summary, "error"), with("error", ""));
    assert_eq!(with("error", "b/"), 2);
    // Per folder: frames, solved, unsolved, error.
    for folder in ["a", "b"] {
        let prefix = format!("{folder}/");
        let row: Vec<usize> = summary
            .lines()
            .find(|l| l.split_whitespace().next() == Some(folder))
            .unwrap_or_else(|| panic!("no {folder} row:\n{summary}"))
            .split_whitespace()
            .skip(1)
            .take(4)
            .map(|n| n.parse().unwrap())
            .collect();
        let frames = records
            .iter()
            .filter(|r| r["file"].as_str().unwrap().starts_with(&prefix))
            .count();
        let want = [
            frames,
            with("solved", &prefix),
            with("unsolved", &prefix),
            with("error", &prefix),
        ];
        assert_eq!(row, want, "{folder}: {summary}");
    }
    let solved = with("solved", "");
    assert!(solved > 0, "{summary}");
    assert_eq!(count(&summary, "rms residual (arcsec)"), solved);
    assert_eq!(count(&summary, "stars matched"), solved);
    // The sequences' attitude: a table row for each of `a` with a solved frame.
    assert!(summary.contains("\n  series "), "{summary}");
    let page = std::fs::read_to_string(&html).unwrap();
    assert!(page.starts_with("<!DOCTYPE html>"));
    assert!(page.contains("<meta name=\"generator\" content=\"gpustar "));
    assert_balanced(&page);
    // Availability, residuals, matches, scatter, time, and RA, Dec, roll over frames.
    assert_eq!(page.matches("<svg ").count(), 8, "{page}");
    assert!(!page.contains("<script") && !page.contains("https://") && !page.contains("src="));
    // Rewriting its own page needs no --overwrite.
    let again = report(&[&run], &["--html", html.to_str().unwrap()]);
    assert!(again.status.success(), "{}", stderr(&again));
}

#[test]
fn report_skips_lines_that_are_not_records_and_refuses_others_files() {
    let tmp = tempfile::tempdir().unwrap();
    let run = tmp.path().join("run.jsonl");
    let solved = serde_json::json!({
        "file": "x/1.png", "status": "solved", "reason": null, "error": null,
        "ra_deg": 10.0, "dec_deg": 20.0, "roll_deg": 30.0, "stars_matched": 12,
        "rmse_arcsec": 4.5, "timing_ms": {"decode": 1.0, "detect": 1.0, "identify": 1.0,
        "total": 3.0}, "backend": "cpu"
    });
    let text = format!("{solved}\nGarbage\n{solved}\n");
    std::fs::write(&run, &text).unwrap();
    let o = report(&[&run], &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("run.jsonl: line 2: not a record: "),
        "{}",
        stderr(&o)
    );
    let summary = String::from_utf8(o.stdout).unwrap();
    assert!(
        summary.contains("2 frames (1 lines not records"),
        "{summary}"
    );
    assert_eq!(count(&summary, "solved"), 2);
    // Nothing to report, or nothing to read: exit 2, said once.
    let junk = tmp.path().join("junk.jsonl");
    std::fs::write(&junk, "{}\n").unwrap();
    let o = report(&[&junk], &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("no result records"), "{}", stderr(&o));
    let o = report(&[&tmp.path().join("absent.jsonl")], &[]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("cannot read"), "{}", stderr(&o));
    // A page is not written over a file gpustar did not write, nor over a RUN.
    let theirs = tmp.path().join("theirs.html");
    std::fs::write(&theirs, "<html>mine</html>\n").unwrap();
    let o = report(&[&run], &["--html", theirs.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--overwrite"), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&theirs).unwrap(),
        "<html>mine</html>\n"
    );
    let o = report(&[&run], &["--html", run.to_str().unwrap(), "--overwrite"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("an input"), "{}", stderr(&o));
    assert_eq!(std::fs::read_to_string(&run).unwrap(), text);
    run_ok(&[
        "report",
        run.to_str().unwrap(),
        "--html",
        theirs.to_str().unwrap(),
        "--overwrite",
    ]);
    assert!(std::fs::read_to_string(&theirs).unwrap().contains("<svg"));
}

/// Chromium on PATH, or None with a printed reason (CI does not install it).
fn chromium(test: &str) -> Option<&'static str> {
    let found = ["chromium", "chromium-browser", "google-chrome"]
        .into_iter()
        .find(|b| {
            std::process::Command::new(b)
                .arg("--version")
                .output()
                .is_ok_and(|o| o.status.success())
        });
    if found.is_none() {
        eprintln!("SKIPPED {test}: no chromium, chromium-browser or google-chrome on PATH");
    }
    found
}

/// The page as a browser reads it: Chromium's DOM after loading holds every chart, and its
/// screenshot is a real image.
#[test]
fn report_page_renders_in_chromium() {
    let Some(browser) = chromium("report_page_renders_in_chromium") else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let (run, _) = batched(tmp.path());
    let html = tmp.path().join("page.html");
    run_ok(&[
        "report",
        run.to_str().unwrap(),
        "--html",
        html.to_str().unwrap(),
    ]);
    let png = tmp.path().join("page.png");
    let profile = tmp.path().join("profile");
    let url = format!("file://{}", html.display());
    let o = std::process::Command::new(browser)
        .args([
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--hide-scrollbars",
        ])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(format!("--screenshot={}", png.display()))
        .args(["--window-size=1200,1800", &url])
        .output()
        .unwrap();
    let shot = std::fs::read(&png).unwrap_or_else(|e| panic!("{e}: {}", stderr(&o)));
    assert!(
        shot.starts_with(b"\x89PNG") && shot.len() > 20_000,
        "{}",
        shot.len()
    );
    let dom = std::process::Command::new(browser)
        .args(["--headless", "--no-sandbox", "--disable-gpu", "--dump-dom"])
        .arg(format!("--user-data-dir={}", profile.display()))
        .arg(&url)
        .output()
        .unwrap();
    let dom = String::from_utf8_lossy(&dom.stdout);
    assert_eq!(dom.matches("<svg ").count(), 8, "{dom}");
}
