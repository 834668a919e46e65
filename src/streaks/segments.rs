//! From the streak mask to line segments: connected components of the mask, lines found in
//! each large component by a coarse Hough vote over its pixels (so a streak that crosses a
//! star or another streak still gives its own line), and collinear pieces of one faint streak
//! joined. Everything here is deterministic (fixed orders, first maximum wins).

use crate::cpu::components::components;
use crate::cpu::threshold::Run;

/// A straight piece of the mask: a point on the line, its direction (unit), and the extent of
/// its pixels along the line from that point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Segment {
    pub cx: f64,
    pub cy: f64,
    pub ux: f64,
    pub uy: f64,
    pub t_min: f64,
    pub t_max: f64,
    /// Mask pixels on it.
    pub pixels: usize,
}

impl Segment {
    pub fn length(&self) -> f64 {
        self.t_max - self.t_min
    }

    /// Signed distance of (x, y) from the line (along the normal (−uy, ux)).
    pub fn across(&self, x: f64, y: f64) -> f64 {
        -(x - self.cx) * self.uy + (y - self.cy) * self.ux
    }

    /// Position of (x, y) along the line.
    pub fn along(&self, x: f64, y: f64) -> f64 {
        (x - self.cx) * self.ux + (y - self.cy) * self.uy
    }

    pub fn point(&self, t: f64) -> (f64, f64) {
        (self.cx + t * self.ux, self.cy + t * self.uy)
    }

    /// The middle of its extent.
    pub fn mid(&self) -> (f64, f64) {
        self.point(0.5 * (self.t_min + self.t_max))
    }

    /// The segment of a grid of `bin`×`bin` blocks in pixels of the frame (block x covers
    /// pixels bin·x … bin·x + bin − 1, so its centre is pixel bin·x + (bin − 1)/2).
    pub fn in_pixels(&self, bin: u32) -> Segment {
        let (b, o) = (bin as f64, (bin as f64 - 1.0) / 2.0);
        Segment {
            cx: b * self.cx + o,
            cy: b * self.cy + o,
            t_min: b * self.t_min,
            t_max: b * self.t_max,
            pixels: self.pixels * (bin * bin) as usize,
            ..*self
        }
    }
}

/// Settings of segment extraction, in cells of the mask (blocks of 2×2 pixels for the streak
/// mask).
#[derive(Clone, Copy, Debug)]
pub struct SegmentSettings {
    /// Shortest piece kept (along the line).
    pub min_piece_px: f64,
    /// Cells within this distance of a line belong to it; pieces whose ends are this close
    /// to each other's lines may join.
    pub band_px: f64,
    /// Largest gap along the line inside one piece.
    pub max_gap_px: f64,
    /// Largest gap between two pieces that join (or their lengths together, if longer).
    pub max_join_gap_px: f64,
}

impl Default for SegmentSettings {
    /// For the 2×2-binned streak mask: 12 px pieces, a 3 px band, 6 px gaps in a piece, 40 px
    /// between pieces.
    fn default() -> Self {
        SegmentSettings {
            min_piece_px: 6.0,
            band_px: 1.5,
            max_gap_px: 3.0,
            max_join_gap_px: 20.0,
        }
    }
}

/// Lines per component at most (a train of streaks seldom crosses in one component).
const MAX_LINES_PER_COMPONENT: usize = 4;

/// A line of joined pieces, and the pieces (longest first): when the whole is no streak (a
/// chance alignment with a star pair far along the line), a piece may still be one.
#[derive(Clone, Debug, PartialEq)]
pub struct Joined {
    pub line: Segment,
    pub pieces: Vec<Segment>,
}

impl Joined {
    /// See [`Segment::in_pixels`].
    pub fn in_pixels(&self, bin: u32) -> Joined {
        Joined {
            line: self.line.in_pixels(bin),
            pieces: self.pieces.iter().map(|p| p.in_pixels(bin)).collect(),
        }
    }
}

/// The segments of a streak mask (runs in raster order).
pub fn segments(runs: &[Run], width: u32, s: &SegmentSettings) -> Vec<Joined> {
    let labels = components(runs, width);
    // Runs of each component, in label order (labels are first pixels in raster order).
    let mut order: Vec<usize> = (0..runs.len()).collect();
    order.sort_by_key(|&i| (labels[i], i));
    let (mut pieces, mut stubs) = (Vec::new(), Vec::new());
    let mut start = 0;
    while start < order.len() {
        let label = labels[order[start]];
        let mut end = start;
        while end < order.len() && labels[order[end]] == label {
            end += 1;
        }
        let comp: Vec<Run> = order[start..end].iter().map(|&i| runs[i]).collect();
        start = end;
        let (x0, x1) = comp
            .iter()
            .fold((u32::MAX, 0), |(a, b), r| (a.min(r.x0), b.max(r.x1)));
        let (y0, y1) = (comp[0].y, comp[comp.len() - 1].y + 1);
        let diag = (((x1 - x0) as f64).powi(2) + ((y1 - y0) as f64).powi(2)).sqrt();
        if diag < s.min_piece_px || (diag < 4.0 * s.min_piece_px && round(&comp)) {
            continue; // stars, noise, hot pixels (large round ones may be crossing streaks)
        }
        let mut px: Vec<(f64, f64)> = comp
            .iter()
            .flat_map(|r| (r.x0..r.x1).map(move |x| (x as f64, r.y as f64)))
            .collect();
        let before = pieces.len();
        let all = px.clone();
        for _ in 0..MAX_LINES_PER_COMPONENT {
            match strongest_line(&px, s) {
                Some((seg, used)) => {
                    pieces.push(seg);
                    let mut k = 0;
                    px.retain(|_| {
                        k += 1;
                        !used[k - 1]
                    });
                }
                None => break,
            }
            if px.len() < s.min_piece_px as usize {
                break;
            }
        }
        // No line of its own (as wide as a third of its length: a bright streak's short piece
        // between two dark stretches), but elongated: it may extend a line it lies on.
        if pieces.len() == before && !round(&comp) {
            stubs.push(extent(principal_axis(&all), &all));
        }
    }
    join_collinear(pieces, &stubs, s)
}

/// `seg`'s extent set to that of the points along it.
fn extent(mut seg: Segment, px: &[(f64, f64)]) -> Segment {
    let (lo, hi) = px.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
        let t = seg.along(p.0, p.1);
        (lo.min(t), hi.max(t))
    });
    (seg.t_min, seg.t_max) = (lo, hi);
    seg
}

/// Is the component about as wide as long (second moments within a factor 4: an axis ratio
/// under 2)? A bright star is; a piece of a streak is not.
fn round(comp: &[Run]) -> bool {
    let (mut n, mut sx, mut sy) = (0.0, 0.0, 0.0);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for r in comp {
        for x in r.x0..r.x1 {
            let (x, y) = (x as f64, r.y as f64);
            n += 1.0;
            sx += x;
            sy += y;
            sxx += x * x;
            syy += y * y;
            sxy += x * y;
        }
    }
    let (mx, my) = (sx / n, sy / n);
    let (a, c, b) = (sxx / n - mx * mx, syy / n - my * my, sxy / n - mx * my);
    // Eigenvalues of [[a, b], [b, c]].
    let root = ((a - c).powi(2) / 4.0 + b * b).sqrt();
    let (l1, l2) = ((a + c) / 2.0 + root, (a + c) / 2.0 - root);
    l1 < 4.0 * l2.max(1e-9)
}

/// The strongest line through a component's pixels, and which pixels it took, or None when
/// no line holds a piece long and full enough.
fn strongest_line(px: &[(f64, f64)], s: &SegmentSettings) -> Option<(Segment, Vec<bool>)> {
    // Coarse Hough: 1° steps, 2 px bins of ρ around the pixels' mean.
    let n = px.len() as f64;
    let (mx, my) = px
        .iter()
        .fold((0.0, 0.0), |(a, b), p| (a + p.0 / n, b + p.1 / n));
    let r_max = px
        .iter()
        .map(|p| ((p.0 - mx).powi(2) + (p.1 - my).powi(2)).sqrt())
        .fold(0.0, f64::max);
    let bins = (r_max / 2.0).ceil() as usize * 2 + 2;
    let mut best = (0u32, 0usize, 0usize);
    let mut acc = vec![0u32; bins];
    // A few thousand of a long streak's pixels find its angle as well as all of them.
    let step = (px.len() / 4096).max(1);
    let half = (bins / 2) as f64;
    for a in 0..180 {
        let th = (a as f64).to_radians();
        let (nx, ny) = (-th.sin() * 0.5, th.cos() * 0.5);
        acc.fill(0);
        for p in px.iter().step_by(step) {
            // ρ/2 + half is positive: the cast floors.
            let bin = (p.0 - mx) * nx + (p.1 - my) * ny + half;
            acc[bin as usize] += 1;
        }
        for (b, &c) in acc.iter().enumerate() {
            if c > best.0 {
                best = (c, a, b);
            }
        }
    }
    let th = (best.1 as f64).to_radians();
    let rho = ((best.2 as isize - (bins / 2) as isize) as f64 + 0.5) * 2.0;
    let mut seg = Segment {
        cx: mx - rho * th.sin(),
        cy: my + rho * th.cos(),
        ux: th.cos(),
        uy: th.sin(),
        t_min: 0.0,
        t_max: 0.0,
        pixels: 0,
    };
    // Refine by principal axes of the pixels near the line: wide first (the coarse angle
    // drifts 0.5° off at most), then twice within the band (the 2-cell bins of ρ leave the
    // line up to a cell off, and a band around a line that is off takes the streak's pixels
    // on one side only).
    for band in [s.band_px + 0.0087 * r_max, s.band_px, s.band_px] {
        let near: Vec<(f64, f64)> = px
            .iter()
            .copied()
            .filter(|p| seg.across(p.0, p.1).abs() <= band)
            .collect();
        if near.len() < 3 {
            return None;
        }
        seg = principal_axis(&near);
    }
    // The longest run of band pixels along the line without a gap.
    let mut ts: Vec<(f64, usize)> = px
        .iter()
        .enumerate()
        .filter(|(_, p)| seg.across(p.0, p.1).abs() <= s.band_px)
        .map(|(i, p)| (seg.along(p.0, p.1), i))
        .collect();
    ts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let (mut lo, mut best_run) = (0usize, (0usize, 0usize));
    for k in 1..=ts.len() {
        if k == ts.len() || ts[k].0 - ts[k - 1].0 > s.max_gap_px {
            if ts[k - 1].0 - ts[lo].0 > ts[best_run.1].0 - ts[best_run.0].0 {
                best_run = (lo, k - 1);
            }
            lo = k;
        }
    }
    let (a, b) = best_run;
    seg.t_min = ts.get(a)?.0;
    seg.t_max = ts[b].0;
    seg.pixels = b + 1 - a;
    // A line piece, not a blob: at least twice as long as it is wide. Its half width is
    // where the count of its pixels per pixel of distance from the line drops below a quarter
    // of the count on the line (a bright streak's mask is wide; a star's is as wide as long; a
    // streak crossing this one adds only a few pixels to each distance).
    let len = seg.length();
    let mut counts = [0usize; 64];
    for p in px {
        let (d, t) = (seg.across(p.0, p.1).abs(), seg.along(p.0, p.1));
        if t >= seg.t_min && t <= seg.t_max && d < 64.0 {
            counts[d as usize] += 1;
        }
    }
    let peak = counts[0].max(counts[1]);
    let half = counts.iter().position(|&c| 4 * c < peak).unwrap_or(64) as f64;
    if len < s.min_piece_px || len < 2.0 * (2.0 * half + 1.0) {
        return None;
    }
    let band = s.band_px.max(half + 1.0);
    let used = px
        .iter()
        .map(|p| {
            let (d, t) = (seg.across(p.0, p.1).abs(), seg.along(p.0, p.1));
            d <= band && t >= seg.t_min - 2.0 && t <= seg.t_max + 2.0
        })
        .collect();
    Some((seg, used))
}

/// The line of least squares through points (their principal axis), extent unset.
fn principal_axis(p: &[(f64, f64)]) -> Segment {
    let n = p.len() as f64;
    let (mx, my) = p
        .iter()
        .fold((0.0, 0.0), |(a, b), q| (a + q.0 / n, b + q.1 / n));
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    for q in p {
        let (dx, dy) = (q.0 - mx, q.1 - my);
        sxx += dx * dx;
        syy += dy * dy;
        sxy += dx * dy;
    }
    let th = 0.5 * (2.0 * sxy).atan2(sxx - syy);
    Segment {
        cx: mx,
        cy: my,
        ux: th.cos(),
        uy: th.sin(),
        t_min: 0.0,
        t_max: 0.0,
        pixels: p.len(),
    }
}

/// Join pieces that lie on one line (a faint streak breaks up; a long one crosses stars):
/// directions within 2°, each one's ends within the band of the other's line, and a gap along
/// the line shorter than the two pieces together (or `max_join_gap_px`). Pieces are joined in a fixed
/// order, so the result does not depend on which piece came first.
fn join_collinear(mut pieces: Vec<Segment>, stubs: &[Segment], s: &SegmentSettings) -> Vec<Joined> {
    pieces.sort_by(|a, b| b.length().total_cmp(&a.length()));
    let mut out: Vec<Joined> = Vec::new();
    for p in pieces {
        join_or_start(&mut out, p, s);
    }
    // A stub's own direction is loose (it is short and wide): it extends the first line its
    // middle lies on, when its axis is within 10° of the line's and the gap is a join's.
    let mut used = vec![false; stubs.len()];
    for (k, p) in stubs.iter().enumerate() {
        if let Some(j) = out.iter_mut().find(|j| stub_on(&j.line, p, s)) {
            let q = &mut j.line;
            let (x, y) = p.mid();
            let (t, half) = (q.along(x, y), 0.5 * p.length());
            if stub_within_join(q, p, s) {
                q.t_min = q.t_min.min(t - half);
                q.t_max = q.t_max.max(t + half);
                q.pixels += p.pixels;
                used[k] = true;
            }
        }
    }
    // Stubs that extended no line, chained along the line through them: a streak lit only in
    // pieces shorter than a piece of its own (a tumbling object's, 11–28 px between dark
    // stretches). Each chain then joins a line as a piece does, or stands as one.
    for chain in stub_chains(stubs, &used, s) {
        join_or_start(&mut out, chain, s);
    }
    out
}

/// Piece `p` joins the first line of `out` it is collinear with, else starts a line of its own.
/// A line it joins keeps its direction (the longer piece's, the better fixed) and takes `p`'s
/// extent.
fn join_or_start(out: &mut Vec<Joined>, p: Segment, s: &SegmentSettings) {
    let Some(j) = out.iter_mut().find(|j| collinear(&j.line, &p, s)) else {
        out.push(Joined {
            line: p,
            pieces: vec![p],
        });
        return;
    };
    j.pieces.push(p);
    let q = &mut j.line;
    let (a, b) = (q.along(p.cx, p.cy), p.ux * q.ux + p.uy * q.uy);
    let (t0, t1) = (a + b * p.t_min, a + b * p.t_max);
    q.t_min = q.t_min.min(t0.min(t1));
    q.t_max = q.t_max.max(t0.max(t1));
    q.pixels += p.pixels;
}

/// Does stub `p` lie on line `q`: its axis within 10° of the line's and its middle within the
/// band?
fn stub_on(q: &Segment, p: &Segment, s: &SegmentSettings) -> bool {
    let (cx, cy) = p.mid();
    (p.ux * q.ux + p.uy * q.uy).abs() > 10f64.to_radians().cos()
        && q.across(cx, cy).abs() <= s.band_px
}

/// The gap along line `q` between its extent and stub `p`'s (0 where they overlap).
fn stub_gap(q: &Segment, p: &Segment) -> f64 {
    let (x, y) = p.mid();
    let (half, t) = (0.5 * p.length(), q.along(x, y));
    (t - half - q.t_max).max(q.t_min - t - half).max(0.0)
}

/// Is stub `p` within a join's gap of line `q`: at most their lengths together, or the
/// settings' least join gap?
fn stub_within_join(q: &Segment, p: &Segment, s: &SegmentSettings) -> bool {
    stub_gap(q, p) <= (q.length() + p.length()).max(s.max_join_gap_px)
}

/// Chains of two or more of the stubs not `used`, longest first: a chain starts at its longest
/// stub and takes, nearest first, each stub on the line through the chain's stubs (see
/// [`stub_on`]; for the first pair, both axes within 10° of the line through their middles)
/// at a join's gap. Its line runs through its stubs' ends, over their extent.
fn stub_chains(stubs: &[Segment], used: &[bool], s: &SegmentSettings) -> Vec<Segment> {
    let mut free: Vec<usize> = (0..stubs.len()).filter(|&k| !used[k]).collect();
    free.sort_by(|&a, &b| {
        (stubs[b].length())
            .total_cmp(&stubs[a].length())
            .then(a.cmp(&b))
    });
    let through = |chain: &[usize]| {
        let ends: Vec<(f64, f64)> = chain
            .iter()
            .flat_map(|&k| {
                [
                    stubs[k].point(stubs[k].t_min),
                    stubs[k].point(stubs[k].t_max),
                ]
            })
            .collect();
        let mut line = extent(principal_axis(&ends), &ends);
        line.pixels = chain.iter().map(|&k| stubs[k].pixels).sum();
        line
    };
    let cos10 = 10f64.to_radians().cos();
    let mut taken = vec![false; stubs.len()];
    let mut out = Vec::new();
    for &first in &free {
        if taken[first] {
            continue;
        }
        let mut chain = vec![first];
        let mut line = stubs[first];
        loop {
            let fits = |m: usize| {
                let p = &stubs[m];
                let on = if chain.len() == 1 {
                    let pair = through(&[first, m]);
                    let along = |q: &Segment| (q.ux * pair.ux + q.uy * pair.uy).abs() > cos10;
                    along(&line) && along(p)
                } else {
                    stub_on(&line, p, s)
                };
                on && stub_within_join(&line, p, s)
            };
            let next = (free.iter().copied())
                .filter(|&m| !taken[m] && !chain.contains(&m) && fits(m))
                .min_by(|&a, &b| {
                    (stub_gap(&line, &stubs[a]))
                        .total_cmp(&stub_gap(&line, &stubs[b]))
                        .then(a.cmp(&b))
                });
            let Some(m) = next else { break };
            chain.push(m);
            line = through(&chain);
        }
        if chain.len() >= 2 {
            for &k in &chain {
                taken[k] = true;
            }
            out.push(line);
        }
    }
    out
}

fn collinear(q: &Segment, p: &Segment, s: &SegmentSettings) -> bool {
    let cos = (p.ux * q.ux + p.uy * q.uy).abs();
    if cos < 2f64.to_radians().cos() {
        return false;
    }
    let ends = [p.point(p.t_min), p.point(p.t_max)];
    if ends.iter().any(|e| q.across(e.0, e.1).abs() > s.band_px) {
        return false;
    }
    let (ta, tb) = (q.along(ends[0].0, ends[0].1), q.along(ends[1].0, ends[1].1));
    let gap = (ta.min(tb) - q.t_max).max(q.t_min - ta.max(tb)).max(0.0);
    gap <= (q.length() + p.length()).max(s.max_join_gap_px)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The runs (raster order) of filled rectangles of cells, (x0, x1, y0, y1) half-open.
    fn rects(r: &[(u32, u32, u32, u32)]) -> Vec<Run> {
        let mut runs: Vec<Run> = r
            .iter()
            .flat_map(|&(x0, x1, y0, y1)| (y0..y1).map(move |y| Run { y, x0, x1 }))
            .collect();
        runs.sort_by_key(|r| (r.y, r.x0));
        runs
    }

    /// Pieces 9 cells long and 4 wide have no line of their own (a line is twice as long as
    /// its band is wide); three of them on one line are one line over all three, and two side
    /// by side, their line across their axes, are none.
    #[test]
    fn stubs_on_one_line_chain_into_one() {
        let s = SegmentSettings::default();
        let three = rects(&[(5, 14, 10, 14), (20, 29, 10, 14), (36, 45, 10, 14)]);
        let found = segments(&three, 64, &s);
        assert_eq!(found.len(), 1, "{found:?}");
        let line = found[0].line;
        assert!(line.ux.abs() > 0.999, "along x: {line:?}");
        let (a, b) = (line.point(line.t_min), line.point(line.t_max));
        let (x0, x1) = (a.0.min(b.0), a.0.max(b.0));
        assert!(
            (x0 - 5.0).abs() < 0.5 && (x1 - 44.0).abs() < 0.5,
            "{x0} {x1}"
        );
        assert!((a.1 - 11.5).abs() < 0.1 && (b.1 - 11.5).abs() < 0.1);
        // Each alone: a stub, no line.
        assert!(segments(&rects(&[(5, 14, 10, 14)]), 64, &s).is_empty());
        // Side by side, 6 cells apart across: the line through them is 22° off their axes.
        let offset = rects(&[(5, 14, 10, 14), (20, 29, 16, 20)]);
        assert!(segments(&offset, 64, &s).is_empty());
    }
}
