use super::*;
use crate::record::Record;

fn solved(file: &str, matched: usize, rmse: f64) -> Record {
    Record {
        status: Status::Solved,
        ra_deg: Some(10.0),
        dec_deg: Some(20.0),
        roll_deg: Some(30.0),
        stars_matched: Some(matched),
        stars_detected: Some(matched + 5),
        rmse_arcsec: Some(rmse),
        fov_x_deg: Some(18.0),
        ..Record::empty(file, "cpu")
    }
}

fn unsolved(file: &str, reason: &str) -> Record {
    Record {
        reason: Some(reason.into()),
        stars_detected: Some(3),
        ..Record::empty(file, "cpu")
    }
}

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

fn jsonl(records: &[Record]) -> String {
    records.iter().map(|r| r.to_json_line() + "\n").collect()
}

#[test]
fn quantiles_interpolate_between_ranks() {
    let v = [1.0, 2.0, 3.0, 4.0, 5.0];
    assert_eq!(quantile(&v, 0.5), 3.0);
    assert_eq!(quantile(&v, 0.1), 1.4);
    assert_eq!(quantile(&v, 0.9), 4.6);
    assert_eq!(quantile(&v, 1.0), 5.0);
    assert_eq!(quantile(&[7.0], 0.9), 7.0);
    let d = Dist::of([4.0, f64::NAN, 1.0, 3.0, 2.0]).unwrap();
    assert_eq!((d.n, d.min, d.median, d.max), (4, 1.0, 2.5, 4.0));
    assert!(
        (d.p10 - 1.3).abs() < 1e-12 && (d.p90 - 3.7).abs() < 1e-12,
        "{d:?}"
    );
    assert!(Dist::of([f64::INFINITY]).is_none());
    assert!(Dist::of([]).is_none());
    // Printed as short as their size allows; a hair off a whole number is that number.
    let shown: Vec<String> = [92.0 - 1e-12, 12.34, 1234.5, 0.5, 2.0e-5]
        .map(text::short)
        .to_vec();
    assert_eq!(shown, ["92", "12.3", "1234", "0.500", "2.00e-5"]);
}

#[test]
fn counts_by_outcome_reason_folder_and_message() {
    let tmp = tempfile::tempdir().unwrap();
    let records = [
        solved("a/1.png", 10, 5.0),
        solved("a/2.png", 20, 15.0),
        unsolved("a/3.png", "too_few_stars"),
        unsolved("b/1.png", "too_few_stars"),
        unsolved("b/2.png", "no_consistent_match"),
        Record::error("b/3.png", "cannot decode b/3.png: truncated".into(), "cpu"),
        Record::error(
            "top.png",
            "cannot decode run/top.png: truncated".into(),
            "cpu",
        ),
    ];
    let run = read_run(&write(tmp.path(), "run.jsonl", &jsonl(&records))).unwrap();
    assert!(run.bad.is_empty(), "{:?}", run.bad);
    let s = summarise(&[run]);
    assert_eq!((s.all.frames, s.all.solved, s.all.errors), (7, 2, 2));
    assert_eq!(
        s.all.unsolved,
        vec![
            ("too_few_stars".to_string(), 2),
            ("no_consistent_match".to_string(), 1)
        ]
    );
    // One cause on two frames is one message.
    assert_eq!(
        s.errors,
        vec![("cannot decode FILE: truncated".to_string(), 2)]
    );
    let names: Vec<&str> = s.groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(names, ["a", "b", "."]);
    assert_eq!((s.groups[0].solved, s.groups[0].frames), (2, 3));
    assert!((s.groups[0].availability() - 2.0 / 3.0).abs() < 1e-12);
    assert_eq!((s.groups[1].unsolved_total(), s.groups[1].errors), (2, 1));
    // Residuals and matches of solved frames only; detections of every frame read.
    assert_eq!(s.residual, [5.0, 15.0]);
    assert_eq!(s.matched, [10.0, 20.0]);
    assert_eq!(s.detected, [15.0, 25.0, 3.0, 3.0, 3.0]);
    assert_eq!(s.scatter, [(10.0, 5.0), (20.0, 15.0)]);
    assert!(s.series.is_empty());
    let text = text::render(&s);
    assert!(text.contains("7 frames"), "{text}");
    assert!(
        text.contains("too_few_stars 2, no_consistent_match 1"),
        "{text}"
    );
}

#[test]
fn bad_lines_are_counted_not_fatal() {
    let tmp = tempfile::tempdir().unwrap();
    let good = jsonl(&[solved("x.png", 9, 3.0)]);
    let text = format!("{good}not json\n\n{{\"file\": 3}}\n{good}{{\"file\":\"torn");
    let run = read_run(&write(tmp.path(), "r.jsonl", &text)).unwrap();
    assert_eq!(run.rows.len(), 2);
    let lines: Vec<usize> = run.bad.iter().map(|b| b.line).collect();
    assert_eq!(lines, [2, 4, 6]);
    assert!(run.bad[2].why.contains("incomplete"), "{:?}", run.bad[2]);
    assert!(
        run.bad[0]
            .to_string()
            .ends_with("line 2: not a record: expected ident at line 1 column 2"),
        "{}",
        run.bad[0]
    );
    // Binary garbage is lines that are not records too.
    let run = read_run(&write(tmp.path(), "bin", "\u{0}\u{1}\n\u{fffd}\n")).unwrap();
    assert_eq!((run.rows.len(), run.bad.len()), (0, 2));
    // A directory is not a run file.
    assert!(read_run(tmp.path()).is_err());
}

#[test]
fn csv_records_read_as_json_lines_do() {
    use crate::io::output::{CSV_HEADER, csv_row};
    let tmp = tempfile::tempdir().unwrap();
    let records = [
        solved("a/1.png", 10, 5.0),
        unsolved("a/x,\"y\"\n2.png", "too_few_stars"),
        Record::error("b/3.png", "bad, very".into(), "cpu"),
    ];
    let mut text = format!("{CSV_HEADER}\n");
    for r in &records {
        text += &csv_row(r);
        text.push('\n');
    }
    text += "a/4.png,maybe\n";
    let csv = read_run(&write(tmp.path(), "r.csv", &text)).unwrap();
    let json = read_run(&write(tmp.path(), "r.jsonl", &jsonl(&records))).unwrap();
    assert_eq!(csv.rows, json.rows);
    assert_eq!(csv.bad.len(), 1);
    assert_eq!(csv.bad[0].line, 6);
}

#[test]
fn sequences_and_dated_folders_are_series() {
    let year = 365.25 * 86400.0;
    let mut records = Vec::new();
    for i in 0..4 {
        let mut r = solved(&format!("seq/f{i}.png"), 10, 2.0);
        r.ra_deg = Some((359.0 + i as f64) % 360.0);
        r.sequence_mode = Some(if i == 0 { "lost_in_space" } else { "tracking" }.into());
        if i == 2 {
            r = Record {
                sequence_mode: r.sequence_mode,
                ..unsolved(&r.file, "too_few_stars")
            };
        }
        records.push(r);
    }
    // FITS frames with their own dates, listed out of time order.
    for (name, t) in [("night/b.fits", 60.0), ("night/a.fits", 0.0)] {
        let mut r = solved(name, 10, 2.0);
        r.epoch = Some(2020.0 + t / year);
        records.push(r);
    }
    // Same epoch throughout: no series.
    records.push(solved("plain/a.png", 10, 2.0));
    records.push(solved("plain/b.png", 10, 2.0));
    let rows: Vec<Row> = records.into_iter().map(Row::from).collect();
    let s = summarise(&[Run {
        path: "r.jsonl".into(),
        rows,
        bad: Vec::new(),
    }]);
    let names: Vec<&str> = s.series.iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["night", "seq"]);
    let seq = &s.series[1];
    assert_eq!(seq.frames, 4);
    let idx: Vec<usize> = seq.points.iter().map(|p| p.index).collect();
    assert_eq!(idx, [0, 1, 3]);
    assert_eq!(seq.points.iter().filter(|p| p.tracking).count(), 2);
    assert!(seq.points.iter().all(|p| p.t_s.is_none()));
    let night = &s.series[0];
    let t: Vec<f64> = night.points.iter().map(|p| p.t_s.unwrap()).collect();
    assert!(
        (t[0] - 0.0).abs() < 1e-3 && (t[1] - 60.0).abs() < 1e-3,
        "{t:?}"
    );
    let text = text::render(&s);
    assert!(text.contains(" 359.00 → 2.00 "), "{text}");
    assert!(text.contains("60.0 s"), "{text}");
}

#[test]
fn folders_of_relative_and_absolute_names() {
    assert_eq!(folder_of("a/b/c.png"), "a");
    assert_eq!(folder_of("c.png"), ".");
    assert_eq!(folder_of("/data/x/c.png"), "/data/x");
}

#[test]
fn page_is_self_contained_and_balanced() {
    let mut records = vec![
        solved("a/1.png", 10, 5.0),
        solved("b/2.png", 20, 15.0),
        unsolved("b/3.png", "no_consistent_match"),
        Record::error("c/<4>.png", "x & y".into(), "cpu"),
    ];
    records[1].sequence_mode = Some("tracking".into());
    let rows: Vec<Row> = records.into_iter().map(Row::from).collect();
    let s = summarise(&[Run {
        path: "r.jsonl".into(),
        rows,
        bad: Vec::new(),
    }]);
    let page = html::render(&s);
    assert!(crate::io::guard::Kind::Report.ours(page.as_bytes()));
    for tag in ["svg", "table", "figure", "html", "body", "p", "tr"] {
        assert_eq!(
            page.matches(&format!("<{tag}>")).count() + page.matches(&format!("<{tag} ")).count(),
            page.matches(&format!("</{tag}>")).count(),
            "<{tag}>"
        );
    }
    // Availability, residuals, matches, scatter, attitude (three panels).
    assert_eq!(page.matches("<svg").count(), 7, "{page}");
    // Nothing fetched, nothing run: the only URL is the SVG namespace.
    assert!(!page.contains("<script") && !page.contains("https://"));
    assert_eq!(
        page.matches("http://").count(),
        page.matches("xmlns=\"http://www.w3.org/2000/svg\"").count()
    );
    assert!(page.contains("x &amp; y") && !page.contains("<4>"));
}

#[test]
fn several_runs_are_grouped_by_run_and_never_join_a_series() {
    let run = |path: &str, epoch: f64, files: &[&str]| Run {
        path: path.into(),
        rows: files
            .iter()
            .map(|f| {
                let mut r = solved(f, 10, 2.0);
                r.epoch = Some(epoch);
                Row::from(r)
            })
            .collect(),
        bad: Vec::new(),
    };
    let s = summarise(&[
        run("x/one.jsonl", 2014.0, &["a.png", "b.png"]),
        run("x/two.jsonl", 2019.0, &["a.png"]),
        run("y/two.jsonl", 2019.0, &["d/a.png", "e/b.png"]),
    ]);
    let names: Vec<&str> = s.groups.iter().map(|g| g.name.as_str()).collect();
    assert_eq!(
        names,
        ["one", "x/two.jsonl", "y/two.jsonl: d", "y/two.jsonl: e"]
    );
    assert_eq!(s.groups[0].frames, 2);
    assert_eq!(s.group_by, "run: folder");
    // Each run's epoch is one: no attitude over time, though the runs' epochs differ.
    assert!(s.series.is_empty(), "{:?}", s.series);
}

#[test]
fn angles_unwrap_only_across_zero_and_within_a_circle() {
    let series = |ras: &[f64]| Series {
        name: "s".into(),
        frames: ras.len(),
        points: ras
            .iter()
            .enumerate()
            .map(|(index, &ra)| AttitudePoint {
                index,
                t_s: None,
                ra_deg: ra,
                dec_deg: 0.0,
                roll_deg: 0.0,
                tracking: false,
            })
            .collect(),
    };
    let (a, b) = (series(&[358.0, 359.5, 1.0, 2.0]), series(&[100.0, 120.0]));
    let (v, unwrapped) = html::angles(&[&a, &b], |p| p.ra_deg);
    assert!(unwrapped);
    // The mean in [0, 360): the ticks read 358, 0, 2.
    assert_eq!(v[0], [-2.0, -0.5, 1.0, 2.0]);
    assert_eq!(v[1], [100.0, 120.0]);
    // Wider than a circle unwrapped together: as recorded.
    let c = series(&[10.0, 200.0]);
    let (v, unwrapped) = html::angles(&[&a, &c], |p| p.ra_deg);
    assert!(!unwrapped);
    assert_eq!(v[0], [358.0, 359.5, 1.0, 2.0]);
    // Nothing crosses 0/360: as recorded.
    assert!(!html::angles(&[&b], |p| p.ra_deg).1);
    let t = svg::nice_ticks(-95.0, 80.0, 5, false).within(-90.0, 90.0);
    assert_eq!((t.lo, t.hi), (-90.0, 90.0));
    assert!(t.values.iter().all(|v| v.abs() <= 90.0), "{t:?}");
}
