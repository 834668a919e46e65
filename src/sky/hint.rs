//! Pointing hints: where a telescope says it points, from `--hint` or its FITS header.
//!
//! A hint narrows identification to the catalog stars of one region (see `solve::hinted`);
//! it never replaces the false-match test, so a wrong hint costs time, not a wrong answer.

use super::station::parse_angle;
use crate::error::{Result, fail};

/// Where a frame is said to point, and how far off that may be.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hint {
    /// ICRS right ascension and declination of the frame's centre, degrees.
    pub ra_deg: f64,
    pub dec_deg: f64,
    /// How far the true centre may lie from it, degrees.
    pub radius_deg: f64,
    /// The header keywords it was read from ("--hint" for the command line).
    pub source: &'static str,
}

/// Radius of a hint that does not give its own: telescope pointing models are good to a few
/// arcminutes, mount encoders of small stations to a fraction of a degree.
pub const DEFAULT_HINT_RADIUS_DEG: f64 = 1.0;

/// Where hints come from in a run.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum HintSource {
    /// `--hint RA,DEC[,RADIUS]`: the same for every frame.
    Fixed(Hint),
    /// `--hint header`: each frame's own header keywords (see [`hint_from_header`]); frames
    /// without them are solved lost-in-space.
    Header { radius_deg: f64 },
}

/// `--hint RA,DEC[,RADIUS_DEG]` (degrees, or sexagesimal: RA in hours as `HH:MM:SS.s`, Dec as
/// `±DD:MM:SS`), or `header`.
pub fn parse_hint(s: &str) -> Result<HintSource> {
    let usage = || {
        format!(
            "--hint expects RA,DEC[,RADIUS_DEG] (degrees, or RA as HH:MM:SS and Dec as \
             ±DD:MM:SS) or 'header', got '{s}'"
        )
    };
    let t = s.trim();
    if let Some(rest) = t.strip_prefix("header") {
        let radius_deg = match rest.strip_prefix(',') {
            None if rest.is_empty() => DEFAULT_HINT_RADIUS_DEG,
            Some(r) => r.trim().parse::<f64>().map_err(|_| error_of(usage()))?,
            None => fail!(Config, "{}", usage()),
        };
        check_radius(radius_deg, &usage)?;
        return Ok(HintSource::Header { radius_deg });
    }
    let f: Vec<&str> = t.split(',').map(str::trim).collect();
    if !(2..=3).contains(&f.len()) {
        fail!(Config, "{}", usage());
    }
    let (Some(ra_deg), Some(dec_deg)) = (ra_of(f[0]), dec_of(f[1])) else {
        fail!(Config, "{}", usage());
    };
    let radius_deg = match f.get(2) {
        Some(r) => r.parse::<f64>().map_err(|_| error_of(usage()))?,
        None => DEFAULT_HINT_RADIUS_DEG,
    };
    check_radius(radius_deg, &usage)?;
    Ok(HintSource::Fixed(Hint {
        ra_deg,
        dec_deg,
        radius_deg,
        source: "--hint",
    }))
}

fn error_of(message: String) -> crate::Error {
    crate::Error::Config(message)
}

fn check_radius(r: f64, usage: &dyn Fn() -> String) -> Result<()> {
    if !(r > 0.0 && r <= 180.0) {
        fail!(
            Config,
            "{} (the radius must be in (0, 180] degrees)",
            usage()
        );
    }
    Ok(())
}

/// Right ascension: a number is degrees, sexagesimal is hours (the FITS habit for RA strings).
fn ra_of(s: &str) -> Option<f64> {
    let s = s.trim();
    let ra = match s.parse::<f64>() {
        Ok(v) => v,
        Err(_) => 15.0 * parse_angle(s, '\0', '\0')?,
    };
    (ra.is_finite() && (0.0..=360.0).contains(&ra)).then_some(ra.rem_euclid(360.0))
}

/// Declination in degrees, a number or sexagesimal.
fn dec_of(s: &str) -> Option<f64> {
    parse_angle(s, 'N', 'S').filter(|d| d.abs() <= 90.0)
}

/// Header keyword pairs that hold a pointing, in order of preference: the object's coordinates,
/// the telescope's, then a rough WCS's reference point (CRVAL is the centre only when CRPIX is
/// near it, which [`hint_from_header`] checks).
const PAIRS: [(&str, &str, &str); 4] = [
    ("OBJCTRA", "OBJCTDEC", "OBJCTRA/OBJCTDEC"),
    ("RA", "DEC", "RA/DEC"),
    ("TELRA", "TELDEC", "TELRA/TELDEC"),
    ("CRVAL1", "CRVAL2", "CRVAL1/CRVAL2"),
];

/// The pointing a FITS header gives, if any: the first usable keyword pair (OBJCTRA/OBJCTDEC,
/// RA/DEC, TELRA/TELDEC, CRVAL1/CRVAL2, in that order). `size` is the
/// frame's (width, height), to accept CRVAL only for a reference pixel within a tenth of the
/// frame of its centre.
pub fn hint_from_header(
    get: &dyn Fn(&str) -> Option<String>,
    size: (u32, u32),
    radius_deg: f64,
) -> Option<Hint> {
    header_hint(get, size, radius_deg).0
}

/// [`hint_from_header`], with why each pointing keyword the header has was not used (a value
/// that is not an angle, a declination beyond ±90, half a pair): a frame's record says so
/// rather than solving it lost-in-space without a word. A WCS reference point away from the
/// frame's centre is no pointing and not a fault: it is passed over silently.
pub fn header_hint(
    get: &dyn Fn(&str) -> Option<String>,
    size: (u32, u32),
    radius_deg: f64,
) -> (Option<Hint>, Vec<String>) {
    let value = |k: &str| super::value(get, k).map(|v| v.trim_matches('\'').to_string());
    let mut notes = Vec::new();
    let not_used =
        |k: &str, v: &str, why: &str| format!("--hint header: {k} = {v} not used: {why}");
    for (ra_key, dec_key, source) in PAIRS {
        let (ra, dec) = match (value(ra_key), value(dec_key)) {
            (Some(ra), Some(dec)) => (ra, dec),
            (None, None) => continue,
            (Some(v), None) if ra_key != "CRVAL1" => {
                notes.push(not_used(
                    ra_key,
                    &v,
                    &format!("the header has no {dec_key}"),
                ));
                continue;
            }
            (None, Some(v)) if ra_key != "CRVAL1" => {
                notes.push(not_used(
                    dec_key,
                    &v,
                    &format!("the header has no {ra_key}"),
                ));
                continue;
            }
            _ => continue,
        };
        if ra_key == "CRVAL1" {
            let celestial = value("CTYPE1").is_some_and(|c| c.starts_with("RA--"))
                && value("CTYPE2").is_some_and(|c| c.starts_with("DEC-"));
            let near = |k: &str, n: u32| {
                value(k)
                    .and_then(|v| v.parse::<f64>().ok())
                    .is_some_and(|p| (p - 0.5 - n as f64 / 2.0).abs() <= n as f64 / 10.0)
            };
            if !(celestial && near("CRPIX1", size.0) && near("CRPIX2", size.1)) {
                continue;
            }
        }
        let (ra_deg, dec_deg) = (ra_of(&ra), dec_of(&dec));
        if ra_deg.is_none() {
            notes.push(not_used(
                ra_key,
                &ra,
                "not a right ascension (degrees 0 to 360, or hours as HH:MM:SS)",
            ));
        }
        if dec_deg.is_none() {
            notes.push(not_used(
                dec_key,
                &dec,
                "not a declination (degrees within ±90, or ±DD:MM:SS)",
            ));
        }
        let (Some(ra_deg), Some(dec_deg)) = (ra_deg, dec_deg) else {
            continue;
        };
        let hint = Hint {
            ra_deg,
            dec_deg,
            radius_deg,
            source,
        };
        return (Some(hint), notes);
    }
    (None, notes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn header(cards: &[(&str, &str)]) -> impl Fn(&str) -> Option<String> {
        let cards: Vec<(String, String)> = cards
            .iter()
            .map(|(k, v)| (k.to_string(), v.to_string()))
            .collect();
        move |k: &str| cards.iter().find(|c| c.0 == k).map(|c| c.1.clone())
    }

    #[test]
    fn command_line_hints() {
        let HintSource::Fixed(h) = parse_hint("10.5,-20.25,0.7").unwrap() else {
            panic!()
        };
        assert_eq!((h.ra_deg, h.dec_deg, h.radius_deg), (10.5, -20.25, 0.7));
        let HintSource::Fixed(h) = parse_hint("01:30:00,-20:15:00").unwrap() else {
            panic!()
        };
        assert!((h.ra_deg - 22.5).abs() < 1e-12 && (h.dec_deg + 20.25).abs() < 1e-12);
        assert_eq!(h.radius_deg, DEFAULT_HINT_RADIUS_DEG);
        assert_eq!(
            parse_hint("header").unwrap(),
            HintSource::Header { radius_deg: 1.0 }
        );
        assert_eq!(
            parse_hint("header,0.5").unwrap(),
            HintSource::Header { radius_deg: 0.5 }
        );
        for bad in [
            "", "10", "10,95", "400,0", "10,20,0", "10,20,-1", "headers", "a,b",
        ] {
            assert!(parse_hint(bad).is_err(), "{bad:?} accepted");
        }
    }

    #[test]
    fn header_keywords_in_their_conventions() {
        let size = (1024, 1024);
        let h = hint_from_header(
            &header(&[("OBJCTRA", "'12 30 00.0'"), ("OBJCTDEC", "'-45 30 00'")]),
            size,
            1.0,
        )
        .unwrap();
        assert!((h.ra_deg - 187.5).abs() < 1e-12 && (h.dec_deg + 45.5).abs() < 1e-12);
        assert_eq!(h.source, "OBJCTRA/OBJCTDEC");
        let h = hint_from_header(&header(&[("RA", "187.5"), ("DEC", "-45.5")]), size, 1.0);
        assert_eq!(h.unwrap().source, "RA/DEC");
        let h = hint_from_header(
            &header(&[("TELRA", "12:30:00"), ("TELDEC", "+45:30:00")]),
            size,
            1.0,
        )
        .unwrap();
        assert!((h.ra_deg - 187.5).abs() < 1e-12 && (h.dec_deg - 45.5).abs() < 1e-12);
        let wcs = [
            ("CTYPE1", "'RA---TAN'"),
            ("CTYPE2", "'DEC--TAN'"),
            ("CRVAL1", "187.5"),
            ("CRVAL2", "-45.5"),
            ("CRPIX1", "512.5"),
            ("CRPIX2", "512.5"),
        ];
        assert_eq!(
            hint_from_header(&header(&wcs), size, 1.0).unwrap().source,
            "CRVAL1/CRVAL2"
        );
        // A reference pixel far from the centre: CRVAL is not where the frame points.
        let mut off = wcs;
        off[4] = ("CRPIX1", "10.0");
        assert!(hint_from_header(&header(&off), size, 1.0).is_none());
        // Unusable values are skipped, not guessed.
        assert!(hint_from_header(&header(&[("RA", "'x'"), ("DEC", "3")]), size, 1.0).is_none());
        assert!(hint_from_header(&header(&[]), size, 1.0).is_none());
    }

    #[test]
    fn unusable_header_keywords_are_named_with_why() {
        let size = (1024, 1024);
        let (h, notes) = header_hint(&header(&[("RA", "'abc'"), ("DEC", "95")]), size, 1.0);
        assert!(h.is_none());
        assert_eq!(notes.len(), 2, "{notes:?}");
        assert!(
            notes[0].contains("RA = abc") && notes[0].contains("not a right ascension"),
            "{notes:?}"
        );
        assert!(
            notes[1].contains("DEC = 95") && notes[1].contains("within ±90"),
            "{notes:?}"
        );
        // A later pair is used; the bad one is still named.
        let (h, notes) = header_hint(
            &header(&[("OBJCTRA", "'12 30 00'"), ("RA", "187.5"), ("DEC", "-45.5")]),
            size,
            1.0,
        );
        assert_eq!(h.unwrap().source, "RA/DEC");
        assert_eq!(notes.len(), 1, "{notes:?}");
        assert!(notes[0].contains("OBJCTRA") && notes[0].contains("no OBJCTDEC"));
        // Usable keywords, no header pointing at all, and a WCS reference point away from
        // the centre: nothing to say.
        for cards in [
            &[("RA", "187.5"), ("DEC", "-45.5")][..],
            &[],
            &[
                ("CTYPE1", "'RA---TAN'"),
                ("CTYPE2", "'DEC--TAN'"),
                ("CRVAL1", "187.5"),
                ("CRVAL2", "-45.5"),
                ("CRPIX1", "10.0"),
                ("CRPIX2", "512.5"),
            ],
        ] {
            assert!(
                header_hint(&header(cards), size, 1.0).1.is_empty(),
                "{cards:?}"
            );
        }
    }
}
