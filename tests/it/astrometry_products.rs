//! What astrometry.net's users read (issue 47): `--new-fits` (the frame with its WCS),
//! `--corr` (matched stars) and `--axy` (detections), read back here with gpustar's own
//! readers; python/tests reads them with astropy (scripts/check_astrometry_products.py).

use crate::common;
use gpustar::io::frame::Frame;
use gpustar::io::wcs::HeaderWcs;
use std::path::Path;

fn header_cards(bytes: &[u8]) -> Vec<String> {
    bytes
        .chunks_exact(80)
        .map(|c| String::from_utf8_lossy(c).into_owned())
        .take_while(|c| c.trim_end() != "END")
        .collect()
}

#[test]
fn new_fits_corr_and_axy_hold_the_solution() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 2);
    // One frame as FITS with a header of its own (a date and an old, wrong WCS), one PNG, and
    // a frame without stars (unsolved).
    let f = Frame::read(&dir.join("sim_00001.png")).unwrap();
    let cards = [
        gpustar::io::fits::card_str("DATE-OBS", "2019-07-29T20:47:26", ""),
        gpustar::io::fits::card_str("CTYPE1", "RA---TAN", "an old solution"),
        gpustar::io::fits::card_real("CRVAL1", 12.0, ""),
        gpustar::io::fits::card_str("OBSERVER", "someone", ""),
    ];
    let fits = gpustar::io::fits::encode_u16(f.width, f.height, &f.pixels, &cards);
    std::fs::write(dir.join("b.fits"), &fits).unwrap();
    std::fs::remove_file(dir.join("sim_00001.png")).unwrap();
    std::fs::write(
        dir.join("c.fits"),
        gpustar::io::fits::encode_u16(64, 48, &[100u16; 64 * 48], &[]),
    )
    .unwrap();
    let out = tmp.path().join("out");
    let (new, corr, axy) = (out.join("new"), out.join("corr"), out.join("axy"));
    let run = || {
        let mut c = common::gpustar();
        c.arg("batch")
            .arg(&dir)
            .args(["--fov-deg", "18", "--backend", "cpu", "-q"]);
        c.arg("--new-fits").arg(&new).arg("--corr").arg(&corr);
        c.arg("--axy").arg(&axy);
        common::run_records(&mut c)
    };
    let records = run();
    let status: Vec<&str> = records
        .iter()
        .map(|r| r["status"].as_str().unwrap())
        .collect();
    assert_eq!(status, ["solved", "unsolved", "solved"], "{records:?}");

    for r in records.iter().filter(|r| r["status"] == "solved") {
        let name = r["file"].as_str().unwrap();
        let stem = name.rsplit_once('.').unwrap().0;
        let input = Frame::read(&dir.join(name)).unwrap();
        // The .new: the frame's pixels, the input's header less its WCS, the solution's WCS.
        let path = new.join(format!("{stem}.fits"));
        let (frame, info) = Frame::read_info(&path).unwrap();
        // (An 8-bit PNG's become 16-bit FITS values: the same numbers.)
        assert_eq!((frame.width, frame.height), (input.width, input.height));
        assert!(
            frame.pixels == input.pixels,
            "{name}: the pixels of the .new"
        );
        let text = header_cards(&std::fs::read(&path).unwrap()).concat();
        if name.ends_with(".fits") {
            assert!(text.contains("OBSERVER= 'someone"), "{text}");
            assert_eq!(info.keywords["DATE-OBS"], "2019-07-29T20:47:26");
            assert_eq!(
                text.matches("CTYPE1").count(),
                1,
                "the old WCS is gone: {text}"
            );
        }
        let wcs = HeaderWcs::from_keywords(&info.keywords, (frame.width, frame.height))
            .unwrap()
            .expect("a WCS");
        // The WCS puts each matched detection within its residual of its catalog star.
        for m in r["matches"].as_array().unwrap() {
            let (ra, dec) = wcs
                .pixel_to_radec(m["x"].as_f64().unwrap(), m["y"].as_f64().unwrap())
                .unwrap();
            let a = gpustar::catalog::radec_to_vector(ra, dec);
            let b = gpustar::catalog::radec_to_vector(
                m["ra_deg"].as_f64().unwrap(),
                m["dec_deg"].as_f64().unwrap(),
            );
            let sep = a.cross(&b).norm().atan2(a.dot(&b)).to_degrees() * 3600.0;
            let res = m["residual_arcsec"].as_f64().unwrap();
            assert!((sep - res).abs() < 0.01, "{name}: {sep} vs {res}");
        }
        // The tables: one row per match, one per detection, each marked as gpustar's.
        let c = std::fs::read(corr.join(format!("{stem}.corr"))).unwrap();
        let head = header_cards(&c[2880..]).concat();
        let rows = r["stars_matched"].as_u64().unwrap();
        assert!(head.contains(&format!("NAXIS2  = {rows:>20}")), "{head}");
        assert!(head.contains("TTYPE1  = 'field_x '") && head.contains("gpustar --corr"));
        let a = std::fs::read(axy.join(format!("{stem}.axy"))).unwrap();
        let head = header_cards(&a[2880..]).concat();
        let rows = r["stars_detected"].as_u64().unwrap();
        assert!(head.contains(&format!("NAXIS2  = {rows:>20}")), "{head}");
        assert!(
            head.contains(&format!("IMAGEW  = {:>20}", frame.width)),
            "{head}"
        );
    }
    // The unsolved frame: its detections (none), no .new and no .corr.
    assert!(axy.join("c.axy").exists());
    assert!(!new.join("c.fits").exists() && !corr.join("c.corr").exists());
    // A rerun replaces gpustar's own files; a file another program wrote is refused.
    assert_eq!(run().len(), 3);
    std::fs::write(corr.join("b.corr"), b"SIMPLE  = T / astrometry.net").unwrap();
    let o = common::gpustar()
        .arg("batch")
        .arg(&dir)
        .args(["--fov-deg", "18", "-q", "--corr"])
        .arg(&corr)
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", common::stderr(&o));
    assert!(
        common::stderr(&o).contains("--overwrite"),
        "{}",
        common::stderr(&o)
    );
    assert!(Path::new(&corr.join("b.corr")).exists());
}

/// `--xyls`: the `.axy` star lists `--axy` wrote (solve-field's format) solve to the attitude
/// their frames gave; a list without its image size needs `--image-size`; options that need
/// pixels are refused.
#[test]
fn star_lists_solve_as_their_frames_did() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("frames");
    common::simulate_small(&dir, 2);
    let axy = tmp.path().join("axy");
    let mut c = common::gpustar();
    c.arg("batch")
        .arg(&dir)
        .args(["--fov-deg", "18", "--backend", "cpu", "-q"]);
    let frames = common::run_records(c.arg("--axy").arg(&axy));
    // The same stars without IMAGEW/IMAGEH, and a list that is not a table.
    let (x, y): (Vec<f64>, Vec<f64>) = frames[0]["matches"]
        .as_array()
        .unwrap()
        .iter()
        .map(|m| {
            (
                m["x"].as_f64().unwrap() + 1.0,
                m["y"].as_f64().unwrap() + 1.0,
            )
        })
        .unzip();
    use gpustar::io::fits::table::{Column, Values, encode_table};
    let bare = encode_table(
        &[
            Column {
                name: "X",
                unit: "",
                values: Values::F64(x),
            },
            Column {
                name: "Y",
                unit: "",
                values: Values::F64(y),
            },
        ],
        &[],
    );
    std::fs::write(axy.join("bare.xyls"), bare).unwrap();
    std::fs::write(axy.join("text.xyls"), "x y\n1 2\n").unwrap();
    let lists = |more: &[&str]| {
        common::gpustar()
            .arg("batch")
            .arg(&axy)
            .args(["--xyls", "--fov-deg", "18", "-q"])
            .args(more)
            .output()
            .unwrap()
    };
    let o = lists(&[]);
    assert_eq!(o.status.code(), Some(1), "{}", common::stderr(&o));
    let records: Vec<serde_json::Value> = String::from_utf8(o.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let names: Vec<&str> = records
        .iter()
        .map(|r| r["file"].as_str().unwrap())
        .collect();
    assert_eq!(
        names,
        ["bare.xyls", "sim_00000.axy", "sim_00001.axy", "text.xyls"]
    );
    assert!(
        records[0]["error"]
            .as_str()
            .unwrap()
            .contains("--image-size")
    );
    assert!(
        records[3]["error"]
            .as_str()
            .unwrap()
            .contains("not a FITS file")
    );
    let v = |r: &serde_json::Value| {
        gpustar::catalog::radec_to_vector(
            r["ra_deg"].as_f64().unwrap(),
            r["dec_deg"].as_f64().unwrap(),
        )
    };
    for (list, frame) in records[1..3].iter().zip(&frames) {
        assert_eq!(list["status"], "solved", "{list}");
        let (a, b) = (v(list), v(frame));
        let arcsec = a.cross(&b).norm().atan2(a.dot(&b)).to_degrees() * 3600.0;
        assert!(
            arcsec < 5.0,
            "{}: {arcsec}\" from its frame's",
            list["file"]
        );
    }
    // With the size given, the bare list (the first frame's matched stars) solves too.
    let o = lists(&["--image-size", "256x256"]);
    let first: serde_json::Value =
        serde_json::from_str(String::from_utf8(o.stdout).unwrap().lines().next().unwrap()).unwrap();
    assert_eq!(first["status"], "solved", "{first}");
    // Pixels needed: refused before any work.
    for more in [
        &["--new-fits", "n"][..],
        &["--backend", "gpu"],
        &["--sequence"],
    ] {
        let o = lists(more);
        assert_eq!(o.status.code(), Some(2), "{more:?}");
        assert!(
            common::stderr(&o).contains("--xyls"),
            "{}",
            common::stderr(&o)
        );
    }
}
