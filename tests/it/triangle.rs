//! Triangle matching (the fallback after the vote): with false stars brighter than the real
//! ones, the confirmed triangles include the true one; every triangle returned agrees with its
//! image stars on all three distances; a mirror image (wrong handedness) finds no true triangle;
//! the hypotheses and their count are those of the method's plain definition, in its order.

use crate::common;

use gpustar::camera::angle;
use gpustar::simulate::random_rotation;
use gpustar::solve::identify::pair_ranges;
use gpustar::solve::refine::stars_in_view;
use gpustar::solve::triangle::{MAX_HYPOTHESES, Triangle, triangle_order, triangles};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use std::collections::{BTreeMap, HashSet};

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
        let (tris, matched) = triangles(band.table(), &ranges, &vectors, band.directions());
        assert!(matched >= tris.len() as u64);
        for t in &tris {
            for (a, b) in [(0, 1), (0, 2), (1, 2)] {
                let d_img = angle(&vectors[t.stars[a]], &vectors[t.stars[b]]);
                let d_cat = angle(
                    &band.refs.v(t.refs[a] as usize),
                    &band.refs.v(t.refs[b] as usize),
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
        let (tris_m, _) = triangles(band.table(), &ranges, &mirrored, band.directions());
        assert!(!tris_m.iter().any(truth), "a mirrored triangle matched");
    }
    assert_eq!(
        found, 10,
        "the true triangle was found in {found} of 10 frames"
    );
}

/// The method as written down (every catalog triangle whose three sides fall in the three
/// image sides' ranges, with the image's handedness, in the order of the image triangles and
/// then of the catalog stars; confirmed by a fourth star on all three of its sides), with
/// ordered maps and hash sets instead of `triangles`'s adjacency lists.
fn triangles_by_definition(
    table: &gpustar::catalog::table::PairTable,
    ranges: &[gpustar::cpu::vote::PairRange],
    vectors: &[Vector3<f64>],
    refs: &gpustar::catalog::RefCatalog,
) -> (Vec<Triangle>, u64) {
    let n = vectors.len();
    let mut sides: BTreeMap<(usize, usize), BTreeMap<u32, Vec<u32>>> = BTreeMap::new();
    let mut has: HashSet<(usize, usize, u32, u32)> = HashSet::new();
    for r in ranges
        .iter()
        .filter(|r| (r.i as usize) < n && (r.j as usize) < n)
    {
        let (i, j) = (r.i.min(r.j) as usize, r.i.max(r.j) as usize);
        let side = sides.entry((i, j)).or_default();
        for row in table.range(r.lo, r.hi) {
            let (a, b) = table.pair(row);
            side.entry(a).or_default().push(b);
            side.entry(b).or_default().push(a);
            has.insert((i, j, a, b));
            has.insert((i, j, b, a));
        }
    }
    for side in sides.values_mut() {
        side.values_mut().for_each(|l| l.sort_unstable());
    }
    let on = |a: usize, b: usize, p: u32, q: u32| has.contains(&(a.min(b), a.max(b), p, q));
    let none = Vec::new();
    let of = |a: usize, b: usize, p: u32| {
        sides
            .get(&(a.min(b), a.max(b)))
            .and_then(|s| s.get(&p))
            .unwrap_or(&none)
    };
    let v = |id: u32| refs.v(id as usize);
    let (mut out, mut matched) = (Vec::new(), 0u64);
    for [i, j, k] in triangle_order(n) {
        let handed = vectors[i].cross(&vectors[j]).dot(&vectors[k]) > 0.0;
        let Some(ij) = sides.get(&(i, j)) else {
            continue;
        };
        for (&p, qs) in ij {
            for &q in qs {
                for &r in of(i, k, p) {
                    if r == q || !on(j, k, q, r) {
                        continue;
                    }
                    if (v(p).cross(&v(q)).dot(&v(r)) > 0.0) != handed {
                        continue;
                    }
                    matched += 1;
                    let confirmed = (0..n).filter(|l| ![i, j, k].contains(l)).any(|l| {
                        of(i, l, p)
                            .iter()
                            .any(|&s| s != q && s != r && on(j, l, q, s) && on(k, l, r, s))
                    });
                    if confirmed {
                        out.push(Triangle {
                            stars: [i, j, k],
                            refs: [p, q, r],
                        });
                        if out.len() == MAX_HYPOTHESES {
                            return (out, matched);
                        }
                    }
                }
            }
        }
    }
    (out, matched)
}

/// With the wide retry's tolerances (4 px sides) every side holds thousands of catalog pairs,
/// with the first pass's (0.4 px) a few hundred (`Side` sorts the two differently): either
/// way the hypotheses, their order and the count of matched triangles are the plain
/// definition's, true stars or false.
#[test]
fn triangles_are_those_of_the_definition_in_its_order() {
    let solver = common::solver(10.0, (1024, 1024));
    let cam = &solver.camera;
    let band = &solver.bands[0];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    for (pair_tol_px, least) in [(4.0, 20), (0.4, 4)] {
        let mut s = solver.settings.identify;
        s.pair_tol_px = pair_tol_px;
        let (mut frames, mut hypotheses) = (0, 0);
        while frames < 4 {
            let r = random_rotation(&mut rng);
            let view = stars_in_view(&r, &band.refs, cam);
            if view.len() < 5 {
                continue;
            }
            frames += 1;
            // Two false stars among the five brightest true ones, centroids off by up to a
            // quarter of the tolerance.
            let e = pair_tol_px / 4.0;
            let mut vectors: Vec<Vector3<f64>> = view
                .iter()
                .take(5)
                .map(|&(_, x, y)| {
                    let (dx, dy) = (rng.random_range(-e..e), rng.random_range(-e..e));
                    cam.pixel_to_vector(x + dx, y + dy)
                })
                .collect();
            for at in [1, 4] {
                let (x, y) = (rng.random_range(0.0..1023.0), rng.random_range(0.0..1023.0));
                vectors.insert(at, cam.pixel_to_vector(x, y));
            }
            let ranges = pair_ranges(&vectors, cam, &s);
            let fast = triangles(band.table(), &ranges, &vectors, band.directions());
            let plain = triangles_by_definition(band.table(), &ranges, &vectors, &band.refs);
            assert_eq!(fast, plain, "{pair_tol_px} px, frame {frames}");
            // Compiled for AVX2 (where the CPU has it: `tests/it/simd.rs`) and as built alike.
            let built = gpustar::simd::baseline(|| {
                triangles(band.table(), &ranges, &vectors, band.directions())
            });
            assert_eq!(fast, built, "{pair_tol_px} px, frame {frames}, baseline");
            hypotheses += fast.0.len();
        }
        // Not a vacuous comparison: the true triangles at least are confirmed.
        assert!(
            hypotheses >= least,
            "{pair_tol_px} px: {hypotheses} hypotheses in 4 frames"
        );
    }
}

/// The passes vote in order, the shallow selection's first (known scale, no magnitude limit),
/// and the first vote that solves a frame gives its solution; the triangle fallback runs once
/// the votes of every pass have failed, so a frame some pass's vote solves is solved by that
/// vote (two fixed stars), not by an earlier pass's triangles, which cost several times as
/// much. The frames drawn include ones whose earlier pass's triangles would have solved them
/// before a later pass's vote did (the order this holds to), and frames no vote solves that
/// triangles still solve.
#[test]
fn passes_vote_in_order_and_triangles_come_last() {
    use gpustar::solve::detect::Detection;
    use gpustar::solve::{Outcome, identify};
    // Without the scale-free pass, identification is the walk alone.
    let settings = gpustar::solve::Settings {
        table_cache: false,
        scale_free: false,
        ..gpustar::solve::Settings::default()
    };
    let camera = gpustar::camera::Camera::from_fov(1024, 1024, 10.0).unwrap();
    let solver =
        gpustar::solve::Solver::new(&gpustar::catalog::Catalog::builtin(), camera, settings)
            .unwrap();
    assert_eq!(solver.passes[0].kind, gpustar::solve::PassKind::Shallow);
    let cam = &solver.camera;
    let refs = &solver.bands[0].refs;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let (mut reordered, mut by_triangles) = (0, 0);
    for _ in 0..600 {
        let r = random_rotation(&mut rng);
        let mut view = stars_in_view(&r, refs, cam);
        view.sort_by(|a, b| {
            let mag = |id: u32| refs.star(id as usize).mag;
            mag(a.0).total_cmp(&mag(b.0))
        });
        // 0.3 px centroid errors; up to two of the brightest stars missed (saturated).
        // Half the frames sparse (five to eight stars, up to two false), half crowded with
        // false stars (ten to twenty stars and as many as ten false ones).
        let crowded = rng.random_bool(0.5);
        let shown = if crowded {
            rng.random_range(10..=20)
        } else {
            rng.random_range(5..=8)
        };
        let skipped = rng.random_range(0..=2);
        let mut at: Vec<(f64, f64)> = view
            .iter()
            .skip(skipped)
            .take(shown)
            .map(|&(_, x, y)| {
                (
                    x + rng.random_range(-0.3..0.3),
                    y + rng.random_range(-0.3..0.3),
                )
            })
            .collect();
        for _ in 0..rng.random_range(0..=if crowded { 10 } else { 2 }) {
            let false_star = (rng.random_range(0.0..1023.0), rng.random_range(0.0..1023.0));
            at.insert(rng.random_range(0..=at.len()), false_star);
        }
        let dets: Vec<Detection> = at
            .iter()
            .enumerate()
            .map(|(k, &(x, y))| Detection {
                x,
                y,
                flux: 1e4 / (k + 1) as f64,
                area: 5,
                peak: 1000,
                saturated: false,
                sigma_px: None,
            })
            .collect();
        let solved = |o: &Outcome| matches!(o, Outcome::Solved(..));
        let vote_attitude = |o: &Outcome| match o {
            Outcome::Solved(refined, _) => Some(refined.r),
            Outcome::Unsolved(_) => None,
        };
        // Each pass's vote alone, and the triangle fallbacks of the passes before the first
        // vote that solves (those the old order ran first).
        let mut votes = Vec::new();
        let mut first_vote = None;
        let mut triangles_before = false;
        for h in 0..solver.passes.len() {
            let Some(p) = solver.prepare(&dets, h) else {
                continue;
            };
            let band = &solver.bands[p.band];
            let voted = identify::vote_cpu(band.table(), &p.ranges, p.n_vote, band.refs.len(), p.k);
            let vote = solver.finish(&dets, &p, &voted, None);
            if !solved(&vote) && !votes.iter().any(|&v| v) {
                triangles_before |= solver.fallback(&dets, &p, None).is_some_and(|o| solved(&o));
            }
            if solved(&vote) && first_vote.is_none() {
                first_vote = Some(vote_attitude(&vote));
            }
            votes.push(solved(&vote));
        }
        let walk = solver.identify(dets, None).outcome;
        let fixed = match &walk {
            Outcome::Solved(refined, _) => Some(refined.fixed),
            Outcome::Unsolved(_) => None,
        };
        if votes.iter().any(|&v| v) {
            assert_eq!(fixed, Some(2), "a vote solves this frame: {votes:?}");
            assert_eq!(vote_attitude(&walk), first_vote.unwrap(), "{votes:?}");
            if triangles_before {
                reordered += 1;
            }
        } else if fixed.is_some() {
            assert_eq!(fixed, Some(3));
            by_triangles += 1;
        }
    }
    eprintln!("{reordered} frames told the order apart, {by_triangles} needed the triangles");
    assert!(reordered > 0, "no frame tells the order apart");
    assert!(by_triangles > 0, "no frame needed the triangles");
}
