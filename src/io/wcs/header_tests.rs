//! Unit tests of `HeaderWcs`: a frame's own WCS keywords read back as positions.

use super::HeaderWcs;

fn keywords(order: &str) -> std::collections::BTreeMap<String, String> {
    [
        ("CTYPE1", "RA---TAN-SIP"),
        ("CTYPE2", "DEC--TAN-SIP"),
        ("CRPIX1", "512"),
        ("CRPIX2", "512"),
        ("CRVAL1", "10"),
        ("CRVAL2", "20"),
        ("CD1_1", "0.001"),
        ("CD2_2", "0.001"),
        ("A_ORDER", order),
        ("B_ORDER", "2"),
        ("A_2_0", "1e-6"),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), v.to_string()))
    .collect()
}

/// Issue 22, item 3: an absurd SIP order is refused at once (it once ran a loop of 2^31
/// squared steps); orders 0 to 9 are read.
#[test]
fn sip_orders_are_bounded() {
    for bad in ["2147483647", "10", "-1", "2.5", "1e300"] {
        let t = std::time::Instant::now();
        let e = HeaderWcs::from_keywords(&keywords(bad), (1024, 1024)).unwrap_err();
        assert!(e.to_string().contains("A_ORDER"), "{bad}: {e}");
        assert!(
            t.elapsed().as_secs_f64() < 1.0,
            "{bad}: took {:?}",
            t.elapsed()
        );
    }
    let w = HeaderWcs::from_keywords(&keywords("2"), (1024, 1024))
        .unwrap()
        .unwrap();
    assert_eq!(w.sip_a, vec![(2, 0, 1e-6)]);
}

/// The keywords of [`keywords`] (order 2) with `changes`; an empty value removes the key.
fn changed(changes: &[(&str, &str)]) -> std::collections::BTreeMap<String, String> {
    let mut k = keywords("2");
    for (key, v) in changes {
        match *v {
            "" => k.remove(*key),
            v => k.insert(key.to_string(), v.to_string()),
        };
    }
    k
}

/// Issue 45, item 8: a header WCS no telescope has (a declination beyond a pole, a scale
/// of 1e10 deg/px or 1e-300, singular terms, 1e300 anywhere, a distortion that moves the
/// corners off the frame) is refused, naming the keyword and the value written; the
/// extremes of real telescopes are read.
#[test]
fn nonsensical_wcs_is_refused_naming_the_keyword() {
    let size = (1024, 1024);
    let cd = |v: &'static str| [("CD1_1", v), ("CD1_2", v), ("CD2_1", v), ("CD2_2", v)];
    let cdelt = [
        ("CD1_1", ""),
        ("CD2_2", ""),
        ("CDELT1", "1e10"),
        ("CDELT2", "0.001"),
    ];
    let bad: Vec<(Vec<(&str, &str)>, &str)> = vec![
        (
            vec![("CRVAL2", "95")],
            "CRVAL2 = 95: declinations from -90 to 90",
        ),
        (vec![("CRVAL2", "-90.5")], "CRVAL2 = -90.5"),
        (vec![("CRVAL1", "1e300")], "CRVAL1 = 1e300"),
        (vec![("CRPIX1", "1e300")], "CRPIX1 = 1e300"),
        (vec![("CRPIX2", "-2e6")], "CRPIX2 = -2e6"),
        (vec![("CD1_1", "1e10")], "CD1_1 = 1e10"),
        (
            vec![("CD1_1", "1e300"), ("CD2_2", "1e300")],
            "CD2_2 = 1e300",
        ),
        (
            vec![("CD1_1", "1e-300"), ("CD2_2", "1e-300")],
            "pixel scales from",
        ),
        (cd("0.001").to_vec(), "singular"),
        (
            vec![("CD1_2", "0.001"), ("CD2_1", "0.0009999999")],
            "singular",
        ),
        (cdelt.to_vec(), "CDELT1 = 1e10"),
        (vec![("A_2_0", "1e300")], "A_2_0 = 1e300"),
        (vec![("B_0_2", "1e300")], "B_0_2 = 1e300"),
        // 2616 px at a corner, the diagonal 1448 px.
        (vec![("A_2_0", "0.01")], "A_2_0 = 0.01: the SIP distortion"),
    ];
    for (changes, want) in bad {
        match HeaderWcs::from_keywords(&changed(&changes), size) {
            Err(e) => assert!(e.to_string().contains(want), "{changes:?}: {e}"),
            Ok(w) => panic!("{changes:?} read as {w:?}"),
        }
    }
    let read = |changes: &[(&str, &str)]| {
        HeaderWcs::from_keywords(&changed(changes), size)
            .unwrap_or_else(|e| panic!("{changes:?}: {e}"))
            .unwrap()
    };
    // 0.01"/px (adaptive optics) to 10 deg/px, poles, a chip's reference pixel far off
    // the frame, a distortion of 26 px at the corners.
    read(&[("CD1_1", "2.8e-6"), ("CD2_2", "-2.8e-6")]);
    read(&[("CD1_1", "10"), ("CD2_2", "10"), ("A_2_0", "")]);
    read(&[("CRVAL2", "90")]);
    read(&[("CRVAL2", "-90")]);
    read(&[("CRPIX1", "-5000"), ("A_2_0", "")]);
    read(&[("A_2_0", "1e-4")]);
    // RA wrapped into [0, 360).
    let (w, east) = (read(&[("CRVAL1", "-10")]), read(&[("CRVAL1", "350")]));
    assert_eq!(w, east);
    let ra = w.pixel_to_radec(511.0, 511.0).unwrap().0;
    assert!((ra - 350.0).abs() < 1e-9, "{ra}");
}
