//! The files astrometry.net's users read after `solve-field`, for a solved frame:
//! - `--new-fits`: the frame with the solution's WCS in its header (solve-field's `.new`;
//!   ASTAP updates the header likewise), which stacking, photometry and viewing tools read;
//! - `--corr`: the matched stars, detection beside catalog star (solve-field's `.corr`);
//! - `--axy`: the detections (solve-field's `.axy`), for every readable frame.
//!
//! Pixels in these files are FITS pixels as astrometry.net writes them: 1-based, (1, 1) the
//! centre of the first stored pixel, so X = gpustar's x + 1 (and the WCS's CRPIX agrees).
//! Column names are astrometry.net's, with gpustar's extra columns after them.

use crate::camera::Camera;
use crate::catalog::{RefCatalog, vector_to_radec};
use crate::error::Result;
use crate::io::fits::copy::{stored_image, with_header};
use crate::io::fits::table::{Column, Values, encode_table};
use crate::io::fits::{card_comment, card_raw, card_str, encode_u16};
use crate::io::frame::Frame;
use crate::io::guard::{AXY_MARK, CORR_MARK, NEW_FITS_MARK};
use crate::solve::Solution;
use crate::solve::detect::Detection;
use crate::solve::refine::Refined;
use std::path::Path;

/// The frame read from `input` as a FITS file with the solution's WCS: a FITS input keeps its
/// header (but its old WCS keywords) and its data as stored; other formats are written as
/// 16-bit FITS of the pixels gpustar read, rows in the file's order.
pub fn new_fits(input: &Path, frame: &Frame, r: &Refined) -> Result<Vec<u8>> {
    let mut wcs: Vec<String> = crate::io::wcs::checked_wcs_header(&r.camera, &r.r)?
        .into_iter()
        .filter(|c| {
            let key = c.get(..8).unwrap_or(c).trim_end();
            !matches!(key, "SIMPLE" | "BITPIX" | "NAXIS" | "EXTEND" | "END")
        })
        .collect();
    wcs.push(card_comment(&format!(
        "{NEW_FITS_MARK}: the WCS above is gpustar's solution."
    )));
    if crate::io::frame::is_fits_file(input) {
        let image = stored_image(input)?;
        return Ok(with_header(&image, &wcs));
    }
    Ok(encode_u16(frame.width, frame.height, &frame.pixels, &wcs))
}

/// Detections sorted as star lists are, brightest first (ties in detection order).
fn by_flux(detections: &[Detection]) -> Vec<usize> {
    let mut order: Vec<usize> = (0..detections.len()).collect();
    order.sort_by(|&a, &b| detections[b].flux.total_cmp(&detections[a].flux));
    order
}

/// The detections as a star list (`.axy`): X, Y (FITS pixels), FLUX, then PEAK, AREA,
/// SIGMA_PX (NaN without a PSF fit) and SATURATED (1 or 0); IMAGEW and IMAGEH in the header, as
/// solve-field needs them to solve a star list.
pub fn axy(width: u32, height: u32, detections: &[Detection]) -> Vec<u8> {
    let order = by_flux(detections);
    let col = |f: &dyn Fn(&Detection) -> f64| -> Values {
        Values::F64(order.iter().map(|&i| f(&detections[i])).collect())
    };
    let int = |f: &dyn Fn(&Detection) -> i32| -> Values {
        Values::I32(order.iter().map(|&i| f(&detections[i])).collect())
    };
    encode_table(
        &[
            Column {
                name: "X",
                unit: "pix",
                values: col(&|d| d.x + 1.0),
            },
            Column {
                name: "Y",
                unit: "pix",
                values: col(&|d| d.y + 1.0),
            },
            Column {
                name: "FLUX",
                unit: "adu",
                values: col(&|d| d.flux),
            },
            Column {
                name: "PEAK",
                unit: "adu",
                values: int(&|d| d.peak.min(i32::MAX as u32) as i32),
            },
            Column {
                name: "AREA",
                unit: "pix",
                values: int(&|d| d.area.min(i32::MAX as u32) as i32),
            },
            Column {
                name: "SIGMA_PX",
                unit: "pix",
                values: col(&|d| d.sigma_px.unwrap_or(f64::NAN)),
            },
            Column {
                name: "SATURATED",
                unit: "",
                values: int(&|d| d.saturated as i32),
            },
        ],
        &[
            card_raw("IMAGEW", &width.to_string(), "image width, pixels"),
            card_raw("IMAGEH", &height.to_string(), "image height, pixels"),
            card_comment(&format!(
                "{AXY_MARK}: detections, brightest first; X, Y: FITS pixels (1 = first)."
            )),
        ],
    )
}

/// The matched stars (`.corr`), in the record's order (brightest first): field_x, field_y
/// (the detection, FITS pixels), field_ra, field_dec (its direction under the solution),
/// index_x, index_y (the catalog star projected), index_ra, index_dec (the catalog's place at
/// the epoch), index_id (gpustar's reference star number), field_id (the detection's row in the
/// `.axy`), FLUX, then MAG, RESIDUAL_ARCSEC and CATALOG_ID.
pub fn corr(sol: &Solution, r: &Refined, refs: &RefCatalog) -> Vec<u8> {
    let rank = {
        let order = by_flux(&sol.detections);
        let mut rank = vec![0; order.len()];
        for (k, &i) in order.iter().enumerate() {
            rank[i] = k as i32;
        }
        rank
    };
    let mut matches = r.matches.clone();
    matches.sort_by(|a, b| {
        let (fa, fb) = (sol.detections[a.det].flux, sol.detections[b.det].flux);
        fb.total_cmp(&fa).then(a.ref_id.cmp(&b.ref_id))
    });
    let cam: &Camera = &r.camera;
    let mut cols: [Vec<f64>; 10] = Default::default();
    let (mut index_id, mut field_id, mut ids) = (Vec::new(), Vec::new(), Vec::new());
    for m in &matches {
        let d = &sol.detections[m.det];
        let field = r.r.transpose() * cam.pixel_to_vector(d.x, d.y);
        let (fra, fdec) = vector_to_radec(&field);
        let v = refs.v(m.ref_id as usize);
        let (ix, iy) = cam
            .vector_to_pixel(&(r.r * v))
            .unwrap_or((f64::NAN, f64::NAN));
        let (ira, idec) = vector_to_radec(&v);
        let row = [
            d.x + 1.0,
            d.y + 1.0,
            fra,
            fdec,
            ix + 1.0,
            iy + 1.0,
            ira,
            idec,
            d.flux,
            refs.star(m.ref_id as usize).mag,
        ];
        for (c, v) in cols.iter_mut().zip(row) {
            c.push(v);
        }
        index_id.push(m.ref_id as i32);
        field_id.push(rank[m.det]);
        ids.push(refs.catalog_id(m.ref_id as usize));
    }
    let residual: Vec<f64> = matches.iter().map(|m| m.residual_arcsec).collect();
    let [fx, fy, fra, fdec, ix, iy, ira, idec, flux, mag] = cols;
    let f = |name, unit, v: Vec<f64>| Column {
        name,
        unit,
        values: Values::F64(v),
    };
    let plain = |name, values| Column {
        name,
        unit: "",
        values,
    };
    encode_table(
        &[
            f("field_x", "pix", fx),
            f("field_y", "pix", fy),
            f("field_ra", "deg", fra),
            f("field_dec", "deg", fdec),
            f("index_x", "pix", ix),
            f("index_y", "pix", iy),
            f("index_ra", "deg", ira),
            f("index_dec", "deg", idec),
            plain("index_id", Values::I32(index_id)),
            plain("field_id", Values::I32(field_id)),
            f("FLUX", "adu", flux),
            f("MAG", "mag", mag),
            f("RESIDUAL_ARCSEC", "arcsec", residual),
            plain("CATALOG_ID", Values::Text(ids)),
        ],
        &[
            card_str("RADESYS", "ICRS", "catalog positions"),
            card_real_epoch(refs.selection.epoch),
            card_comment(&format!(
                "{CORR_MARK}: matched stars; x, y: FITS pixels (1 = first)."
            )),
        ],
    )
}

fn card_real_epoch(epoch: f64) -> String {
    // Not EPOCH, which old FITS used for the equinox.
    crate::io::fits::card_real("CATEPOCH", epoch, "Julian year of the catalog positions")
}
