//! Files written per frame beside the records: a FITS WCS header for each solved frame
//! (`--wcs-dir`), an annotated PNG for each decoded frame (`--annotate-dir`), and what
//! astrometry.net's users read (`astrometry`: `--new-fits`, `--corr`, `--axy`), at the input's
//! relative path with the extension replaced (`a/b.png` → `DIR/a/b.wcs`, `DIR/a/b.png`,
//! `DIR/a/b.fits`, `DIR/a/b.corr`, `DIR/a/b.axy`).

pub mod annotate;
pub mod astrometry;

use self::annotate::{Annotation, Mark};
use crate::error::{Context, Result};
use crate::io::frame::{Frame, is_image_path};
use crate::io::guard::{Claims, Kind, check_existing, check_takes_files};
use crate::io::inputs::Input;
use crate::solve::attitude::pointing;
use crate::solve::refine::stars_in_view;
use crate::solve::{Outcome, Solution};
use crate::streaks::fit::StreakFit;
use std::collections::{HashMap, HashSet};
use std::path::{Component, Path, PathBuf};

/// Where per-frame products go; None = not written.
#[derive(Clone, Debug, Default)]
pub struct Products {
    pub wcs_dir: Option<PathBuf>,
    pub annotate_dir: Option<PathBuf>,
    pub new_fits_dir: Option<PathBuf>,
    pub corr_dir: Option<PathBuf>,
    pub axy_dir: Option<PathBuf>,
    /// Replace files there that gpustar did not write (`--overwrite`).
    pub overwrite: bool,
    /// Inputs whose products keep the input's extension (`x.fits` → `x.fits.wcs`): another
    /// image beside them has the same stem, and the two would write one file. Found by
    /// [`Products::check`].
    pub keep_extension: HashSet<String>,
}

impl Products {
    /// Before a run: make the directories, name every input's products, and claim each one
    /// (none on an input, on another output, or on a frame the next run would read), refusing
    /// files there that gpustar did not write unless `overwrite`.
    pub fn check(&mut self, inputs: &[Input], claims: &mut Claims) -> Result<()> {
        let wanted: Vec<(PathBuf, &str, &str, Kind)> = [
            (&self.wcs_dir, "--wcs-dir", "wcs", Kind::Wcs),
            (
                &self.annotate_dir,
                "--annotate-dir",
                "png",
                Kind::Annotation,
            ),
            (&self.new_fits_dir, "--new-fits", "fits", Kind::NewFits),
            (&self.corr_dir, "--corr", "corr", Kind::Corr),
            (&self.axy_dir, "--axy", "axy", Kind::Axy),
        ]
        .into_iter()
        .filter_map(|(d, o, e, k)| d.clone().map(|d| (d, o, e, k)))
        .collect();
        if wanted.is_empty() {
            return Ok(());
        }
        self.keep_extension = shared_stems(inputs);
        let (mut first, mut refused) = (None, 0);
        for i in inputs {
            for (dir, option, ext, kind) in &wanted {
                let path = self.path(dir, &i.name, ext);
                let checked = claims
                    .output(&path, option)
                    .and_then(|_| check_existing(&path, *kind, self.overwrite));
                if let Err(e) = checked {
                    refused += 1;
                    first.get_or_insert(e);
                }
            }
        }
        match first {
            None => {}
            Some(e) if refused == 1 => return Err(e),
            Some(e) => {
                return Err(e).with_context(|| {
                    format!("{refused} of the products this run would write are refused; the first")
                });
            }
        }
        // Made only now, when nothing is refused: a refused run leaves no folder behind.
        for (dir, option, ..) in &wanted {
            std::fs::create_dir_all(dir)
                .and_then(|_| std::fs::read_dir(dir).map(drop))
                .with_context(|| format!("{option} {}", dir.display()))?;
            check_takes_files(dir).with_context(|| format!("{option} {}", dir.display()))?;
        }
        Ok(())
    }

    /// Where the product `ext` of the input named `name` goes in `dir`.
    pub fn path(&self, dir: &Path, name: &str, ext: &str) -> PathBuf {
        if self.keep_extension.contains(name) {
            let mut p = product_path(dir, name, "");
            let mut file = p.file_name().unwrap_or_default().to_os_string();
            let given = Path::new(name).extension().unwrap_or_default();
            file.push(".");
            file.push(given);
            file.push(".");
            file.push(ext);
            p.set_file_name(file);
            p
        } else {
            product_path(dir, name, ext)
        }
    }

    /// The products that need only the solution, not the pixels: `--wcs-dir` and `--corr`
    /// (what star lists get, `--xyls`).
    pub fn write_solution(&self, name: &str, sol: &Solution) -> Result<()> {
        if let (Some(dir), Outcome::Solved(r, _)) = (&self.wcs_dir, &sol.outcome) {
            crate::io::wcs::write_wcs_file(&self.path(dir, name, "wcs"), &r.camera, &r.r)?;
        }
        if let (Some(dir), Outcome::Solved(r, refs)) = (&self.corr_dir, &sol.outcome) {
            write_product(
                &self.path(dir, name, "corr"),
                &astrometry::corr(sol, r, refs),
            )?;
        }
        Ok(())
    }

    /// Write the products asked for of one frame (named `name`, read from `input`).
    pub fn write(
        &self,
        name: &str,
        input: &Path,
        frame: &Frame,
        sol: &Solution,
        streaks: &[StreakFit],
    ) -> Result<()> {
        self.write_solution(name, sol)?;
        if let (Some(dir), Outcome::Solved(r, _)) = (&self.new_fits_dir, &sol.outcome) {
            let bytes = astrometry::new_fits(input, frame, r)?;
            write_product(&self.path(dir, name, "fits"), &bytes)?;
        }
        if let Some(dir) = &self.axy_dir {
            let bytes = astrometry::axy(frame.width, frame.height, &sol.detections);
            write_product(&self.path(dir, name, "axy"), &bytes)?;
        }
        if let Some(dir) = &self.annotate_dir {
            let out = self.path(dir, name, "png");
            annotate::write_png(&out, &annotation(frame, sol, streaks))?;
        }
        Ok(())
    }
}

/// Write a product file whole (its folder made first).
fn write_product(path: &Path, bytes: &[u8]) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create directory {}", dir.display()))?;
    }
    crate::io::guard::write_atomically(path, bytes)
}

/// The names of inputs that share their directory and stem with another image file there
/// (`x.fits` beside `x.png`), whether or not that file is an input of this run (a shard, a
/// resumed run): each directory is read once.
fn shared_stems(inputs: &[Input]) -> HashSet<String> {
    let mut stems: HashMap<PathBuf, HashMap<std::ffi::OsString, usize>> = HashMap::new();
    let mut shared = HashSet::new();
    for i in inputs {
        let (Some(dir), Some(stem)) = (i.path.parent(), i.path.file_stem()) else {
            continue;
        };
        let counts = stems.entry(dir.to_path_buf()).or_insert_with(|| {
            let mut counts = HashMap::new();
            let listed = std::fs::read_dir(if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            });
            for e in listed.into_iter().flatten().flatten() {
                let p = e.path();
                if is_image_path(&p)
                    && let Some(s) = p.file_stem()
                {
                    *counts.entry(s.to_os_string()).or_insert(0) += 1;
                }
            }
            counts
        });
        if counts.get(stem).is_some_and(|&n| n > 1) {
            shared.insert(i.name.clone());
        }
    }
    shared
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
            reason.as_str().to_uppercase().replace('_', " "),
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
