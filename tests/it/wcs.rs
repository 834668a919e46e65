//! Products of a solved batch: the WCS header of each solved frame (`--wcs-dir`) maps the
//! identified stars' catalog positions back to their centroids within the solution's
//! residuals, read here by an independent FITS TAN + SIP reader; `--annotate-dir` writes a PNG
//! of the frame's size for every frame.

use crate::common;

use std::collections::HashMap;
use std::path::Path;

/// The cards of a header-only FITS file: keyword → value text.
fn read_cards(path: &Path) -> HashMap<String, String> {
    let bytes = std::fs::read(path).unwrap();
    assert_eq!(
        bytes.len() % 2880,
        0,
        "{}: not in 2880-byte blocks",
        path.display()
    );
    let mut cards = HashMap::new();
    for card in bytes.chunks(80) {
        let card = std::str::from_utf8(card).unwrap();
        let key = card[..8].trim_end();
        if key == "END" {
            return cards;
        }
        if &card[8..10] == "= " {
            let value = card[10..].split('/').next().unwrap().trim();
            cards.insert(key.to_string(), value.trim_matches('\'').trim().to_string());
        }
    }
    panic!("{}: no END card", path.display());
}

/// FITS pixel (1-based) of an ICRS direction: TAN projection, then SIP AP/BP when present
/// (Calabretta & Greisen 2002; Shupe et al. 2005).
fn world_to_pixel(c: &HashMap<String, String>, ra_deg: f64, dec_deg: f64) -> (f64, f64) {
    let num = |k: &str| c.get(k).map_or(0.0, |v| v.parse::<f64>().unwrap());
    let (ra0, dec0) = (num("CRVAL1").to_radians(), num("CRVAL2").to_radians());
    let (ra, dec) = (ra_deg.to_radians(), dec_deg.to_radians());
    // Standard coordinates (gnomonic), degrees.
    let cos_c = dec.sin() * dec0.sin() + dec.cos() * dec0.cos() * (ra - ra0).cos();
    let xi = (dec.cos() * (ra - ra0).sin() / cos_c).to_degrees();
    let eta =
        ((dec.sin() * dec0.cos() - dec.cos() * dec0.sin() * (ra - ra0).cos()) / cos_c).to_degrees();
    // Invert CD: intermediate pixel offsets.
    let (a, b, cc, d) = (num("CD1_1"), num("CD1_2"), num("CD2_1"), num("CD2_2"));
    let det = a * d - b * cc;
    let u = (d * xi - b * eta) / det;
    let v = (-cc * xi + a * eta) / det;
    let poly = |name: &str, order: usize| {
        let mut s = 0.0;
        for p in 0..=order {
            for q in 0..=order - p {
                s += num(&format!("{name}_{p}_{q}")) * u.powi(p as i32) * v.powi(q as i32);
            }
        }
        s
    };
    let (du, dv) = if c["CTYPE1"].ends_with("-SIP") {
        let order = num("AP_ORDER") as usize;
        (poly("AP", order), poly("BP", order))
    } else {
        (0.0, 0.0)
    };
    (num("CRPIX1") + u + du, num("CRPIX2") + v + dv)
}

#[test]
fn wcs_headers_map_catalog_stars_to_their_centroids_and_frames_are_annotated() {
    let dir = tempfile::tempdir().unwrap();
    let (sim, wcs, ann) = (
        dir.path().join("sim"),
        dir.path().join("wcs"),
        dir.path().join("ann"),
    );
    // Non-square pixels and barrel distortion: the headers need SIP.
    let cam = dir.path().join("cam.toml");
    std::fs::write(
        &cam,
        "width = 800\nheight = 600\nfx_px = 2500.0\nfy_px = 2540.0\nk1 = -0.2\n",
    )
    .unwrap();
    common::simulate(
        &sim,
        &["-n", "4", "--seed", "3", "--camera", cam.to_str().unwrap()],
    );
    // The user's camera lacks k1: refinement fits it.
    let given = dir.path().join("given.toml");
    std::fs::write(
        &given,
        "width = 800\nheight = 600\nfx_px = 2500.0\nfy_px = 2540.0\n",
    )
    .unwrap();
    let records = common::run_records(
        common::gpustar()
            .arg("batch")
            .arg(&sim)
            .arg("--camera")
            .arg(&given)
            .args([
                "--mag-limit",
                "6",
                "--fit",
                "distortion",
                "--fov-tolerance",
                "0.01",
                "--backend",
                "cpu",
                "-q",
            ])
            .arg("--wcs-dir")
            .arg(&wcs)
            .arg("--annotate-dir")
            .arg(&ann),
    );
    assert_eq!(records.len(), 4);
    let mut checked = 0;
    let mut sip = 0;
    for r in &records {
        let name = r["file"].as_str().unwrap();
        let png = ann.join(name);
        let img = image::open(&png).unwrap_or_else(|e| panic!("{}: {e}", png.display()));
        assert_eq!((img.width(), img.height()), (800, 600));
        if r["status"] != "solved" {
            continue;
        }
        let cards = read_cards(&wcs.join(name).with_extension("wcs"));
        sip += cards["CTYPE1"].ends_with("-SIP") as usize;
        // Arcsec per pixel at the centre, and at most 4 % more where the barrel squeezes.
        let scale = 206_264.8 / 2540.0;
        for m in r["matches"].as_array().unwrap() {
            let f = |k: &str| m[k].as_f64().unwrap();
            let (px, py) = world_to_pixel(&cards, f("ra_deg"), f("dec_deg"));
            let d = (px - 1.0 - f("x")).hypot(py - 1.0 - f("y"));
            let allowed = f("residual_arcsec") / scale * 1.04 + 0.02;
            assert!(
                d <= allowed,
                "{name} HIP {}: header puts it {d:.3} px from its centroid, residual {:.3} px",
                m["hip"],
                allowed
            );
            checked += 1;
        }
    }
    eprintln!("{checked} identified stars checked against the WCS headers; {sip} with SIP");
    assert!(checked >= 40, "only {checked} stars checked");
    assert!(sip >= 1, "no header carried the fitted distortion");
}
