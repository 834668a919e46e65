//! Stages `vote` and `select`, and verification, on a tiny hand-made catalog.

use crate::common;

use gpustar::camera::Camera;
use gpustar::catalog::table::PairTable;
use gpustar::catalog::{Catalog, DoubleStars, RefCatalog, Selection, vector_to_radec};
use gpustar::cpu::select::unpack_candidate;
use gpustar::gpu::vote::VoteJob;
use gpustar::solve::identify::{IdentifySettings, pair_ranges, verify, vote_cpu};
use nalgebra::{Rotation3, Vector3};

/// Ten stars: six in a 10° field around (RA 30°, Dec 20°) at distinct separations, four far
/// away; magnitudes make the field stars ids 0..5 (brightest first).
fn tiny() -> (Catalog, Vec<(f64, f64)>) {
    let field = [
        (30.0, 20.0),
        (32.1, 21.3),
        (27.4, 18.9),
        (29.2, 23.6),
        (33.5, 17.2),
        (26.8, 22.7),
    ];
    let far = [(120.0, -40.0), (200.0, 60.0), (300.0, 5.0), (31.0, -60.0)];
    let mut csv = String::from("hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag\n");
    for (k, (ra, dec)) in field.iter().chain(far.iter()).enumerate() {
        let (ra, dec): (f64, f64) = (*ra, *dec);
        csv += &format!(
            "{},{},{},0,0,{}\n",
            100 + k,
            ra.to_radians(),
            dec.to_radians(),
            1.0 + k as f64 * 0.1
        );
    }
    (Catalog::parse(&csv, "tiny").unwrap(), field.to_vec())
}

/// The tiny catalog selected, a 12° camera and its pair table.
fn tiny_setup() -> (Vec<(f64, f64)>, RefCatalog, Camera, PairTable) {
    let (cat, field) = tiny();
    let refs = RefCatalog::select(
        &cat,
        Selection {
            epoch: 1991.25,
            mag_limit: 9.0,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        },
    )
    .unwrap();
    let camera = Camera::from_fov(1024, 1024, 12.0).unwrap();
    let table = PairTable::build(&refs, camera.diagonal_rad());
    (field, refs, camera, table)
}

#[test]
fn every_field_star_is_voted_to_its_catalog_star() {
    let (field, refs, camera, table) = tiny_setup();
    // Look at the field with some roll; the image stars are the field stars in another order.
    let centre = gpustar::catalog::radec_to_vector(30.0, 20.0);
    let r = Rotation3::face_towards(&centre, &Vector3::z())
        .inverse()
        .into_inner();
    let r = Rotation3::from_axis_angle(&Vector3::z_axis(), 0.7).into_inner() * r;
    let order = [3usize, 0, 5, 1, 4, 2];
    let vectors: Vec<Vector3<f64>> = order
        .iter()
        .map(|&k| r * gpustar::catalog::radec_to_vector(field[k].0, field[k].1))
        .collect();
    for v in &vectors {
        assert!(v.z > 0.9, "star in front of the camera");
    }
    let s = IdentifySettings::default();
    let ranges = pair_ranges(&vectors, &camera, &s);
    assert_eq!(ranges.len(), 15);
    let voted = vote_cpu(&table, &ranges, vectors.len(), refs.len(), 4);
    for (i, &k) in order.iter().enumerate() {
        // Each image star gets one vote from each of its 5 partners for its own star; nothing
        // else reaches 5, so the argmax is right.
        let (votes, id) = unpack_candidate(voted.candidates[i * 4]).unwrap();
        assert_eq!(
            (votes, refs.star(id as usize).hip),
            (5, Some(100 + k as u32)),
            "image star {i}"
        );
    }
    let ids = verify(&voted, &vectors, &refs, &camera, &s);
    assert_eq!(ids.len(), 6);
    for m in ids {
        assert_eq!(
            refs.star(m.ref_id as usize).hip,
            Some(100 + order[m.star] as u32)
        );
    }
    // The pair table held every field pair and no far one.
    assert_eq!(table.len(), 15);
    let (ra, _) = vector_to_radec(&refs.v(0));
    assert!((ra - 30.0).abs() < 1e-9);
}

#[test]
fn a_star_off_the_catalog_is_left_unidentified() {
    let (field, refs, camera, table) = tiny_setup();
    let centre = gpustar::catalog::radec_to_vector(30.0, 20.0);
    let r = Rotation3::face_towards(&centre, &Vector3::z())
        .inverse()
        .into_inner();
    let mut vectors: Vec<Vector3<f64>> = field
        .iter()
        .map(|&(ra, dec)| r * gpustar::catalog::radec_to_vector(ra, dec))
        .collect();
    // A false star.
    vectors.push(r * gpustar::catalog::radec_to_vector(31.0, 19.0));
    let s = IdentifySettings::default();
    let ranges = pair_ranges(&vectors, &camera, &s);
    let voted = vote_cpu(&table, &ranges, vectors.len(), refs.len(), 4);
    let ids = verify(&voted, &vectors, &refs, &camera, &s);
    assert_eq!(ids.len(), 6, "{ids:?}");
    assert!(
        ids.iter()
            .all(|m| m.star < 6 && m.ref_id as usize == m.star)
    );
}

/// The first pass's vote job of each frame that has one.
fn vote_jobs(
    solver: &gpustar::solve::Solver,
    frames: &[gpustar::io::frame::Frame],
) -> Vec<VoteJob> {
    frames
        .iter()
        .filter_map(|f| {
            let d = gpustar::solve::detect::detect(f, &solver.settings.detect);
            solver.prepare(&d, 0).map(|p| VoteJob {
                ranges: p.ranges,
                stars: p.n_vote,
                k: p.k,
            })
        })
        .collect()
}

#[test]
fn gpu_votes_equal_cpu_on_simulated_frames() {
    let Some(g) = common::gpu("gpu_votes_equal_cpu_on_simulated_frames") else {
        return;
    };
    let size = (1024, 1024);
    let solver = common::solver(18.0, size);
    let jobs = vote_jobs(&solver, &common::sim_frames(6, size, 18.0, 8, 21));
    assert_eq!(jobs.len(), 6);
    common::assert_votes_equal(&g, &solver, &jobs);
}

/// Issue 24, item 2: a table larger than one binding is voted through in slices, and vote
/// counters larger than one binding a window of voting stars at a time; both give the CPU's
/// counters and candidates exactly. The binding limit is lowered to force both splits.
#[test]
fn gpu_votes_equal_cpu_when_table_and_counters_are_split() {
    let Some(mut g) = common::gpu("gpu_votes_equal_cpu_when_table_and_counters_are_split") else {
        return;
    };
    let size = (1024, 1024);
    let solver = common::solver(18.0, size);
    let band = &solver.bands[0];
    // A binding for the counters of 4 voting stars (a window), and a 60th of the table.
    let refs = band.refs.len() as u64;
    g.limits.max_storage_buffer_binding_size = 4 * refs * 4;
    let table = g.upload_table(band.table(), band.refs.len()).unwrap();
    assert!(table.slices() > 4, "{} slices", table.slices());
    let jobs = vote_jobs(&solver, &common::sim_frames(3, size, 18.0, 8, 22));
    assert_eq!(jobs.len(), 3);
    assert!(jobs.iter().all(|j| j.stars > 8));
    common::assert_votes_equal(&g, &solver, &jobs);
}
