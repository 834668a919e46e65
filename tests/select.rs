//! Stage `select` (CPU twin) on hand-made inputs.

use gpustar::cpu::select::*;

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
