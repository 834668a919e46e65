//! `gpustar simulate --hint-offset-deg D`: frames written as 16-bit FITS whose header says where
//! the frame points, off by D degrees in a direction drawn per frame, as a telescope's pointing
//! model or a mount's encoders would say it: `OBJCTRA`/`OBJCTDEC` (sexagesimal, RA in hours
//! 'HH MM SS.ss', Dec '+DD MM SS.s'), `RA`/`DEC` (degrees), `DATE-OBS` (the epoch of the star
//! positions) and `EXPTIME`. `batch --hint header` reads them back (`sky::hint`).

use crate::catalog::{radec_to_vector, vector_to_radec};
use crate::io::fits::{card_comment, card_real, card_str};
use nalgebra::Vector3;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// What the header hints of a simulated set are like.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct HintSim {
    /// How far the hint lies from the frame's centre, degrees.
    pub offset_deg: f64,
    /// The exposure time written as `EXPTIME`, seconds.
    pub exposure_s: f64,
}

/// The hint a frame's header carries, in its truth record.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthHint {
    /// Where the header says the frame points (ICRS, degrees): `RA`/`DEC` as written;
    /// `OBJCTRA`/`OBJCTDEC` are these rounded to 0.01 s and 0.1″.
    pub ra_deg: f64,
    pub dec_deg: f64,
    /// Its distance from the frame's true centre, degrees.
    pub offset_deg: f64,
    /// The direction it is off in, from north through east, degrees.
    pub position_angle_deg: f64,
}

/// The name of frame k of a set with hints.
pub fn frame_name(index: usize) -> String {
    format!("sim_{index:05}.fits")
}

/// The hint of frame `index` of the set of `seed`: the true centre (`ra_deg`, `dec_deg`, the
/// truth's) moved by `h.offset_deg` toward a position angle drawn uniformly from a stream of
/// the frame's own (seed, index), so that the frame's pixels are those it would have without
/// a hint.
pub fn hint_for(ra_deg: f64, dec_deg: f64, seed: u64, h: &HintSim, index: usize) -> TruthHint {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x4849_4E54);
    rng.set_stream(index as u64);
    let pa = rng.random_range(0.0..std::f64::consts::TAU);
    let centre = radec_to_vector(ra_deg, dec_deg);
    let hint = offset_towards(&centre, h.offset_deg.to_radians(), pa);
    let (ra_deg, dec_deg) = vector_to_radec(&hint);
    TruthHint {
        ra_deg,
        dec_deg,
        offset_deg: crate::camera::angle(&centre, &hint).to_degrees(),
        position_angle_deg: pa.to_degrees(),
    }
}

/// `v` (a unit vector) moved by `angle` toward position angle `pa` (from north through east),
/// radians; at a pole, north is taken as the direction of RA 180°.
fn offset_towards(v: &Vector3<f64>, angle: f64, pa: f64) -> Vector3<f64> {
    let east = Vector3::z().cross(v);
    let east = if east.norm() < 1e-12 {
        Vector3::y()
    } else {
        east.normalize()
    };
    let north = v.cross(&east);
    (v * angle.cos() + (north * pa.cos() + east * pa.sin()) * angle.sin()).normalize()
}

/// The header cards of a frame with this hint, taken at `epoch` (Julian year) for
/// `exposure_s` seconds.
pub fn header_cards(hint: &TruthHint, epoch: f64, exposure_s: f64) -> Vec<String> {
    vec![
        card_str(
            "DATE-OBS",
            &crate::sky::iso_of_julian_year(epoch),
            "epoch of the star positions",
        ),
        card_real("EXPTIME", exposure_s, "[s]"),
        card_str(
            "OBJCTRA",
            &sexagesimal(hint.ra_deg / 15.0, 2, false),
            "pointing hint, RA [h m s]",
        ),
        card_str(
            "OBJCTDEC",
            &sexagesimal(hint.dec_deg, 1, true),
            "pointing hint, Dec [d m s]",
        ),
        card_real("RA", hint.ra_deg, "[deg] pointing hint"),
        card_real("DEC", hint.dec_deg, "[deg] pointing hint"),
        card_comment(&format!(
            "gpustar simulate: the hint is {:.6} deg off the true centre",
            hint.offset_deg
        )),
    ]
}

/// `value` (hours or degrees) as 'DD MM SS.s…' with `decimals` decimals of seconds, the
/// rounding carried up; `signed` writes a sign (Dec), else the value wraps at 24 (RA hours).
fn sexagesimal(value: f64, decimals: u32, signed: bool) -> String {
    let scale = 10i64.pow(decimals);
    let mut total = (value.abs() * 3600.0 * scale as f64).round() as i64;
    if !signed {
        total = total.rem_euclid(24 * 3600 * scale);
    }
    let (units, rest) = (total / (3600 * scale), total % (3600 * scale));
    let (minutes, seconds) = (rest / (60 * scale), rest % (60 * scale));
    let (whole, fraction) = (seconds / scale, seconds % scale);
    let sign = match (signed, value < 0.0 && total > 0) {
        (false, _) => "",
        (true, true) => "-",
        (true, false) => "+",
    };
    let fraction = if decimals > 0 {
        format!(".{fraction:0width$}", width = decimals as usize)
    } else {
        String::new()
    };
    format!("{sign}{units:02} {minutes:02} {whole:02}{fraction}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::simulate::{SimSettings, Truth};
    use crate::sky::hint::hint_from_header;

    #[test]
    fn sexagesimal_rounds_and_carries() {
        assert_eq!(sexagesimal(12.5, 2, false), "12 30 00.00");
        assert_eq!(sexagesimal(23.999_999_99, 2, false), "00 00 00.00");
        assert_eq!(sexagesimal(-45.5, 1, true), "-45 30 00.0");
        assert_eq!(sexagesimal(-0.1, 1, true), "-00 06 00.0");
        assert_eq!(sexagesimal(10.0 - 1e-9, 1, true), "+10 00 00.0");
        assert_eq!(sexagesimal(0.0, 1, true), "+00 00 00.0");
    }

    /// A header written for a hint reads back, through the FITS reader and `hint_from_header`
    /// (which prefers the sexagesimal OBJCTRA/OBJCTDEC), to that hint within 1″, and its
    /// DATE-OBS to the epoch.
    #[test]
    fn written_headers_read_back_to_their_hint() {
        let s = SimSettings::default();
        let h = HintSim {
            offset_deg: 0.3,
            exposure_s: 2.0,
        };
        for (k, (ra, dec)) in [
            (187.5, -45.5),
            (0.001, 0.02),
            (359.9999, -0.05),
            (45.0, 89.9),
            (300.0, -89.95),
            (12.345678, 33.333333),
        ]
        .into_iter()
        .enumerate()
        {
            let truth = Truth {
                file: frame_name(k),
                ra_deg: ra,
                dec_deg: dec,
                roll_tetra3_deg: 0.0,
                rotation_matrix: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
                quaternion: [1.0, 0.0, 0.0, 0.0],
                epoch: 2024.5,
                mirrored: false,
                width: 4,
                height: 3,
                fov_x_deg: 1.0,
                fov_y_deg: 0.75,
                stars: Vec::new(),
                false_stars: Vec::new(),
                hint: None,
            };
            let hint = hint_for(truth.ra_deg, truth.dec_deg, s.seed, &h, k);
            assert!((hint.offset_deg - 0.3).abs() < 1e-9, "{hint:?}");
            let bytes = crate::io::fits::encode_u16(
                4,
                3,
                &[100; 12],
                &header_cards(&hint, truth.epoch, h.exposure_s),
            );
            let f = crate::io::fits::decode_fits(&bytes, 1 << 20).unwrap();
            assert!((f.epoch.unwrap() - 2024.5).abs() < 1e-9, "{:?}", f.epoch);
            assert_eq!(f.keywords["EXPTIME"].parse::<f64>().unwrap(), 2.0);
            let read = hint_from_header(&|key| f.keywords.get(key).cloned(), (4, 3), 1.0).unwrap();
            assert_eq!(read.source, "OBJCTRA/OBJCTDEC");
            let off = crate::camera::angle(
                &radec_to_vector(read.ra_deg, read.dec_deg),
                &radec_to_vector(hint.ra_deg, hint.dec_deg),
            );
            assert!(off.to_degrees() * 3600.0 < 1.0, "{hint:?} read as {read:?}");
            // RA/DEC in degrees carry it to the last digits.
            let ra: f64 = f.keywords["RA"].parse().unwrap();
            let dec: f64 = f.keywords["DEC"].parse().unwrap();
            assert!((ra - hint.ra_deg).abs() < 1e-9 && (dec - hint.dec_deg).abs() < 1e-9);
        }
    }
}
