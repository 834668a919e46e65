//! Fixed-pattern noise removal before detection: subtract a dark frame (`--dark FILE`) or the
//! per-pixel median of the frames of the same directory (`--dark-median`).
//!
//! Hot pixels, amplifier glow and bias structure sit at the same pixels in every frame of a
//! camera, while the stars move between pointings; the median of several frames keeps the
//! first and loses the second. Subtracting it leaves faint stars on a flat background (the
//! openstartracker frames need this: their fixed pattern is as bright as their stars).

use crate::error::{Context, Result, fail};
use crate::io::frame::{Frame, is_image_path};
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock};

/// Frames of a directory that enter its median, evenly spaced in name order: enough for the
/// median to ignore stars, few enough to read quickly.
pub const MEDIAN_FRAMES: usize = 25;

/// The fewest frames a median dark is made of: with fewer, a star in one frame shows in it.
pub const MIN_MEDIAN_FRAMES: usize = 3;

/// How frames are cleaned before detection.
#[derive(Debug, Default)]
pub enum Darks {
    /// Frames are used as decoded.
    #[default]
    None,
    /// One dark frame for every input.
    File {
        path: PathBuf,
        frame: Frame<'static>,
    },
    /// The median of each directory's frames of the same size, made on first use.
    DirectoryMedian(Mutex<HashMap<DarkKey, Arc<OnceLock<DarkResult>>>>),
}

/// A directory and a frame size: frames of other sizes in the directory get their own dark.
type DarkKey = (PathBuf, u32, u32);
type DarkResult = Result<Arc<Frame<'static>>>;

impl Darks {
    /// Read the dark frame of `--dark FILE`. With `expect`, the frames' (width, height) from a
    /// camera file, a dark of another size is refused from its header before it is decoded: a
    /// PNG of a few hundred kB can declare 30000² pixels, 1.8 GB decoded. Without it (frames
    /// of any size), the decoders' limits on frames apply.
    pub fn from_file(path: &Path, expect: Option<(u32, u32)>) -> Result<Darks> {
        if let Some((w, h)) = expect
            && let Some((dw, dh)) = header_size(path)
            && (dw, dh) != (w, h)
        {
            fail!(
                Input,
                "the dark frame {} is {dw}x{dh} but the camera file says {w}x{h}: pass a dark \
                 of this camera",
                path.display()
            );
        }
        let (frame, _) = Frame::read_info_sized(path, expect)?;
        Ok(Darks::File {
            path: path.to_path_buf(),
            frame,
        })
    }

    pub fn directory_median() -> Darks {
        Darks::DirectoryMedian(Mutex::new(HashMap::new()))
    }

    /// The frame of `path` with the dark subtracted, or why that cannot be done (a person can
    /// act on the message: wrong dark size, too few frames for a median; a directory's failed
    /// median is every frame's error there).
    pub fn apply<'a>(&self, path: &Path, frame: Frame<'a>) -> Result<Frame<'a>> {
        match self {
            Darks::None => Ok(frame),
            Darks::File { path: dp, frame: d } => {
                if (d.width, d.height) != (frame.width, frame.height) {
                    fail!(
                        Input,
                        "image is {}x{} but the dark frame {} is {}x{}: pass a dark of this \
                         camera",
                        frame.width,
                        frame.height,
                        dp.display(),
                        d.width,
                        d.height
                    );
                }
                Ok(subtract_dark(&frame, d))
            }
            Darks::DirectoryMedian(cache) => {
                let dir = path.parent().unwrap_or(Path::new(".")).to_path_buf();
                let key = (dir, frame.width, frame.height);
                let cell = {
                    let mut map = cache.lock().unwrap_or_else(|e| e.into_inner());
                    map.entry(key.clone()).or_default().clone()
                };
                // Built once per directory and size; other workers wait for it.
                let dark = cell.get_or_init(|| median_of_directory(&key.0, key.1, key.2));
                Ok(subtract_dark(&frame, dark.as_ref().map_err(|e| e.clone())?))
            }
        }
    }
}

/// The size an image file's header declares (PNG, JPEG, TIFF: read without decoding), or
/// None for a file the image decoders do not know (FITS, whose data are not compressed and so
/// no larger than the file) or cannot open: [`Frame::read_info_sized`] then says what is wrong.
fn header_size(path: &Path) -> Option<(u32, u32)> {
    // Not opened unless regular: a FIFO would block the open.
    if !std::fs::metadata(path).is_ok_and(|m| m.is_file()) {
        return None;
    }
    image::ImageReader::open(path)
        .ok()?
        .with_guessed_format()
        .ok()?
        .into_dimensions()
        .ok()
}

/// `frame − dark`, shifted back up by the dark's median so the background keeps its noise on
/// both sides (clipping at 0 would halve it and bias the thresholds). Saturated pixels stay
/// saturated: they are saturated whatever the dark holds.
pub fn subtract_dark(frame: &Frame, dark: &Frame) -> Frame<'static> {
    let offset = i32::from(median(dark.pixels.to_vec()));
    let sat = frame.saturation;
    let pixels = frame
        .pixels
        .iter()
        .zip(dark.pixels.iter())
        .map(|(&p, &d)| {
            if p >= sat {
                sat
            } else {
                (i32::from(p) - i32::from(d) + offset).clamp(0, i32::from(sat) - 1) as u16
            }
        })
        .collect();
    Frame {
        width: frame.width,
        height: frame.height,
        pixels,
        saturation: sat,
    }
}

/// The per-pixel median of up to `MEDIAN_FRAMES` frames of `dir` that are `width`×`height`.
fn median_of_directory(dir: &Path, width: u32, height: u32) -> DarkResult {
    let mut files: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("--dark-median: cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.is_file() && is_image_path(p))
        .collect();
    files.sort();
    // Evenly spaced picks, so a long sequence of one pointing does not fill the median.
    let step = (files.len() as f64 / MEDIAN_FRAMES as f64).max(1.0);
    let picks = (0..MEDIAN_FRAMES.min(files.len())).map(|k| &files[(k as f64 * step) as usize]);
    let frames: Vec<Frame<'static>> = picks
        .filter_map(|p| Frame::read(p).ok())
        .filter(|f| (f.width, f.height) == (width, height))
        .collect();
    if frames.len() < MIN_MEDIAN_FRAMES {
        fail!(
            Input,
            "--dark-median needs at least {MIN_MEDIAN_FRAMES} readable {width}x{height} frames \
             in {} to make a dark, found {}: pass a dark frame with --dark FILE instead",
            dir.display(),
            frames.len()
        );
    }
    tracing::info!(
        "dark for {}x{} frames of {}: median of {} frames",
        width,
        height,
        dir.display(),
        frames.len()
    );
    Ok(Arc::new(median_frame(&frames)))
}

/// Per-pixel median of frames of one size (the lower middle value for an even count).
pub fn median_frame(frames: &[Frame]) -> Frame<'static> {
    let n = frames[0].pixels.len();
    let mut column = Vec::with_capacity(frames.len());
    let pixels = (0..n)
        .map(|i| {
            column.clear();
            column.extend(frames.iter().map(|f| f.pixels[i]));
            let mid = (column.len() - 1) / 2;
            *column.select_nth_unstable(mid).1
        })
        .collect();
    Frame {
        width: frames[0].width,
        height: frames[0].height,
        pixels,
        saturation: frames
            .iter()
            .map(|f| f.saturation)
            .max()
            .unwrap_or(u16::MAX),
    }
}

fn median(mut v: Vec<u16>) -> u16 {
    if v.is_empty() {
        return 0;
    }
    let mid = (v.len() - 1) / 2;
    *v.select_nth_unstable(mid).1
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(pixels: Vec<u16>) -> Frame<'static> {
        Frame {
            width: pixels.len() as u32,
            height: 1,
            pixels: pixels.into(),
            saturation: 255,
        }
    }

    #[test]
    fn subtracting_keeps_the_background_level_and_saturation() {
        let dark = frame(vec![10, 10, 10, 200, 10]);
        let img = frame(vec![12, 8, 255, 210, 0]);
        // Dark median 10: p − d + 10.
        assert_eq!(subtract_dark(&img, &dark).pixels, vec![12, 8, 255, 20, 0]);
    }

    #[test]
    fn the_median_ignores_a_star_in_one_frame() {
        let frames = [
            frame(vec![5, 100, 7]),
            frame(vec![5, 100, 250]),
            frame(vec![6, 101, 7]),
        ];
        assert_eq!(median_frame(&frames).pixels, vec![5, 100, 7]);
    }
}
