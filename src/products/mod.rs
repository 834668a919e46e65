//! Files written per frame beside the records: a FITS WCS header for each solved frame
//! (`--wcs-dir`) and an annotated PNG for each decoded frame (`--annotate-dir`), at the
//! input's relative path with the extension replaced (`a/b.png` → `DIR/a/b.wcs`, `DIR/a/b.png`).

pub mod annotate;

use self::annotate::{Annotation, Mark};
use crate::error::{Result, fail};
use crate::io::frame::Frame;
use crate::solve::attitude::pointing;
use crate::solve::refine::stars_in_view;
use crate::solve::{Outcome, Solution};
use crate::streaks::fit::StreakFit;
use std::path::{Component, Path, PathBuf};

/// Where per-frame products go; None = not written.
#[derive(Clone, Debug, Default)]
pub struct Products {
    pub wcs_dir: Option<PathBuf>,
    pub annotate_dir: Option<PathBuf>,
}

impl Products {
    /// Write the products asked for of one frame (read from `input`, named `name`).
    pub fn write(
        &self,
        input: &Path,
        name: &str,
        frame: &Frame,
        sol: &Solution,
        streaks: &[StreakFit],
    ) -> Result<()> {
        if let (Some(dir), Outcome::Solved(r, _)) = (&self.wcs_dir, &sol.outcome) {
            crate::io::wcs::write_wcs_file(&product_path(dir, name, "wcs"), &r.camera, &r.r)?;
        }
        if let Some(dir) = &self.annotate_dir {
            let out = product_path(dir, name, "png");
            if same_file(&out, input) {
                fail!(
                    Output,
                    "not writing the annotated image over its input {}: choose another \
                     --annotate-dir",
                    input.display()
                );
            }
            annotate::write_png(&out, &annotation(frame, sol, streaks))?;
        }
        Ok(())
    }
}

/// `dir/name` with the extension replaced; only the normal components of `name` count, so a
/// name given as an absolute path (or with `..`) still lands inside `dir`.
pub fn product_path(dir: &Path, name: &str, ext: &str) -> PathBuf {
    let mut p = dir.to_path_buf();
    for c in Path::new(name).components() {
        if let Component::Normal(part) = c {
            p.push(part);
        }
    }
    p.set_extension(ext);
    p
}

fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}

/// What the annotated image shows: identified detections with their catalog ids, the other
/// detections, and the catalog stars the solution puts in the frame that nothing matched.
fn annotation<'a>(frame: &'a Frame, sol: &Solution, streaks: &[StreakFit]) -> Annotation<'a> {
    let mark = |x: f64, y: f64, area: u32| Mark {
        x,
        y,
        radius_px: (area as f64 / std::f64::consts::PI).sqrt(),
    };
    let mut identified = Vec::new();
    let mut predicted = Vec::new();
    let mut matched = vec![false; sol.detections.len()];
    let caption = match &sol.outcome {
        Outcome::Solved(r, refs) => {
            let mut star_matched = vec![false; refs.len()];
            for m in &r.matches {
                let d = &sol.detections[m.det];
                matched[m.det] = true;
                star_matched[m.ref_id as usize] = true;
                identified.push((mark(d.x, d.y, d.area), refs.catalog_id(m.ref_id as usize)));
            }
            for (id, x, y) in stars_in_view(&r.r, refs, &r.camera) {
                if !star_matched[id as usize] {
                    predicted.push(Mark {
                        x,
                        y,
                        radius_px: 2.0,
                    });
                }
            }
            let p = pointing(&r.r, &r.camera);
            format!(
                "SOLVED RA {:.4} DEC {:+.4} ROLL {:.2}  FOV {:.3}  {} OF {} STARS IDENTIFIED",
                p.ra_deg,
                p.dec_deg,
                p.roll_deg,
                r.camera.fov_x_deg(),
                r.matches.len(),
                sol.detections.len()
            )
        }
        Outcome::Unsolved(reason) => format!(
            "UNSOLVED ({})  {} STARS DETECTED",
            reason.to_uppercase().replace('_', " "),
            sol.detections.len()
        ),
    };
    let unmatched = sol
        .detections
        .iter()
        .zip(&matched)
        .filter(|(_, m)| !**m)
        .map(|(d, _)| mark(d.x, d.y, d.area))
        .collect();
    Annotation {
        width: frame.width,
        height: frame.height,
        pixels: &frame.pixels,
        saturation: frame.saturation,
        identified,
        unmatched,
        predicted,
        streaks: streaks.iter().map(|f| (f.ends, f.edge)).collect(),
        caption,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn product_paths_stay_inside_the_directory() {
        let d = Path::new("/out");
        assert_eq!(product_path(d, "a/b.png", "wcs"), Path::new("/out/a/b.wcs"));
        assert_eq!(
            product_path(d, "/abs/c.tiff", "png"),
            Path::new("/out/abs/c.png")
        );
        assert_eq!(
            product_path(d, "../x/y.jpg", "wcs"),
            Path::new("/out/x/y.wcs")
        );
        assert_eq!(product_path(d, "noext", "wcs"), Path::new("/out/noext.wcs"));
    }
}
