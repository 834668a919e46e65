//! Triangle matching (the fallback after the vote): with false stars brighter than the real
//! ones, the confirmed triangles include the true one; every triangle returned agrees with its
//! image stars on all three distances; a mirror image (wrong handedness) finds no true triangle.

use crate::common;

use gpustar::camera::angle;
use gpustar::simulate::random_rotation;
use gpustar::solve::identify::pair_ranges;
use gpustar::solve::refine::stars_in_view;
use gpustar::solve::triangle::triangles;
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};

#[test]
fn confirmed_triangles_find_the_true_stars_among_false_ones() {
    let solver = common::solver(10.0, (1024, 1024));
    let cam = &solver.camera;
    let band = &solver.bands[0];
    let s = solver.settings.identify;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
    let mut found = 0;
    let mut frames = 0;
    while frames < 10 {
        let r = random_rotation(&mut rng);
        let view = stars_in_view(&r, &band.refs, cam);
        if view.len() < 6 {
            continue;
        }
        frames += 1;
        // Three false stars first (the brightest), then the five brightest real ones.
        let mut vectors: Vec<Vector3<f64>> = (0..3)
            .map(|_| {
                let (x, y) = (rng.random_range(0.0..1023.0), rng.random_range(0.0..1023.0));
                cam.pixel_to_vector(x, y)
            })
            .collect();
        let mut ids = vec![u32::MAX; 3];
        for &(id, x, y) in view.iter().take(5) {
            // Centroid errors of 0.2 px.
            let (dx, dy) = (rng.random_range(-0.2..0.2), rng.random_range(-0.2..0.2));
            vectors.push(cam.pixel_to_vector(x + dx, y + dy));
            ids.push(id);
        }
        let ranges = pair_ranges(&vectors, cam, &s);
        let (tris, matched) = triangles(band.table(), &ranges, &vectors, &band.refs);
        assert!(matched >= tris.len() as u64);
        for t in &tris {
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                let d_img = angle(&vectors[t.stars[a]], &vectors[t.stars[b]]);
                let d_cat = angle(
                    &band.refs.stars[t.refs[a] as usize].v,
                    &band.refs.stars[t.refs[b] as usize].v,
                );
                let e = s.tolerance(cam, d_img) + 1e-9;
                assert!((d_img - d_cat).abs() <= e * 1.001, "side {a}{b} off: {t:?}");
            }
        }
        let truth = |t: &gpustar::solve::triangle::Triangle| {
            t.stars.iter().zip(&t.refs).all(|(&i, &id)| ids[i] == id)
        };
        if tris.iter().any(truth) {
            found += 1;
        }
        // The mirror image: every true triangle has the wrong handedness.
        let mirrored: Vec<Vector3<f64>> = vectors
            .iter()
            .map(|v| Vector3::new(-v.x, v.y, v.z))
            .collect();
        let (tris_m, _) = triangles(band.table(), &ranges, &mirrored, &band.refs);
        assert!(!tris_m.iter().any(truth), "a mirrored triangle matched");
    }
    assert_eq!(
        found, 10,
        "the true triangle was found in {found} of 10 frames"
    );
}
