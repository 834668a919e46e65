//! FITS input end to end: simulated frames written as FITS (unsigned 16-bit, and 32-bit float
//! with NaN blanks) with a DATE-OBS solve like their PNGs, and the catalog positions of a
//! dated frame are those at its own epoch, not the run's.

use crate::common;

use gpustar::catalog::{Catalog, vector_to_radec};
use gpustar::simulate::{SimSettings, render};
use std::path::Path;

/// A FITS card: keyword, value text.
fn card(key: &str, value: &str) -> String {
    format!("{key:<8}= {value:>20}")
        .chars()
        .chain(std::iter::repeat(' '))
        .take(80)
        .collect()
}

fn pad(mut bytes: Vec<u8>, fill: u8) -> Vec<u8> {
    while !bytes.len().is_multiple_of(2880) {
        bytes.push(fill);
    }
    bytes
}

/// Write pixels as a FITS primary image: BITPIX 16 with BZERO 32768 (unsigned), or −32 with
/// every 97th pixel blank (NaN).
fn write_fits(path: &Path, w: u32, h: u32, pixels: &[u16], float: bool, date_obs: &str) {
    write_fits_with(
        path,
        w,
        h,
        pixels,
        float,
        &[("DATE-OBS", &format!("'{date_obs}'"))],
    );
}

/// [`write_fits`] with these cards (keyword, value text) in the header.
fn write_fits_with(
    path: &Path,
    w: u32,
    h: u32,
    pixels: &[u16],
    float: bool,
    extra: &[(&str, &str)],
) {
    let mut cards = vec![
        card("SIMPLE", "T"),
        card("BITPIX", if float { "-32" } else { "16" }),
        card("NAXIS", "2"),
        card("NAXIS1", &w.to_string()),
        card("NAXIS2", &h.to_string()),
    ];
    if !float {
        cards.push(card("BZERO", "32768"));
        cards.push(card("BSCALE", "1"));
    }
    for (k, v) in extra {
        cards.push(card(k, v));
    }
    cards.push(format!("{:<80}", "END"));
    let mut bytes = pad(cards.concat().into_bytes(), b' ');
    let mut data = Vec::new();
    for (i, &p) in pixels.iter().enumerate() {
        if float {
            let v = if i % 97 == 0 {
                f32::NAN
            } else {
                p as f32 * 0.25 + 10.0
            };
            data.extend_from_slice(&v.to_be_bytes());
        } else {
            data.extend_from_slice(&((p as i32 - 32768) as i16).to_be_bytes());
        }
    }
    bytes.extend(pad(data, 0));
    std::fs::write(path, bytes).unwrap();
}

#[test]
fn fits_frames_solve_at_their_own_epoch() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("fits");
    std::fs::create_dir(&dir).unwrap();
    let cat = Catalog::builtin();
    // The sky of 2030; the run's epoch stays at its default, 2000.
    let s = SimSettings {
        width: 640,
        height: 480,
        fov_x_deg: 15.0,
        bits: 16,
        seed: 5,
        epoch: 2030.0,
        ..SimSettings::default()
    };
    for k in 0..4 {
        let (pixels, _) = render(&cat, &s, k).unwrap();
        let path = dir.join(format!("f{k}.fits"));
        write_fits(&path, 640, 480, &pixels, k % 2 == 1, "2030-01-01T12:00:00");
    }
    let records = common::run_records(common::gpustar().arg("batch").arg(&dir).args([
        "--fov-deg",
        "15",
        "--mag-limit",
        "6",
        "--backend",
        "cpu",
        "-q",
    ]));
    assert_eq!(records.len(), 4);
    // 2030-01-01T12:00 UT is JD 2462503.0: 2000 + 10957.5 / 365.25 = 2029.9999316.
    let epoch = 2000.0 + (2_462_503.0 - 2_451_545.0) / 365.25;
    let (mut at_epoch, mut total) = (0, 0);
    for r in &records {
        assert_eq!(r["status"], "solved", "{r}");
        assert!((r["epoch"].as_f64().unwrap() - epoch).abs() < 1e-9, "{r}");
        for m in r["matches"].as_array().unwrap() {
            let hip = m["hip"].as_u64().unwrap() as u32;
            let star = cat.stars.iter().find(|s| s.hip == Some(hip)).unwrap();
            let (ra, dec) = vector_to_radec(&star.vector_at(epoch));
            let d_ra = (m["ra_deg"].as_f64().unwrap() - ra) * dec.to_radians().cos();
            let d_dec = m["dec_deg"].as_f64().unwrap() - dec;
            total += 1;
            // At the 2030 place to 1 mas; at the 2000 place a typical star is ~0.5″ away.
            at_epoch += (d_ra.hypot(d_dec) * 3.6e6 < 1.0) as usize;
        }
    }
    eprintln!("{at_epoch} of {total} identified stars at their 2030 positions (to 1 mas)");
    assert!(total >= 40, "only {total} stars identified");
    // Merged doubles sit at their photocentre, so not quite every star.
    assert!(at_epoch * 10 >= total * 9, "{at_epoch} of {total}");
}

/// Without --camera, --fov-deg or --scale-arcsec each frame's camera comes from the pixel scale
/// its header states (issue 47, as ASTAP reads it): a focal length and pixel size 1 % off the
/// truth (a nominal value), a CD matrix; the record says which. A frame that states none gets
/// an error record saying what to give.
#[test]
fn frames_solve_from_the_pixel_scale_their_header_states() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("fits");
    std::fs::create_dir(&dir).unwrap();
    let cat = Catalog::builtin();
    let s = SimSettings {
        width: 640,
        height: 480,
        fov_x_deg: 15.0,
        bits: 16,
        seed: 8,
        ..SimSettings::default()
    };
    // One pixel at the centre: atan(tan(7.5°) / 320).
    let rad = (7.5f64.to_radians().tan() / 320.0).atan();
    let deg = rad.to_degrees();
    let focal = format!("{}", 250.0);
    let pixel_um = format!("{}", (rad.tan() * 250.0e3 * 1.01));
    let cd = (format!("{:e}", -deg), format!("{:e}", deg));
    let headers: [Vec<(&str, &str)>; 3] = [
        vec![
            ("FOCALLEN", &focal),
            ("XPIXSZ", &pixel_um),
            ("YPIXSZ", &pixel_um),
        ],
        vec![
            ("CD1_1", &cd.0),
            ("CD1_2", "0.0"),
            ("CD2_1", "0.0"),
            ("CD2_2", &cd.1),
        ],
        vec![("OBJECT", "'no scale'")],
    ];
    let mut truths = Vec::new();
    for (k, cards) in headers.iter().enumerate() {
        let (pixels, truth) = render(&cat, &s, k).unwrap();
        write_fits_with(
            &dir.join(format!("f{k}.fits")),
            640,
            480,
            &pixels,
            false,
            cards,
        );
        truths.push(truth);
    }
    let out = common::gpustar()
        .arg("batch")
        .arg(&dir)
        .args(["--mag-limit", "6", "-q"])
        .output()
        .unwrap();
    // The frame without a scale is an error record: exit 1.
    assert_eq!(out.status.code(), Some(1), "{}", common::stderr(&out));
    let records: Vec<serde_json::Value> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    assert_eq!(records.len(), 3);
    for (r, (t, source)) in records[..2]
        .iter()
        .zip(truths.iter().zip(["FOCALLEN, XPIXSZ", "CD1_1..CD2_2"]))
    {
        assert_eq!(r["status"], "solved", "{r}");
        let d_ra = (r["ra_deg"].as_f64().unwrap() - t.ra_deg) * t.dec_deg.to_radians().cos();
        let d_dec = r["dec_deg"].as_f64().unwrap() - t.dec_deg;
        assert!(d_ra.hypot(d_dec) * 3600.0 < 5.0, "{r}");
        assert!(
            (r["fov_x_deg"].as_f64().unwrap() - 15.0).abs() < 0.01,
            "{r}"
        );
        assert_eq!(r["pixel_scale"]["source"], source, "{r}");
    }
    let stated = records[0]["pixel_scale"]["arcsec_per_px"].as_f64().unwrap();
    assert!((stated / (deg * 3600.0) - 1.01).abs() < 1e-4, "{stated}");
    assert_eq!(records[2]["status"], "error");
    let e = records[2]["error"].as_str().unwrap();
    assert!(
        e.contains("no pixel scale") && e.contains("--fov-deg"),
        "{e}"
    );
    assert!(records[2].get("pixel_scale").is_none());
}

/// Gzipped FITS (issue 47): `x.fits.gz` gives the record `x.fits` gives, field for field but
/// the file's name; a stream cut short, a gzip that is not FITS and a FITS file named .gz that
/// is not gzipped are error records.
#[test]
fn gzipped_fits_frames_give_the_records_of_the_uncompressed_ones() {
    use std::io::Write;
    let tmp = tempfile::tempdir().unwrap();
    let plain = tmp.path().join("plain");
    common::simulate(
        &plain,
        &[
            "-n",
            "3",
            "--fov-deg",
            "12",
            "--size",
            "400x300",
            "--hint-offset-deg",
            "0.5",
        ],
    );
    let gzipped = tmp.path().join("gz");
    std::fs::create_dir(&gzipped).unwrap();
    let gzip = |bytes: &[u8]| {
        let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
        e.write_all(bytes).unwrap();
        e.finish().unwrap()
    };
    let mut names = Vec::new();
    for e in std::fs::read_dir(&plain).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "fits") {
            let name = p.file_name().unwrap().to_str().unwrap().to_string();
            std::fs::write(
                gzipped.join(format!("{name}.gz")),
                gzip(&std::fs::read(&p).unwrap()),
            )
            .unwrap();
            names.push(name);
        }
    }
    assert_eq!(names.len(), 3);
    let records = |dir: &Path| {
        let mut c = common::gpustar();
        c.arg("batch")
            .arg(dir)
            .args(["--fov-deg", "12", "--backend", "cpu", "-q"]);
        common::run_records(&mut c)
            .into_iter()
            .map(|mut r| {
                let o = r.as_object_mut().unwrap();
                o.remove("timing_ms");
                let file = o.remove("file").unwrap();
                (file.as_str().unwrap().to_string(), r)
            })
            .collect::<Vec<_>>()
    };
    let (a, b) = (records(&plain), records(&gzipped));
    assert_eq!(a.len(), 3);
    assert!(a.iter().all(|(_, r)| r["status"] == "solved"), "{a:?}");
    for ((fa, ra), (fb, rb)) in a.iter().zip(&b) {
        assert_eq!(format!("{fa}.gz"), *fb);
        assert_eq!(ra, rb, "{fa}");
    }
    // Bad ones: each an error record naming what is wrong.
    let bad = tmp.path().join("bad");
    std::fs::create_dir(&bad).unwrap();
    let whole = std::fs::read(plain.join(&names[0])).unwrap();
    let packed = gzip(&whole);
    std::fs::write(bad.join("cut.fits.gz"), &packed[..packed.len() / 2]).unwrap();
    std::fs::write(bad.join("text.fits.gz"), gzip(b"not a FITS file at all")).unwrap();
    std::fs::write(bad.join("plain.fits.gz"), &whole).unwrap();
    let out = common::gpustar()
        .arg("batch")
        .arg(&bad)
        .args(["--fov-deg", "12", "-q"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", common::stderr(&out));
    let errors: Vec<String> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str::<serde_json::Value>(l).unwrap())
        .map(|r| {
            format!(
                "{}: {}",
                r["file"].as_str().unwrap(),
                r["error"].as_str().unwrap()
            )
        })
        .collect();
    assert_eq!(errors.len(), 3, "{errors:?}");
    assert!(
        errors[0].starts_with("cut.fits.gz") && errors[0].contains("truncated"),
        "{errors:?}"
    );
    assert!(
        errors[1].starts_with("plain.fits.gz") && errors[1].contains("gzip"),
        "{errors:?}"
    );
    assert!(
        errors[2].starts_with("text.fits.gz") && errors[2].contains("not a FITS file"),
        "{errors:?}"
    );
}

/// Frames whose headers state scales a hair apart (the CD matrices of an archive's solved
/// frames differ in their last digits) share one solver; a scale 1 % off gets its own.
#[test]
fn header_scales_a_hair_apart_share_a_solver() {
    use gpustar::pipeline::{CameraSource, Decoded, Solvers};
    use std::sync::Arc;
    let solvers = Solvers::new(
        Catalog::builtin(),
        gpustar::solve::Settings {
            scale_range: Some((0.97, 1.03)),
            ..Default::default()
        },
        CameraSource::Header,
    );
    let decoded = |secpix: f64| {
        let frame = gpustar::io::frame::Frame {
            width: 320,
            height: 240,
            pixels: vec![0u16; 320 * 240].into(),
            saturation: u16::MAX,
        };
        let keywords = [("SECPIX".to_string(), secpix.to_string())].into();
        Decoded::in_memory("f", Ok((frame, Vec::new())), None, keywords)
    };
    let get = |secpix: f64| {
        let d = decoded(secpix);
        solvers.get_for(&d, d.frame.as_ref().unwrap())
    };
    let a = get(120.0).unwrap();
    assert!(Arc::ptr_eq(&a, &get(120.0 * (1.0 + 1e-9)).unwrap()));
    assert!(!Arc::ptr_eq(&a, &get(121.2).unwrap()));
}
