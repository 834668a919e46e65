//! The catalog: propagation to the epoch, double stars, reproducible import.

use crate::common;

use gpustar::camera::angle;
use gpustar::catalog::{Catalog, DoubleStars, RefCatalog, Selection, radec_to_vector};

fn star(cat: &Catalog, hip: u32) -> gpustar::catalog::Star {
    *cat.stars
        .iter()
        .find(|s| s.hip == Some(hip))
        .expect("star in catalog")
}

fn arcsec(a: &nalgebra::Vector3<f64>, b: &nalgebra::Vector3<f64>) -> f64 {
    angle(a, b).to_degrees() * 3600.0
}

#[test]
fn sirius_at_j2000_matches_its_published_position() {
    // SIMBAD, ICRS at epoch J2000 (from the Hipparcos new reduction):
    // 06h45m08.91728s −16°42′58.0171″.
    let published = radec_to_vector(
        15.0 * (6.0 + 45.0 / 60.0 + 8.91728 / 3600.0),
        -(16.0 + 42.0 / 60.0 + 58.0171 / 3600.0),
    );
    let v = star(&Catalog::builtin(), 32349).vector_at(2000.0);
    let err = arcsec(&v, &published);
    assert!(err < 0.01, "Sirius off by {err} arcsec");
}

#[test]
fn propagation_matches_hand_computation_near_the_pole_and_for_fast_stars() {
    // By hand, first order: α = α₀ + μα*·Δt / cos δ₀, δ = δ₀ + μδ·Δt, from the catalog values.
    let cat = Catalog::builtin();
    for (hip, epoch, ra, dec) in [
        (11767, 2025.0, 37.9786124, 89.2640267), // Polaris: 0.7° from the pole
        (69673, 2000.0, 213.9153002, 19.1824092), // Arcturus: 2.3″/yr
    ] {
        let err = arcsec(&star(&cat, hip).vector_at(epoch), &radec_to_vector(ra, dec));
        assert!(err < 0.01, "HIP {hip} at {epoch}: {err} arcsec");
    }
    // And the motion is really applied: Arcturus moves ~20″ between 1991.25 and 2000.
    let s = star(&cat, 69673);
    let moved = arcsec(&s.vector_at(2000.0), &s.vector_at(1991.25));
    assert!((moved - 19.9).abs() < 0.5, "moved {moved}");
}

fn tiny_catalog() -> Catalog {
    // Two stars 10″ apart (a double), three far away.
    let csv = "hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag\n\
               1,1.0,0.5,0,0,3.0\n\
               2,1.0000484813681,0.5,0,0,3.0\n\
               3,1.2,0.6,0,0,4.0\n\
               4,1.5,0.2,0,0,5.0\n\
               5,2.5,-0.2,0,0,5.5\n";
    Catalog::parse(csv, "tiny").unwrap()
}

fn select(mode: DoubleStars) -> RefCatalog {
    RefCatalog::select(
        &tiny_catalog(),
        Selection {
            epoch: 1991.25,
            mag_limit: 6.0,
            double_stars: mode,
            double_sep_rad: (30.0f64 / 3600.0).to_radians(),
        },
    )
    .unwrap()
}

#[test]
fn double_stars_are_merged_dropped_or_kept() {
    let merged = select(DoubleStars::Merge);
    assert_eq!(merged.len(), 4);
    let m = merged.star(0);
    assert_eq!((m.hip, m.members), (Some(1), 2));
    // Equal fluxes: the photocentre is halfway, the magnitude 2.5·log10(2) brighter.
    let half = radec_to_vector((1.0f64 + 0.0000242406840).to_degrees(), 0.5f64.to_degrees());
    assert!(arcsec(&m.v, &half) < 0.01);
    assert!((m.mag - (3.0 - 2.5 * 2f64.log10())).abs() < 1e-12);
    assert_eq!(select(DoubleStars::Drop).len(), 3);
    assert_eq!(select(DoubleStars::Keep).len(), 5);
    assert_eq!(merged.doubles_removed, 1);
}

#[test]
fn import_of_hip2_reproduces_the_shipped_catalog() {
    let Some(shared) = common::shared_dir("import_of_hip2_reproduces_the_shipped_catalog") else {
        return;
    };
    let text = std::fs::read_to_string(shared.join("catalog/hip2.dat")).unwrap();
    let csv = gpustar::catalog::import_hip2(&text, 9.0).unwrap();
    assert!(
        csv == gpustar::catalog::BUILTIN_CSV,
        "catalog/hip2_hp9.csv differs from `gpustar catalog import hip2.dat --max-mag 9`"
    );
}

/// A run warns when the built-in catalog holds few stars in the field on average (78,352
/// stars to Hp 9 in a 3° field: 17.1), and not in a 4° field (30.4), an 18° field or under a
/// magnitude limit the user chose.
#[test]
fn a_catalog_too_shallow_for_the_field_is_said() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    common::simulate_small(&dir, 1);
    let run = |args: &[&str]| {
        let out = common::run_ok(&[&["batch", dir.to_str().unwrap(), "-q"], args].concat());
        common::stderr(&out)
    };
    let narrow = run(&["--fov-deg", "3"]);
    assert!(
        narrow.contains("holds 17 stars on average in this 3.0°×3.0° field")
            && narrow.contains("deeper catalog"),
        "{narrow}"
    );
    for quiet in [
        vec!["--fov-deg", "4"],
        vec!["--fov-deg", "18"],
        vec!["--fov-deg", "3", "--mag-limit", "7"],
    ] {
        let said = run(&quiet);
        assert!(!said.contains("deeper catalog"), "{quiet:?}: {said}");
    }
}
