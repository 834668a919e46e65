//! Frames from pixels already in memory (a camera SDK's buffer, a numpy array): the frame a
//! file of the same values decodes to, so that their records equal the command line's. 8-bit
//! values are kept (saturation 255), as an 8-bit PNG's are; 16-bit values are kept
//! (saturation 65535); 32-bit floats are scaled from the range of their values as a
//! BITPIX −32 FITS file's are. Non-finite floats are refused, not filled in: a caller who has
//! NaN pixels knows better than gpustar what they stand for.

use crate::error::{Result, fail};
use crate::io::frame::{Frame, MAX_SIDE};
use std::borrow::Cow;

/// Row-major pixel values of one frame, borrowed from the caller.
#[derive(Clone, Copy, Debug)]
pub enum Samples<'a> {
    U8(&'a [u8]),
    U16(&'a [u16]),
    F32(&'a [f32]),
}

impl Samples<'_> {
    fn len(&self) -> usize {
        match self {
            Samples::U8(v) => v.len(),
            Samples::U16(v) => v.len(),
            Samples::F32(v) => v.len(),
        }
    }
}

impl<'a> Frame<'a> {
    /// The frame of `width` × `height` row-major values, with the warnings its record carries
    /// (float sentinels taken as bad pixels, as in FITS files). u16 values are borrowed, not
    /// copied (the frame lives as long as they do; [`Frame::into_owned`] detaches it); u8 and
    /// f32 values are converted into pixels of its own. An error (kind `Input`) says
    /// what is wrong with values gpustar cannot take: an empty or oversized frame, a count
    /// that is not width × height, non-finite floats. Frames too small to hold a star field
    /// are taken here and get an error record from the solver, as such files do.
    pub fn from_samples(
        width: u32,
        height: u32,
        samples: Samples<'a>,
    ) -> Result<(Frame<'a>, Vec<String>)> {
        if width == 0 || height == 0 {
            fail!(Input, "the image is empty ({width}x{height} pixels)");
        }
        if width > MAX_SIDE || height > MAX_SIDE {
            fail!(
                Input,
                "the image is {width}x{height} pixels: gpustar takes at most {MAX_SIDE} a side"
            );
        }
        let count = width as usize * height as usize;
        if samples.len() != count {
            fail!(
                Input,
                "{} values for a {width}x{height} image ({count} expected)",
                samples.len()
            );
        }
        let (pixels, saturation, warning): (Cow<'a, [u16]>, _, _) = match samples {
            Samples::U8(v) => (v.iter().map(|&p| u16::from(p)).collect(), 255, None),
            Samples::U16(v) => (Cow::Borrowed(v), u16::MAX, None),
            Samples::F32(v) => {
                if let Some(i) = v.iter().position(|p| !p.is_finite()) {
                    let bad = v.iter().filter(|p| !p.is_finite()).count();
                    fail!(
                        Input,
                        "{bad} pixels are NaN or infinite (the first at x = {}, y = {}): give \
                         finite values (e.g. replace them with the median of the others)",
                        i % width as usize,
                        i / width as usize
                    );
                }
                let (pixels, saturation, warning) = crate::io::fits::float_pixels(v)?;
                (pixels.into(), saturation, warning)
            }
        };
        let frame = Frame {
            width,
            height,
            pixels,
            saturation,
        };
        Ok((frame, warning.into_iter().collect()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn values_are_kept_or_scaled_as_files_are() {
        let (f, _) = Frame::from_samples(2, 2, Samples::U8(&[0, 1, 2, 255])).unwrap();
        assert_eq!((&f.pixels[..], f.saturation), (&[0, 1, 2, 255][..], 255));
        let (f, _) = Frame::from_samples(2, 1, Samples::U16(&[7, 65535])).unwrap();
        assert_eq!((&f.pixels[..], f.saturation), (&[7, 65535][..], 65535));
        // Floats span 0..=65535 over their range, as a BITPIX -32 file's do.
        let (f, w) = Frame::from_samples(3, 1, Samples::F32(&[-1.0, 0.0, 1.0])).unwrap();
        assert_eq!((&f.pixels[..], w.len()), (&[0, 32768, 65535][..], 0));
    }

    #[test]
    fn bad_arrays_are_refused_with_what_is_wrong() {
        let msg = |r: Result<(Frame<'_>, Vec<String>)>| r.unwrap_err().to_string();
        assert!(msg(Frame::from_samples(0, 4, Samples::U8(&[]))).contains("empty"));
        assert!(msg(Frame::from_samples(2, 2, Samples::U8(&[1, 2, 3]))).contains("3 values"));
        let nan = msg(Frame::from_samples(
            2,
            2,
            Samples::F32(&[1.0, 2.0, 3.0, f32::NAN]),
        ));
        assert!(
            nan.contains("1 pixels are NaN") && nan.contains("x = 1, y = 1"),
            "{nan}"
        );
        let big = msg(Frame::from_samples(MAX_SIDE + 1, 1, Samples::U8(&[])));
        assert!(big.contains("at most"), "{big}");
    }
}
