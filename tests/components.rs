//! Stage `components` (CPU twin) on hand-made inputs.

use gpustar::cpu::components::*;

fn mask(rows: &[&str]) -> (Vec<u8>, u32, u32) {
    let w = rows[0].len() as u32;
    let m = rows
        .iter()
        .flat_map(|r| r.bytes().map(|b| (b == b'#') as u8))
        .collect();
    (m, w, rows.len() as u32)
}

#[test]
fn diagonal_touch_joins_and_u_shape_takes_the_smallest_index() {
    // A U shape whose right arm starts first in raster order only at its top: both arms
    // must end with the label of the top-left pixel (index 0).
    let (m, w, h) = mask(&["#..#", "#..#", "####", "....", ".#..", "..#."]);
    let l = components(&m, w, h);
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
fn separate_blobs_and_borders() {
    let (m, w, h) = mask(&["#.#", "...", "#.#"]);
    let l = components(&m, w, h);
    assert_eq!(
        l,
        vec![0, NO_LABEL, 2, NO_LABEL, NO_LABEL, NO_LABEL, 6, NO_LABEL, 8]
    );
    let (m, w, h) = mask(&["#"]);
    assert_eq!(components(&m, w, h), vec![0]);
    let (m, w, h) = mask(&["."]);
    assert_eq!(components(&m, w, h), vec![NO_LABEL]);
}
