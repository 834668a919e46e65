//! Stage `components` (CPU twin) on hand-made masks.

use crate::common;

use gpustar::cpu::components::*;
use gpustar::cpu::threshold::DetectParams;
use gpustar::cpu::threshold::Run;

/// Runs and size of a mask drawn with '#'.
fn mask(rows: &[&str]) -> (Vec<Run>, u32, u32) {
    let w = rows[0].len() as u32;
    let mut runs = Vec::new();
    for (y, r) in rows.iter().enumerate() {
        let b = r.as_bytes();
        let mut x = 0;
        while x < b.len() {
            if b[x] == b'#' {
                let x0 = x;
                while x < b.len() && b[x] == b'#' {
                    x += 1;
                }
                runs.push(Run {
                    y: y as u32,
                    x0: x0 as u32,
                    x1: x as u32,
                });
            } else {
                x += 1;
            }
        }
    }
    (runs, w, rows.len() as u32)
}

fn labels(rows: &[&str]) -> Vec<u32> {
    let (runs, w, h) = mask(rows);
    dense_labels(&runs, &components(&runs, w), w, h)
}

#[test]
fn diagonal_touch_joins_and_u_shape_takes_the_smallest_index() {
    // A U shape whose arms meet only at the bottom: both arms end with the label of the
    // top-left pixel (index 0).
    let l = labels(&["#..#", "#..#", "####", "....", ".#..", "..#."]);
    for i in [0, 3, 4, 7, 8, 9, 10, 11] {
        assert_eq!(l[i], 0, "pixel {i}");
    }
    assert_eq!(l[17], 17);
    assert_eq!(
        l[22], 17,
        "diagonal neighbour belongs to the same component"
    );
    assert_eq!(l[1], NO_LABEL);
}

#[test]
fn runs_joined_late_take_the_first_pixel_of_the_component() {
    // A W shape: three runs per row that only join in the last row.
    let n = NO_LABEL;
    let l = labels(&["#.#.#", "#.#.#", "#####"]);
    assert_eq!(l, vec![0, n, 0, n, 0, 0, n, 0, n, 0, 0, 0, 0, 0, 0]);
    // An anti-diagonal: the component's first pixel is index 2.
    let l = labels(&["..#", ".#.", "#.."]);
    assert_eq!(
        l,
        vec![
            NO_LABEL, NO_LABEL, 2, NO_LABEL, 2, NO_LABEL, 2, NO_LABEL, NO_LABEL
        ]
    );
}

#[test]
fn separate_blobs_borders_gaps_and_single_pixels() {
    assert_eq!(
        labels(&["#.#", "...", "#.#"]),
        vec![0, NO_LABEL, 2, NO_LABEL, NO_LABEL, NO_LABEL, 6, NO_LABEL, 8]
    );
    // Rows without runs in between: no join across the gap.
    assert_eq!(
        labels(&["##", "..", "##"]),
        vec![0, 0, NO_LABEL, NO_LABEL, 4, 4]
    );
    assert_eq!(labels(&["#"]), vec![0]);
    assert_eq!(labels(&["."]), vec![NO_LABEL]);
    // Two runs one apart in a row are separate unless the row above joins them.
    assert_eq!(labels(&["#.#"]), vec![0, NO_LABEL, 2]);
    assert_eq!(
        labels(&[".#.", "#.#"]),
        vec![NO_LABEL, 1, NO_LABEL, 1, NO_LABEL, 1]
    );
}

#[test]
fn gpu_equals_cpu_on_hand_made_masks_touching_borders() {
    let Some(g) = common::gpu("gpu_equals_cpu_on_hand_made_masks_touching_borders") else {
        return;
    };
    let frames = [
        common::drawn(&["#..#", "#..#", "####", "....", ".#..", "..#."]),
        common::drawn(&["#.#.#", "#.#.#", "#####"]),
        common::drawn(&["..#", ".#.", "#.."]),
        common::drawn(&["################################################################"]),
        common::drawn(&["#", "#", "#", "#", "#", "#"]),
    ];
    common::assert_detect_stages_equal(&g, &frames, 16);
    // No star at all.
    let dark = common::drawn(&[]);
    let p = DetectParams::new(dark.width, dark.height, 16, 5.0, 255);
    assert!(g.detect(&[&dark], &p).unwrap()[0].is_empty());
}

#[test]
fn gpu_reruns_when_components_and_set_pixels_overflow_its_first_buffers() {
    let Some(g) =
        common::gpu("gpu_reruns_when_components_and_set_pixels_overflow_its_first_buffers")
    else {
        return;
    };
    let (w, h) = (512u32, 512u32);
    // Isolated bright pixels on every other column of every other row: 65,536 components,
    // more than the 4,096 the blob buffer holds at first.
    let dots = gpustar::io::frame::Frame {
        width: w,
        height: h,
        pixels: (0..w * h)
            .map(|i| {
                if (i % w) % 2 == 0 && (i / w) % 2 == 0 {
                    200
                } else {
                    10
                }
            })
            .collect(),
        saturation: 255,
    };
    // A checkerboard: 131,072 set pixels, more than the 65,536 the set list holds at first,
    // all one component through their diagonals.
    let checks = gpustar::io::frame::Frame {
        pixels: (0..w * h)
            .map(|i| {
                if ((i % w) + (i / w)) % 2 == 0 {
                    200
                } else {
                    10
                }
            })
            .collect(),
        ..dots.clone()
    };
    let blobs = common::assert_detect_stages_equal(&g, &[dots, checks], 32);
    assert_eq!(blobs, 65_536 + 1);
}
