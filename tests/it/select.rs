//! Stage `select` (CPU twin) on hand-made inputs.

use crate::common;

use gpustar::cpu::select::*;
use gpustar::cpu::vote::PairRange;
use gpustar::gpu::vote::VoteJob;

#[test]
fn best_first_and_ties_go_to_the_lowest_id() {
    let votes = [0, 3, 5, 5, 1, /* star 1 */ 0, 0, 0, 0, 0];
    let c = select(&votes, 2, 5, 3);
    let got: Vec<_> = c.iter().map(|&p| unpack_candidate(p)).collect();
    assert_eq!(
        got,
        vec![Some((5, 2)), Some((5, 3)), Some((3, 1)), None, None, None]
    );
}

#[test]
fn gpu_selects_like_cpu_on_ranges_at_row_keys_padding_and_few_candidates() {
    let Some(g) =
        common::gpu("gpu_selects_like_cpu_on_ranges_at_row_keys_padding_and_few_candidates")
    else {
        return;
    };
    let solver = common::solver(10.0, (512, 512));
    let t = solver.bands[0].table();
    let k = |r: usize| t.keys[r];
    // Ranges whose ends are exactly row keys (inclusive ends), empty ranges, the top of the
    // key space, and the first row.
    let ranges = vec![
        PairRange {
            i: 0,
            j: 1,
            lo: k(100),
            hi: k(100),
        },
        PairRange {
            i: 0,
            j: 2,
            lo: k(5000),
            hi: k(5200),
        },
        PairRange {
            i: 1,
            j: 2,
            lo: k(7000) + 1,
            hi: k(7000),
        },
        PairRange {
            i: 1,
            j: 3,
            lo: t.max_key,
            hi: u32::MAX,
        },
        PairRange {
            i: 2,
            j: 3,
            lo: 0,
            hi: k(0),
        },
    ];
    let jobs = vec![
        VoteJob {
            ranges: ranges.clone(),
            stars: 4,
            k: 64,
        },
        // Fewer stars than the batch's widest job: padding pairs and rows.
        VoteJob {
            ranges: ranges[..1].to_vec(),
            stars: 2,
            k: 16,
        },
        // A single narrow range: fewer nonzero candidates than k.
        VoteJob {
            ranges: vec![PairRange {
                i: 0,
                j: 1,
                lo: k(3),
                hi: k(3),
            }],
            stars: 2,
            k: 20,
        },
    ];
    common::assert_votes_equal(&g, &solver, &jobs);
}
