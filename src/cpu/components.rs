//! Stage `components`: 8-connected components of the mask.
//!
//! Each pixel of a component is labelled with the smallest pixel index (y·W + x) in it, so the
//! labels are canonical: the GPU's union-find with `atomicMin` reaches the same labels in any
//! scheduling. Here: union-find in raster order, always hanging the larger root under the
//! smaller, then a compression pass.

/// Label of pixels outside the mask.
pub const NO_LABEL: u32 = u32::MAX;

fn find(parent: &mut [u32], mut i: u32) -> u32 {
    while parent[i as usize] != i {
        let grand = parent[parent[i as usize] as usize];
        parent[i as usize] = grand;
        i = grand;
    }
    i
}

fn union(parent: &mut [u32], a: u32, b: u32) {
    let (ra, rb) = (find(parent, a), find(parent, b));
    if ra != rb {
        parent[ra.max(rb) as usize] = ra.min(rb);
    }
}

/// Labels of a `width`×`height` mask (row-major, non-zero = set).
pub fn components(mask: &[u8], width: u32, height: u32) -> Vec<u32> {
    let (w, h) = (width as usize, height as usize);
    assert_eq!(mask.len(), w * h, "mask size");
    let mut parent = vec![NO_LABEL; w * h];
    for y in 0..h {
        for x in 0..w {
            let i = y * w + x;
            if mask[i] == 0 {
                continue;
            }
            parent[i] = i as u32;
            // Neighbours already visited: W, NW, N, NE.
            if x > 0 && mask[i - 1] != 0 {
                union(&mut parent, i as u32, (i - 1) as u32);
            }
            if y > 0 {
                let up = i - w;
                if x > 0 && mask[up - 1] != 0 {
                    union(&mut parent, i as u32, (up - 1) as u32);
                }
                if mask[up] != 0 {
                    union(&mut parent, i as u32, up as u32);
                }
                if x + 1 < w && mask[up + 1] != 0 {
                    union(&mut parent, i as u32, (up + 1) as u32);
                }
            }
        }
    }
    for i in 0..w * h {
        if parent[i] != NO_LABEL {
            parent[i] = find(&mut parent, i as u32);
        }
    }
    parent
}
