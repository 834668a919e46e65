//! The TDM and IOD writers read back by the test-side parsers (`common::formats`): round
//! trips, the parsers' checks and errors, and the UTC strings the writers accept.
//!
//! Size: about 940 lines, over the ~700 guideline, because most of it is tables (the Annex E
//! style example, one line per error case of each parser, writer refusals as struct literals)
//! that read best beside the round trips they complement.

use crate::common::formats::{mx_decode, parse_iod_line, parse_tdm};
use gpustar::sky::Utc;
use gpustar::streaks::formats::{AngleObs, IodObs, Track, iod_line, tdm_text, write_tdm};

// ---------------------------------------------------------------- time

/// `Utc::parse(..).iso()`: the reading and the millisecond rounding both writers use.
fn iso(s: &str) -> Result<String, String> {
    Utc::parse(s).map(|t| t.iso()).map_err(|e| e.to_string())
}

#[test]
fn utc_parses_normalises_and_carries() {
    assert_eq!(
        iso("2026-04-15T07:37:12.322").unwrap(),
        "2026-04-15T07:37:12.322"
    );
    assert_eq!(
        iso("2026-04-15T07:37:12").unwrap(),
        "2026-04-15T07:37:12.000"
    );
    assert_eq!(
        iso("2026-04-15T07:37:12.3Z").unwrap(),
        "2026-04-15T07:37:12.300"
    );
    assert_eq!(
        iso("2026-04-15T07:37:12.32249").unwrap(),
        "2026-04-15T07:37:12.322"
    );
    assert_eq!(
        iso("2026-04-15T07:37:12.3225").unwrap(),
        "2026-04-15T07:37:12.323"
    );
    // SOFA rounds the binary day fraction, not the decimal digits: an exact half
    // millisecond can go down (12.0075 is held just below), where a decimal half-up
    // rounding would give .008.
    assert_eq!(
        iso("2026-04-15T07:37:12.0075").unwrap(),
        "2026-04-15T07:37:12.007"
    );
    // The carry runs through the calendar, including a leap day and the year.
    assert_eq!(
        iso("2024-02-28T23:59:59.9996").unwrap(),
        "2024-02-29T00:00:00.000"
    );
    assert_eq!(
        iso("2023-12-31T23:59:59.99951").unwrap(),
        "2024-01-01T00:00:00.000"
    );
    // An explicit leap second is kept, and the carry knows the leap-second table: on
    // 2016-12-31 the second after 23:59:59 is 23:59:60.
    assert_eq!(
        iso("2016-12-31T23:59:60.500").unwrap(),
        "2016-12-31T23:59:60.500"
    );
    assert_eq!(
        iso("2016-12-31T23:59:59.9996").unwrap(),
        "2016-12-31T23:59:60.000"
    );
    assert_eq!(
        iso("2016-12-31T23:59:60.9996").unwrap(),
        "2017-01-01T00:00:00.000"
    );
    // The shorter forms the one ISO parser also reads.
    assert_eq!(iso("2026-04-15").unwrap(), "2026-04-15T00:00:00.000");
    assert_eq!(
        iso("2026-04-15 07:37:12").unwrap(),
        "2026-04-15T07:37:12.000"
    );
    for (bad, why) in [
        ("", "not a YYYY-MM-DD date"),
        ("yesterday", "not a YYYY-MM-DD date"),
        ("2026-13-15T07:37:12", "bad month"),
        ("2023-02-29T07:37:12", "bad day"),
        ("2026-04-15T24:00:00", "bad hour"),
        ("2026-04-15T07:60:00", "bad minute"),
        ("2026-04-15T07:37:60", "seconds out of range"),
        ("2016-12-31T23:59:61", "seconds out of range"),
        ("2026-04-15T07:37:12.", "not a hh:mm:ss[.fff] time"),
        ("2026-04-15T07:37:12,5", "not a hh:mm:ss[.fff] time"),
        ("2026-04-15T07:37:1x", "not a hh:mm:ss[.fff] time"),
        ("2026-04-15T07:38", "not a hh:mm:ss[.fff] time"),
        ("2026-04-15T07:37:12.5ZZ", "not a hh:mm:ss[.fff] time"),
        ("２026-04-15T07:37:12", "not a YYYY-MM-DD date"),
    ] {
        let e = iso(bad).unwrap_err();
        assert!(e.contains(why), "{bad:?}: {e}");
        // The writers name the time and say what is wrong with it.
        let mut o = sample_obs(0.0, 0.0);
        o.time_utc = bad.to_string();
        let e = iod_line(&o).unwrap_err().to_string();
        assert!(
            e.contains(&format!("time '{}'", bad.escape_default())) && e.contains(why),
            "{bad:?}: {e}"
        );
    }
}

/// The strings gpustar passes ("YYYY-MM-DDThh:mm:ss.sss") come out of both writers as they
/// went in, for every millisecond of a leap second, a leap day's last second and others.
/// (Not on the UTC days of 1961-1971 that end in a fractional step: there SOFA's dtf2d
/// scales the day by the step and d2dtf does not, so `Utc` moves such a time by up to 0.1 s.)
#[test]
fn millisecond_strings_pass_through_unchanged() {
    for base in [
        "2016-12-31T23:59:59",
        "2016-12-31T23:59:60",
        "2024-02-28T23:59:59",
        "2026-04-15T07:37:12",
        "1972-06-30T23:59:60",
        "1999-12-31T23:59:59",
        "2099-12-31T00:00:00",
    ] {
        for ms in 0..1000 {
            let t = format!("{base}.{ms:03}");
            assert_eq!(iso(&t).unwrap(), t);
            let mut o = sample_obs(0.0, 0.0);
            o.time_utc = t.clone();
            let digits: String = t.chars().filter(char::is_ascii_digit).collect();
            assert_eq!(iod_line(&o).unwrap()[23..40], digits);
        }
    }
}

#[test]
fn writers_carry_rounding_into_the_calendar_and_refuse_year_10000() {
    let digits = |t: &str| {
        let mut o = sample_obs(0.0, 0.0);
        o.time_utc = t.to_string();
        iod_line(&o)
            .map(|l| l[23..40].to_string())
            .map_err(|e| e.to_string())
    };
    assert_eq!(
        digits("2016-12-31T23:59:59.9996").unwrap(),
        "20161231235960000"
    );
    assert_eq!(
        digits("2016-12-31T23:59:60.9996").unwrap(),
        "20170101000000000"
    );
    assert_eq!(
        digits("2024-02-28T23:59:59.9996").unwrap(),
        "20240229000000000"
    );
    assert_eq!(digits("0000-01-01T00:00:00").unwrap(), "00000101000000000");
    let e = digits("9999-12-31T23:59:59.9996").unwrap_err();
    assert!(e.contains("year 10000"), "{e}");
    let track = Track {
        object: "X".to_string(),
        station: "GPUSTAR".to_string(),
        observations: vec![obs("9999-12-31T23:59:59.9996", 1.0, 2.0, None)],
    };
    let e = tdm_text("2026-04-16T10:00:00", "GPUSTAR", &[track])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("observation 1: time") && e.contains("year 10000"),
        "{e}"
    );
    let e = tdm_text("9999-12-31T23:59:59.9996", "GPUSTAR", &[])
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("CREATION_DATE") && e.contains("year 10000"),
        "{e}"
    );
    // A leap second read from a line is kept; second 60 elsewhere is refused.
    let mut o = sample_obs(0.0, 0.0);
    o.time_utc = "2016-12-31T23:59:60.500".to_string();
    let line = iod_line(&o).unwrap();
    assert_eq!(&line[23..40], "20161231235960500");
    assert_eq!(parse_iod_line(&line).unwrap().time_utc, o.time_utc);
    let mut bad = line.clone();
    bad.replace_range(23..31, "20161230");
    let e = parse_iod_line(&bad).unwrap_err();
    assert!(
        e.contains("columns 24-40") && e.contains("seconds out of range"),
        "{e}"
    );
}

// ---------------------------------------------------------------- TDM

fn obs(t: &str, ra: f64, dec: f64, azel: Option<(f64, f64)>) -> AngleObs {
    AngleObs {
        time_utc: t.to_string(),
        ra_deg: ra,
        dec_deg: dec,
        az_deg: azel.map(|a| a.0),
        el_deg: azel.map(|a| a.1),
    }
}

fn sample_tracks() -> Vec<Track> {
    vec![
        Track {
            object: "frame_0001".to_string(),
            station: "GPUSTAR".to_string(),
            // Out of order on purpose: the writer sorts by time.
            observations: vec![
                obs(
                    "2026-04-15T07:37:42.322",
                    15.123456789,
                    -0.0000000004,
                    Some((359.9999999999, 45.5)),
                ),
                obs(
                    "2026-04-15T07:37:12.322",
                    359.9999999996,
                    -89.987654321,
                    Some((120.25, -0.5)),
                ),
            ],
        },
        Track {
            object: "UNKNOWN".to_string(),
            station: "4353".to_string(),
            observations: vec![
                obs("2026-04-15T07:38:00.000", -10.5, 45.0, Some((10.0, 20.0))),
                obs("2026-04-15T07:38:30.5", 720.25, 89.999999999, None),
            ],
        },
    ]
}

fn write(tracks: &[Track]) -> String {
    let mut out = Vec::new();
    write_tdm(&mut out, "2026-04-16T10:00:00.000", "GPUSTAR", tracks).unwrap();
    String::from_utf8(out).unwrap()
}

fn close(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-9
}

/// The angle `expected` as the TDM holds it, wrapped into [0, 360).
fn close_360(a: f64, expected: f64) -> bool {
    let d = (a - expected.rem_euclid(360.0)).rem_euclid(360.0);
    d.min(360.0 - d) <= 1e-9
}

#[test]
fn tdm_round_trip() {
    let tracks = sample_tracks();
    let text = write(&tracks);
    let tdm = parse_tdm(&text).unwrap();
    assert_eq!(tdm.header_value("CCSDS_TDM_VERS"), Some("2.0"));
    assert_eq!(
        tdm.header_value("CREATION_DATE"),
        Some("2026-04-16T10:00:00.000")
    );
    assert_eq!(tdm.header_value("ORIGINATOR"), Some("GPUSTAR"));
    // Track 1: RADEC + AZEL; track 2: RADEC only (one observation lacks az/el).
    assert_eq!(tdm.segments.len(), 3);
    let types: Vec<_> = tdm
        .segments
        .iter()
        .map(|s| s.meta_value("ANGLE_TYPE"))
        .collect();
    assert_eq!(types, [Some("RADEC"), Some("AZEL"), Some("RADEC")]);

    let expect = [(&tracks[0], false), (&tracks[0], true), (&tracks[1], false)];
    for (seg, (track, azel)) in tdm.segments.iter().zip(expect) {
        let m = |k| seg.meta_value(k);
        assert_eq!(m("TIME_SYSTEM"), Some("UTC"));
        assert_eq!(m("PARTICIPANT_1"), Some(track.station.as_str()));
        assert_eq!(m("PARTICIPANT_2"), Some(track.object.as_str()));
        assert_eq!(m("MODE"), Some("SEQUENTIAL"));
        assert_eq!(m("PATH"), Some("2,1"));
        assert_eq!(m("REFERENCE_FRAME"), if azel { None } else { Some("ICRF") });
        assert!(seg.meta.iter().any(|(k, _)| k == "COMMENT"));

        let mut want: Vec<_> = track
            .observations
            .iter()
            .map(|o| (iso(&o.time_utc).unwrap(), o))
            .collect();
        want.sort_by(|a, b| a.0.cmp(&b.0));
        assert_eq!(m("START_TIME"), Some(want[0].0.as_str()));
        assert_eq!(m("STOP_TIME"), Some(want[want.len() - 1].0.as_str()));
        let a1 = seg.values("ANGLE_1");
        let a2 = seg.values("ANGLE_2");
        assert_eq!(a1.len(), want.len());
        assert_eq!(a2.len(), want.len());
        for ((t, o), ((t1, v1), (t2, v2))) in want.iter().zip(a1.iter().zip(&a2)) {
            assert_eq!(*t1, t.as_str());
            assert_eq!(*t2, t.as_str());
            assert!((0.0..360.0).contains(v1), "{v1}");
            let (e1, e2) = if azel {
                (o.az_deg.unwrap(), o.el_deg.unwrap())
            } else {
                (o.ra_deg, o.dec_deg)
            };
            assert!(close_360(*v1, e1), "{v1} vs {e1}");
            assert!(close(*v2, e2), "{v2} vs {e2}");
        }
    }
    // The writer's fixed forms: RA rounding to 360 wraps to 0, no "-0".
    assert!(text.contains("ANGLE_1 = 2026-04-15T07:37:12.322 0.000000000\n"));
    assert!(text.contains("ANGLE_2 = 2026-04-15T07:37:42.322 0.000000000\n"));
    assert!(text.contains("ANGLE_1 = 2026-04-15T07:38:30.500 0.250000000\n"));
    assert!(text.contains("ANGLE_1 = 2026-04-15T07:38:00.000 349.500000000\n"));
    assert!(!text.contains("-0.000000000"));
    assert!(text.lines().all(|l| l.len() <= 254 && l.is_ascii()));
}

#[test]
fn tdm_without_tracks_is_a_header() {
    let text = write(&[]);
    let tdm = parse_tdm(&text).unwrap();
    assert!(tdm.segments.is_empty());
    assert_eq!(tdm.header_value("ORIGINATOR"), Some("GPUSTAR"));
    assert_eq!(tdm.header_value("COMMENT"), Some("No streak observations."));
}

#[test]
fn tdm_writer_refuses_bad_input_and_writes_nothing() {
    let good = sample_tracks();
    let cases: Vec<(Vec<Track>, &str)> = vec![
        (
            {
                let mut t = good.clone();
                t[0].observations.clear();
                t
            },
            "no observations",
        ),
        (
            {
                let mut t = good.clone();
                t[1].observations[0].time_utc = "2026-04-15T07:38:6x".to_string();
                t
            },
            "track 2 (object 'UNKNOWN'), observation 1: time",
        ),
        (
            {
                let mut t = good.clone();
                t[0].observations[1].dec_deg = 90.5;
                t
            },
            "Dec 90.5",
        ),
        (
            {
                let mut t = good.clone();
                t[0].observations[1].ra_deg = f64::NAN;
                t
            },
            "RA NaN",
        ),
        (
            {
                let mut t = good.clone();
                t[0].observations[0].el_deg = Some(f64::NAN);
                t
            },
            "elevation",
        ),
        (
            {
                let mut t = good.clone();
                t[1].observations[1].time_utc = "2026-04-15T07:38:00.0001".to_string();
                t
            },
            "two observations at 2026-04-15T07:38:00.000",
        ),
        (
            {
                let mut t = good.clone();
                t[0].object = "a\nMETA_STOP".to_string();
                t
            },
            "object",
        ),
        (
            {
                let mut t = good.clone();
                t[0].station = "  ".to_string();
                t
            },
            "station is empty",
        ),
    ];
    for (tracks, needle) in cases {
        let mut out = Vec::new();
        let e = write_tdm(&mut out, "2026-04-16T10:00:00", "GPUSTAR", &tracks).unwrap_err();
        assert!(matches!(e, gpustar::Error::Output(_)), "{e:?}");
        assert!(e.to_string().contains(needle), "{e} lacks {needle:?}");
        assert!(out.is_empty());
    }
    let mut out = Vec::new();
    assert!(write_tdm(&mut out, "yesterday", "GPUSTAR", &good).is_err());
    assert!(write_tdm(&mut out, "2026-04-16T10:00:00", "", &good).is_err());
    assert!(out.is_empty());
}

/// Hand-written in the style of the optical examples of CCSDS 503.0-B-2 Annex E
/// (values invented), with the liberties the parser allows: comments, blank lines,
/// indentation, uneven spacing, metadata out of table order, CRLF line ends, a
/// day-of-year epoch form and a MAG data type.
const ANNEX_E_STYLE: &str = "\
CCSDS_TDM_VERS = 2.0
COMMENT Optical observations of two uncatalogued GEO objects.
COMMENT All angles are free of aberration effects.
CREATION_DATE = 2021-03-15T06:00:00
ORIGINATOR = TESTOBS

META_START
   COMMENT first object
   TIME_SYSTEM    =    UTC
   PARTICIPANT_2 = TRACK NUMBER 001
   PARTICIPANT_1 = TESTOBS-T1
   START_TIME = 2021-03-14T21:10:05.10
   STOP_TIME = 2021-03-14T21:14:19.10
   MODE = SEQUENTIAL
   PATH = 2,1
   REFERENCE_FRAME = EME2000
   ANGLE_TYPE = RADEC
META_STOP

DATA_START
COMMENT three frames, 127 s apart
ANGLE_1 = 2021-03-14T21:10:05.10   41.2265417
ANGLE_2 = 2021-03-14T21:10:05.10   -3.4018222
MAG     = 2021-03-14T21:10:05.10   12.7
ANGLE_1=2021-03-14T21:12:12.10 41.7459583
ANGLE_2=2021-03-14T21:12:12.10 -3.2864306
MAG=2021-03-14T21:12:12.10 12.9
\tANGLE_1 = 2021-03-14T21:14:19.10 42.2655000
\tANGLE_2 = 2021-03-14T21:14:19.10 -3.1699139
\tMAG = 2021-03-14T21:14:19.10 13.0
DATA_STOP

META_START
TIME_SYSTEM = UTC
START_TIME = 2021-073T21:30:00Z
STOP_TIME = 2021-073T21:30:00Z
PARTICIPANT_1 = TESTOBS-T1
PARTICIPANT_2 = TRACK NUMBER 002
MODE = SEQUENTIAL
PATH = 2,1
ANGLE_TYPE = RADEC
REFERENCE_FRAME = EME2000
META_STOP
DATA_START
ANGLE_1 = 2021-073T21:30:00Z 300.0000001
ANGLE_2 = 2021-073T21:30:00Z +1.5E-01
DATA_STOP
";

#[test]
fn tdm_parses_annex_e_style_example() {
    let text = ANNEX_E_STYLE.replace('\n', "\r\n");
    let tdm = parse_tdm(&text).unwrap();
    assert_eq!(tdm.header_value("ORIGINATOR"), Some("TESTOBS"));
    let comments: Vec<_> = tdm.header.iter().filter(|(k, _)| k == "COMMENT").collect();
    assert_eq!(comments.len(), 2);
    assert_eq!(comments[1].1, "All angles are free of aberration effects.");
    assert_eq!(tdm.segments.len(), 2);

    let s = &tdm.segments[0];
    assert_eq!(
        s.meta[0],
        ("COMMENT".to_string(), "first object".to_string())
    );
    assert_eq!(s.meta_value("TIME_SYSTEM"), Some("UTC"));
    assert_eq!(s.meta_value("PARTICIPANT_2"), Some("TRACK NUMBER 001"));
    assert_eq!(s.meta_value("REFERENCE_FRAME"), Some("EME2000"));
    assert_eq!(s.data_comments, ["three frames, 127 s apart"]);
    assert_eq!(s.data.len(), 9);
    let ra = s.values("ANGLE_1");
    let dec = s.values("ANGLE_2");
    let mag = s.values("MAG");
    assert_eq!(ra[1], ("2021-03-14T21:12:12.10", 41.7459583));
    assert_eq!(dec[2], ("2021-03-14T21:14:19.10", -3.1699139));
    assert_eq!(
        mag.iter().map(|m| m.1).collect::<Vec<_>>(),
        [12.7, 12.9, 13.0]
    );

    let s = &tdm.segments[1];
    assert_eq!(s.meta_value("START_TIME"), Some("2021-073T21:30:00Z"));
    assert_eq!(s.values("ANGLE_1"), [("2021-073T21:30:00Z", 300.0000001)]);
    assert_eq!(s.values("ANGLE_2"), [("2021-073T21:30:00Z", 0.15)]);
}

#[test]
fn tdm_parse_errors_name_the_line() {
    let good = ANNEX_E_STYLE;
    // (edit of the good text, expected words in the message)
    let cases: Vec<(String, &str)> = vec![
        (String::new(), "no CCSDS_TDM_VERS"),
        (good.replace("CCSDS_TDM_VERS", "CCSDS_OEM_VERS"), "line 1: expected CCSDS_TDM_VERS"),
        (good.replace("ORIGINATOR = TESTOBS\n", ""), "has no ORIGINATOR"),
        (good.replacen("   TIME_SYSTEM    =    UTC\n", "", 1), "line 17: the metadata section opened at line 7 has no TIME_SYSTEM"),
        (good.replacen("META_STOP\n", "", 1), "line 19: DATA_START inside the metadata section opened at line 7"),
        (good.replacen("DATA_STOP\n", "", 1), "line 32: META_START inside the data section opened at line 20"),
        (good.replacen("   41.2265417", " 41.22x65417", 1), "line 22: ANGLE_1 value '41.22x65417' is not a finite number"),
        (good.replacen("   41.2265417", " NaN", 1), "line 22: ANGLE_1 value 'NaN'"),
        (good.replacen("2021-03-14T21:10:05.10   41", "41", 1), "line 22: ANGLE_1 needs 'epoch value'"),
        (good.replacen("2021-03-14T21:10:05.10   41", "2021-03-14T25:10:05.10 41", 1), "line 22: ANGLE_1 epoch"),
        (good.replacen("ANGLE_2 = 2021-03-14T21:10:05.10   -3.4018222", "ANGLE_2 = 2021-03-14T21:10:05.10 -3.4 7", 1), "line 23: ANGLE_2 has '7' after its value"),
        (good.replacen("   MODE = SEQUENTIAL", "   mode = SEQUENTIAL", 1), "line 14: keyword 'mode' must be upper-case"),
        (good.replacen("   MODE = SEQUENTIAL", "   PATH = 1,2", 1), "line 15: PATH appears twice"),
        (good.replacen("   MODE = SEQUENTIAL", "   MODE =", 1), "line 14: MODE has an empty value"),
        (good.replacen("   MODE = SEQUENTIAL", "   MODE SEQUENTIAL", 1), "line 14: expected 'KEYWORD = value'"),
        (good.replacen("DATA_START\nCOMMENT three", "ANGLE_1 = 2021-03-14T21:10:05.10 1\nCOMMENT three", 1), "line 20: expected DATA_START after META_STOP (line 18)"),
        (good.replacen("\nMETA_START\nTIME_SYSTEM", "\nANGLE_1 = 2021-03-14T21:10:05.10 1\nTIME_SYSTEM", 1), "line 33: expected META_START or the end after DATA_STOP"),
        (good.replacen("ORIGINATOR = TESTOBS", "ORIGINATOR = TESTOBS\nPARTICIPANT_1 = X", 1), "line 6: PARTICIPANT_1 is not a TDM header keyword"),
        (good.replacen("CREATION_DATE = 2021-03-15T06:00:00", "CREATION_DATE = 15/03/2021", 1), "line 4: CREATION_DATE"),
        (good.replacen("   START_TIME = 2021-03-14T21:10:05.10", "   START_TIME = soon", 1), "line 12: START_TIME 'soon'"),
        (good.strip_suffix("DATA_STOP\n").unwrap().to_string(), "missing DATA_STOP"),
        (good.split("\nDATA_START\nANGLE_1 = 2021-073").next().unwrap().to_string(), "without a data section"),
        ("CCSDS_TDM_VERS = 2.0\nCREATION_DATE = 2021-03-15T06:00:00\nORIGINATOR = X\nMETA_START\nTIME_SYSTEM = UTC\n".to_string(), "line 5: the input ends inside the metadata section opened at line 4"),
        ("CCSDS_TDM_VERS = two\n".to_string(), "line 1: CCSDS_TDM_VERS 'two'"),
        ("DATA_STOP\n".to_string(), "line 1: DATA_STOP without META_START"),
    ];
    for (text, needle) in cases {
        let e = parse_tdm(&text).unwrap_err();
        assert!(e.contains(needle), "{e:?} lacks {needle:?}");
    }
}

// ---------------------------------------------------------------- IOD

const EXAMPLE: &str = "25544 98 067A   4353 F 20160720013132250 17 25 1918175+113996 56 S-030 10";

fn close_to(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol
}

#[test]
fn iod_columns_of_the_satobs_example() {
    let o = parse_iod_line(EXAMPLE).unwrap();
    assert_eq!(o.norad, 25544);
    assert_eq!(o.intl_des, "98 067A");
    assert_eq!(o.station, 4353);
    assert_eq!(o.status, 'F');
    assert_eq!(o.time_utc, "2016-07-20T01:31:32.250");
    assert!(close_to(o.time_unc_s, 0.1, 1e-15));
    // RA 19h18.175m, Dec +11°39.96′.
    assert!(close_to(o.ra_deg, (19.0 + 18.175 / 60.0) * 15.0, 1e-12));
    assert!(close_to(o.dec_deg, 11.0 + 39.96 / 60.0, 1e-12));
    // "56" in format 2 is 5e-2 arcmin.
    assert!(close_to(o.pos_unc_deg, 0.05 / 60.0, 1e-15));
    assert_eq!(o.behaviour, 'S');
    // Written back: identical up to column 66 (magnitude columns are not carried).
    let line = iod_line(&o).unwrap();
    assert_eq!(line, EXAMPLE[..66]);
    // Padded to 80 columns, or with CRLF, it reads the same.
    assert_eq!(parse_iod_line(&format!("{EXAMPLE:<80}")).unwrap(), o);
    assert_eq!(parse_iod_line(&format!("{EXAMPLE}\r\n")).unwrap(), o);
}

#[test]
fn iod_writes_what_stvid_writes() {
    // stvid: "%05d %-9s %04d G %s 17 25 %s 37 S"
    let stvid = format!(
        "{:05} {:<9} {:04} G {} 17 25 {} 37 S",
        1328, "65 034C", 4171, "20240102030405678", "0512345-012345"
    );
    let o = IodObs {
        norad: 1328,
        intl_des: "65 034C".to_string(),
        station: 4171,
        status: 'G',
        time_utc: "2024-01-02T03:04:05.678".to_string(),
        time_unc_s: 0.1,
        ra_deg: (5.0 + 12.345 / 60.0) * 15.0,
        dec_deg: -(1.0 + 23.45 / 60.0),
        pos_unc_deg: 0.3 / 60.0,
        behaviour: 'S',
    };
    assert_eq!(iod_line(&o).unwrap(), stvid);
    let back = parse_iod_line(&stvid).unwrap();
    assert_eq!(back.time_utc, o.time_utc);
    assert!(close_to(back.ra_deg, o.ra_deg, 1e-12));
    assert!(close_to(back.dec_deg, o.dec_deg, 1e-12));
    assert!(close_to(back.pos_unc_deg, o.pos_unc_deg, 1e-15));
    assert!(close_to(back.time_unc_s, 0.1, 1e-15));
    // The column layout stvid's format implies.
    assert_eq!(&stvid[44..46], "25");
    assert_eq!(&stvid[47..61], "0512345-012345");
    assert_eq!(&stvid[62..64], "37");
    assert_eq!(stvid.len(), 66);
}

fn sample_obs(ra: f64, dec: f64) -> IodObs {
    IodObs {
        norad: 99999,
        intl_des: String::new(),
        station: 9999,
        status: ' ',
        time_utc: "2026-04-15T07:37:12.322".to_string(),
        time_unc_s: f64::NAN,
        ra_deg: ra,
        dec_deg: dec,
        pos_unc_deg: f64::NAN,
        behaviour: ' ',
    }
}

fn angles(ra: f64, dec: f64) -> String {
    iod_line(&sample_obs(ra, dec)).unwrap()[47..61].to_string()
}

#[test]
fn iod_round_trip_within_resolution() {
    // A fixed pseudo-random sequence (64-bit LCG): reproducible without a crate.
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let mut next = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let ra_tol = 0.0005 / 60.0 * 15.0 + 1e-12; // half of 0.001 min of time
    let dec_tol = 0.005 / 60.0 + 1e-12; // half of 0.01 arcmin
    for i in 0..5000 {
        let o = IodObs {
            norad: (next() * 99_999.0) as u32,
            intl_des: format!("{:02} {:03}A", i % 100, i % 1000),
            station: (next() * 9999.0) as u16,
            status: ['E', 'G', 'F', 'P', 'B', 'T', ' '][i % 7],
            time_utc: format!(
                "20{:02}-{:02}-{:02}T{:02}:{:02}:{:02}.{:03}",
                i % 100,
                1 + i % 12,
                1 + i % 28,
                i % 24,
                (i * 7) % 60,
                (i * 13) % 60,
                (i * 37) % 1000
            ),
            time_unc_s: 1e-3 + next() * 10.0,
            ra_deg: next() * 360.0,
            dec_deg: next() * 180.0 - 90.0,
            pos_unc_deg: next() * 1.5,
            behaviour: ['S', 'I', ' '][i % 3],
        };
        let line = iod_line(&o).unwrap();
        assert!(line.len() <= 80 && line == line.trim_end(), "{line:?}");
        let b = parse_iod_line(&line).unwrap();
        assert_eq!(b.norad, o.norad);
        assert_eq!(b.intl_des, o.intl_des);
        assert_eq!(b.station, o.station);
        assert_eq!(b.status, o.status);
        assert_eq!(b.time_utc, o.time_utc);
        assert_eq!(b.behaviour, o.behaviour);
        let dra = (b.ra_deg - o.ra_deg).rem_euclid(360.0);
        assert!(
            dra.min(360.0 - dra) <= ra_tol,
            "{line}: RA {} vs {}",
            b.ra_deg,
            o.ra_deg
        );
        assert!(close_to(b.dec_deg, o.dec_deg, dec_tol), "{line}: Dec");
        // MX never understates, and is within one step of M.
        assert!(b.time_unc_s >= o.time_unc_s * (1.0 - 1e-9));
        assert!(b.time_unc_s <= o.time_unc_s * 2.0 + 1e-12);
        assert!(b.pos_unc_deg >= o.pos_unc_deg * (1.0 - 1e-9));
        assert!(b.pos_unc_deg <= o.pos_unc_deg * 2.0 + 1e-12);
        // What was read writes the same line again.
        assert_eq!(iod_line(&b).unwrap(), line);
    }
}

#[test]
fn iod_rounding_carries_and_signs() {
    let ra = |h: f64, m: f64| (h + m / 60.0) * 15.0;
    let dec = |d: f64, m: f64| d + m / 60.0;
    assert_eq!(angles(ra(19.0, 18.175), dec(11.0, 39.96)), "1918175+113996");
    // 59.9995 min and above rounds into the next hour; 24h wraps to 0.
    assert_eq!(angles(ra(5.0, 59.99951), 0.0), "0600000+000000");
    assert_eq!(angles(ra(5.0, 59.99949), 0.0), "0559999+000000");
    assert_eq!(angles(ra(23.0, 59.9996), 0.0), "0000000+000000");
    assert_eq!(angles(360.0, 0.0), "0000000+000000");
    assert_eq!(angles(-15.0, 0.0), "2300000+000000");
    assert_eq!(angles(375.0, 0.0), "0100000+000000");
    // Dec minutes 59.995 and above round into the next degree.
    assert_eq!(angles(0.0, dec(11.0, 59.996)), "0000000+120000");
    assert_eq!(angles(0.0, -dec(11.0, 59.996)), "0000000-120000");
    assert_eq!(angles(0.0, dec(89.0, 59.999)), "0000000+900000");
    assert_eq!(angles(0.0, -90.0), "0000000-900000");
    // Between 0 and -1 degree the sign stays.
    assert_eq!(angles(0.0, -0.5), "0000000-003000");
    assert_eq!(angles(0.0, -0.01), "0000000-000060");
    assert_eq!(angles(0.0, -0.0001), "0000000-000001");
    // Only a value that rounds to zero loses it.
    assert_eq!(angles(0.0, -0.00001), "0000000+000000");
    assert_eq!(angles(0.0, -0.0), "0000000+000000");
    for (s, want) in [("-003000", -0.5), ("-000060", -0.01), ("+000000", 0.0)] {
        let mut line = iod_line(&sample_obs(0.0, 0.0)).unwrap();
        line.replace_range(54..61, s);
        assert!(close_to(
            parse_iod_line(&line).unwrap().dec_deg,
            want,
            1e-12
        ));
    }
}

/// The writer's choice of code for a value is a unit test in `src/streaks/formats/tests.rs`.
#[test]
fn iod_mx_codes() {
    // Every code decodes to a value that the writer encodes back to it, in both fields
    // (the position's in arcminutes, the unit of angle format 2).
    for x in 0..=9 {
        for m in 1..=9 {
            let code = format!("{m}{x}");
            let v = mx_decode(&code, "", "").unwrap();
            let mut o = sample_obs(0.0, 0.0);
            o.time_unc_s = v;
            o.pos_unc_deg = v / 60.0;
            let line = iod_line(&o).unwrap();
            assert_eq!(&line[41..43], code, "{line}");
            assert_eq!(&line[62..64], code, "{line}");
            let back = parse_iod_line(&line).unwrap();
            assert_eq!(back.time_unc_s, v);
            assert!(close_to(back.pos_unc_deg, v / 60.0, v * 1e-15));
        }
    }
    assert!(mx_decode("  ", "", "").unwrap().is_nan());
    assert!(
        mx_decode("1x", "42-43", "time uncertainty")
            .unwrap_err()
            .contains("columns 42-43")
    );
    let mut o = sample_obs(0.0, 0.0);
    o.time_unc_s = 100.0;
    assert!(
        iod_line(&o)
            .unwrap_err()
            .to_string()
            .contains("time uncertainty")
    );
    o.time_unc_s = 0.1;
    o.pos_unc_deg = 2.0;
    assert!(
        iod_line(&o)
            .unwrap_err()
            .to_string()
            .contains("position uncertainty")
    );
    o.pos_unc_deg = f64::NAN;
    o.time_unc_s = f64::NAN;
    // Blank uncertainties and codes trim the line after the angles.
    assert_eq!(iod_line(&o).unwrap().len(), 61);
}

#[test]
fn iod_reads_other_formats_and_truncated_fields() {
    // From the examples of the IOD description (epoch changed to 5 where needed).
    let o =
        parse_iod_line("12345 98 123A   2007 P 200811221122334   27 35 11223  +112    27 S+070 10")
            .unwrap();
    assert_eq!(o.time_utc, "2008-11-22T11:22:33.400");
    assert!(close_to(o.time_unc_s, 0.2, 1e-15));
    assert!(close_to(o.ra_deg, (11.0 + 22.3 / 60.0) * 15.0, 1e-12));
    assert!(close_to(o.dec_deg, 11.2, 1e-12)); // format 3: DD.dddd
    assert!(close_to(o.pos_unc_deg, 0.2, 1e-15)); // format 3: degrees

    let o =
        parse_iod_line("12345 98 123A   2007 F 2008112211223344  56 25 1122   +1122   28 R+05  1")
            .unwrap();
    assert_eq!(o.time_utc, "2008-11-22T11:22:33.440");
    assert!(close_to(o.ra_deg, (11.0 + 22.0 / 60.0) * 15.0, 1e-12));
    assert!(close_to(o.dec_deg, 11.0 + 22.0 / 60.0, 1e-12));
    assert!(close_to(o.pos_unc_deg, 2.0 / 60.0, 1e-15));
    assert_eq!(o.behaviour, 'R');

    // Format 1 (HHMMSSs+DDMMSS, arcsec) and 7 (HHMMSSs+DDdddd, degrees).
    let o =
        parse_iod_line("23794 96 010A   2701 G 20040506012614270 17 15 0047196-603829 38 I+020 10")
            .unwrap();
    assert!(close_to(
        o.ra_deg,
        (0.0 + 47.0 / 60.0 + 19.6 / 3600.0) * 15.0,
        1e-12
    ));
    assert!(close_to(
        o.dec_deg,
        -(60.0 + 38.0 / 60.0 + 29.0 / 3600.0),
        1e-12
    ));
    assert!(close_to(o.pos_unc_deg, 3e0 / 3600.0, 1e-15));
    let o =
        parse_iod_line("23794 96 010A   2701 G 20040506012614270 17 75 2047449+293762 38").unwrap();
    assert!(close_to(
        o.ra_deg,
        (20.0 + 47.0 / 60.0 + 44.9 / 3600.0) * 15.0,
        1e-12
    ));
    assert!(close_to(o.dec_deg, 29.3762, 1e-12));
    assert!(close_to(o.pos_unc_deg, 3.0, 1e-15));

    // Time truncated to hours; angles truncated to HH and DD; no uncertainties.
    let mut l = format!("{:<80}", "12345 98 123A   2007 E 2008112211");
    l.replace_range(44..46, "25");
    l.replace_range(47..49, "18");
    l.replace_range(54..57, "-08");
    let o = parse_iod_line(&l).unwrap();
    assert_eq!(o.time_utc, "2008-11-22T11:00:00.000");
    assert!(o.time_unc_s.is_nan() && o.pos_unc_deg.is_nan());
    assert!(close_to(o.ra_deg, 18.0 * 15.0, 1e-12));
    assert!(close_to(o.dec_deg, -8.0, 1e-12));
    assert_eq!(o.status, 'E');
    assert_eq!(o.behaviour, ' ');
}

#[test]
fn iod_parse_errors_say_where() {
    let good = EXAMPLE;
    let edit = |at: usize, s: &str| {
        let mut l = good.to_string();
        l.replace_range(at..at + s.len(), s);
        l
    };
    let cases: Vec<(String, &str)> = vec![
        (edit(0, "2554x"), "columns 1-5"),
        (format!(" {good}"), "column 6"),
        (edit(15, "X"), "column 16"),
        (edit(16, "43a3"), "columns 17-20"),
        (edit(23, "20161320"), "2016-13-20T01:31:32.250 (bad month)"),
        (edit(23, "20160230"), "2016-02-30T01:31:32.250 (bad day)"),
        (edit(31, "2513"), "T25:13:32.250 (bad hour)"),
        (edit(31, "01 1"), "columns 24-40"),
        (edit(31, "         "), "columns 24-40"),
        (edit(41, "1x"), "columns 42-43"),
        (edit(44, "5"), "azimuth/elevation"),
        (edit(44, " "), "no angle format"),
        (edit(44, "8"), "angle format '8'"),
        (edit(45, "4"), "epoch code '4'"),
        (edit(47, "2518175"), "columns 48-54"),
        (edit(47, "1960175"), "columns 48-54"),
        (edit(47, "19 8175"), "columns 48-54"),
        (edit(47, " 918175"), "columns 48-54"),
        (edit(54, " "), "column 55"),
        (edit(55, "116996"), "columns 56-61"),
        (edit(54, "+910000"), "beyond 90"),
        (edit(62, "5x"), "columns 63-64"),
        (format!("{good:<80}x"), "80 columns"),
        (good.replacen('S', "§", 1), "non-ASCII"),
        (String::new(), "column"),
    ];
    for (line, needle) in cases {
        let e = parse_iod_line(&line).unwrap_err();
        assert!(e.contains(needle), "{line:?}: {e:?} lacks {needle:?}");
    }
}

#[test]
fn iod_writer_refuses_what_does_not_fit() {
    let base = sample_obs(10.0, 10.0);
    let cases: Vec<(IodObs, &str)> = vec![
        (
            IodObs {
                norad: 100_000,
                ..base.clone()
            },
            "NORAD",
        ),
        (
            IodObs {
                station: 10_000,
                ..base.clone()
            },
            "station",
        ),
        (
            IodObs {
                intl_des: "98 067ABCD".to_string(),
                ..base.clone()
            },
            "designation",
        ),
        (
            IodObs {
                intl_des: "98\t067A".to_string(),
                ..base.clone()
            },
            "designation",
        ),
        (
            IodObs {
                status: 'É',
                ..base.clone()
            },
            "station status",
        ),
        (
            IodObs {
                behaviour: '\n',
                ..base.clone()
            },
            "behaviour",
        ),
        (
            IodObs {
                time_utc: "2026-04-15T07:37:1".to_string(),
                ..base.clone()
            },
            "time",
        ),
        (
            IodObs {
                dec_deg: -90.01,
                ..base.clone()
            },
            "Dec",
        ),
        (
            IodObs {
                ra_deg: f64::INFINITY,
                ..base.clone()
            },
            "RA",
        ),
        (
            IodObs {
                time_unc_s: -1.0,
                ..base.clone()
            },
            "time uncertainty",
        ),
    ];
    for (o, needle) in cases {
        let e = iod_line(&o).unwrap_err().to_string();
        assert!(e.contains(needle), "{e:?} lacks {needle:?}");
    }
}

#[test]
fn parsers_never_panic_on_mangled_input() {
    let line = format!("{EXAMPLE:<80}");
    let replacements = [' ', '0', '9', '+', '-', 'x', '.', 'é'];
    for i in 0..line.len() {
        let _ = parse_iod_line(&line[..i]);
        for r in replacements {
            let mut l: String = line.chars().take(i).collect();
            l.push(r);
            l.extend(line.chars().skip(i + 1));
            let _ = parse_iod_line(&l);
        }
    }
    let tdm = ANNEX_E_STYLE;
    for (i, _) in tdm.char_indices() {
        let _ = parse_tdm(&tdm[..i]);
        let mut t = tdm.to_string();
        t.replace_range(i..i + 1, "=");
        let _ = parse_tdm(&t);
    }
}

// ------------------------------------------------------------------------------------
// The readers' rules (ports in tests/it/common/formats.rs)
// ------------------------------------------------------------------------------------

#[test]
fn readers_accept_stvid_lines_and_refuse_gpustar_s_old_short_ones() {
    use crate::common::formats::{sattools_decode, trusat_format_test};
    // stvid's format_iod_line: "%05d %-9s %04d G %s 17 25 %s 37 S".
    let stvid = "99999 26 835A   4171 G 20261201031500123 17 25 0512345-012345 37 S";
    let o = sattools_decode(stvid).unwrap();
    assert_eq!((o.satno, o.desig.as_str(), o.site), (99999, "26835A", 4171));
    assert!((o.st - 0.1).abs() < 1e-12 && (o.sr - 0.3 / 60.0).abs() < 1e-12);
    assert!((o.ra_deg - (5.0 + 12.345 / 60.0) * 15.0).abs() < 1e-9);
    assert!((o.dec_deg + 1.0 + 23.45 / 60.0).abs() < 1e-9);
    assert!(trusat_format_test(stvid));
    assert!(trusat_format_test(&stvid[..64]));
    // What gpustar wrote before: 61 characters, no designation, blank MX fields, site 9999.
    let old = "99999           9999   20240315200002500    25 1945557-075079";
    assert!(sattools_decode(old).unwrap_err().contains("< 64"));
    assert!(!trusat_format_test(old));
    let blank_mx = "99999 26 835A   4171 G 20261201031500123    25 0512345-012345   ";
    assert!(sattools_decode(blank_mx).unwrap_err().contains("%1d%1d"));
    assert!(!trusat_format_test(blank_mx));
    let no_site = stvid.replace(" 4171 ", " 9999 ");
    assert!(sattools_decode(&no_site).unwrap_err().contains("9999"));
}

#[test]
fn unidentified_designations_follow_stvid() {
    use gpustar::streaks::formats::{PIECES_PER_DAY, unidentified_designation};
    let d = |t: &str, k| unidentified_designation(t, k).unwrap();
    assert_eq!(d("2026-12-01T03:15:00.123", 0), "26 835A");
    assert_eq!(d("2024-03-15T20:00:00", 0), "24 575A"); // leap year: day 75
    assert_eq!(d("2023-03-15T20:00:00", 0), "23 574A");
    assert_eq!(d("2026-01-01T00:00:00", 7), "26 501H");
    assert_eq!(d("2026-01-01T00:00:00", 8), "26 501J"); // no I, no O
    assert_eq!(d("2026-01-01T00:00:00", 24), "26 501AA");
    assert_eq!(d("2026-01-01T00:00:00", PIECES_PER_DAY - 1), "26 501ZZ");
    assert_eq!(d("2026-01-01T00:00:00", PIECES_PER_DAY), "26 501A");
    let mut all: Vec<_> = (0..PIECES_PER_DAY)
        .map(|k| d("2026-01-01T00:00:00", k))
        .collect();
    all.sort();
    all.dedup();
    assert_eq!(all.len(), PIECES_PER_DAY);
}

#[test]
fn written_lines_pass_both_readers() {
    use crate::common::formats::{sattools_decode, trusat_format_test};
    for (k, (ra, dec)) in [
        (0.0, 0.0),
        (359.9999, -89.99),
        (123.456, 45.678),
        (5.0, -0.5),
    ]
    .into_iter()
    .enumerate()
    {
        let o = IodObs {
            norad: 99_999 - k as u32,
            intl_des: gpustar::streaks::formats::unidentified_designation(
                "2026-12-01T03:15:00.123",
                k * 30,
            )
            .unwrap(),
            station: 4171,
            status: 'G',
            time_utc: "2026-12-01T03:15:00.123".to_string(),
            time_unc_s: 0.001,
            ra_deg: ra,
            dec_deg: dec,
            pos_unc_deg: 3.0 / 3600.0,
            behaviour: ' ',
        };
        let line = iod_line(&o).unwrap();
        assert_eq!(line.len(), 64, "{line}");
        let s = sattools_decode(&line).unwrap_or_else(|e| panic!("{line}: {e}"));
        assert!(trusat_format_test(&line), "{line}");
        assert!(
            (s.st - 0.001).abs() < 1e-12 && s.sr >= 3.0 / 3600.0,
            "{line}"
        );
        let dra = (s.ra_deg - ra).rem_euclid(360.0);
        assert!(dra.min(360.0 - dra) < 0.001 / 60.0 * 15.0, "{line}");
        assert!((s.dec_deg - dec).abs() < 0.01 / 60.0, "{line}");
    }
}

#[test]
fn names_are_escaped_for_the_tdm() {
    use gpustar::streaks::formats::kvn_escape;
    assert_eq!(kvn_escape("sub/img_01.fits"), "sub/img_01.fits");
    assert_eq!(kvn_escape("café.fits"), "caf\\u{e9}.fits");
    assert_eq!(kvn_escape("a\\b\nc"), "a\\\\b\\nc");
    assert_eq!(kvn_escape(" x "), "\\u{20}x\\u{20}");
    assert_eq!(kvn_escape(""), "(unnamed)");
    let long = kvn_escape(&"é".repeat(300));
    assert!(long.len() <= 200 && long.contains("..."), "{long}");
    let t = Track {
        object: kvn_escape("ñame.fits#1"),
        station: kvn_escape("Observatório"),
        observations: vec![obs("2026-12-01T03:15:00", 1.0, 2.0, None)],
    };
    assert!(tdm_text("2026-12-01T04:00:00", "GPUSTAR", &[t]).is_ok());
}
