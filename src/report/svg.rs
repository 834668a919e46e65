//! Plot primitives for the report page: axes with "nice" ticks, bars, dots and lines as inline
//! SVG text. Enough for a few fixed charts; no layout engine.

use std::fmt::Write;

/// `&`, `<`, `>` and quotes escaped, for text and attribute values alike.
pub fn esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => out.push_str("&amp;"),
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '"' => out.push_str("&quot;"),
            '\'' => out.push_str("&#39;"),
            c => out.push(c),
        }
    }
    out
}

/// An axis' range, widened to whole steps of 1, 2 or 5 × 10ⁿ, and its ticks.
#[derive(Clone, Debug, PartialEq)]
pub struct Ticks {
    pub lo: f64,
    pub hi: f64,
    pub step: f64,
    pub values: Vec<f64>,
}

impl Ticks {
    /// The axis cut to [lo, hi] where it reaches past (Dec past ±90°), ticks outside dropped.
    pub fn within(mut self, lo: f64, hi: f64) -> Ticks {
        self.lo = self.lo.max(lo);
        self.hi = self.hi.min(hi);
        let (a, b) = (self.lo, self.hi);
        self.values.retain(|v| (a..=b).contains(v));
        self
    }
}

/// About `target` ticks over [lo, hi] at a step of 1, 2 or 5 × 10ⁿ (at least 1 when
/// `integer`). An empty or non-finite range is widened to one that holds it (0–1 when there is
/// nothing finite), so every chart gets axes.
pub fn nice_ticks(lo: f64, hi: f64, target: usize, integer: bool) -> Ticks {
    let (mut lo, mut hi) = if lo.is_finite() && hi.is_finite() {
        (lo.min(hi), lo.max(hi))
    } else {
        (0.0, 1.0)
    };
    if hi - lo <= f64::EPSILON * lo.abs().max(1.0) {
        let pad = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
        (lo, hi) = (lo - pad, hi + pad);
    }
    let raw = (hi - lo) / target.max(1) as f64;
    let mag = 10f64.powf(raw.log10().floor());
    let mut step = [1.0, 2.0, 5.0, 10.0]
        .iter()
        .map(|m| m * mag)
        .find(|s| *s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * mag);
    if integer {
        step = step.max(1.0).round();
    }
    let first = (lo / step + 1e-9).floor();
    let last = (hi / step - 1e-9).ceil();
    // Whole multiples of the step, each computed afresh (no sum of rounding errors).
    let values: Vec<f64> = (0..=((last - first) as usize).min(1000))
        .map(|k| (first + k as f64) * step)
        .collect();
    Ticks {
        lo: first * step,
        hi: last * step,
        step,
        values,
    }
}

/// A tick's label: as many decimals as the step needs; `wrap` (e.g. 360) reduces angles into
/// [0, wrap).
pub fn tick_label(v: f64, step: f64, wrap: Option<f64>) -> String {
    let v = match wrap {
        Some(w) => v.rem_euclid(w),
        None => v,
    };
    let decimals = (-step.log10().floor()).clamp(0.0, 6.0) as usize;
    let s = format!("{v:.decimals$}");
    // "-0" where a value rounds to zero from below.
    if s.trim_start_matches('-')
        .chars()
        .all(|c| c == '0' || c == '.')
    {
        s.trim_start_matches('-').to_string()
    } else {
        s
    }
}

/// Maps the data range [d0, d1] onto pixels [r0, r1] (r1 < r0 for a y axis, which grows up).
#[derive(Clone, Copy, Debug)]
pub struct Scale {
    pub d0: f64,
    pub d1: f64,
    pub r0: f64,
    pub r1: f64,
}

impl Scale {
    pub fn map(&self, v: f64) -> f64 {
        self.r0 + (v - self.d0) / (self.d1 - self.d0) * (self.r1 - self.r0)
    }
}

/// Histogram bins over the values: (from, to, count). Whole numbers (star counts) get bins
/// centred on them; others bins at a nice step. Empty for no finite values.
pub fn histogram(values: &[f64], target_bins: usize, integer: bool) -> Vec<(f64, f64, usize)> {
    let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    let (Some(min), Some(max)) = (
        v.iter().copied().reduce(f64::min),
        v.iter().copied().reduce(f64::max),
    ) else {
        return Vec::new();
    };
    let (start, step, n) = if integer {
        let step = nice_ticks(min, max + 1.0, target_bins, true).step;
        let first = (min / step).floor() * step - 0.5;
        (first, step, ((max - first) / step).floor() as usize + 1)
    } else {
        let t = nice_ticks(min, max, target_bins, false);
        (
            t.lo,
            t.step,
            ((t.hi - t.lo) / t.step).round().max(1.0) as usize,
        )
    };
    let mut counts = vec![0usize; n];
    for x in v {
        let i = ((x - start) / step).floor().max(0.0) as usize;
        counts[i.min(n - 1)] += 1;
    }
    counts
        .into_iter()
        .enumerate()
        .map(|(i, c)| (start + i as f64 * step, start + (i + 1) as f64 * step, c))
        .collect()
}

/// Text style shared by every chart.
const FONT: &str = "font-family=\"system-ui, -apple-system, 'Segoe UI', sans-serif\"";

/// One chart with x and y axes: marks are added in data coordinates, then [`Plot::finish`]
/// draws the grid, ticks, labels and title around them.
pub struct Plot {
    pub width: f64,
    pub height: f64,
    title: String,
    x_label: String,
    y_label: String,
    x: Ticks,
    y: Ticks,
    y_wrap: Option<f64>,
    /// Left, right, top, bottom.
    margin: [f64; 4],
    marks: String,
}

impl Plot {
    pub fn new(title: &str, width: f64, height: f64, x: Ticks, y: Ticks) -> Plot {
        Plot {
            width,
            height,
            title: title.into(),
            x_label: String::new(),
            y_label: String::new(),
            x,
            y,
            y_wrap: None,
            margin: [62.0, 16.0, 34.0, 44.0],
            marks: String::new(),
        }
    }

    pub fn labels(mut self, x: &str, y: &str) -> Plot {
        self.x_label = x.into();
        self.y_label = y.into();
        self
    }

    /// Label the y ticks as angles reduced into [0, wrap) (RA, roll unwrapped for the plot).
    pub fn wrap_y(mut self, wrap: f64) -> Plot {
        self.y_wrap = Some(wrap);
        self
    }

    pub fn sx(&self) -> Scale {
        Scale {
            d0: self.x.lo,
            d1: self.x.hi,
            r0: self.margin[0],
            r1: self.width - self.margin[1],
        }
    }

    pub fn sy(&self) -> Scale {
        Scale {
            d0: self.y.lo,
            d1: self.y.hi,
            r0: self.height - self.margin[3],
            r1: self.margin[2],
        }
    }

    /// A bar from (x0, y0) to (x1, y1), data coordinates, with a tooltip.
    pub fn bar(&mut self, x0: f64, x1: f64, y0: f64, y1: f64, color: &str, tip: &str) {
        let (sx, sy) = (self.sx(), self.sy());
        let (a, b) = (sx.map(x0), sx.map(x1));
        let (c, d) = (sy.map(y0), sy.map(y1));
        let _ = write!(
            self.marks,
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{color}\">\
             <title>{}</title></rect>",
            a.min(b),
            c.min(d),
            (b - a).abs(),
            (d - c).abs(),
            esc(tip)
        );
    }

    /// A dot, filled or a ring, with a tooltip.
    pub fn dot(&mut self, x: f64, y: f64, color: &str, filled: bool, tip: &str) {
        let (px, py) = (self.sx().map(x), self.sy().map(y));
        let paint = if filled {
            format!("fill=\"{color}\" fill-opacity=\"0.7\"")
        } else {
            format!("fill=\"white\" stroke=\"{color}\" stroke-width=\"1.3\"")
        };
        let _ = write!(
            self.marks,
            "<circle cx=\"{px:.1}\" cy=\"{py:.1}\" r=\"3.2\" {paint}><title>{}</title></circle>",
            esc(tip)
        );
    }

    /// A line through the points (data coordinates).
    pub fn line(&mut self, points: &[(f64, f64)], color: &str) {
        if points.len() < 2 {
            return;
        }
        let (sx, sy) = (self.sx(), self.sy());
        let pts: Vec<String> = points
            .iter()
            .map(|&(x, y)| format!("{:.1},{:.1}", sx.map(x), sy.map(y)))
            .collect();
        let _ = write!(
            self.marks,
            "<polyline points=\"{}\" fill=\"none\" stroke=\"{color}\" stroke-width=\"1.5\" \
             stroke-opacity=\"0.8\"/>",
            pts.join(" ")
        );
    }

    /// The chart as an `<svg>` element.
    pub fn finish(self) -> String {
        let (w, h) = (self.width, self.height);
        let [l, r, t, b] = self.margin;
        let (sx, sy) = (self.sx(), self.sy());
        let mut s = String::new();
        let _ = write!(
            s,
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{w}\" height=\"{h}\" \
             viewBox=\"0 0 {w} {h}\" {FONT} font-size=\"12\" role=\"img\">\
             <title>{}</title>",
            esc(&self.title)
        );
        let _ = write!(
            s,
            "<text x=\"{l}\" y=\"20\" font-size=\"14\" font-weight=\"600\" fill=\"#222\">{}</text>",
            esc(&self.title)
        );
        for &v in &self.y.values {
            let y = sy.map(v);
            let _ = write!(
                s,
                "<line x1=\"{l}\" x2=\"{:.1}\" y1=\"{y:.1}\" y2=\"{y:.1}\" stroke=\"#e4e4e4\"/>\
                 <text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" fill=\"#555\">{}</text>",
                w - r,
                l - 6.0,
                y + 4.0,
                tick_label(v, self.y.step, self.y_wrap)
            );
        }
        for &v in &self.x.values {
            let x = sx.map(v);
            let _ = write!(
                s,
                "<line x1=\"{x:.1}\" x2=\"{x:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"#999\"/>\
                 <text x=\"{x:.1}\" y=\"{:.1}\" text-anchor=\"middle\" fill=\"#555\">{}</text>",
                h - b,
                h - b + 5.0,
                h - b + 18.0,
                tick_label(v, self.x.step, None)
            );
        }
        s += &self.marks;
        let _ = write!(
            s,
            "<line x1=\"{l}\" x2=\"{:.1}\" y1=\"{:.1}\" y2=\"{:.1}\" stroke=\"#777\"/>\
             <line x1=\"{l}\" x2=\"{l}\" y1=\"{t}\" y2=\"{:.1}\" stroke=\"#777\"/>",
            w - r,
            h - b,
            h - b,
            h - b
        );
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" fill=\"#333\">{}</text>\
             <text transform=\"translate(14 {:.1}) rotate(-90)\" text-anchor=\"middle\" \
             fill=\"#333\">{}</text>",
            (l + w - r) / 2.0,
            h - 8.0,
            esc(&self.x_label),
            (t + h - b) / 2.0,
            esc(&self.y_label)
        );
        s += "</svg>";
        s
    }
}

/// Horizontal bars, one per row, each split into its categories' shares of the row's total
/// (percent); the count is in each segment's tooltip and, where it fits, on it.
pub fn stacked_bars(
    title: &str,
    width: f64,
    rows: &[(String, Vec<usize>)],
    categories: &[(String, &str)],
) -> String {
    let label_w = rows
        .iter()
        .map(|(n, _)| n.chars().count().min(30))
        .max()
        .unwrap_or(4) as f64
        * 7.0
        + 16.0;
    let (top, bar_h, gap) = (52.0, 22.0, 8.0);
    let height = top + rows.len() as f64 * (bar_h + gap) + 34.0;
    let x = Scale {
        d0: 0.0,
        d1: 100.0,
        r0: label_w,
        r1: width - 28.0,
    };
    let mut s = String::new();
    let _ = write!(
        s,
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" \
         viewBox=\"0 0 {width} {height}\" {FONT} font-size=\"12\" role=\"img\">\
         <title>{t}</title><text x=\"{label_w}\" y=\"20\" font-size=\"14\" font-weight=\"600\" \
         fill=\"#222\">{t}</text>",
        t = esc(title)
    );
    let mut lx = label_w;
    for (name, color) in categories {
        let _ = write!(
            s,
            "<rect x=\"{lx:.1}\" y=\"30\" width=\"11\" height=\"11\" fill=\"{color}\"/>\
             <text x=\"{:.1}\" y=\"40\" fill=\"#333\">{}</text>",
            lx + 15.0,
            esc(name)
        );
        lx += 7.0 * name.chars().count() as f64 + 30.0;
    }
    let bottom = top + rows.len() as f64 * (bar_h + gap);
    for v in (0..=100).step_by(20) {
        let px = x.map(v as f64);
        let _ = write!(
            s,
            "<line x1=\"{px:.1}\" x2=\"{px:.1}\" y1=\"{top}\" y2=\"{bottom:.1}\" \
             stroke=\"#e4e4e4\"/><text x=\"{px:.1}\" y=\"{:.1}\" text-anchor=\"middle\" \
             fill=\"#555\">{v} %</text>",
            bottom + 14.0
        );
    }
    for (i, (name, counts)) in rows.iter().enumerate() {
        let y = top + i as f64 * (bar_h + gap);
        let total: usize = counts.iter().sum();
        let shown: String = if name.chars().count() > 30 {
            let n = name.chars().count();
            format!("…{}", name.chars().skip(n - 29).collect::<String>())
        } else {
            name.clone()
        };
        let _ = write!(
            s,
            "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\" fill=\"#333\">{}<title>{}</title>\
             </text>",
            label_w - 8.0,
            y + bar_h / 2.0 + 4.0,
            esc(&shown),
            esc(&format!("{name}: {total} frames"))
        );
        let mut at = 0.0;
        for (&n, (cat, color)) in counts.iter().zip(categories) {
            if n == 0 {
                continue;
            }
            let share = 100.0 * n as f64 / total.max(1) as f64;
            let (a, b) = (x.map(at), x.map(at + share));
            let _ = write!(
                s,
                "<rect x=\"{a:.1}\" y=\"{y:.1}\" width=\"{:.1}\" height=\"{bar_h}\" \
                 fill=\"{color}\"><title>{}</title></rect>",
                b - a,
                esc(&format!("{name}: {cat} {n} of {total} ({share:.1} %)"))
            );
            let text = n.to_string();
            if b - a > 8.0 * text.len() as f64 + 6.0 {
                let _ = write!(
                    s,
                    "<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\" fill=\"white\">{text}\
                     </text>",
                    (a + b) / 2.0,
                    y + bar_h / 2.0 + 4.0
                );
            }
            at += share;
        }
    }
    s += "</svg>";
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ticks_are_nice_and_cover_the_range() {
        let t = nice_ticks(0.3, 9.7, 5, false);
        assert_eq!(t.step, 2.0);
        assert_eq!((t.lo, t.hi), (0.0, 10.0));
        assert_eq!(t.values, vec![0.0, 2.0, 4.0, 6.0, 8.0, 10.0]);
        let t = nice_ticks(-0.013, 0.042, 5, false);
        assert_eq!(t.step, 0.02);
        assert!(t.lo <= -0.013 && t.hi >= 0.042, "{t:?}");
        assert_eq!(tick_label(t.values[1], t.step, None), "0.00");
        // A single value and nothing finite still get an axis; integers step by 1 at least.
        let t = nice_ticks(7.0, 7.0, 5, false);
        assert!(t.lo < 7.0 && t.hi > 7.0, "{t:?}");
        assert_eq!(nice_ticks(f64::NAN, 1.0, 5, false).lo, 0.0);
        assert_eq!(nice_ticks(3.0, 5.0, 10, true).step, 1.0);
    }

    #[test]
    fn scales_map_ends_to_ends_and_y_grows_up() {
        let p = Plot::new("t", 400.0, 300.0, nice_ticks(0.0, 10.0, 5, false), {
            nice_ticks(0.0, 100.0, 5, false)
        });
        let (sx, sy) = (p.sx(), p.sy());
        assert_eq!(sx.map(0.0), 62.0);
        assert_eq!(sx.map(10.0), 400.0 - 16.0);
        assert_eq!(sx.map(5.0), (62.0 + 384.0) / 2.0);
        assert_eq!(sy.map(0.0), 300.0 - 44.0);
        assert_eq!(sy.map(100.0), 34.0);
        assert!(sy.map(75.0) < sy.map(25.0));
    }

    #[test]
    fn histogram_counts_every_value_once() {
        let v = [1.0, 2.5, 2.6, 9.9, 10.0, f64::NAN];
        let h = histogram(&v, 5, false);
        assert_eq!(h.iter().map(|b| b.2).sum::<usize>(), 5);
        assert_eq!(h.first().unwrap().0, 0.0);
        assert_eq!(h.last().unwrap().1, 10.0);
        // The maximum lands in the last bin, not past it.
        assert_eq!(h.last().unwrap().2, 2);
        // Whole numbers: bins centred on them.
        let h = histogram(&[4.0, 5.0, 5.0, 9.0], 20, true);
        let five = h.iter().find(|b| b.0 < 5.0 && b.1 > 5.0).unwrap();
        assert_eq!((five.0, five.1, five.2), (4.5, 5.5, 2));
        assert_eq!(h.iter().map(|b| b.2).sum::<usize>(), 4);
        assert!(histogram(&[], 10, false).is_empty());
        assert_eq!(
            histogram(&[3.0], 10, false)
                .iter()
                .map(|b| b.2)
                .sum::<usize>(),
            1
        );
    }

    #[test]
    fn labels_and_text_are_escaped_and_wrapped() {
        assert_eq!(esc("a<b & \"c\""), "a&lt;b &amp; &quot;c&quot;");
        assert_eq!(tick_label(370.0, 10.0, Some(360.0)), "10");
        assert_eq!(tick_label(-20.0, 10.0, Some(360.0)), "340");
        assert_eq!(tick_label(-0.0001, 0.5, None), "0.0");
        let mut p = Plot::new("<x>", 300.0, 200.0, nice_ticks(0.0, 1.0, 4, false), {
            nice_ticks(0.0, 1.0, 4, false)
        });
        p.dot(0.5, 0.5, "#000", true, "a & b");
        let svg = p.finish();
        assert!(
            svg.contains("&lt;x&gt;") && svg.contains("a &amp; b"),
            "{svg}"
        );
        assert_eq!(svg.matches("<svg").count(), svg.matches("</svg>").count());
    }
}
