//! The result record: one JSON object per input file (spec/INTERFACE.md). Scripts parse these;
//! fields are only ever added.

use crate::camera::Camera;
use crate::error::{Context, Error, IntoKind, Result, fail};
use serde::{Deserialize, Serialize};
use std::path::Path;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Status {
    Solved,
    Unsolved,
    Error,
}

/// One identified star.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MatchRecord {
    pub x: f64,
    pub y: f64,
    /// The star's Hipparcos number; null for a star without one (Gaia, Tycho-2 and user
    /// catalogs' stars that the catalog does not cross-identify).
    pub hip: Option<u32>,
    /// Catalog position at the observation epoch.
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub mag: f64,
    pub flux: f64,
    pub residual_arcsec: f64,
    /// With `--centroid ml`: the position's 1σ per axis (pixels) from the PSF fit's Fisher
    /// information; absent for a centre of gravity.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_px: Option<f64>,
    /// The star's id in its catalog: "HIP 71683", "Gaia DR3 1576683529448755328",
    /// "TYC 4424-1234-1", or a user catalog's id verbatim (of a merged double: its brightest
    /// member's). Empty in records written before it existed.
    #[serde(default)]
    pub catalog_id: String,
}

/// The pointing hint a frame was solved with (`--hint`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HintRecord {
    pub ra_deg: f64,
    pub dec_deg: f64,
    pub radius_deg: f64,
    /// `--hint`, or the header keywords it was read from (e.g. `OBJCTRA/OBJCTDEC`).
    pub source: String,
    /// Angle between the hint and the solved boresight; null when unsolved.
    pub offset_deg: Option<f64>,
}

/// One end (or the midpoint) of a streak (spec/INTERFACE.md, "Streaks").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StreakEnd {
    pub x: f64,
    pub y: f64,
    /// ICRS direction through the plate solution ("as a star"); null without one.
    pub ra_deg: Option<f64>,
    pub dec_deg: Option<f64>,
    /// This end is where the streak leaves the frame, not where the object was at a known
    /// time: its time, Az and El are null. Absent on the midpoint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub edge: Option<bool>,
    /// Exposure start or end for an end inside the frame, mid-exposure for the midpoint.
    pub time_utc: Option<String>,
    /// Topocentric azimuth (from north through east) and elevation, airless; null without a
    /// station, a time or RA/Dec.
    pub az_deg: Option<f64>,
    pub el_deg: Option<f64>,
}

/// A satellite streak.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StreakRecord {
    /// The two ends; without `direction_known` their order is arbitrary (the first takes
    /// the exposure start).
    pub ends: [StreakEnd; 2],
    pub direction_known: bool,
    /// The midpoint at mid-exposure; null unless both ends are inside the frame.
    pub mid: Option<StreakEnd>,
    /// Between the two ends, in the frame.
    pub length_px: f64,
    /// FWHM of the profile across the track.
    pub width_px: f64,
    /// Background-subtracted flux of the part in the frame (ADU).
    pub flux: f64,
    /// Matched-filter signal-to-noise ratio of the part in the frame.
    pub snr: f64,
    /// RMS distance of the track's local centroids from the fitted line.
    pub fit_rms_px: f64,
    /// The station that observed it, as the TDM names it: the header's OBSERVAT, SITE or
    /// TELESCOP, and the coordinates Az/El are reduced for (`--station` or the header's);
    /// null when neither is known. Absent from records of earlier versions.
    #[serde(default)]
    pub station: Option<String>,
    /// The tracklet this streak belongs to: streaks of one object in consecutive frames of a
    /// directory, named by its first streak, `FILE#N` (N counts that record's streaks from
    /// 1). Absent from records of earlier versions.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracklet: Option<String>,
    /// This streak's place in its tracklet, from 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tracklet_index: Option<usize>,
    /// With `--tle`: the object of the file whose predicted path the streak lies on; null
    /// when none does (then `uncorrelated` is true). Absent without `--tle`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub satellite: Option<SatelliteRecord>,
    /// With `--tle`: true when the streak could be tested and no object of the file matched,
    /// false when one did; absent without `--tle` or where the frame gave no RA/Dec, time or
    /// station to test with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncorrelated: Option<bool>,
    /// The ends the other way along the streak (positions swapped, each end's time kept, Az/El
    /// recomputed for it), for the tracklet stage to turn the streak once it knows the
    /// direction. Never written.
    #[serde(skip)]
    pub reversed: Option<Box<[StreakEnd; 2]>>,
    /// The frame's exposure start and end (UTC, as the ends' times), for the tracklet stage:
    /// an end on the frame's edge has no time. Never written.
    #[serde(skip)]
    pub exposure_utc: Option<[String; 2]>,
}

impl StreakRecord {
    /// A streak of the streak modules' tests: these ends (and the other way along,
    /// `reversed`), a nominal width, flux and SNR, nothing linked or named yet.
    #[cfg(test)]
    pub(crate) fn for_tests(
        ends: [StreakEnd; 2],
        reversed: [StreakEnd; 2],
        length_px: f64,
        exposure_utc: Option<[String; 2]>,
    ) -> StreakRecord {
        StreakRecord {
            ends,
            direction_known: false,
            mid: None,
            length_px,
            width_px: 3.0,
            flux: 1e4,
            snr: 50.0,
            fit_rms_px: 0.2,
            station: None,
            tracklet: None,
            tracklet_index: None,
            satellite: None,
            uncorrelated: None,
            reversed: Some(Box::new(reversed)),
            exposure_utc,
        }
    }

    /// Turn the streak the other way along (ends swapped, times kept); false when it cannot
    /// be (no reversed ends were made).
    pub fn reverse(&mut self) -> bool {
        match self.reversed.as_mut() {
            Some(r) => {
                std::mem::swap(&mut self.ends, r);
                true
            }
            None => false,
        }
    }
}

/// The object a streak was matched to (`--tle`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SatelliteRecord {
    /// The NORAD catalog number.
    pub norad: u64,
    /// The file's name for it (empty when it gives none).
    pub name: String,
    /// International designator as the file gives it (`98067A`, `1998-067A`).
    pub intl_des: Option<String>,
    /// The ends' mean distance across the predicted path (arcsec; positive towards the pole
    /// of the motion, start × end).
    pub cross_track_arcsec: f64,
    /// The time offset along the path (s): the streak is where the elements put the object
    /// this much later (positive: the object is ahead of its elements). For a partial match
    /// (`seen_fraction`), the offset nearest 0 that keeps the whole streak on the path the
    /// exposure covers.
    pub along_track_s: f64,
    /// Present when the streak covers less than 90 % of the path the elements predict over
    /// the exposure (the share it covers): the object was dark over the rest (a tumbling
    /// object's dark face, its shadow), so its ends are not its positions at the exposure's
    /// start and end, and its observations are left out of `--tdm` and `--iod`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seen_fraction: Option<f64>,
}

/// Milliseconds spent per stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Timing {
    pub decode: f64,
    pub detect: f64,
    pub identify: f64,
    pub total: f64,
}

impl Timing {
    /// Each stage's time, and their sum as the total.
    pub fn of(decode: f64, detect: f64, identify: f64) -> Timing {
        let total = decode + detect + identify;
        Timing {
            decode,
            detect,
            identify,
            total,
        }
    }
}

/// The record of one input file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Record {
    /// Path relative to the batch directory (or as given to `solve`).
    pub file: String,
    pub status: Status,
    /// Why an unsolved frame is unsolved: too_few_stars | no_consistent_match | low_confidence.
    pub reason: Option<String>,
    /// What went wrong with an `error` record, for a person to act on.
    pub error: Option<String>,
    pub ra_deg: Option<f64>,
    pub dec_deg: Option<f64>,
    pub roll_deg: Option<f64>,
    pub quaternion: Option<[f64; 4]>,
    pub rotation_matrix: Option<[[f64; 3]; 3]>,
    /// Field of view of the solution: the camera's, or the fitted one when the scale was
    /// searched or fitted.
    pub fov_x_deg: Option<f64>,
    pub fov_y_deg: Option<f64>,
    pub stars_detected: Option<usize>,
    pub stars_matched: Option<usize>,
    pub rmse_arcsec: Option<f64>,
    pub p90_arcsec: Option<f64>,
    pub max_arcsec: Option<f64>,
    pub false_match_prob: Option<f64>,
    pub matches: Option<Vec<MatchRecord>>,
    pub timing_ms: Timing,
    pub backend: String,
    /// Radial distortion k1 fitted by refinement (`--fit distortion`); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub distortion_k1: Option<f64>,
    /// Solved records, where the parity was searched (`--fov-deg`, `--parity either`) or the
    /// camera is mirrored: whether the image is a mirror image of the sky (+Y then points to
    /// decreasing row; a FITS image stored the conventional way, north up and east left, is).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mirrored: Option<bool>,
    /// Epoch (Julian year) of the catalog positions the solution used: the run's `--epoch`,
    /// or the frame's own date (FITS DATE-OBS); solved records only.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epoch: Option<f64>,
    /// Problems that did not stop the solution (e.g. a product file that could not be
    /// written); absent when there were none.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub warnings: Vec<String>,
    /// With `--streaks`: the frame's satellite streaks (an empty list when none); absent
    /// otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub streaks: Option<Vec<StreakRecord>>,
    /// With `--hint`: the frame's pointing hint (absent when it had none).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub hint: Option<HintRecord>,
    /// Solved records: the attitude's 1σ (arcsec) from its matches (Shuster's covariance
    /// [Σ(I − bbᵀ)/σ_i²]⁻¹, σ_i each match's 1σ: the residuals' rms per axis, or with
    /// `--centroid ml` the PSF fit's with `sigma_floor_px` in quadrature): `boresight` about the
    /// two axes across the line of sight together, `roll` about it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub attitude_sigma_arcsec: Option<AttitudeSigma>,
    /// Solved records: how far the rotation matrix is from a rotation, ‖RRᵀ − I‖ (Frobenius),
    /// and its determinant (seed 003's check; a warning beyond 1e-9).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub orthogonality_error: Option<f64>,
    /// With `--centroid ml`: the floor (pixels) added in quadrature to the PSF fits' 1σ so that
    /// the residuals' χ² equals its degrees of freedom (what photon noise does not explain: the
    /// camera model, the catalog); the matches are weighted by 1/(σ² + floor²).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sigma_floor_px: Option<f64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub determinant: Option<f64>,
    /// With `--sequence`: how the frame was identified, `tracking` (from the attitude the
    /// previous frames predict) or `lost_in_space`; absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sequence_mode: Option<String>,
    /// With `--sequence`: detections judged to move against the star field (never used as
    /// stars; an empty list when none); absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub particles: Option<Vec<ParticleRecord>>,
    /// Without --camera, --fov-deg or --scale-arcsec: the pixel scale the frame's header
    /// stated, which its camera was made from; absent otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub pixel_scale: Option<PixelScaleRecord>,
    /// Solved records: the camera of the solution (the fitted scale, distortion and parity),
    /// which with `rotation_matrix` is the plate solution `--wcs-dir` writes; for the Python
    /// package's `Result.wcs()` and `pixel_to_sky`. Never written (a record read back has
    /// none).
    #[serde(skip)]
    pub camera: Option<Camera>,
}

/// The pixel scale a frame's header stated (`io::fits::scale`), as its record gives it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PixelScaleRecord {
    /// The angle one pixel's width subtends, arcseconds (the search around it fits the
    /// solution's: `fov_x_deg`).
    pub arcsec_per_px: f64,
    /// A pixel's height over its width.
    pub pixel_aspect: f64,
    /// The keywords it was read from, e.g. "FOCALLEN, XPIXSZ".
    pub source: String,
}

/// The attitude's 1σ (arcsec).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AttitudeSigma {
    pub boresight: f64,
    pub roll: f64,
}

/// A detection judged to be a moving particle (`--sequence`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ParticleRecord {
    pub x: f64,
    pub y: f64,
    /// Its velocity against the stars, in this frame's pixels per second; null for a
    /// particle seen in this frame only (judged by what the previous frame did not show).
    pub vx_px_s: Option<f64>,
    pub vy_px_s: Option<f64>,
}

impl Record {
    /// The names of a record's fields, as JSON writes them (its whole schema's names, present
    /// or not in a given record): read from the `Deserialize` impl, so never out of date.
    pub fn field_names() -> &'static [&'static str] {
        static NAMES: std::sync::OnceLock<&'static [&'static str]> = std::sync::OnceLock::new();
        NAMES.get_or_init(struct_fields::<Record>)
    }

    pub fn empty(file: &str, backend: &str) -> Record {
        Record {
            file: file.to_string(),
            status: Status::Unsolved,
            reason: None,
            error: None,
            ra_deg: None,
            dec_deg: None,
            roll_deg: None,
            quaternion: None,
            rotation_matrix: None,
            fov_x_deg: None,
            fov_y_deg: None,
            stars_detected: None,
            stars_matched: None,
            rmse_arcsec: None,
            p90_arcsec: None,
            max_arcsec: None,
            false_match_prob: None,
            matches: None,
            timing_ms: Timing::default(),
            backend: backend.to_string(),
            distortion_k1: None,
            mirrored: None,
            epoch: None,
            warnings: Vec::new(),
            streaks: None,
            hint: None,
            attitude_sigma_arcsec: None,
            orthogonality_error: None,
            sigma_floor_px: None,
            determinant: None,
            sequence_mode: None,
            particles: None,
            pixel_scale: None,
            camera: None,
        }
    }

    pub fn error(file: &str, message: String, backend: &str) -> Record {
        Record {
            status: Status::Error,
            error: Some(message),
            ..Record::empty(file, backend)
        }
    }

    /// The record as one line of JSON (no newline).
    pub fn to_json_line(&self) -> String {
        serde_json::to_string(self).expect("records serialise")
    }
}

/// The JSON names of the fields of a struct `T` (those `#[serde(skip)]` leaves out are not
/// among them), as serde's derived `Deserialize` lists them to a deserializer.
fn struct_fields<'de, T: Deserialize<'de>>() -> &'static [&'static str] {
    use serde::de::{self, Visitor};
    /// A deserializer that only notes the field list serde asks a struct for.
    struct Fields<'a>(&'a mut &'static [&'static str]);
    impl<'de> de::Deserializer<'de> for Fields<'_> {
        type Error = de::value::Error;
        fn deserialize_any<V: Visitor<'de>>(
            self,
            _: V,
        ) -> std::result::Result<V::Value, Self::Error> {
            Err(de::Error::custom("only the field names are read"))
        }
        fn deserialize_struct<V: Visitor<'de>>(
            self,
            _: &'static str,
            fields: &'static [&'static str],
            _: V,
        ) -> std::result::Result<V::Value, Self::Error> {
            *self.0 = fields;
            Err(de::Error::custom("only the field names are read"))
        }
        serde::forward_to_deserialize_any! {
            bool i8 i16 i32 i64 i128 u8 u16 u32 u64 u128 f32 f64 char str string bytes
            byte_buf option unit unit_struct newtype_struct seq tuple tuple_struct map enum
            identifier ignored_any
        }
    }
    let mut names: &'static [&'static str] = &[];
    let _ = T::deserialize(Fields(&mut names));
    names
}

/// gpustar's one JSON Lines reader (result records, truth files): every line one `T`, blank
/// lines skipped. A last line without its newline is a run that did not finish (a crash
/// mid-write): an error, not a record quietly dropped. `what` names the records in messages.
pub fn read_jsonl<T: serde::de::DeserializeOwned>(path: &Path, what: &str) -> Result<Vec<T>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read {what}s {}", path.display()))?;
    if !text.is_empty() && !text.ends_with('\n') {
        fail!(
            Input,
            "{} ends with an incomplete {what}: that run did not finish; run it again with \
             --resume",
            path.display()
        );
    }
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(n, l)| {
            serde_json::from_str(l)
                .into_kind(Error::Input)
                .with_context(|| format!("{}: line {}: not a {what}", path.display(), n + 1))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn field_names_are_every_field_a_record_can_write() {
        let names = Record::field_names();
        assert!(names.len() > 30, "{names:?}");
        let mut r = Record::error("f", "e".into(), "cpu");
        r.hint = Some(HintRecord {
            ra_deg: 1.0,
            dec_deg: 2.0,
            radius_deg: 1.0,
            source: "--hint".into(),
            offset_deg: None,
        });
        r.pixel_scale = Some(PixelScaleRecord {
            arcsec_per_px: 1.0,
            pixel_aspect: 1.0,
            source: "SECPIX".into(),
        });
        let written = serde_json::to_value(&r).unwrap();
        for key in written.as_object().unwrap().keys() {
            assert!(names.contains(&key.as_str()), "{key} not in {names:?}");
        }
        for key in [
            "file",
            "status",
            "ra_deg",
            "matches",
            "false_match_prob",
            "pixel_scale",
        ] {
            assert!(names.contains(&key), "{key}");
        }
    }

    /// docs/record.schema.json, the record's JSON Schema.
    fn schema() -> serde_json::Value {
        serde_json::from_str(include_str!("../docs/record.schema.json"))
            .expect("the schema is JSON")
    }

    fn keys(v: &serde_json::Value) -> std::collections::BTreeSet<String> {
        v.as_object()
            .unwrap_or_else(|| panic!("not an object: {v}"))
            .keys()
            .cloned()
            .collect()
    }

    fn required(v: &serde_json::Value) -> std::collections::BTreeSet<String> {
        let list = v["required"].as_array();
        let list = list.unwrap_or_else(|| panic!("no required list: {v}"));
        list.iter()
            .map(|k| k.as_str().unwrap().to_string())
            .collect()
    }

    fn set(names: &[&str]) -> std::collections::BTreeSet<String> {
        names.iter().map(|n| n.to_string()).collect()
    }

    /// Issue 47, item 6: docs/record.schema.json names exactly the fields a record can have, at
    /// the top level (`Record::field_names`) and in every nested object, closes each object
    /// (`additionalProperties: false`) and requires exactly the fields always written (those
    /// without `skip_serializing_if`): a field added to a record and not to the schema fails
    /// here, and the Python tests validate the records the command line writes against it.
    #[test]
    fn the_schema_has_exactly_the_records_fields() {
        let s = schema();
        assert_eq!(s["$schema"], "https://json-schema.org/draft/2020-12/schema");
        assert_eq!(keys(&s["properties"]), set(Record::field_names()));
        assert_eq!(s["additionalProperties"], false);
        let written = |v: &dyn erased::Ser| keys(&v.value());
        assert_eq!(required(&s), written(&Record::empty("f", "cpu")));

        let end = |edge| StreakEnd {
            x: 1.0,
            y: 2.0,
            ra_deg: None,
            dec_deg: None,
            edge,
            time_utc: None,
            az_deg: None,
            el_deg: None,
        };
        let streak = StreakRecord::for_tests(
            [end(Some(false)), end(Some(true))],
            [end(Some(true)), end(Some(false))],
            10.0,
            None,
        );
        let matched = MatchRecord {
            x: 1.0,
            y: 2.0,
            hip: None,
            ra_deg: 0.0,
            dec_deg: 0.0,
            mag: 1.0,
            flux: 1.0,
            residual_arcsec: 1.0,
            sigma_px: None,
            catalog_id: String::new(),
        };
        let hint = HintRecord {
            ra_deg: 1.0,
            dec_deg: 2.0,
            radius_deg: 1.0,
            source: "--hint".into(),
            offset_deg: None,
        };
        let satellite = SatelliteRecord {
            norad: 25544,
            name: String::new(),
            intl_des: None,
            cross_track_arcsec: 0.0,
            along_track_s: 0.0,
            seen_fraction: None,
        };
        let scale = PixelScaleRecord {
            arcsec_per_px: 1.0,
            pixel_aspect: 1.0,
            source: "SECPIX".into(),
        };
        let sigma = AttitudeSigma {
            boresight: 1.0,
            roll: 1.0,
        };
        let particle = ParticleRecord {
            x: 1.0,
            y: 1.0,
            vx_px_s: None,
            vy_px_s: None,
        };
        // Each object of the schema: its fields (from `Deserialize`) and one value of it with
        // every optional field left out.
        let objects: [(&str, &[&str], &dyn erased::Ser); 9] = [
            ("match", struct_fields::<MatchRecord>(), &matched),
            ("timing", struct_fields::<Timing>(), &Timing::default()),
            ("hint", struct_fields::<HintRecord>(), &hint),
            ("streak", struct_fields::<StreakRecord>(), &streak),
            ("streak_end", struct_fields::<StreakEnd>(), &end(None)),
            ("satellite", struct_fields::<SatelliteRecord>(), &satellite),
            ("attitude_sigma", struct_fields::<AttitudeSigma>(), &sigma),
            ("pixel_scale", struct_fields::<PixelScaleRecord>(), &scale),
            ("particle", struct_fields::<ParticleRecord>(), &particle),
        ];
        let defs = &s["$defs"];
        for (name, fields, value) in objects {
            let def = &defs[name];
            assert_eq!(keys(&def["properties"]), set(fields), "$defs/{name}");
            assert_eq!(def["additionalProperties"], false, "$defs/{name}");
            assert_eq!(required(def), written(value), "$defs/{name}");
        }
    }

    /// The schema's enums are the code's sets: every `Outcome::Unsolved` reason in src/ and
    /// both sequence modes.
    #[test]
    fn the_schemas_enums_are_the_codes() {
        let s = schema();
        let listed = |v: &serde_json::Value| -> std::collections::BTreeSet<String> {
            v.as_array()
                .unwrap_or_else(|| panic!("not an enum: {v}"))
                .iter()
                .map(|x| x.as_str().unwrap().to_string())
                .collect()
        };
        let reasons: std::collections::BTreeSet<String> = (crate::solve::Unsolved::ALL.iter())
            .map(|r| r.as_str().to_string())
            .collect();
        assert!(reasons.contains("too_few_stars"), "{reasons:?}");
        assert_eq!(
            listed(&s["properties"]["reason"]["oneOf"][0]["enum"]),
            reasons
        );
        assert_eq!(
            listed(&s["properties"]["sequence_mode"]["enum"]),
            set(&[crate::sequence::TRACKING, crate::sequence::LOST_IN_SPACE])
        );
        assert_eq!(
            listed(&s["properties"]["status"]["enum"]),
            [Status::Solved, Status::Unsolved, Status::Error]
                .iter()
                .map(|st| serde_json::to_value(st)
                    .unwrap()
                    .as_str()
                    .unwrap()
                    .to_string())
                .collect()
        );
    }

    /// Values of different types serialised alike, for the table above.
    mod erased {
        pub trait Ser {
            fn value(&self) -> serde_json::Value;
        }
        impl<T: serde::Serialize> Ser for T {
            fn value(&self) -> serde_json::Value {
                serde_json::to_value(self).expect("serialises")
            }
        }
    }
}
