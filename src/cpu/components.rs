//! Stage `components`: 8-connected components of the mask.
//!
//! Each pixel of a component is labelled with the smallest pixel index (y·W + x) in it, so the
//! labels are canonical: the GPU's union-find with `atomicMin` reaches the same labels in any
//! scheduling. Here the mask comes as runs: a run joins every run of the row above that
//! touches it (diagonals included), union-find hangs the later run under the earlier, and the
//! label of a component is the first pixel of its first run in raster order.

use super::threshold::Run;

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

/// The label of each run (runs in raster order, as `threshold` gives them).
pub fn components(runs: &[Run], width: u32) -> Vec<u32> {
    let mut parent: Vec<u32> = (0..runs.len() as u32).collect();
    // Runs of the previous row: [prev_start, cur_start).
    let (mut prev_start, mut cur_start) = (0usize, 0usize);
    for i in 0..runs.len() {
        let r = runs[i];
        if i > 0 && runs[i - 1].y != r.y {
            prev_start = if runs[i - 1].y + 1 == r.y {
                cur_start
            } else {
                i
            };
            cur_start = i;
        }
        for (j, q) in runs.iter().enumerate().take(cur_start).skip(prev_start) {
            // 8-connected: the columns overlap once widened by one on each side.
            if q.x0 <= r.x1 && r.x0 <= q.x1 {
                let (a, b) = (find(&mut parent, i as u32), find(&mut parent, j as u32));
                if a != b {
                    parent[a.max(b) as usize] = a.min(b);
                }
            }
        }
    }
    (0..runs.len() as u32)
        .map(|i| {
            let root = runs[find(&mut parent, i) as usize];
            root.y * width + root.x0
        })
        .collect()
}

/// Labels as one value per pixel ([`NO_LABEL`] outside the mask), as the GPU stores them.
pub fn dense_labels(runs: &[Run], labels: &[u32], width: u32, height: u32) -> Vec<u32> {
    let mut out = vec![NO_LABEL; (width * height) as usize];
    for (r, &l) in runs.iter().zip(labels) {
        let row = (r.y * width) as usize;
        out[row + r.x0 as usize..row + r.x1 as usize].fill(l);
    }
    out
}
