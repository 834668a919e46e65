//! Stored FITS values to u16 pixels: scaling, blanks and sentinels.

use crate::error::{Result, fail};

/// BZERO and BSCALE. `int` holds them as integers when both are integral and small enough
/// for exact arithmetic in i128: unsigned 64-bit data have BZERO = 2^63, which f64
/// arithmetic on the stored values would round away.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Scaling {
    pub(crate) scale: f64,
    pub(crate) int: Option<(i128, i128)>,
}

impl Scaling {
    pub(crate) fn new(zero: f64, scale: f64) -> Scaling {
        let limit = 2f64.powi(63);
        let integral = |v: f64| v.fract() == 0.0 && v.abs() <= limit;
        let int = (integral(zero) && integral(scale)).then_some((zero as i128, scale as i128));
        Scaling { scale, int }
    }
}

/// Integer data to u16 pixels and the saturation (see the module documentation). Works on
/// stored values: BZERO/BSCALE are affine, so the physical range follows from the stored one,
/// and the linear map only needs BSCALE's sign.
pub(crate) fn convert_int<T: IntSample>(
    data: &[u8],
    s: Scaling,
    blank: Option<i64>,
    count: u64,
) -> Result<(Vec<u16>, u16)> {
    let stored = || data.chunks_exact(T::BYTES).map(T::read);
    let (mut lo, mut hi, mut blanks) = (i64::MAX, i64::MIN, 0u64);
    // Every value the type can store maps into 0..=65535 (16-bit data with BZERO = 32768, the
    // usual camera frame): the range of the data cannot change the result, so it is not read.
    let all_fit = s.int.is_some_and(|(zero, scale)| {
        let physical = |v: i64| zero + scale * i128::from(v);
        let (a, b) = (physical(T::MIN), physical(T::MAX));
        a.min(b) >= 0 && a.max(b) <= 65535
    });
    match blank {
        None if all_fit => (lo, hi) = (T::MIN, T::MAX),
        // Without BLANK the range is a plain fold, which the compiler vectorises.
        None => {
            (lo, hi) = stored().fold((lo, hi), |(lo, hi), v| (lo.min(v), hi.max(v)));
        }
        Some(b) => {
            for v in stored() {
                if v == b {
                    blanks += 1;
                } else {
                    lo = lo.min(v);
                    hi = hi.max(v);
                }
            }
        }
    }
    let mut pixels = new_pixels(count, blanks)?;
    let exact = s.int.and_then(|(zero, scale)| {
        let physical = |v: i64| zero + scale * i128::from(v);
        let (a, b) = (physical(lo), physical(hi));
        (a.min(b) >= 0 && a.max(b) <= 65535).then(|| {
            let top = physical(T::MIN).max(physical(T::MAX));
            (zero, scale, top.clamp(0, 65535) as u16)
        })
    });
    let saturation = if let Some((zero, scale, saturation)) = exact {
        // Wrapping i64 arithmetic is exact modulo 2^64, and the results lie in 0..=65535.
        // Blanks come out as garbage here and are replaced below.
        let (zero, scale) = (zero as i64, scale as i64);
        pixels.extend(stored().map(|v| zero.wrapping_add(scale.wrapping_mul(v)) as u16));
        saturation
    } else {
        let k = if hi > lo && s.scale != 0.0 {
            65535.0 / hi.abs_diff(lo) as f64
        } else {
            0.0
        };
        // A negative BSCALE turns the stored order around. The distance fits in u64.
        let flip = s.scale < 0.0;
        let offset = |v: i64| if flip { hi.abs_diff(v) } else { v.abs_diff(lo) };
        pixels.extend(stored().map(|v| (offset(v) as f64 * k + 0.5) as u16));
        u16::MAX
    };
    if blanks > 0 {
        fill_blanks(&mut pixels, data, T::BYTES, |b| Some(T::read(b)) == blank);
    }
    Ok((pixels, saturation))
}

/// Float data to u16 pixels over the range of the valid values (see [`float_range`]): values
/// outside it (sentinels) and non-finite ones are bad pixels, given the median. Returns a
/// warning when sentinels were found.
pub(crate) fn convert_float<T: FloatSample>(
    data: &[u8],
    s: Scaling,
    count: u64,
) -> Result<(Vec<u16>, u16, Option<String>)> {
    let stored = || data.chunks_exact(T::BYTES).map(T::read);
    let (lo, hi) = float_range(stored);
    let bad = |v: f64| !(v >= lo && v <= hi);
    let (mut blanks, mut sentinels, mut example) = (0u64, 0u64, 0.0);
    for v in stored() {
        if bad(v) {
            blanks += 1;
            if v.is_finite() {
                sentinels += 1;
                example = v;
            }
        }
    }
    let mut pixels = new_pixels(count, blanks)?;
    // In halves, so that hi − lo cannot overflow.
    let (from, sign) = if s.scale < 0.0 {
        (hi * 0.5, -1.0)
    } else {
        (lo * 0.5, 1.0)
    };
    let span = (hi * 0.5 - lo * 0.5).abs();
    let k = if span > 0.0 && s.scale != 0.0 {
        65535.0 / span
    } else {
        0.0
    };
    // Bad values become anything (`as` saturates, NaN → 0) and are replaced below.
    pixels.extend(stored().map(|v| ((v * 0.5 - from) * sign * k + 0.5) as u16));
    if blanks > 0 {
        fill_blanks(&mut pixels, data, T::BYTES, |b| bad(T::read(b)));
    }
    let warning = (sentinels > 0).then(|| {
        format!(
            "{sentinels} pixels far outside the others' values (e.g. {example:e}; the rest lie \
             in {lo:e}..{hi:e}) were taken as bad pixels (sentinel values?)"
        )
    });
    Ok((pixels, u16::MAX, warning))
}

/// How far (in the spread of the 0.1–99.9 % quantiles) values may lie beyond those quantiles
/// and still be mapped whatever follows them; beyond it, see [`float_range`].
pub(crate) const FLOAT_TAIL_SPREADS: f64 = 1000.0;
/// A jump in the sorted tail by more than this factor (distances from the quantile) starts the
/// sentinels.
pub(crate) const FLOAT_SENTINEL_JUMP: f64 = 100.0;

/// The range of the finite values, less sentinels: a bad-pixel marker such as 1e9 or −1e30
/// stretched over the u16 range would leave the sky and every star in a level or two. Beyond
/// FLOAT_TAIL_SPREADS of the quantiles' spread, the tail's values are walked outward and cut
/// at the first jump by FLOAT_SENTINEL_JUMP: the peaks of bright and saturated stars rise by
/// degrees, sentinels jump. A tail of more than 1 % of the values is data, not sentinels.
pub(crate) fn float_range<I: Iterator<Item = f64>>(stored: impl Fn() -> I) -> (f64, f64) {
    let (mut lo, mut hi, mut n) = (f64::INFINITY, f64::NEG_INFINITY, 0usize);
    for v in stored() {
        if v.is_finite() {
            // Comparisons rather than f64::min/max, which spend time on NaN.
            if v < lo {
                lo = v;
            }
            if v > hi {
                hi = v;
            }
            n += 1;
        }
    }
    if n == 0 {
        return (lo, hi);
    }
    // Quantiles of a strided sample of at most ~65536 values.
    let stride = (n / 65_536).max(1);
    let mut sample: Vec<f64> = stored().filter(|v| v.is_finite()).step_by(stride).collect();
    sample.sort_unstable_by(f64::total_cmp);
    let cut = sample.len() / 1000;
    let (q_lo, q_hi) = (sample[cut], sample[sample.len() - 1 - cut]);
    let reach = FLOAT_TAIL_SPREADS * (q_hi - q_lo);
    if reach.is_nan() || reach <= 0.0 || reach.is_infinite() {
        return (lo, hi);
    }
    // Each tail: distances beyond the quantile, ascending; the last before a jump is the end.
    let end_of = |distances: Vec<f64>| -> Option<f64> {
        if distances.len() > n / 100 {
            return None;
        }
        let mut d = distances;
        d.sort_unstable_by(f64::total_cmp);
        let mut last = reach;
        for &x in &d {
            if x > FLOAT_SENTINEL_JUMP * last {
                return Some(last);
            }
            last = x;
        }
        None
    };
    // Both tails in one pass, then the range less their sentinels in another.
    let (mut above, mut below) = (Vec::new(), Vec::new());
    for v in stored().filter(|v| v.is_finite()) {
        if v - q_hi > reach {
            above.push(v - q_hi);
        } else if q_lo - v > reach {
            below.push(q_lo - v);
        }
    }
    let (cut_hi, cut_lo) = (end_of(above), end_of(below));
    if cut_hi.is_some() || cut_lo.is_some() {
        let (dh, dl) = (
            cut_hi.unwrap_or(f64::INFINITY),
            cut_lo.unwrap_or(f64::INFINITY),
        );
        (lo, hi) = stored()
            .filter(|&v| v.is_finite() && v - q_hi <= dh && q_lo - v <= dl)
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
                (l.min(v), h.max(v))
            });
    }
    (lo, hi)
}

/// The pixel buffer, or an error when there is no memory for it or nothing valid to put in.
pub(crate) fn new_pixels(count: u64, blanks: u64) -> Result<Vec<u16>> {
    if blanks == count {
        fail!(
            Input,
            "every pixel of the FITS image is blank (NaN or BLANK)"
        );
    }
    let mut pixels = Vec::new();
    if usize::try_from(count).map_or(true, |n| pixels.try_reserve_exact(n).is_err()) {
        fail!(
            Input,
            "not enough memory for a FITS image of {count} pixels"
        );
    }
    Ok(pixels)
}

/// Give blank pixels the median of the others (from a histogram: linear time, no copy).
pub(crate) fn fill_blanks(
    pixels: &mut [u16],
    data: &[u8],
    bytes: usize,
    is_blank: impl Fn(&[u8]) -> bool,
) {
    let mut histogram = vec![0u64; 65536];
    let mut valid = 0u64;
    for (p, b) in pixels.iter().zip(data.chunks_exact(bytes)) {
        if !is_blank(b) {
            histogram[usize::from(*p)] += 1;
            valid += 1;
        }
    }
    let rank = valid.saturating_sub(1) / 2;
    let mut seen = 0;
    let median = histogram
        .iter()
        .position(|&n| {
            seen += n;
            seen > rank
        })
        .unwrap_or(0) as u16;
    for (p, b) in pixels.iter_mut().zip(data.chunks_exact(bytes)) {
        if is_blank(b) {
            *p = median;
        }
    }
}

/// An integer stored type (BITPIX 8, 16, 32, 64), read as i64.
pub(crate) trait IntSample {
    const BYTES: usize;
    const MIN: i64;
    const MAX: i64;
    /// `b` holds BYTES big-endian bytes.
    fn read(b: &[u8]) -> i64;
}

/// A floating-point stored type (BITPIX −32, −64), read as f64.
pub(crate) trait FloatSample {
    const BYTES: usize;
    fn read(b: &[u8]) -> f64;
}

macro_rules! sample {
    ($trait:ident, $t:ty, $out:ty) => {
        impl $trait for $t {
            const BYTES: usize = size_of::<$t>();
            sample!(@range $trait, $t);
            fn read(b: &[u8]) -> $out {
                <$t>::from_be_bytes(b.try_into().unwrap_or_default()) as $out
            }
        }
    };
    (@range IntSample, $t:ty) => {
        const MIN: i64 = <$t>::MIN as i64;
        const MAX: i64 = <$t>::MAX as i64;
    };
    (@range FloatSample, $t:ty) => {};
}
sample!(IntSample, u8, i64);
sample!(IntSample, i16, i64);
sample!(IntSample, i32, i64);
sample!(IntSample, i64, i64);
sample!(FloatSample, f32, f64);
sample!(FloatSample, f64, f64);
