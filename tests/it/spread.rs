//! The spread retry: when a bright cluster of false stars (lit foliage, a roof, a hot corner)
//! fills the brightest detections, voters taken round a grid of cells bring the real stars back.

use crate::common;

use gpustar::io::frame::Frame;
use gpustar::simulate::{SimSettings, Truth};
use gpustar::solve::detect::Detection;
use gpustar::solve::{PassKind, Solver, spread_order};

fn det(x: f64, y: f64) -> Detection {
    Detection {
        x,
        y,
        flux: 0.0,
        area: 4,
        peak: 0,
        saturated: false,
        sigma_px: None,
    }
}

#[test]
fn spread_order_takes_the_brightest_of_each_cell_in_turn() {
    // 400×400 in 16 cells of 100 px. Brightest first: five in the top-left cell, then one in
    // each of three other cells, then a second one in the top-left's right neighbour.
    let dets = [
        det(10.0, 10.0),
        det(20.0, 20.0),
        det(30.0, 30.0),
        det(40.0, 40.0),
        det(50.0, 50.0),
        det(150.0, 10.0),
        det(350.0, 350.0),
        det(10.0, 250.0),
        det(160.0, 20.0),
    ];
    let order = spread_order(&dets, 400, 400);
    assert_eq!(order, vec![0, 5, 6, 7, 1, 8, 2, 3, 4]);
    // A permutation whatever the shape: a wide frame, points on the edges.
    let edge = [
        det(-0.5, -0.5),
        det(751.4, 289.4),
        det(375.0, 0.0),
        det(0.0, 289.0),
    ];
    let mut o = spread_order(&edge, 752, 290);
    o.sort_unstable();
    assert_eq!(o, vec![0, 1, 2, 3]);
}

/// 10 simulated 1024² frames at 14° (Hp ≤ 6) with 90 bright spots crowding one corner.
fn crowded() -> Vec<(Frame<'static>, Truth)> {
    let s = SimSettings {
        fov_x_deg: 14.0,
        mag_limit: 6.0,
        seed: 5,
        ..SimSettings::default()
    };
    let mut set = common::rendered(&s, 10);
    for (k, (f, _)) in set.iter_mut().enumerate() {
        common::crowd_corner(f, 90, k as u64);
    }
    set
}

/// (solved, wrong: more than 0.1° off) with the solver's passes, or without the spread ones.
fn solve(solver: &mut Solver, spread: bool, set: &[(Frame, Truth)]) -> (usize, usize) {
    if !spread {
        solver.passes.retain(|p| p.kind != PassKind::Spread);
    }
    common::solved_and_wrong(solver, set, 0.1)
}

#[test]
fn the_spread_retry_solves_frames_whose_brightest_spots_crowd_one_corner() {
    let set = crowded();
    let with = solve(&mut common::solver(14.0, (1024, 1024)), true, &set);
    let without = solve(&mut common::solver(14.0, (1024, 1024)), false, &set);
    common::assert_retry_adds(
        "90 bright spots in one corner",
        "the spread retry",
        10,
        9,
        with,
        without,
    );
}
