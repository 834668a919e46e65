use super::*;

/// The defaults are the library's own: a default configuration makes the default settings.
#[test]
fn defaults_make_the_default_settings() {
    let c = RunConfig::default();
    c.validate().unwrap();
    let choice = (
        CameraSource::Fov {
            fov_x_deg: 10.0,
            pixel_aspect: 1.0,
        },
        None,
        None,
    );
    let s = c.settings(&choice);
    let d = Settings::DEFAULT;
    assert_eq!(
        (s.epoch, s.detect.k_sigma, s.identify.vote_stars, s.retry),
        (d.epoch, d.detect.k_sigma, d.identify.vote_stars, d.retry)
    );
    assert_eq!(
        (s.refine.max_false_prob, s.refine.fit, s.method, s.parity),
        (
            d.refine.max_false_prob,
            d.refine.fit,
            d.method,
            Parity::Either
        )
    );
}

/// A config file names options as the command line does; values out of range, unknown names
/// and options that exclude each other are refused with the option's name.
#[test]
fn a_config_file_reads_back_and_bad_ones_are_refused() {
    let p = Path::new("run.toml");
    let c = RunConfig::from_toml(
        "fov_deg = \"8..20\"\nsigma = 4.5\nmethod = \"radial\"\nvote_stars = 60\nimage_size = [640, 480]\n",
        p,
    )
    .unwrap();
    assert_eq!(c.fov_deg, Some(ValueOrRange::Range(8.0, 20.0)));
    assert_eq!((c.sigma, c.method, c.vote_stars), (4.5, Method::Radial, 60));
    assert_eq!(c.image_size, Some((640, 480)));
    assert_eq!(c.epoch, DEFAULTS.epoch);
    // What it writes, it reads back.
    let again = RunConfig::from_toml(&toml::to_string(&c).unwrap(), p).unwrap();
    assert_eq!(again, c);
    assert_eq!(
        RunConfig::from_toml("fov_deg = [10, 12]", p)
            .unwrap()
            .fov_deg,
        Some(ValueOrRange::Range(10.0, 12.0))
    );
    for (text, says) in [
        ("sigma = 1000", "sigma: 1000 is outside 0.5 to 100"),
        ("vote_stars = 2", "vote_stars: 2 is outside 4 to 200"),
        ("sigmaa = 4", "unknown field `sigmaa`"),
        (
            "method = \"guess\"",
            "\"guess\" is not one of vote, radial, triangle",
        ),
        ("fov_deg = 200", "between 0 and 170"),
        ("fov_deg = \"20..8\"", "expected LOW..HIGH"),
        ("fov_deg = 10\ncamera = \"c.toml\"", "give one of them"),
        ("dark = \"d.fits\"\ndark_median = true", "give one of them"),
        ("hint = \"north\"", "hint"),
    ] {
        let e = RunConfig::from_toml(text, p).unwrap_err().to_string();
        assert!(e.contains(says), "{text}: {e}");
    }
}

/// `--resume`'s comparison names each option that differs, and leaves out the backend and the
/// batch size, which do not change a record.
#[test]
fn differences_name_the_options_that_change_records() {
    let a = RunConfig::default();
    let mut b = a.clone();
    b.backend = BackendChoice::Cpu;
    b.batch_size = 8;
    assert!(a.differences(&b).is_empty());
    b.sigma = 4.0;
    b.fov_deg = Some(ValueOrRange::Exact(12.0));
    let d = b.differences(&a);
    assert_eq!(d.len(), 2, "{d:?}");
    assert!(
        d[0].starts_with("fov_deg: (not set) then, 12.0 now"),
        "{d:?}"
    );
    assert!(d[1].starts_with("sigma: 5.0 then, 4.0 now"), "{d:?}");
}
