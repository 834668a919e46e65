//! Annotated PNG previews of a frame and its solution, for people checking results by eye.
//!
//! The frame is stretched so faint stars show; detections identified with a
//! catalog star get a green circle and its catalog id ("HIP n"), unmatched detections an
//! orange square, and catalog stars predicted in the field but not detected a
//! small cyan cross. Shapes differ as well as colours so the marks stay apart for
//! red–green colour-blind readers. Labels go right, left, above or below their
//! star, whichever collides least. A caption goes top-left and a legend (with
//! counts) at the bottom, both on dimmed bands; the output has the frame's size.
//!
//! Drawing is done here with span-filled rings and rectangles plus an embedded 5×7
//! bitmap font: `imageproc` would duplicate the crate's `rand` stack and still lack
//! thick rings and a built-in font, and a TTF would add ~700 kB and a licence.
//!
//! Nothing here panics on odd input: marks with non-finite coordinates are
//! skipped, everything is clipped at the borders, radii are capped, and a frame
//! with no pixels (zero width/height or a too-short pixel buffer) renders as a
//! 1×1 black image while [`write_png`] returns an error for it.
//!
//! Label placement, marks and legend share the canvas type and the clipping they need, and
//! stay together; the font is in `font.rs`.

use std::path::Path;

use crate::error::{Context, Error, IntoKind, fail};
use image::{Rgb, RgbImage};

mod font;
use font::glyph;

/// A position on the frame: `(x, y)` = (column, row), `(0, 0)` = centre of the
/// top-left pixel; `radius_px` is the detection's size (its circle is drawn larger).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Mark {
    pub x: f64,
    pub y: f64,
    pub radius_px: f64,
}

/// A streak as drawn: its two ends `(x, y)` and which of them are edge ends.
pub type StreakMark = ([(f64, f64); 2], [bool; 2]);

/// Everything one annotated PNG shows.
#[derive(Debug, Clone)]
pub struct Annotation<'a> {
    pub width: u32,
    pub height: u32,
    /// Row-major, as decoded (8-bit inputs hold 0..=255, 16-bit 0..=65535).
    pub pixels: &'a [u16],
    /// The format's maximum (255 or 65535); values at or above it show white.
    pub saturation: u16,
    /// Detection + its label (the star's catalog id, e.g. "HIP 27989").
    pub identified: Vec<(Mark, String)>,
    /// Detections not identified.
    pub unmatched: Vec<Mark>,
    /// Catalog stars projected in the frame with no detection.
    pub predicted: Vec<Mark>,
    /// Satellite streaks: their two ends, and which are edge ends (where the streak leaves
    /// the frame). Drawn as two lines beside the track, a ring at each end inside the frame.
    pub streaks: Vec<StreakMark>,
    /// One ASCII line, shown in upper case (the font has no lower case) and
    /// wrapped at word boundaries when wider than the frame.
    pub caption: String,
}

const IDENTIFIED: Rgb<u8> = Rgb([0, 255, 0]);
const UNMATCHED: Rgb<u8> = Rgb([255, 96, 0]);
const PREDICTED: Rgb<u8> = Rgb([0, 200, 255]);
const STREAK: Rgb<u8> = Rgb([255, 0, 255]);
const TEXT: Rgb<u8> = Rgb([255, 255, 255]);
const OUTLINE: Rgb<u8> = Rgb([0, 0, 0]);

/// Marks whose centre is further than this from the origin are meaningless
/// (bad projections) and skipped; radii are capped to it. Keeps squared
/// distances exact in f64 and loops bounded.
const COORD_LIMIT: f64 = 1e7;

/// Grey level the sky background is stretched to: dark, but with its noise visible.
const BACKGROUND_GREY: f64 = 0.13;

/// Renders the annotated frame. Invalid frames (no pixels, or fewer pixels than
/// `width * height`) give a 1×1 black image; [`write_png`] rejects them instead.
pub fn render(a: &Annotation) -> RgbImage {
    let Some(n) = pixel_count(a) else {
        return RgbImage::new(1, 1);
    };
    let mut img = stretch(a.width, a.height, &a.pixels[..n], a.saturation);
    let scale = font_scale(a.width, a.height);
    // 1 px lines on small frames, 2 px on large ones so they survive downscaled viewing.
    let thick = scale.min(2);
    // Circle radius (also the square's half-side): twice the detection's, at least
    // 6 px, scaled with the font so marks stay visible on big frames.
    let ring_r = |m: &Mark| (m.radius_px * 2.0).max(6.0 * scale as f64);

    let count = |v: &[Mark]| v.iter().filter_map(usable).count();
    let identified: Vec<(Mark, &str)> = a
        .identified
        .iter()
        .filter_map(|(m, label)| usable(m).map(|m| (m, label.as_str())))
        .collect();
    let counts = [identified.len(), count(&a.unmatched), count(&a.predicted)];
    let caption = caption_layout(a.width, &a.caption, scale);
    let legend = legend_layout(a.width, a.height, counts, scale);

    // Dim the text bands first so marks under them keep their full colour.
    for &(band, _) in caption.iter().chain([&legend]) {
        darken_rect(&mut img, band);
    }
    for (ends, edge) in &a.streaks {
        draw_streak(&mut img, *ends, *edge, 6.0 * scale as f64, thick);
    }
    for m in a.predicted.iter().filter_map(usable) {
        let arm = (m.radius_px * 2.0).clamp(4.0 * scale as f64, 12.0 * scale as f64);
        draw_cross(&mut img, m.x, m.y, arm, thick, PREDICTED);
    }
    for m in a.unmatched.iter().filter_map(usable) {
        draw_square(&mut img, m.x, m.y, ring_r(&m), thick, UNMATCHED);
    }
    for (m, _) in &identified {
        draw_ring(&mut img, m.x, m.y, ring_r(m), thick, IDENTIFIED);
    }
    // Labels after all marks so no circle is drawn over a label; placed around
    // their star to avoid each other, other marks and the text bands.
    let boxes: Vec<Rect> = identified
        .iter()
        .map(|(m, _)| m)
        .chain(a.unmatched.iter())
        .filter_map(usable)
        .map(|m| {
            let r = ring_r(&m) + thick as f64;
            let (x0, y0) = ((m.x - r).floor() as i64, (m.y - r).floor() as i64);
            (x0, y0, (m.x + r).ceil() as i64, (m.y + r).ceil() as i64)
        })
        .collect();
    let mut around = Obstacles {
        bands: caption
            .iter()
            .chain([&legend])
            .map(|(band, _)| *band)
            .collect(),
        labels: Vec::new(),
        marks: boxes,
    };
    let size = (i64::from(a.width), i64::from(a.height));
    for &(m, text) in &identified {
        let r = ring_r(&m) + thick as f64;
        let rect = place_label(
            &m,
            r,
            text_width(text.chars().count(), scale),
            scale,
            size,
            &around,
        );
        draw_text(
            &mut img,
            rect.0 + 1,
            rect.1 + 1,
            text,
            scale,
            IDENTIFIED,
            true,
        );
        around.labels.push(rect);
    }
    for (_, items) in caption.iter().chain([&legend]) {
        draw_placed(&mut img, items, scale, thick);
    }
    img
}

/// Renders and writes the PNG, creating parent directories.
pub fn write_png(path: &Path, a: &Annotation) -> crate::error::Result<()> {
    if pixel_count(a).is_none() {
        fail!(
            Output,
            "cannot annotate {}: frame is {}x{} with {} pixels",
            path.display(),
            a.width,
            a.height,
            a.pixels.len()
        );
    }
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("creating annotation directory {}", dir.display()))?;
    }
    // Marked as gpustar's (a tEXt chunk), so that a later run knows it may replace it.
    let img = render(a);
    let mut bytes = Vec::new();
    let mut e = png::Encoder::new(&mut bytes, img.width(), img.height());
    e.set_color(png::ColorType::Rgb);
    e.set_depth(png::BitDepth::Eight);
    let (key, value) = crate::io::guard::PNG_SOFTWARE;
    e.add_text_chunk(key.into(), value.into())
        .and_then(|_| e.write_header())
        .and_then(|mut w| {
            w.write_image_data(img.as_raw())?;
            w.finish()
        })
        .into_kind(Error::Output)
        .with_context(|| format!("encoding annotated PNG {}", path.display()))?;
    crate::io::guard::write_atomically(path, &bytes)
}

/// Text scale: 5×7 glyphs stay legible when big frames are viewed shrunk to a screen.
/// Uses the larger dimension so tall frames scale like wide ones.
fn font_scale(width: u32, height: u32) -> u32 {
    match width.max(height) {
        0..1500 => 1,
        1500..=3000 => 2,
        _ => 3,
    }
}

/// Number of pixels to use, or `None` when the frame cannot be drawn.
fn pixel_count(a: &Annotation) -> Option<usize> {
    let n = (a.width as usize).checked_mul(a.height as usize)?;
    (n > 0 && a.pixels.len() >= n).then_some(n)
}

/// The mark with a sane radius, or `None` when its position is unusable.
fn usable(m: &Mark) -> Option<Mark> {
    let ok = |v: f64| v.is_finite() && v.abs() <= COORD_LIMIT;
    if !ok(m.x) || !ok(m.y) {
        return None;
    }
    let radius_px = if m.radius_px.is_finite() {
        m.radius_px.clamp(0.0, COORD_LIMIT)
    } else {
        0.0
    };
    Some(Mark { radius_px, ..*m })
}

// ---------------------------------------------------------------- stretch

/// Greyscale RGB image of the frame, stretched with asinh between a black point
/// just below the sky and the 99.9th percentile. The asinh softness is chosen so
/// the median (the sky in star fields) lands at `BACKGROUND_GREY`: faint stars
/// a few sigma up are then clearly visible while bright ones still saturate.
fn stretch(width: u32, height: u32, pixels: &[u16], saturation: u16) -> RgbImage {
    let mut hist = vec![0u64; 65536];
    for &p in pixels {
        hist[p as usize] += 1;
    }
    let n = pixels.len() as u64;
    let pct = |q: f64| -> f64 {
        let target = ((q * n as f64) as u64).min(n.saturating_sub(1));
        let mut acc = 0;
        for (v, &c) in hist.iter().enumerate() {
            acc += c;
            if acc > target {
                return v as f64;
            }
        }
        65535.0
    };
    let median = pct(0.5);
    // Lower half of the histogram is star-free: median − 16th pct ≈ 1 sigma of sky noise.
    let sigma = (median - pct(0.1587)).max(1.0);
    let lo = (median - 2.0 * sigma).max(0.0);
    // Star-poor frames have a 99.9th percentile inside the noise; keep the sky dark there.
    let mut hi = pct(0.999).max(median + 8.0 * sigma);
    let sat = f64::from(saturation.max(1));
    if sat > lo + 1.0 {
        hi = hi.min(sat);
    }
    let range = (hi - lo).max(1.0);

    let sky = (median - lo) / range;
    let beta = asinh_softness(sky, BACKGROUND_GREY);
    let norm = (beta.asinh()).max(f64::MIN_POSITIVE);
    let lut: Vec<u8> = (0..=u16::MAX)
        .map(|v| {
            let u = ((f64::from(v).min(sat) - lo) / range).clamp(0.0, 1.0);
            let g = if beta > 0.0 {
                (beta * u).asinh() / norm
            } else {
                u
            };
            (g.clamp(0.0, 1.0) * 255.0).round() as u8
        })
        .collect();
    RgbImage::from_fn(width, height, |x, y| {
        let g = lut[pixels[y as usize * width as usize + x as usize] as usize];
        Rgb([g, g, g])
    })
}

/// β such that asinh(β·u)/asinh(β) = `target`, or 0 (plain linear) when `u` is
/// already at least `target`. The ratio rises monotonically from u (β→0) to 1.
fn asinh_softness(u: f64, target: f64) -> f64 {
    if u.is_nan() || u <= 0.0 || u >= target {
        return 0.0;
    }
    let f = |b: f64| (b * u).asinh() / b.asinh();
    let (mut lo, mut hi) = (1e-3_f64.ln(), 1e9_f64.ln());
    if f(hi.exp()) < target {
        return hi.exp(); // sky extremely far below the stars: stretch as hard as allowed
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if f(mid.exp()) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    hi.exp()
}

// ---------------------------------------------------------------- primitives

/// Fills the inclusive rectangle, clipped to the image.
fn fill_rect(img: &mut RgbImage, x0: i64, y0: i64, x1: i64, y1: i64, c: Rgb<u8>) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    let (x0, x1) = (x0.max(0), x1.min(w - 1));
    let (y0, y1) = (y0.max(0), y1.min(h - 1));
    for y in y0..=y1 {
        for x in x0..=x1 {
            img.put_pixel(x as u32, y as u32, c);
        }
    }
}

/// Scales the inclusive rectangle's pixels towards black, so text over it reads.
fn darken_rect(img: &mut RgbImage, (x0, y0, x1, y1): Rect) {
    let (w, h) = (i64::from(img.width()), i64::from(img.height()));
    for y in y0.max(0)..=y1.min(h - 1) {
        for x in x0.max(0)..=x1.min(w - 1) {
            let p = img.get_pixel_mut(x as u32, y as u32);
            p.0 = p.0.map(|v| (u16::from(v) * 90 / 256) as u8);
        }
    }
}

/// Ring of pixels whose centres lie within `thick/2` of the circle, filled row
/// by row as spans so huge radii cost only the rows inside the image.
fn draw_ring(img: &mut RgbImage, cx: f64, cy: f64, r: f64, thick: u32, c: Rgb<u8>) {
    let half = thick as f64 / 2.0;
    let (r_in, r_out) = ((r - half).max(0.0), r + half);
    let h = i64::from(img.height());
    let y0 = ((cy - r_out).ceil() as i64).max(0);
    let y1 = ((cy + r_out).floor() as i64).min(h - 1);
    for y in y0..=y1 {
        let dy = y as f64 - cy;
        let outer = (r_out * r_out - dy * dy).max(0.0).sqrt();
        let (a, b) = ((cx - outer).ceil() as i64, (cx + outer).floor() as i64);
        if dy.abs() < r_in {
            let inner = (r_in * r_in - dy * dy).sqrt();
            fill_rect(img, a, y, (cx - inner).floor() as i64, y, c);
            fill_rect(img, (cx + inner).ceil() as i64, y, b, y, c);
        } else {
            fill_rect(img, a, y, b, y, c);
        }
    }
}

/// Square outline of half-side `half` around the pixel nearest (cx, cy).
fn draw_square(img: &mut RgbImage, cx: f64, cy: f64, half: f64, thick: u32, c: Rgb<u8>) {
    let (x, y) = (cx.round() as i64, cy.round() as i64);
    let half = half.round() as i64;
    let t = i64::from(thick);
    let (o, i) = (half + t / 2, half + t / 2 - t + 1); // outer / inner edge offsets
    fill_rect(img, x - o, y - o, x + o, y - i, c); // top
    fill_rect(img, x - o, y + i, x + o, y + o, c); // bottom
    fill_rect(img, x - o, y - o, x - i, y + o, c); // left
    fill_rect(img, x + i, y - o, x + o, y + o, c); // right
}

/// Plus-shaped cross through the pixel nearest (cx, cy), including that pixel.
/// Two lines `gap` pixels either side of the streak, so the track itself stays visible,
/// and a ring at each end that is inside the frame.
fn draw_streak(img: &mut RgbImage, ends: [(f64, f64); 2], edge: [bool; 2], gap: f64, thick: u32) {
    let [(x0, y0), (x1, y1)] = ends;
    let len = (x1 - x0).hypot(y1 - y0);
    if !(len.is_finite() && len > 0.0 && len < COORD_LIMIT) {
        return;
    }
    let (nx, ny) = (-(y1 - y0) / len, (x1 - x0) / len);
    let steps = (2.0 * len).ceil() as usize;
    for side in [-1.0, 1.0] {
        for k in 0..=steps {
            let t = k as f64 / steps as f64;
            let (x, y) = (
                x0 + t * (x1 - x0) + side * gap * nx,
                y0 + t * (y1 - y0) + side * gap * ny,
            );
            fill_rect(
                img,
                x.round() as i64,
                y.round() as i64,
                x.round() as i64 + thick as i64 - 1,
                y.round() as i64 + thick as i64 - 1,
                STREAK,
            );
        }
    }
    for ((x, y), e) in ends.into_iter().zip(edge) {
        if !e {
            draw_ring(img, x, y, gap, thick, STREAK);
        }
    }
}

fn draw_cross(img: &mut RgbImage, cx: f64, cy: f64, arm: f64, thick: u32, c: Rgb<u8>) {
    let (x, y) = (cx.round() as i64, cy.round() as i64);
    let arm = arm.round() as i64;
    let (a, b) = (-(i64::from(thick) - 1) / 2, i64::from(thick) / 2);
    fill_rect(img, x - arm, y + a, x + arm, y + b, c);
    fill_rect(img, x + a, y - arm, x + b, y + arm, c);
}

// ---------------------------------------------------------------- text

const GLYPH_W: i64 = 5;
const GLYPH_H: i64 = 7;
const ADVANCE: i64 = 6; // glyph + 1 column gap
const LINE: i64 = 10; // glyph + 3 rows gap

/// Width in pixels of `chars` characters at `scale`.
fn text_width(chars: usize, scale: u32) -> i64 {
    if chars == 0 {
        return 0;
    }
    (chars as i64 * ADVANCE - (ADVANCE - GLYPH_W)) * i64::from(scale)
}

/// Draws `text` with its top-left at (x, y); with `outline`, a 1 px black rim
/// first so it reads on bright stars and nebulosity.
fn draw_text(
    img: &mut RgbImage,
    x: i64,
    y: i64,
    text: &str,
    scale: u32,
    c: Rgb<u8>,
    outline: bool,
) {
    let s = i64::from(scale);
    let passes: &[(i64, Rgb<u8>)] = if outline {
        &[(1, OUTLINE), (0, c)]
    } else {
        &[(0, c)]
    };
    for &(grow, colour) in passes {
        for (i, ch) in text.chars().enumerate() {
            let gx = x + i as i64 * ADVANCE * s;
            for (row, bits) in glyph(ch).iter().enumerate() {
                for col in 0..GLYPH_W {
                    if bits & (0x10 >> col) != 0 {
                        let (px, py) = (gx + col * s, y + row as i64 * s);
                        fill_rect(
                            img,
                            px - grow,
                            py - grow,
                            px + s - 1 + grow,
                            py + s - 1 + grow,
                            colour,
                        );
                    }
                }
            }
        }
    }
}

/// Pixels shared by two inclusive rectangles.
fn overlap(a: Rect, b: Rect) -> i64 {
    let w = (a.2.min(b.2) - a.0.max(b.0) + 1).max(0);
    let h = (a.3.min(b.3) - a.1.max(b.1) + 1).max(0);
    w * h
}

/// What a label should not cover, most important last.
struct Obstacles {
    /// Caption and legend bands (text there is dimmed, so covering it costs little).
    bands: Vec<Rect>,
    /// Labels already placed.
    labels: Vec<Rect>,
    /// Bounding boxes of circles and squares.
    marks: Vec<Rect>,
}

/// Rectangle (with outline) for a label of width `w` next to a circle of radius
/// `r`: right, left, above or below, whichever (in that order of preference)
/// covers least. Overlapping another label or running off the image is worst,
/// then marks, then the text bands. Greedy, but keeps close pairs legible.
fn place_label(
    m: &Mark,
    r: f64,
    w: i64,
    scale: u32,
    (iw, ih): (i64, i64),
    around: &Obstacles,
) -> Rect {
    let s = i64::from(scale);
    let (h, gap) = (GLYPH_H * s, 2 * s);
    let (cx, cy, r) = (m.x.round() as i64, m.y.round() as i64, r.ceil() as i64);
    let mid_y = cy - h / 2;
    let candidates = [
        (cx + r + gap, mid_y),
        (cx - r - gap - w, mid_y),
        (cx - w / 2, cy - r - gap - h),
        (cx - w / 2, cy + r + gap),
    ];
    let sum = |rects: &[Rect], rect: Rect| rects.iter().map(|&o| overlap(rect, o)).sum::<i64>();
    let cost = |&(x, y): &(i64, i64)| {
        let rect = (x - 1, y - 1, x + w, y + h);
        let off = (w + 2) * (h + 2) - overlap(rect, (0, 0, iw - 1, ih - 1));
        8 * (off + sum(&around.labels, rect))
            + 2 * sum(&around.marks, rect)
            + sum(&around.bands, rect)
    };
    let (x, y) = candidates
        .iter()
        .fold((candidates[0], i64::MAX), |best, c| {
            let k = cost(c);
            if k < best.1 { (*c, k) } else { best }
        })
        .0;
    (x - 1, y - 1, x + w, y + h)
}

/// Greedy word wrap to `max` characters per line; over-long words are cut.
fn wrap(text: &str, max: usize) -> Vec<String> {
    let mut lines = Vec::new();
    let mut cur: Vec<char> = Vec::new();
    for word in text.split_whitespace() {
        let mut word: Vec<char> = word.chars().collect();
        while word.len() > max {
            if !cur.is_empty() {
                lines.push(cur.drain(..).collect());
            }
            lines.push(word.drain(..max).collect());
        }
        if word.is_empty() {
            continue;
        }
        if !cur.is_empty() && cur.len() + 1 + word.len() > max {
            lines.push(cur.drain(..).collect());
        }
        if !cur.is_empty() {
            cur.push(' ');
        }
        cur.extend(word);
    }
    if !cur.is_empty() {
        lines.push(cur.into_iter().collect());
    }
    lines
}

/// Inclusive pixel rectangle (x0, y0, x1, y1); may extend past the image.
type Rect = (i64, i64, i64, i64);

/// A text item placed on the image; `sample` is the legend mark (0 identified,
/// 1 unmatched, 2 predicted) drawn in the `SAMPLE` box before the text.
struct Placed {
    x: i64,
    y: i64,
    text: String,
    sample: Option<usize>,
}

const SAMPLE: i64 = 8; // legend sample box width, in font pixels

/// Caption lines top-left, wrapped to the frame width, and the band behind them.
fn caption_layout(width: u32, caption: &str, scale: u32) -> Option<(Rect, Vec<Placed>)> {
    let s = i64::from(scale);
    let pad = 3 * s;
    let max = ((i64::from(width) - 2 * pad) / (ADVANCE * s)).max(0) as usize;
    if max == 0 {
        return None;
    }
    let lines = wrap(caption, max);
    let longest = lines.iter().map(|l| l.chars().count()).max()?;
    let bottom = pad + (lines.len() as i64 - 1) * LINE * s + GLYPH_H * s + pad;
    let band = (0, 0, text_width(longest, scale) + 2 * pad - 1, bottom - 1);
    let placed = lines
        .into_iter()
        .enumerate()
        .map(|(i, text)| Placed {
            x: pad,
            y: pad + i as i64 * LINE * s,
            text,
            sample: None,
        })
        .collect();
    Some((band, placed))
}

/// Bottom-left legend: a sample of each mark, what it means and how many were
/// drawn; items wrap onto more lines on narrow frames.
fn legend_layout(width: u32, height: u32, counts: [usize; 3], scale: u32) -> (Rect, Vec<Placed>) {
    let s = i64::from(scale);
    let pad = 3 * s;
    let labels = [
        format!("IDENTIFIED {}", counts[0]),
        format!("UNMATCHED {}", counts[1]),
        format!("PREDICTED NOT DETECTED {}", counts[2]),
    ];
    // Greedy layout: (line, x) for each item.
    let (mut line, mut x, mut right) = (0, pad, 0);
    let mut slots = Vec::new();
    for label in &labels {
        let w = (SAMPLE + 2) * s + text_width(label.len(), scale);
        if x > pad && x + w > i64::from(width) - pad {
            line += 1;
            x = pad;
        }
        slots.push((line, x));
        right = right.max(x + w);
        x += w + 3 * ADVANCE * s;
    }
    let lines = line + 1;
    let top = i64::from(height) - (lines * LINE - (LINE - GLYPH_H)) * s - 2 * pad;
    let placed = labels
        .into_iter()
        .zip(slots)
        .enumerate()
        .map(|(k, (text, (line, x)))| Placed {
            x,
            y: top + pad + line * LINE * s,
            text,
            sample: Some(k),
        })
        .collect();
    ((0, top, right + pad - 1, i64::from(height) - 1), placed)
}

/// Draws placed text (and legend samples) in white with a dark rim.
fn draw_placed(img: &mut RgbImage, items: &[Placed], scale: u32, thick: u32) {
    let s = i64::from(scale);
    for p in items {
        // Dim the line's own box again so labels or stars under it don't garble it.
        let sample_w = if p.sample.is_some() {
            (SAMPLE + 2) * s
        } else {
            0
        };
        let end = p.x + sample_w + text_width(p.text.chars().count(), scale);
        darken_rect(img, (p.x - s, p.y - s, end + s, p.y + GLYPH_H * s));
        let mut x = p.x;
        if let Some(k) = p.sample {
            let (cx, cy) = ((x + SAMPLE * s / 2) as f64, (p.y + GLYPH_H * s / 2) as f64);
            let r = 3.0 * s as f64;
            match k {
                0 => draw_ring(img, cx, cy, r, thick, IDENTIFIED),
                1 => draw_square(img, cx, cy, r, thick, UNMATCHED),
                _ => draw_cross(img, cx, cy, r, thick, PREDICTED),
            }
            x += (SAMPLE + 2) * s;
        }
        draw_text(img, x, p.y, &p.text, scale, TEXT, true);
    }
}

#[cfg(test)]
mod tests;
