use super::*;

const W: u32 = 200;
const H: u32 = 150;

/// 200×150 frame: noisy sky at `sky` with Gaussian blobs of `peak` at `blobs`,
/// clipped at `max` like a sensor.
fn frame(sky: u16, noise: u16, peak: u16, max: u16, blobs: &[(f64, f64)]) -> Vec<u16> {
    let mut state = 12345u32;
    (0..W * H)
        .map(|i| {
            state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            let n = f64::from(state >> 16) / 65536.0 - 0.5;
            let (x, y) = (f64::from(i % W), f64::from(i / W));
            let star: f64 = blobs
                .iter()
                .map(|(bx, by)| {
                    let d2 = (x - bx).powi(2) + (y - by).powi(2);
                    f64::from(peak) * (-d2 / 4.0).exp()
                })
                .sum();
            (f64::from(sky) + n * 2.0 * f64::from(noise) + star).clamp(0.0, f64::from(max)) as u16
        })
        .collect()
}

fn mark(x: f64, y: f64, r: f64) -> Mark {
    Mark { x, y, radius_px: r }
}

fn annotation(pixels: &[u16]) -> Annotation<'_> {
    Annotation {
        width: W,
        height: H,
        pixels,
        saturation: 255,
        identified: vec![(mark(60.0, 60.0, 2.0), "HIP 27989".into())],
        unmatched: vec![mark(140.0, 40.0, 2.0)],
        predicted: vec![mark(120.0, 100.0, 2.0)],
        streaks: vec![],
        caption: "solved RA 83.82 Dec -5.39".into(),
    }
}

#[test]
fn streaks_are_drawn_beside_their_track_with_rings_at_inside_ends() {
    let pixels = vec![0u16; (W * H) as usize];
    let mut a = annotation(&pixels);
    a.identified.clear();
    a.unmatched.clear();
    a.predicted.clear();
    a.streaks = vec![([(40.0, 70.0), (160.0, 70.0)], [false, true])];
    let img = render(&a);
    let gap = 6 * font_scale(W, H);
    assert_ne!(px(&img, 100, 70), STREAK, "the track itself is left to see");
    assert_eq!(px(&img, 100, 70 - gap), STREAK);
    assert_eq!(px(&img, 100, 70 + gap), STREAK);
    // A ring around the inside end (left of it), none beyond the edge end.
    assert_eq!(px(&img, 40 - gap, 70), STREAK);
    assert_ne!(px(&img, 160 + gap, 70), STREAK);
}

fn px(img: &RgbImage, x: u32, y: u32) -> Rgb<u8> {
    *img.get_pixel(x, y)
}

#[test]
fn identified_circle_is_green_at_radius() {
    let pixels = frame(20, 4, 255, 255, &[(60.0, 60.0), (140.0, 40.0)]);
    let img = render(&annotation(&pixels));
    // radius max(2*2, 6) = 6: the four compass points of the ring.
    for (x, y) in [(66, 60), (54, 60), (60, 54), (60, 66)] {
        assert_eq!(px(&img, x, y), IDENTIFIED, "({x},{y})");
    }
    // Inside and just outside the ring stay grey (the star itself is visible).
    for (x, y) in [(60, 60), (63, 60), (68, 60), (60, 51)] {
        let p = px(&img, x, y);
        assert!(p[0] == p[1] && p[1] == p[2], "({x},{y}) = {p:?}");
    }
    assert!(
        px(&img, 60, 60)[0] > 200,
        "bright blob stretched to near white"
    );
}

#[test]
fn unmatched_marks_use_other_colour_and_shape() {
    let pixels = frame(20, 4, 255, 255, &[(140.0, 40.0)]);
    let img = render(&annotation(&pixels));
    // Square of half-side 6: edges and corners are orange, none green.
    for (x, y) in [
        (146, 40),
        (134, 40),
        (140, 34),
        (140, 46),
        (146, 46),
        (134, 34),
    ] {
        assert_eq!(px(&img, x, y), UNMATCHED, "({x},{y})");
    }
    assert_ne!(UNMATCHED, IDENTIFIED);
}

#[test]
fn predicted_cross_marks_centre() {
    let pixels = frame(20, 4, 255, 255, &[]);
    let img = render(&annotation(&pixels));
    for (x, y) in [(120, 100), (124, 100), (116, 100), (120, 96), (120, 104)] {
        assert_eq!(px(&img, x, y), PREDICTED, "({x},{y})");
    }
    // Diagonals are not part of a plus.
    assert_ne!(px(&img, 123, 103), PREDICTED);
}

#[test]
fn label_drawn_right_of_identified_star() {
    let pixels = frame(20, 4, 255, 255, &[(60.0, 60.0)]);
    let img = render(&annotation(&pixels));
    let count = |x0: u32, x1: u32, colour: Rgb<u8>| {
        (x0..x1)
            .flat_map(|x| (54..67).map(move |y| (x, y)))
            .filter(|&(x, y)| px(&img, x, y) == colour)
            .count()
    };
    // "HIP 27989" = 9 glyphs, 53 px wide, starting just right of the ring.
    assert!(count(68, 130, IDENTIFIED) > 60, "green label pixels");
    assert!(count(68, 130, OUTLINE) > 30, "dark outline around them");
    assert_eq!(count(20, 53, IDENTIFIED), 0, "nothing to the left");
}

#[test]
fn label_moves_left_at_right_edge() {
    let pixels = frame(20, 4, 255, 255, &[]);
    let mut a = annotation(&pixels);
    a.identified = vec![(mark(185.0, 80.0, 1.0), "HIP 7".into())];
    a.unmatched.clear();
    a.predicted.clear();
    let img = render(&a);
    let green_left = (140..178).flat_map(|x| (74..88).map(move |y| (x, y)));
    assert!(
        green_left
            .filter(|&(x, y)| px(&img, x, y) == IDENTIFIED)
            .count()
            > 10
    );
}

#[test]
fn marks_at_edges_are_clipped() {
    let pixels = frame(20, 4, 255, 255, &[]);
    let mut a = annotation(&pixels);
    let corners = [
        mark(-5.0, -5.0, 3.0),
        mark(199.9, 149.9, 3.0),
        mark(-1e6, 3e6, 1e9),
    ];
    a.identified = corners.iter().map(|m| (*m, "HIP 1".into())).collect();
    a.unmatched = corners.to_vec();
    a.predicted = corners.to_vec();
    a.predicted.push(mark(0.0, 0.0, f64::INFINITY));
    a.unmatched.push(mark(100.0, 75.0, 1e300)); // ring far outside the frame
    let img = render(&a);
    assert_eq!(img.dimensions(), (W, H));
    // The ring around (199.9, 149.9) shows inside the frame, over the legend band.
    assert_eq!(px(&img, 199, 144), IDENTIFIED);
    assert_eq!(px(&img, 194, 147), UNMATCHED);
    // Its cross centre rounds to (200, 150), outside: nothing cyan in that corner.
    let mut corner = (185..200).flat_map(|x| (135..150).map(move |y| (x, y)));
    assert!(corner.all(|(x, y)| px(&img, x, y) != PREDICTED));
}

#[test]
fn nan_marks_are_skipped() {
    let pixels = frame(20, 4, 255, 255, &[]);
    let mut a = annotation(&pixels);
    a.identified = vec![
        (mark(f64::NAN, 50.0, 2.0), "HIP 5".into()),
        (mark(60.0, 60.0, f64::NAN), "HIP 6".into()),
    ];
    a.unmatched = vec![mark(10.0, f64::NAN, 2.0)];
    a.predicted = vec![mark(f64::INFINITY, 10.0, 2.0)];
    a.caption.clear();
    let img = render(&a);
    // The NaN-radius mark still draws at the minimum radius; NaN positions do not.
    assert_eq!(px(&img, 66, 60), IDENTIFIED);
    let coloured = img
        .pixels()
        .filter(|p| **p == UNMATCHED || **p == PREDICTED)
        .count();
    let legend = render(&Annotation {
        identified: vec![],
        unmatched: vec![],
        predicted: vec![],
        ..a.clone()
    });
    let legend_only = legend
        .pixels()
        .filter(|p| **p == UNMATCHED || **p == PREDICTED)
        .count();
    assert_eq!(
        coloured, legend_only,
        "only the legend samples are orange/cyan"
    );
}

#[test]
fn sixteen_bit_frame_is_stretched() {
    let pixels = frame(1000, 60, 65535, 65535, &[(60.0, 60.0), (150.0, 100.0)]);
    let mut a = annotation(&pixels);
    a.saturation = 65535;
    a.identified.clear();
    a.unmatched.clear();
    a.predicted.clear();
    a.caption.clear();
    let img = render(&a);
    // Sky region (away from blobs, caption and legend).
    let sky: Vec<u8> = (20..50)
        .flat_map(|x| (30..100).map(move |y| (x, y)))
        .map(|(x, y)| px(&img, x, y)[0])
        .collect();
    let mean = sky.iter().map(|&v| f64::from(v)).sum::<f64>() / sky.len() as f64;
    assert!(
        (15.0..80.0).contains(&mean),
        "sky is dark grey, mean {mean}"
    );
    assert!(sky.iter().any(|&v| v != sky[0]), "sky noise is visible");
    assert!(px(&img, 60, 60)[0] == 255, "star saturates white");
    // A faint 10-sigma star stands out well above the sky.
    let faint = frame(1000, 60, 600, 65535, &[(60.0, 60.0)]);
    let f = render(&Annotation {
        pixels: &faint,
        ..a.clone()
    });
    assert!(
        f64::from(px(&f, 60, 60)[0]) > mean + 60.0,
        "faint star visible"
    );
}

#[test]
fn degenerate_frames_do_not_panic() {
    let empty = Annotation {
        width: 0,
        height: 10,
        pixels: &[],
        saturation: 255,
        identified: vec![(mark(1.0, 1.0, 1.0), "HIP 1".into())],
        unmatched: vec![],
        predicted: vec![],
        streaks: vec![],
        caption: "x".into(),
    };
    assert_eq!(render(&empty).dimensions(), (1, 1));
    let short = Annotation {
        width: 10,
        height: 10,
        pixels: &[0; 50],
        ..empty.clone()
    };
    assert_eq!(render(&short).dimensions(), (1, 1));
    let dir = std::env::temp_dir().join(format!("annotate-test-{}", std::process::id()));
    let err = write_png(&dir.join("empty.png"), &empty).unwrap_err();
    assert!(err.to_string().contains("0x10"), "{err}");
    // Tiny and flat frames, odd saturation, non-ASCII caption.
    let tiny = Annotation {
        width: 1,
        height: 1,
        pixels: &[7],
        saturation: 0,
        caption: "é ü".into(),
        ..empty.clone()
    };
    assert_eq!(render(&tiny).dimensions(), (1, 1));
    let flat = [500u16; 64 * 4];
    let flat = render(&Annotation {
        width: 64,
        height: 4,
        pixels: &flat,
        ..empty
    });
    assert_eq!(flat.dimensions(), (64, 4));
}

#[test]
fn write_png_creates_parent_dirs() {
    let pixels = frame(20, 4, 255, 255, &[(60.0, 60.0)]);
    let dir = std::env::temp_dir().join(format!("annotate-test-{}-w", std::process::id()));
    let path = dir.join("a/b/frame.png");
    write_png(&path, &annotation(&pixels)).unwrap();
    let back = image::open(&path).unwrap().to_rgb8();
    assert_eq!(back, render(&annotation(&pixels)));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn font_scale_grows_with_frame() {
    assert_eq!(font_scale(200, 150), 1);
    assert_eq!(font_scale(1499, 1000), 1);
    assert_eq!(font_scale(1500, 1000), 2);
    assert_eq!(font_scale(3000, 3000), 2);
    assert_eq!(font_scale(4096, 4096), 3);
    assert_eq!(font_scale(1000, 4000), 3);
}

#[test]
fn caption_wraps_and_font_covers_caption_text() {
    assert_eq!(
        wrap("solved RA 83.82  Dec -5.39", 12),
        ["solved RA", "83.82 Dec", "-5.39"]
    );
    assert_eq!(wrap("abcdefghij", 4), ["abcd", "efgh", "ij"]);
    let question = glyph('?');
    for c in "solved RA 83.82 Dec -5.39 roll 12.3 23 stars HIP".chars() {
        assert!(c == '?' || glyph(c) != question, "{c:?} missing from font");
    }
    assert_eq!(glyph('~'), question);
}
