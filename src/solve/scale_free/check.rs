//! The scale-free pass's geometric check of one catalog quad against one image quad: the
//! focal length that matches their chords, the order of the catalog stars, every chord within
//! twice the pair tolerance, and the attitude (the candidates refinement then judges).

use super::super::Solver;
use super::super::bands::{SCALE_STEP, scaled};
use super::super::detect::Detection;
use super::Hypothesis;
use crate::camera::angle;
use crate::catalog::patterns;
use crate::solve::Parity;
use nalgebra::Vector3;

/// The 24 orders of four items.
pub(super) fn permutations() -> Vec<[usize; 4]> {
    let mut out = Vec::with_capacity(24);
    for a in 0..4 {
        for b in 0..4 {
            for c in 0..4 {
                for d in 0..4 {
                    let p = [a, b, c, d];
                    if (0..4).all(|i| p.contains(&i)) {
                        out.push(p);
                    }
                }
            }
        }
    }
    out
}

const PAIRS: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

impl Solver {
    /// A catalog quad against an image quad: the order of its stars whose chords best match
    /// the image's up to scale, the focal length that matches them (within `lo..hi`), every
    /// chord then within twice the pair tolerance, and the attitude of the four stars
    /// (Wahba) placing each within that tolerance (which refuses a mirror image, unless the
    /// parity is left open: then the parity the four stars fit).
    #[allow(clippy::too_many_arguments)]
    pub(super) fn check_quad(
        &self,
        detections: &[Detection],
        stars: [usize; 4],
        img1: &[f64; 6],
        ids: [u32; 4],
        refs: &crate::catalog::RefCatalog,
        (lo, hi): (f64, f64),
        perms: &[[usize; 4]],
    ) -> Option<Hypothesis> {
        // A pattern index's quads are checked here, as they are used, not when it is mapped
        // (patterns::read_index): a quad naming a star the selection lacks is no candidate.
        if ids.iter().any(|&id| id as usize >= refs.len()) {
            return None;
        }
        let cat = ids.map(|id| refs.v(id as usize));
        let at = |s: f64| {
            let c = scaled(&self.camera, s);
            stars.map(|i| c.pixel_to_vector(detections[i].x, detections[i].y))
        };
        // The catalog chords, each pair once; every order of the stars reads them.
        let mut d = [[0.0; 4]; 4];
        for &(i, j) in &PAIRS {
            d[i][j] = (cat[i] - cat[j]).norm();
            d[j][i] = d[i][j];
        }
        let sum_cat: f64 = PAIRS.iter().map(|&(i, j)| d[i][j]).sum();
        // The image's chords at the camera's own focal length, and the scale that brings
        // their sum to the catalog's.
        let k = sum_cat / img1.iter().sum::<f64>();
        // Image chords shrink about as the focal length grows: from 1 / k, a few fixed-point
        // steps. The sums do not depend on the order of the stars: most catalog quads of a
        // key are of another size, and are refused here before their order is sought.
        let mut scale = 1.0 / k;
        for _ in 0..3 {
            let sum_img: f64 = patterns::chords(&at(scale)).iter().sum();
            scale *= sum_img / sum_cat;
        }
        let margin = 1.0 + SCALE_STEP;
        if !(scale >= lo / margin && scale <= hi * margin) {
            return None;
        }
        // The order of the catalog stars: the closest chords up to that scale factor (the
        // first of the least largest error; an order is left as soon as its error reaches the
        // best's, since it cannot then be chosen).
        let mut best: Option<(f64, [usize; 4])> = None;
        'orders: for p in perms {
            let mut err = 0.0f64;
            for (&(i, j), x) in PAIRS.iter().zip(img1) {
                let c = d[p[i]][p[j]];
                err = err.max((x * k - c).abs() / c.max(1e-12));
                if best.is_some_and(|(b, _)| err >= b) {
                    continue 'orders;
                }
            }
            best = Some((err, *p));
        }
        let (_, p) = best?;
        let cat = p.map(|i| cat[i]);
        let refs_in_order = p.map(|i| ids[i]);
        let cat_chords = patterns::chords(&cat);
        // A known scale is the camera's: the chords are checked at it, within the vote's
        // tolerance, which holds the scale's own.
        let scale = if self.settings.scale_range.is_some() {
            scale
        } else {
            1.0
        };
        let camera = scaled(&self.camera, scale);
        let img = at(scale);
        let s = &self.settings.identify;
        let img_chords = patterns::chords(&img);
        for e in 0..6 {
            let d = crate::catalog::table::angle_of_chord(cat_chords[e]);
            let tol = 2.0 * s.tolerance(&camera, d);
            let di = crate::catalog::table::angle_of_chord(img_chords[e]);
            if (di - d).abs() > tol {
                return None;
            }
        }
        let (r, mirrored) = crate::solve::attitude::wahba_parity(
            &img,
            &cat,
            self.settings.parity == Parity::Either,
        )?;
        let img = img.map(|v| {
            if mirrored {
                Vector3::new(v.x, -v.y, v.z)
            } else {
                v
            }
        });
        let tol = 2.0 * s.pair_tol_px * camera.ifov_rad();
        if (0..4).any(|i| angle(&(r * cat[i]), &img[i]) > tol) {
            return None;
        }
        Some(Hypothesis {
            stars,
            refs: refs_in_order,
            scale,
            r,
            mirrored,
        })
    }
}
