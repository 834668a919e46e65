//! The summary `gpustar report` prints: counts, per-folder availability, distributions and
//! attitude series, in aligned columns.

use super::{Counts, Dist, Series, Summary};
use std::fmt::Write;

/// A number in as few characters as its size needs (whole numbers without decimals).
pub fn short(v: f64) -> String {
    let a = v.abs();
    // A percentile between two equal counts can come out a hair off the whole number.
    let whole = (v - v.round()).abs() <= 1e-9 * a.max(1.0);
    if whole && a < 1e9 || a >= 100.0 {
        format!("{v:.0}")
    } else if a >= 10.0 {
        format!("{v:.1}")
    } else if a >= 1.0 {
        format!("{v:.2}")
    } else if a >= 0.001 {
        format!("{v:.3}")
    } else {
        format!("{v:.2e}")
    }
}

/// A duration in the unit that suits it.
pub fn duration(s: f64) -> String {
    match s.abs() {
        a if a < 120.0 => format!("{} s", short(s)),
        a if a < 7200.0 => format!("{} min", short(s / 60.0)),
        a if a < 172_800.0 => format!("{} h", short(s / 3600.0)),
        _ => format!("{} d", short(s / 86400.0)),
    }
}

fn percent(n: usize, of: usize) -> String {
    format!("{:.1} %", 100.0 * n as f64 / of.max(1) as f64)
}

/// "too_few_stars 4, no_consistent_match 2".
fn breakdown(v: &[(String, usize)]) -> String {
    v.iter()
        .map(|(k, n)| format!("{k} {n}"))
        .collect::<Vec<_>>()
        .join(", ")
}

/// The distributions the summary and the page show: (label, unit, values).
pub fn distributions(s: &Summary) -> Vec<(&'static str, &'static str, &[f64])> {
    vec![
        ("rms residual", "arcsec", &s.residual[..]),
        ("stars matched", "", &s.matched[..]),
        ("stars detected", "", &s.detected[..]),
        ("solve time", "ms", &s.time_ms[..]),
        ("FOV x", "deg", &s.fov_x[..]),
        ("pixel scale", "arcsec/px", &s.scale[..]),
    ]
}

fn counts_line(out: &mut String, label: &str, n: usize, of: usize, detail: &str) {
    let _ = write!(out, "  {label:<9}{n:>7}  {:>7}", percent(n, of));
    if !detail.is_empty() {
        let _ = write!(out, "   {detail}");
    }
    out.push('\n');
}

fn groups(out: &mut String, groups: &[Counts], group_by: &str) {
    let w = groups
        .iter()
        .map(|g| g.name.chars().count())
        .max()
        .unwrap_or(0);
    let w = w.clamp(6, 40);
    let _ = writeln!(
        out,
        "\n  {:<w$}  {:>6}  {:>6}  {:>8}  {:>5}  {:>9}",
        group_by, "frames", "solved", "unsolved", "error", "available"
    );
    for g in groups {
        let name: String = if g.name.chars().count() > w {
            let tail: String = g
                .name
                .chars()
                .skip(g.name.chars().count() + 1 - w)
                .collect();
            format!("…{tail}")
        } else {
            g.name.clone()
        };
        let _ = writeln!(
            out,
            "  {name:<w$}  {:>6}  {:>6}  {:>8}  {:>5}  {:>9}",
            g.frames,
            g.solved,
            g.unsolved_total(),
            g.errors,
            percent(g.solved, g.frames)
        );
    }
}

fn dist_table(out: &mut String, s: &Summary) {
    let rows: Vec<(String, Dist)> = distributions(s)
        .into_iter()
        .filter_map(|(label, unit, v)| {
            let name = if unit.is_empty() {
                label.to_string()
            } else {
                format!("{label} ({unit})")
            };
            Some((name, Dist::of(v.iter().copied())?))
        })
        .collect();
    if rows.is_empty() {
        return;
    }
    let _ = writeln!(
        out,
        "\n  {:<24}{:>6}{:>10}{:>10}{:>10}{:>10}",
        "", "n", "p10", "median", "p90", "max"
    );
    for (name, d) in rows {
        let _ = writeln!(
            out,
            "  {name:<24}{:>6}{:>10}{:>10}{:>10}{:>10}",
            d.n,
            short(d.p10),
            short(d.median),
            short(d.p90),
            short(d.max)
        );
    }
}

/// One line per series: frames, solved, tracked, span, and the attitude at its first and last
/// solved frames.
fn series_lines(out: &mut String, series: &[Series]) {
    if series.is_empty() {
        return;
    }
    let w = series
        .iter()
        .map(|s| s.name.chars().count())
        .max()
        .unwrap_or(0)
        .clamp(6, 40);
    let _ = writeln!(
        out,
        "\n  {:<w$}  {:>6}  {:>6}  {:>8}  {:>8}  {:^17}  {:^17}  {:^17}",
        "series", "frames", "solved", "tracking", "span", "RA (deg)", "Dec (deg)", "roll (deg)"
    );
    out.truncate(out.trim_end().len());
    out.push('\n');
    // first → last solved frame
    let pair = |a: f64, b: f64| format!("{:>7} → {:<7}", format!("{a:.2}"), format!("{b:.2}"));
    for s in series {
        let tracked = s.points.iter().filter(|p| p.tracking).count();
        let _ = write!(
            out,
            "  {:<w$}  {:>6}  {:>6}  {:>8}",
            s.name,
            s.frames,
            s.points.len(),
            tracked
        );
        if let (Some(a), Some(b)) = (s.points.first(), s.points.last()) {
            let span = match (a.t_s, b.t_s) {
                (Some(t0), Some(t1)) => duration(t1 - t0),
                _ => "-".into(),
            };
            let _ = write!(
                out,
                "  {span:>8}  {}  {}  {}",
                pair(a.ra_deg, b.ra_deg),
                pair(a.dec_deg, b.dec_deg),
                pair(a.roll_deg, b.roll_deg).trim_end()
            );
        }
        out.push('\n');
    }
}

/// The whole summary.
pub fn render(s: &Summary) -> String {
    let mut out = String::new();
    let files: Vec<String> = s
        .runs
        .iter()
        .map(|(p, _)| p.display().to_string())
        .collect();
    let _ = write!(out, "{}: {} frames", files.join(", "), s.all.frames);
    if !s.bad.is_empty() {
        let _ = write!(out, " ({} lines not records, skipped)", s.bad.len());
    }
    out.push('\n');
    let all = &s.all;
    counts_line(&mut out, "solved", all.solved, all.frames, "");
    counts_line(
        &mut out,
        "unsolved",
        all.unsolved_total(),
        all.frames,
        &breakdown(&all.unsolved),
    );
    counts_line(&mut out, "error", all.errors, all.frames, "");
    for (msg, n) in s.errors.iter().take(5) {
        let msg: String = if msg.chars().count() > 100 {
            msg.chars().take(99).chain(['…']).collect()
        } else {
            msg.clone()
        };
        let _ = writeln!(out, "  {n:>16}  {msg}");
    }
    if s.errors.len() > 5 {
        let _ = writeln!(out, "  {:>16}  … {} other messages", "", s.errors.len() - 5);
    }
    if s.groups.len() > 1 {
        groups(&mut out, &s.groups, s.group_by);
    }
    dist_table(&mut out, s);
    series_lines(&mut out, &s.series);
    out
}
