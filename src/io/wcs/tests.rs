use super::*;
use nalgebra::{Quaternion, UnitQuaternion};
use std::collections::HashMap;
use std::f64::consts::PI;

/// xorshift64*: deterministic and dependency-free.
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
    fn gauss(&mut self) -> f64 {
        (-2.0 * (1.0 - self.next()).ln()).sqrt() * (2.0 * PI * self.next()).cos()
    }
    fn rotation(&mut self) -> Matrix3<f64> {
        let q = Quaternion::new(self.gauss(), self.gauss(), self.gauss(), self.gauss());
        UnitQuaternion::from_quaternion(q)
            .to_rotation_matrix()
            .into_inner()
    }
}

/// Attitude whose boresight is `b` (ICRS), rolled by `roll` about it.
fn attitude(b: Vector3<f64>, roll: f64) -> Matrix3<f64> {
    let z = b.normalize();
    let helper = if z.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let x0 = z.cross(&helper).normalize();
    let y0 = z.cross(&x0);
    let x = x0 * roll.cos() + y0 * roll.sin();
    let y = z.cross(&x);
    Matrix3::from_rows(&[x.transpose(), y.transpose(), z.transpose()])
}

fn radec_vec(ra_deg: f64, dec_deg: f64) -> Vector3<f64> {
    let (a, d) = (ra_deg.to_radians(), dec_deg.to_radians());
    Vector3::new(d.cos() * a.cos(), d.cos() * a.sin(), d.sin())
}

fn random_camera(rng: &mut Rng, distorted: bool) -> Camera {
    loop {
        let width = rng.range(64.0, 4096.0) as u32;
        // Star-camera-like: aspect ratio up to 2:1, so at most ~60° across.
        let height = ((width as f64 * rng.range(0.5, 1.5)) as u32).max(64);
        let fov = rng.range(1.0, 40.0).to_radians();
        let fx = width as f64 / 2.0 / (fov / 2.0).tan();
        let cam = Camera {
            width,
            height,
            fx,
            fy: fx * rng.range(0.8, 1.25),
            cx: width as f64 * rng.range(0.3, 0.7),
            cy: height as f64 * rng.range(0.3, 0.7),
            k1: if distorted { rng.range(-0.3, 0.3) } else { 0.0 },
            k2: if distorted {
                rng.range(-0.05, 0.05)
            } else {
                0.0
            },
            mirrored: rng.next() < 0.5,
        };
        // The model must stay monotonic over the image to be a camera at all.
        let (w, h) = (width as f64, height as f64);
        let r_max = [(-0.5, -0.5), (w, -0.5), (-0.5, h), (w, h)]
            .iter()
            .map(|&(x, y)| ((x - cam.cx) / cam.fx).hypot((y - cam.cy) / cam.fy))
            .fold(0.0, f64::max)
            * 1.5;
        let slope = 1.0 + 3.0 * cam.k1 * r_max.powi(2) + 5.0 * cam.k2 * r_max.powi(4);
        if slope > 0.3 {
            return cam;
        }
    }
}

/// A WCS as read back from our cards, with the FITS TAN(+SIP) transforms implemented
/// from the standard (Calabretta & Greisen 2002; Shupe et al. 2005), not from `Camera`.
struct Parsed {
    keys: HashMap<String, String>,
    crval: [f64; 2],
    crpix: [f64; 2],
    cd: [[f64; 2]; 2],
    lonpole: f64,
    sip: bool,
}

fn parse(cards: &[String]) -> Parsed {
    let mut keys = HashMap::new();
    for card in cards {
        if &card[8..10] != "= " {
            continue;
        }
        let key = card[..8].trim().to_string();
        let rest = card[10..].trim_start();
        let value = if let Some(s) = rest.strip_prefix('\'') {
            let end = s.find('\'').expect("closing quote");
            s[..end].trim_end().to_string()
        } else {
            rest.split('/').next().unwrap().trim().to_string()
        };
        keys.insert(key, value);
    }
    let f = |k: &str| -> f64 { keys[k].parse().unwrap_or_else(|_| panic!("{k}")) };
    let ctype1 = keys["CTYPE1"].clone();
    Parsed {
        crval: [f("CRVAL1"), f("CRVAL2")],
        crpix: [f("CRPIX1"), f("CRPIX2")],
        cd: [[f("CD1_1"), f("CD1_2")], [f("CD2_1"), f("CD2_2")]],
        lonpole: f("LONPOLE"),
        sip: ctype1.ends_with("-SIP"),
        keys,
    }
}

impl Parsed {
    fn poly(&self, name: &str, u: f64, v: f64) -> f64 {
        let order: usize = self.keys[&format!("{name}_ORDER")].parse().unwrap();
        let mut sum = 0.0;
        for p in 0..=order {
            for q in 0..=order - p {
                if let Some(c) = self.keys.get(&format!("{name}_{p}_{q}")) {
                    sum += c.parse::<f64>().unwrap() * u.powi(p as i32) * v.powi(q as i32);
                }
            }
        }
        sum
    }

    /// ICRS unit vector → our 0-based pixel, via CD⁻¹ and AP/BP.
    fn world_to_pixel(&self, d: &Vector3<f64>) -> Option<(f64, f64)> {
        let (ra, dec) = (d.y.atan2(d.x), d.z.atan2(d.x.hypot(d.y)));
        let (a0, d0) = (self.crval[0].to_radians(), self.crval[1].to_radians());
        let phip = self.lonpole.to_radians();
        // Celestial → native spherical (C&G eq. 5), θ via atan2 for precision.
        let da = ra - a0;
        let s = -dec.cos() * da.sin(); // cos θ sin(φ − φp)
        let c = dec.sin() * d0.cos() - dec.cos() * d0.sin() * da.cos(); // cos θ cos(φ − φp)
        let sin_t = dec.sin() * d0.sin() + dec.cos() * d0.cos() * da.cos();
        if sin_t <= 0.0 {
            return None;
        }
        let phi = phip + s.atan2(c);
        let theta = sin_t.atan2(s.hypot(c));
        // TAN (C&G II eq. 54): R = (180/π) cot θ, x = R sin φ, y = −R cos φ.
        let rr = (180.0 / PI) / theta.tan();
        let (x, y) = (rr * phi.sin(), -rr * phi.cos());
        let cd = &self.cd;
        let det = cd[0][0] * cd[1][1] - cd[0][1] * cd[1][0];
        let uu = (cd[1][1] * x - cd[0][1] * y) / det;
        let vu = (-cd[1][0] * x + cd[0][0] * y) / det;
        let (u, v) = if self.sip {
            (uu + self.poly("AP", uu, vu), vu + self.poly("BP", uu, vu))
        } else {
            (uu, vu)
        };
        Some((u + self.crpix[0] - 1.0, v + self.crpix[1] - 1.0))
    }

    /// Our 0-based pixel → ICRS unit vector, via A/B and CD.
    fn pixel_to_world(&self, px: f64, py: f64) -> Vector3<f64> {
        let (u, v) = (px + 1.0 - self.crpix[0], py + 1.0 - self.crpix[1]);
        let (uu, vu) = if self.sip {
            (u + self.poly("A", u, v), v + self.poly("B", u, v))
        } else {
            (u, v)
        };
        let cd = &self.cd;
        let x = cd[0][0] * uu + cd[0][1] * vu;
        let y = cd[1][0] * uu + cd[1][1] * vu;
        let phi = x.atan2(-y);
        let theta = (180.0 / PI).atan2(x.hypot(y));
        let (a0, d0) = (self.crval[0].to_radians(), self.crval[1].to_radians());
        let dphi = phi - self.lonpole.to_radians();
        // Native → celestial (C&G eq. 2).
        let s = -theta.cos() * dphi.sin(); // cos δ sin(α − α0)
        let c = theta.sin() * d0.cos() - theta.cos() * d0.sin() * dphi.cos();
        let sin_d = theta.sin() * d0.sin() + theta.cos() * d0.cos() * dphi.cos();
        let ra = a0 + s.atan2(c);
        let dec = sin_d.atan2(s.hypot(c));
        Vector3::new(dec.cos() * ra.cos(), dec.cos() * ra.sin(), dec.sin())
    }
}

/// Max pixel errors (world → pixel, pixel → world → camera pixel) over points in the field.
fn errors(camera: &Camera, r: &Matrix3<f64>, rng: &mut Rng) -> (f64, f64) {
    let wcs = parse(&wcs_header(camera, r));
    let (w, h) = (camera.width as f64, camera.height as f64);
    let mut pixels = vec![
        (-0.5, -0.5),
        (w - 0.5, -0.5),
        (-0.5, h - 0.5),
        (w - 0.5, h - 0.5),
    ];
    pixels.extend((0..60).map(|_| (rng.range(-0.5, w - 0.5), rng.range(-0.5, h - 0.5))));
    let (mut fwd, mut back) = (0.0f64, 0.0f64);
    for (x, y) in pixels {
        // A catalog-like direction in the field; its true pixel is the camera's forward model.
        let (uu, vu) = undistort_offset(camera, x - camera.cx, y - camera.cy);
        let m = if camera.mirrored { -1.0 } else { 1.0 };
        let d = r.transpose() * Vector3::new(uu / camera.fx, m * vu / camera.fy, 1.0).normalize();
        let (ex, ey) = camera.vector_to_pixel(&(r * d)).unwrap();
        let (wx, wy) = wcs
            .world_to_pixel(&d)
            .expect("in front of the tangent plane");
        fwd = fwd.max((wx - ex).hypot(wy - ey));
        let d2 = wcs.pixel_to_world(ex, ey);
        let (bx, by) = camera.vector_to_pixel(&(r * d2)).unwrap();
        back = back.max((bx - ex).hypot(by - ey));
    }
    (fwd, back)
}

#[test]
fn tan_header_matches_camera_model() {
    let mut rng = Rng(0x5EED_0001);
    let (mut fwd, mut back) = (0.0f64, 0.0f64);
    for _ in 0..300 {
        let cam = random_camera(&mut rng, false);
        let r = rng.rotation();
        let (f, b) = errors(&cam, &r, &mut rng);
        fwd = fwd.max(f);
        back = back.max(b);
        assert!(
            !wcs_header(&cam, &r)
                .iter()
                .any(|c| c.starts_with("A_ORDER"))
        );
    }
    eprintln!("TAN: max world->pixel {fwd:.2e} px, pixel->world {back:.2e} px");
    assert!(fwd < 0.01 && back < 0.01, "{fwd} {back}");
}

#[test]
fn sip_header_matches_camera_model() {
    let mut rng = Rng(0x5EED_0002);
    let (mut fwd, mut back) = (0.0f64, 0.0f64);
    for _ in 0..80 {
        let cam = random_camera(&mut rng, true);
        let r = rng.rotation();
        let (f, b) = errors(&cam, &r, &mut rng);
        fwd = fwd.max(f);
        back = back.max(b);
    }
    eprintln!("SIP: max world->pixel (AP/BP) {fwd:.2e} px, pixel->world (A/B) {back:.2e} px");
    // AP/BP are exact; A/B are a fit held to SIP_FIT_TARGET_PX.
    assert!(fwd < 1e-4, "{fwd}");
    assert!(back < 0.05, "{back}");
}

#[test]
fn poles_and_ra_wrap() {
    let mut rng = Rng(0x5EED_0003);
    let boresights = [
        Vector3::new(0.0, 0.0, 1.0),
        Vector3::new(0.0, 0.0, -1.0),
        Vector3::new(3e-10, -2e-10, 1.0),
        Vector3::new(-1e-10, 4e-10, -1.0),
        Vector3::new(1e-6, 0.0, 1.0),
        radec_vec(123.0, 89.9), // field contains the pole
        radec_vec(300.0, -89.5),
        radec_vec(1e-10, 12.0),
        radec_vec(360.0 - 1e-10, -30.0),
        radec_vec(0.0, 0.0),
    ];
    for (i, b) in boresights.iter().enumerate() {
        for distorted in [false, true] {
            let cam = random_camera(&mut rng, distorted);
            let r = attitude(*b, rng.range(0.0, 2.0 * PI));
            let wcs = parse(&wcs_header(&cam, &r));
            assert!((0.0..360.0).contains(&wcs.crval[0]), "{}", wcs.crval[0]);
            assert!(wcs.crval[1].abs() <= 90.0);
            let (f, back) = errors(&cam, &r, &mut rng);
            let limit = if distorted { 0.05 } else { 0.01 };
            assert!(f < 1e-4 && back < limit, "boresight {i}: {f} {back}");
        }
    }
}

#[test]
fn cd_matrix_follows_sky_orientation() {
    // Looking at RA 0, Dec 0 with north up (towards row 0): a true (unmirrored) view of
    // the sky has east on the left, so RA increases to decreasing columns.
    let cam = Camera::from_fov(1000, 800, 10.0).unwrap();
    let (east, north, b) = (Vector3::y(), Vector3::z(), Vector3::x());
    let r = Matrix3::from_rows(&[(-east).transpose(), (-north).transpose(), b.transpose()]);
    let wcs = parse(&wcs_header(&cam, &r));
    let scale = ((5.0f64).to_radians().tan() / 500.0).to_degrees(); // degrees per pixel
    assert!(wcs.crval[0].abs() < 1e-12 && wcs.crval[1].abs() < 1e-12);
    assert!((wcs.cd[0][0] + scale).abs() < 1e-12 * scale, "{:?}", wcs.cd);
    assert!((wcs.cd[1][1] + scale).abs() < 1e-12 * scale);
    assert!(wcs.cd[0][1].abs() < 1e-15 && wcs.cd[1][0].abs() < 1e-15);
    // A mirrored camera sees north at increasing rows instead.
    let mirrored = Camera {
        mirrored: true,
        ..cam.clone()
    };
    let r_m = Matrix3::from_rows(&[(-east).transpose(), north.transpose(), b.transpose()]);
    let wcs = parse(&wcs_header(&mirrored, &r_m));
    assert!(wcs.cd[0][0] < 0.0 && wcs.cd[1][1] < 0.0, "{:?}", wcs.cd);
}

#[test]
fn sip_fit_error_for_star_cameras() {
    // A typical star camera: order 5 is far inside the target.
    let mut cam = Camera::from_fov(2048, 1536, 15.0).unwrap();
    cam.k1 = -0.3;
    cam.k2 = 0.02;
    let sip = Sip::new(&cam);
    eprintln!(
        "15° FOV, k1 -0.3: order {}, fit error {:.2e} px",
        sip.order, sip.fit_error_px
    );
    assert_eq!(sip.order, 5);
    assert!(sip.fit_error_px < 1e-3);
    // A wide lens needs a higher order but stays within the target.
    let mut wide = Camera::from_fov(4000, 3000, 40.0).unwrap();
    wide.k1 = 0.3;
    wide.cx = 1500.0;
    let sip = Sip::new(&wide);
    eprintln!(
        "40° FOV, k1 0.3: order {}, fit error {:.2e} px",
        sip.order, sip.fit_error_px
    );
    assert!(sip.fit_error_px <= SIP_FIT_TARGET_PX);
    // Only k1: AP/BP of order 3.
    cam.k2 = 0.0;
    let sip = Sip::new(&cam);
    assert_eq!((sip.ap_order, sip.ap.len(), sip.bp.len()), (3, 2, 2));
}

#[test]
fn cards_are_fixed_format_fits() {
    let mut rng = Rng(0x5EED_0004);
    for distorted in [false, true] {
        let cam = random_camera(&mut rng, distorted);
        let r = rng.rotation();
        let cards = wcs_header(&cam, &r);
        assert!(cards[0].starts_with(&format!("SIMPLE  = {:>20} /", "T")));
        assert_eq!(cards.last().unwrap(), &format!("{:<80}", "END"));
        assert_eq!(cards.iter().filter(|c| c.starts_with("END ")).count(), 1);
        for card in &cards {
            assert_eq!(card.len(), 80, "{card:?}");
            assert!(card.bytes().all(|b| (32..127).contains(&b)), "{card:?}");
            let key = card[..8].trim_end();
            assert!(
                key.bytes()
                    .all(|b| b.is_ascii_uppercase() || b.is_ascii_digit() || b"-_".contains(&b)),
                "{card:?}"
            );
            if &card[8..10] == "= " {
                let value = &card[10..];
                if let Some(quoted) = value.strip_prefix('\'') {
                    // Fixed format: closing quote at column 20 or later.
                    assert!(quoted.find('\'').unwrap() >= 8, "{card:?}");
                } else {
                    // Numbers and logicals end in column 30.
                    assert!(card.as_bytes()[29] != b' ', "{card:?}");
                    assert!(card[10..30].trim().parse::<f64>().is_ok() || card[29..30] == *"T");
                }
            }
        }
        for key in [
            "SIMPLE", "BITPIX", "NAXIS", "WCSAXES", "CTYPE1", "CTYPE2", "CUNIT1", "CUNIT2",
            "CRVAL1", "CRVAL2", "CRPIX1", "CRPIX2", "CD1_1", "CD1_2", "CD2_1", "CD2_2", "EQUINOX",
            "RADESYS", "LONPOLE", "IMAGEW", "IMAGEH",
        ] {
            assert!(parse(&cards).keys.contains_key(key), "{key}");
        }
        let wcs = parse(&cards);
        assert_eq!(wcs.keys["IMAGEW"], cam.width.to_string());
        assert_eq!(wcs.keys["NAXIS"], "0");
        assert_eq!(
            wcs.keys["CTYPE2"],
            if distorted {
                "DEC--TAN-SIP"
            } else {
                "DEC--TAN"
            }
        );
        // Values round-trip to ~1e-13 relative.
        let tan = tan_frame(&cam, &r);
        for (got, want) in [
            (wcs.crval[0], tan.crval[0]),
            (wcs.crval[1], tan.crval[1]),
            (wcs.cd[0][0], tan.cd[0][0]),
            (wcs.cd[1][0], tan.cd[1][0]),
            (wcs.crpix[0], cam.cx + 1.0),
        ] {
            assert!(
                (got - want).abs() <= 1e-13 * want.abs().max(1.0),
                "{got} {want}"
            );
        }
    }
}

#[test]
fn file_is_padded_header_only_fits() {
    let dir = std::env::temp_dir().join(format!("gpustar_wcs_test_{}", std::process::id()));
    let path = dir.join("sub").join("frame.wcs");
    let mut cam = Camera::from_fov(640, 480, 12.0).unwrap();
    cam.k1 = 0.1;
    let r = attitude(radec_vec(10.0, 20.0), 0.3);
    write_wcs_file(&path, &cam, &r).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(bytes.len() % 2880, 0);
    let text = std::str::from_utf8(&bytes).unwrap();
    let cards = wcs_header(&cam, &r);
    assert!(text.starts_with(&cards.concat()));
    assert!(text[cards.len() * 80..].bytes().all(|b| b == b' '));
    // Bad inputs are refused with a message.
    let mut folded = Camera::from_fov(640, 480, 40.0).unwrap();
    folded.k1 = -2.0;
    let err = write_wcs_file(&path, &folded, &r).unwrap_err();
    assert!(format!("{err:#}").contains("distortion"), "{err:#}");
    cam.fx = f64::NAN;
    let err = write_wcs_file(&path, &cam, &r).unwrap_err();
    assert!(format!("{err:#}").contains("focal"));
}

#[test]
fn newton_undistortion_inverts_the_camera() {
    let mut rng = Rng(0x5EED_0005);
    for _ in 0..50 {
        let cam = random_camera(&mut rng, true);
        let (x, y) = (
            rng.range(0.0, cam.width as f64),
            rng.range(0.0, cam.height as f64),
        );
        let (uu, vu) = undistort_offset(&cam, x - cam.cx, y - cam.cy);
        let m = if cam.mirrored { -1.0 } else { 1.0 };
        let v = Vector3::new(uu / cam.fx, m * vu / cam.fy, 1.0);
        let (x2, y2) = cam.vector_to_pixel(&v).unwrap();
        assert!(
            (x2 - x).abs() < 1e-8 && (y2 - y).abs() < 1e-8,
            "{x},{y} -> {x2},{y2}"
        );
    }
}
