//! `--xyls`: inputs that are star lists (solve-field's `.xyls`, gpustar's `--axy`), not
//! images: their stars identified as a frame's detections would be, on the CPU.

use super::{BACKEND_CPU, Solvers};
use crate::error::error;
use crate::io::fits::star_list::read_star_list;
use crate::record::Record;
use crate::solve::detect::Detection;
use std::path::Path;
use std::time::Instant;

/// What star-list runs need beyond [`Solvers`]' settings.
#[derive(Clone, Copy, Debug, Default)]
pub struct StarLists {
    /// The image size for lists whose header states none (`--image-size`).
    pub size: Option<(u32, u32)>,
}

impl Solvers {
    /// The record of the star list at `path`: its stars identified in a frame of the size its
    /// header states (IMAGEW, IMAGEH) or `--image-size` gives; with `--wcs-dir` and `--corr`
    /// their files too.
    pub fn solve_star_list(&self, path: &Path, name: &str, lists: StarLists) -> Record {
        let t0 = Instant::now();
        let list = match read_star_list(path) {
            Ok(l) => l,
            Err(e) => return self.error_record(name, &e, BACKEND_CPU),
        };
        let Some((width, height)) = list.size.or(lists.size) else {
            let e = error!(
                Input,
                "{}: the star list states no image size (IMAGEW, IMAGEH): give --image-size \
                 WIDTHxHEIGHT",
                path.display()
            );
            return self.error_record(name, &e, BACKEND_CPU);
        };
        let n = list.x.len();
        let stars: Vec<Detection> = (0..n)
            .map(|i| Detection {
                x: list.x[i],
                y: list.y[i],
                // Without fluxes the list's order is the brightness order, as solve-field
                // takes it.
                flux: list.flux.as_ref().map_or((n - i) as f64, |f| f[i]),
                area: 1,
                peak: 0,
                saturated: false,
                sigma_px: None,
            })
            .collect();
        let read_ms = t0.elapsed().as_secs_f64() * 1e3;
        let (mut r, sol) = self.identify_detections(name, (width, height), stars, None, read_ms);
        let Some(sol) = sol else { return r };
        if let Err(e) = self.products.write_solution(name, &sol) {
            tracing::warn!("{name}: {e:#}");
            r.warnings.push(format!("{e:#}"));
        }
        r
    }
}
