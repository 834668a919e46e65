//! The report as one self-contained HTML page: the summary's tables and inline SVG charts, no
//! scripts, no fonts or styles fetched, so it opens the same offline, attached to a mail or in
//! an archive years later.

use super::svg::{Plot, esc, histogram, nice_ticks, stacked_bars};
use super::text::{distributions, duration, short};
use super::{AttitudePoint, Counts, Dist, Series, Summary};
use crate::io::guard::HTML_GENERATOR;
use std::fmt::Write;

const SOLVED: &str = "#3b8d3b";
const ERROR: &str = "#c0392b";
/// Unsolved reasons, in the order of their frequency.
const UNSOLVED: [&str; 5] = ["#f0a030", "#d9782d", "#e3c23a", "#a8642a", "#9a9a9a"];
/// Attitude series.
const SERIES: [&str; 8] = [
    "#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#17becf", "#8c564b", "#e377c2",
];
/// Series drawn; a run of many sequences lists the rest by name.
const MAX_SERIES: usize = 8;

const STYLE: &str = "body{font-family:system-ui,-apple-system,'Segoe UI',sans-serif;\
color:#222;margin:24px auto;max-width:1120px;padding:0 16px}\
h1{font-size:22px;margin:0 0 4px}h2{font-size:16px;margin:28px 0 8px}\
.sub{color:#666;margin:0 0 16px}\
table{border-collapse:collapse;font-size:13px;margin:4px 0 8px}\
td,th{padding:3px 10px;border-bottom:1px solid #e6e6e6;text-align:right}\
th{font-weight:600;background:#f6f6f6}td:first-child,th:first-child{text-align:left}\
.grid{display:flex;flex-wrap:wrap;gap:16px;align-items:flex-start}\
figure{margin:0;border:1px solid #e6e6e6;border-radius:6px;padding:6px}\
.note{color:#666;font-size:13px}code{font-size:12px}\
.legend{font-size:13px;margin:4px 0}.legend span{margin-right:18px;white-space:nowrap}\
.legend i{display:inline-block;width:11px;height:11px;margin-right:5px}";

fn row(cells: &[String], header: bool) -> String {
    let tag = if header { "th" } else { "td" };
    let mut s = String::from("<tr>");
    for c in cells {
        let _ = write!(s, "<{tag}>{c}</{tag}>");
    }
    s + "</tr>"
}

fn pct(n: usize, of: usize) -> String {
    format!("{:.1} %", 100.0 * n as f64 / of.max(1) as f64)
}

/// The outcome categories of the availability chart (solved, each unsolved reason, error) and
/// a group's counts in them.
fn categories(all: &Counts) -> Vec<(String, &'static str)> {
    let mut c = vec![("solved".to_string(), SOLVED)];
    for (i, (reason, _)) in all.unsolved.iter().enumerate() {
        c.push((
            format!("unsolved: {reason}"),
            UNSOLVED[i.min(UNSOLVED.len() - 1)],
        ));
    }
    c.push(("error".into(), ERROR));
    c
}

fn category_counts(all: &Counts, g: &Counts) -> Vec<usize> {
    let mut v = vec![g.solved];
    for (reason, _) in &all.unsolved {
        v.push(
            g.unsolved
                .iter()
                .find(|(r, _)| r == reason)
                .map_or(0, |(_, n)| *n),
        );
    }
    v.push(g.errors);
    v
}

fn summary_tables(out: &mut String, s: &Summary) {
    let all = &s.all;
    out.push_str("<div class=\"grid\"><table>");
    out.push_str(&row(
        &["outcome".into(), "frames".into(), "share".into()],
        true,
    ));
    out.push_str(&row(
        &[
            "solved".into(),
            all.solved.to_string(),
            pct(all.solved, all.frames),
        ],
        false,
    ));
    for (reason, n) in &all.unsolved {
        out.push_str(&row(
            &[
                format!("unsolved: {}", esc(reason)),
                n.to_string(),
                pct(*n, all.frames),
            ],
            false,
        ));
    }
    out.push_str(&row(
        &[
            "error".into(),
            all.errors.to_string(),
            pct(all.errors, all.frames),
        ],
        false,
    ));
    out.push_str(&row(
        &["<b>all</b>".into(), all.frames.to_string(), String::new()],
        false,
    ));
    out.push_str("</table>");
    if !s.errors.is_empty() {
        out.push_str("<table>");
        out.push_str(&row(&["error message".into(), "frames".into()], true));
        for (msg, n) in s.errors.iter().take(10) {
            out.push_str(&row(&[esc(msg), n.to_string()], false));
        }
        out.push_str("</table>");
    }
    if s.groups.len() > 1 {
        out.push_str("<table>");
        out.push_str(&row(
            &[
                "folder",
                "frames",
                "solved",
                "unsolved",
                "error",
                "available",
            ]
            .map(String::from),
            true,
        ));
        for g in &s.groups {
            out.push_str(&row(
                &[
                    esc(&g.name),
                    g.frames.to_string(),
                    g.solved.to_string(),
                    g.unsolved_total().to_string(),
                    g.errors.to_string(),
                    pct(g.solved, g.frames),
                ],
                false,
            ));
        }
        out.push_str("</table>");
    }
    let dists: Vec<_> = distributions(s)
        .into_iter()
        .filter_map(|(l, u, v)| Some((l, u, Dist::of(v.iter().copied())?)))
        .collect();
    if !dists.is_empty() {
        out.push_str("<table>");
        out.push_str(&row(
            &["", "n", "p10", "median", "p90", "max"].map(String::from),
            true,
        ));
        for (label, unit, d) in dists {
            let name = if unit.is_empty() {
                label.to_string()
            } else {
                format!("{label} ({unit})")
            };
            out.push_str(&row(
                &[
                    name,
                    d.n.to_string(),
                    short(d.p10),
                    short(d.median),
                    short(d.p90),
                    short(d.max),
                ],
                false,
            ));
        }
        out.push_str("</table>");
    }
    out.push_str("</div>");
}

/// A histogram chart, or a note when there is nothing to count.
fn histogram_chart(title: &str, unit: &str, values: &[f64], integer: bool) -> String {
    let bins = histogram(values, 24, integer);
    let (Some(first), Some(last)) = (bins.first(), bins.last()) else {
        return format!("<p class=\"note\">{}: no solved frames.</p>", esc(title));
    };
    let top = bins.iter().map(|b| b.2).max().unwrap_or(1) as f64;
    let mut p = Plot::new(
        title,
        520.0,
        300.0,
        nice_ticks(first.0, last.1, 8, integer),
        nice_ticks(0.0, top, 5, true),
    )
    .labels(unit, "frames");
    for &(a, b, n) in &bins {
        if n > 0 {
            let w = b - a;
            p.bar(
                a + 0.06 * w,
                b - 0.06 * w,
                0.0,
                n as f64,
                "#4a78b5",
                &format!("{}–{}: {n} frames", short(a), short(b)),
            );
        }
    }
    p.finish()
}

fn scatter_chart(points: &[(f64, f64)]) -> String {
    if points.is_empty() {
        return "<p class=\"note\">Residual against matches: no solved frames.</p>".into();
    }
    let (mx, ex) = points
        .iter()
        .fold((0f64, 0f64), |(m, e), p| (m.max(p.0), e.max(p.1)));
    let mut p = Plot::new(
        "Residual against stars matched",
        520.0,
        300.0,
        nice_ticks(0.0, mx, 8, true),
        nice_ticks(0.0, ex, 5, false),
    )
    .labels("stars matched", "rms residual (arcsec)");
    for &(m, e) in points {
        p.dot(
            m,
            e,
            "#4a78b5",
            true,
            &format!("{m} matched, {}″", short(e)),
        );
    }
    p.finish()
}

/// Unwrap angles along a series so that a step across 0/360 is drawn as the small turn it is.
fn unwrapped(values: impl Iterator<Item = f64>) -> Vec<f64> {
    let mut out: Vec<f64> = Vec::new();
    for v in values {
        let v = match out.last() {
            Some(&prev) => prev + (v - prev + 180.0).rem_euclid(360.0) - 180.0,
            None => v,
        };
        out.push(v);
    }
    // The turn's whole circles taken out again: the series' mean in [0, 360).
    let mean = out.iter().sum::<f64>() / out.len().max(1) as f64;
    let shift = mean - mean.rem_euclid(360.0);
    out.iter().map(|v| v - shift).collect()
}

/// A wrapping angle's values per series as drawn, and whether they were unwrapped: only where
/// a series crosses 0/360 and the series unwrapped together span no more than a circle; else
/// as recorded (a line then breaks where one crosses 0/360).
pub(crate) fn angles(series: &[&Series], get: fn(&AttitudePoint) -> f64) -> (Vec<Vec<f64>>, bool) {
    let raw: Vec<Vec<f64>> = series
        .iter()
        .map(|s| s.points.iter().map(get).collect())
        .collect();
    let crosses = raw
        .iter()
        .any(|v| v.windows(2).any(|w| (w[1] - w[0]).abs() > 180.0));
    let un: Vec<Vec<f64>> = raw.iter().map(|v| unwrapped(v.iter().copied())).collect();
    let (lo, hi) = range(un.iter().flatten().copied());
    if crosses && hi - lo <= 360.0 {
        (un, true)
    } else {
        (raw, false)
    }
}

fn range(v: impl Iterator<Item = f64>) -> (f64, f64) {
    v.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), x| {
        (a.min(x), b.max(x))
    })
}

/// RA, Dec and roll over time (or frame index), one panel each, one colour per series.
fn attitude_charts(series: &[Series]) -> String {
    let drawn: Vec<&Series> = series
        .iter()
        .filter(|s| !s.points.is_empty())
        .take(MAX_SERIES)
        .collect();
    if drawn.is_empty() {
        return "<p class=\"note\">No solved frames in the sequences.</p>".into();
    }
    let timed = drawn
        .iter()
        .all(|s| s.points.iter().all(|p| p.t_s.is_some()));
    let span = drawn
        .iter()
        .flat_map(|s| s.points.iter().filter_map(|p| p.t_s))
        .fold(0f64, f64::max);
    // The time axis' unit, as `duration` would name the whole span.
    let (unit, per) = match span {
        s if s < 120.0 => ("s", 1.0),
        s if s < 7200.0 => ("min", 60.0),
        s if s < 172_800.0 => ("h", 3600.0),
        _ => ("d", 86400.0),
    };
    let x_of = |p: &AttitudePoint| match (timed, p.t_s) {
        (true, Some(t)) => t / per,
        _ => p.index as f64,
    };
    let x_label = if timed {
        format!("time since the series' first frame ({unit})")
    } else {
        "frame index in the series".to_string()
    };
    let (x0, x1) = range(drawn.iter().flat_map(|s| s.points.iter().map(x_of)));
    // (axis label, the angle, whether it wraps at 360)
    type Panel = (&'static str, fn(&AttitudePoint) -> f64, bool);
    let panels: [Panel; 3] = [
        ("RA (deg)", |p| p.ra_deg, true),
        ("Dec (deg)", |p| p.dec_deg, false),
        ("roll (deg)", |p| p.roll_deg, true),
    ];
    let mut out = String::from("<p class=\"legend\">");
    for (i, s) in drawn.iter().enumerate() {
        let _ = write!(
            out,
            "<span><i style=\"background:{}\"></i>{}</span>",
            SERIES[i % SERIES.len()],
            esc(&s.name)
        );
    }
    out += "</p>";
    for (name, get, wraps) in panels {
        let (ys, unwrapped) = if wraps {
            angles(&drawn, get)
        } else {
            let v = drawn.iter().map(|s| s.points.iter().map(get).collect());
            (v.collect(), false)
        };
        let (y0, y1) = range(ys.iter().flatten().copied());
        // Ticks past where the angle can go only while its values are drawn unwrapped.
        let y = match (wraps, unwrapped) {
            (false, _) => nice_ticks(y0, y1, 5, false).within(-90.0, 90.0),
            (true, false) => nice_ticks(y0, y1, 5, false).within(0.0, 360.0),
            (true, true) => nice_ticks(y0, y1, 5, false),
        };
        let title = format!(
            "{} over {}",
            &name[..name.find(' ').unwrap_or(name.len())],
            if timed { "time" } else { "frames" }
        );
        let mut p = Plot::new(&title, 1080.0, 230.0, nice_ticks(x0, x1, 12, !timed), y)
            .labels(&x_label, name);
        if wraps {
            p = p.wrap_y(360.0);
        }
        for (i, (s, y)) in drawn.iter().zip(&ys).enumerate() {
            let color = SERIES[i % SERIES.len()];
            // A line through consecutive solved frames only: a gap shows unsolved ones (and
            // an angle as recorded crossing 0/360).
            let mut run: Vec<(f64, f64)> = Vec::new();
            for (j, (pt, &v)) in s.points.iter().zip(y).enumerate() {
                if j > 0
                    && (pt.index != s.points[j - 1].index + 1
                        || wraps && !unwrapped && (v - y[j - 1]).abs() > 180.0)
                {
                    p.line(&run, color);
                    run.clear();
                }
                run.push((x_of(pt), v));
            }
            p.line(&run, color);
            for (pt, &v) in s.points.iter().zip(y) {
                let when = match pt.t_s {
                    Some(t) => duration(t),
                    None => format!("frame {}", pt.index),
                };
                let mode = if pt.tracking { ", tracking" } else { "" };
                let tip = format!(
                    "{}: {when}{mode}: RA {:.3}, Dec {:.3}, roll {:.3}",
                    s.name, pt.ra_deg, pt.dec_deg, pt.roll_deg
                );
                p.dot(x_of(pt), v, color, !pt.tracking, &tip);
            }
        }
        out += "<figure>";
        out += &p.finish();
        out += "</figure>";
    }
    out += "<p class=\"note\">Filled dots: identified lost in space; rings: tracked from the \
            previous frames' attitude. Lines join consecutive solved frames.</p>";
    if series.len() > drawn.len() {
        let rest: Vec<String> = series
            .iter()
            .filter(|s| !drawn.iter().any(|d| std::ptr::eq(*d, *s)))
            .map(|s| esc(&s.name))
            .collect();
        let _ = write!(
            out,
            "<p class=\"note\">Not drawn ({} series): {}</p>",
            rest.len(),
            rest.join(", ")
        );
    }
    out
}

/// The page.
pub fn render(s: &Summary) -> String {
    let files: Vec<String> = s
        .runs
        .iter()
        .map(|(p, n)| {
            format!(
                "<code>{}</code> ({n} records)",
                esc(&p.display().to_string())
            )
        })
        .collect();
    let mut out = String::new();
    let _ = write!(
        out,
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\n\
         {HTML_GENERATOR} {}\">\n<title>gpustar report: {}</title>\
         <style>{STYLE}</style></head><body>",
        env!("CARGO_PKG_VERSION"),
        esc(&s
            .runs
            .iter()
            .map(|(p, _)| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", "))
    );
    let _ = write!(
        out,
        "<h1>gpustar report</h1><p class=\"sub\">{} — {} frames, {} solved ({})</p>",
        files.join(", "),
        s.all.frames,
        s.all.solved,
        pct(s.all.solved, s.all.frames)
    );
    if !s.bad.is_empty() {
        let _ = write!(
            out,
            "<p class=\"note\">{} lines are not records and were skipped; the first: {}</p>",
            s.bad.len(),
            esc(&s.bad[0].to_string())
        );
    }
    out += "<h2>Summary</h2>";
    summary_tables(&mut out, s);
    out += "<h2>Availability</h2><figure>";
    let mut rows: Vec<(String, Vec<usize>)> = Vec::new();
    if s.groups.len() > 1 {
        rows.push(("all".into(), category_counts(&s.all, &s.all)));
    }
    rows.extend(
        s.groups
            .iter()
            .map(|g| (g.name.clone(), category_counts(&s.all, g))),
    );
    let title = format!("Outcome of each frame, per {}", s.group_by);
    out += &stacked_bars(&title, 1080.0, &rows, &categories(&s.all));
    out += "</figure><h2>Solutions</h2><div class=\"grid\"><figure>";
    out += &histogram_chart(
        "RMS residual of solved frames",
        "rms residual (arcsec)",
        &s.residual,
        false,
    );
    out += "</figure><figure>";
    out += &histogram_chart(
        "Stars matched in solved frames",
        "stars matched",
        &s.matched,
        true,
    );
    out += "</figure><figure>";
    out += &scatter_chart(&s.scatter);
    out += "</figure>";
    if !s.time_ms.is_empty() {
        out += "<figure>";
        out += &histogram_chart("Solve time per frame", "total time (ms)", &s.time_ms, false);
        out += "</figure>";
    }
    out += "</div>";
    if !s.series.is_empty() {
        out += "<h2>Attitude over time</h2>";
        out += &attitude_charts(&s.series);
    }
    out += "</body></html>\n";
    out
}
