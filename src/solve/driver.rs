//! The identification flow, written once for both backends, over a batch of frames of one size
//! (one frame on the CPU, a GPU batch on the GPU); the backend's [`Kernels`] compute the
//! lookups, votes and detections. For each frame:
//!
//! 1. within its pointing hint's region first, when it has one (the CPU twins: a region's
//!    table is a few thousand rows, less work than its upload);
//! 2. lost in space (the size's solver, built only now if every frame had a region): the
//!    scale-free pass, round by round (all rounds in one lookup on the GPU);
//! 3. with a searched scale, the pass again on the matched filter's detections and on the
//!    point sources (`detect::point_sources`) of frames without a region, before any walk
//!    (`Solver::scale_free_first`);
//! 4. the walk: each pass of the solver (the vote, radial features or triangles, at each
//!    scale) for the frames not solved yet, then the triangle fallbacks of the passes whose
//!    vote failed;
//! 5. the detection retry: frames still unsolved, detected with the matched filter, are
//!    identified again (1, 2 and 4) when that finds a star the first detection did not.
//!
//! A frame's solution is the same whichever backend and batch it is solved in.

use super::detect::{self, Detection};
use super::kernels::{CpuKernels, Kernels};
use super::outcome::{Outcome, Solution, Unsolved};
use super::scale_free::Checked;
use super::solver::{Prepared, Solver};
use crate::io::frame::Frame;
use std::ops::Deref;
use std::time::Instant;

/// Identify a batch's frames from their first detections (`first[i]`, frame `i`'s epoch
/// `epochs[i]` and hinted region's solver `regional[i]`). `global` makes the lost-in-space
/// solver, called only when some frame is not solved within its region. `sizes` (each frame's
/// width and height) when the kernels can detect the frames again: the matched filter's and
/// the point sources' stages and the detection retry run only then (not for star lists, nor
/// with `--streaks`, whose detection takes the streaks out first).
pub fn identify_batch<K, G>(
    kernels: &mut K,
    regional: &[Option<&Solver>],
    global: impl FnOnce() -> Option<G>,
    first: Vec<Vec<Detection>>,
    epochs: &[Option<f64>],
    sizes: Option<&[(u32, u32)]>,
) -> Result<Vec<Solution>, K::Error>
where
    K: Kernels + ?Sized,
    G: Deref<Target = Solver>,
{
    let n = first.len();
    let mut dets = first;
    let all: Vec<usize> = (0..n).collect();
    let mut outcomes = within_regions(regional, &dets, epochs, &all);
    let global = if outcomes.iter().all(solved) {
        None
    } else {
        global()
    };
    let g = global.as_deref();
    // The matched filter's detections of the frames stage 3 has detected again.
    let mut filtered: Vec<Option<Vec<Detection>>> = vec![None; n];
    if let Some(g) = g {
        pass_stage(kernels, g, &dets, epochs, &all, &mut outcomes, &[])?;
        if let Some(sizes) = sizes.filter(|_| g.scale_free_first()) {
            let todo: Vec<usize> = (0..n)
                .filter(|&i| regional[i].is_none() && !solved(&outcomes[i]))
                .collect();
            if !todo.is_empty() {
                let stars = kernels.detect_filtered(&todo, &g.settings.detect.filtered())?;
                for (&i, s) in todo.iter().zip(stars) {
                    filtered[i] = Some(s);
                }
                let lists: Vec<&[Detection]> = todo
                    .iter()
                    .map(|&i| filtered[i].as_deref().unwrap_or(&[]))
                    .collect();
                let found = scale_free(kernels, g, &lists, &pick(epochs, &todo))?;
                for (&i, o) in todo.iter().zip(found) {
                    if let Some(o) = o {
                        outcomes[i] = o;
                        dets[i] = filtered[i].take().unwrap_or_default();
                    }
                }
                if !g.settings.walks() {
                    point_sources(kernels, g, &mut dets, epochs, sizes, &todo, &mut outcomes)?;
                }
            }
        }
        walk(kernels, g, &dets, epochs, &all, &mut outcomes)?;
    } else {
        unsolved_without_global(regional, &all, &mut outcomes);
    }
    if sizes.is_some() {
        retry(
            kernels,
            regional,
            g,
            &mut dets,
            epochs,
            &mut filtered,
            &mut outcomes,
        )?;
    }
    Ok(dets
        .into_iter()
        .zip(outcomes)
        .zip(epochs)
        .map(|((detections, outcome), &epoch)| Solution {
            detections,
            outcome,
            epoch,
        })
        .collect())
}

fn solved(o: &Outcome) -> bool {
    matches!(o, Outcome::Solved(..))
}

fn pick<T: Copy>(v: &[T], which: &[usize]) -> Vec<T> {
    which.iter().map(|&i| v[i]).collect()
}

/// Step 1 for frames `which`: each frame with a region identified within it; the others (and
/// those it did not solve) keep the region's outcome until lost-in-space decides.
fn within_regions(
    regional: &[Option<&Solver>],
    dets: &[Vec<Detection>],
    epochs: &[Option<f64>],
    which: &[usize],
) -> Vec<Outcome> {
    let mut outcomes = vec![Outcome::Unsolved(Unsolved::TooFewStars); dets.len()];
    for &i in which {
        if let Some(r) = regional[i] {
            outcomes[i] = r.identify(dets[i].clone(), epochs[i]).outcome;
        }
    }
    outcomes
}

/// Without a lost-in-space solver (it could not be built): a region's outcome stands, and a
/// frame without one has no consistent match.
fn unsolved_without_global(
    regional: &[Option<&Solver>],
    which: &[usize],
    outcomes: &mut [Outcome],
) {
    for &i in which {
        if regional[i].is_none() && !solved(&outcomes[i]) {
            outcomes[i] = Outcome::Unsolved(Unsolved::NoConsistentMatch);
        }
    }
}

/// Step 2 for the frames of `which` not solved yet, less those of `skip_pass`.
fn pass_stage<K: Kernels + ?Sized>(
    kernels: &mut K,
    g: &Solver,
    dets: &[Vec<Detection>],
    epochs: &[Option<f64>],
    which: &[usize],
    outcomes: &mut [Outcome],
    skip_pass: &[usize],
) -> Result<(), K::Error> {
    let todo: Vec<usize> = (which.iter().copied())
        .filter(|&i| !solved(&outcomes[i]) && !skip_pass.contains(&i))
        .collect();
    let lists: Vec<&[Detection]> = todo.iter().map(|&i| dets[i].as_slice()).collect();
    let found = scale_free(kernels, g, &lists, &pick(epochs, &todo))?;
    for (&i, o) in todo.iter().zip(found) {
        if let Some(o) = o {
            outcomes[i] = o;
        }
    }
    Ok(())
}

/// The scale-free pass over star lists: each list's rounds, `rounds_per_lookup` at a time,
/// until one solves it or its budget is spent. The outcome of each list it solved.
fn scale_free<K: Kernels + ?Sized>(
    kernels: &mut K,
    g: &Solver,
    lists: &[&[Detection]],
    epochs: &[Option<f64>],
) -> Result<Vec<Option<Outcome>>, K::Error> {
    let mut found: Vec<Option<Outcome>> = vec![None; lists.len()];
    if g.scale_free.is_none() {
        return Ok(found);
    }
    let per = kernels.rounds_per_lookup().max(1);
    let mut checked = vec![Checked::default(); lists.len()];
    let mut live: Vec<usize> = (0..lists.len()).collect();
    let mut start = 0usize;
    while !live.is_empty() {
        let lookups: Vec<_> = (live.iter())
            .filter_map(|&k| {
                let end = g.scale_free_rounds(lists[k].len());
                (start < end)
                    .then(|| {
                        g.scale_free_lookup(lists[k], start..start.saturating_add(per).min(end))
                    })
                    .flatten()
                    .map(|l| (k, l))
            })
            .collect();
        if lookups.is_empty() {
            break;
        }
        let rows = kernels.pattern(g, &lookups.iter().map(|(_, l)| l).collect::<Vec<_>>())?;
        live.clear();
        for ((k, l), rows) in lookups.iter().zip(rows) {
            let c = &mut checked[*k];
            match g.finish_scale_free(lists[*k], l, &rows, epochs[*k], c) {
                Some(o) => found[*k] = Some(o),
                None if !c.spent => live.push(*k),
                None => {}
            }
        }
        start = start.saturating_add(per);
    }
    Ok(found)
}

/// Step 3's second half: the pass on the point sources of the frames of `todo` it has not
/// solved; a frame solved there keeps those detections.
fn point_sources<K: Kernels + ?Sized>(
    kernels: &mut K,
    g: &Solver,
    dets: &mut [Vec<Detection>],
    epochs: &[Option<f64>],
    sizes: &[(u32, u32)],
    todo: &[usize],
    outcomes: &mut [Outcome],
) -> Result<(), K::Error> {
    let s = &g.settings.detect;
    let (which, points): (Vec<usize>, Vec<Vec<Detection>>) = (todo.iter())
        .filter(|&&i| !solved(&outcomes[i]))
        .filter_map(|&i| {
            let (w, h) = sizes[i];
            Some((i, detect::point_sources(&dets[i], w, h, s)?))
        })
        .unzip();
    let lists: Vec<&[Detection]> = points.iter().map(Vec::as_slice).collect();
    let found = scale_free(kernels, g, &lists, &pick(epochs, &which))?;
    for ((&i, o), p) in which.iter().zip(found).zip(points) {
        if let Some(o) = o {
            outcomes[i] = o;
            dets[i] = p;
        }
    }
    Ok(())
}

/// Step 4 for the frames of `which` not solved yet: each of the solver's passes in turn, then
/// the triangle fallbacks of the passes whose vote failed, in pass order.
fn walk<K: Kernels + ?Sized>(
    kernels: &mut K,
    g: &Solver,
    dets: &[Vec<Detection>],
    epochs: &[Option<f64>],
    which: &[usize],
    outcomes: &mut [Outcome],
) -> Result<(), K::Error> {
    let todo: Vec<usize> = (which.iter().copied())
        .filter(|&i| !solved(&outcomes[i]))
        .collect();
    for &i in &todo {
        outcomes[i] = g.unsolved_before_walk(&dets[i]);
    }
    let mut fallbacks: Vec<Vec<(usize, Prepared)>> = vec![Vec::new(); dets.len()];
    for h in 0..g.passes.len() {
        let prepared: Vec<(usize, Prepared)> = (todo.iter())
            .filter(|&&i| !solved(&outcomes[i]))
            .filter_map(|&i| Some((i, g.prepare(&dets[i], h)?)))
            .collect();
        if prepared.is_empty() {
            continue;
        }
        let ran: Vec<usize> = prepared.iter().map(|(i, _)| *i).collect();
        let band = g.passes[h].band;
        let jobs: Vec<&Prepared> = prepared.iter().map(|(_, p)| p).collect();
        match (g.passes[h].method, &g.bands[band].radial) {
            (super::radial::Method::Triangle, _) => {
                for (i, p) in &prepared {
                    outcomes[*i] = g.finish_triangle_method(&dets[*i], p, epochs[*i]);
                }
            }
            (super::radial::Method::Radial, Some(_)) => {
                let found = kernels.radial(g, band, &jobs)?;
                for ((i, p), f) in prepared.iter().zip(found) {
                    outcomes[*i] = g.finish_radial(&dets[*i], p, &f, epochs[*i]);
                }
            }
            _ => {
                let voted = kernels.vote(g, band, &jobs)?;
                for ((i, p), v) in prepared.into_iter().zip(voted) {
                    outcomes[i] = g.finish(&dets[i], &p, &v, epochs[i]);
                    if !solved(&outcomes[i]) && Solver::falls_back(&p) {
                        fallbacks[i].push((h, p));
                    }
                }
            }
        }
        for &i in &ran {
            if solved(&outcomes[i]) {
                tracing::debug!("solved by pass {h} ({:?})", g.passes[h].kind);
            }
        }
    }
    for &i in &todo {
        if !solved(&outcomes[i])
            && let Some(o) = g.fall_back(&dets[i], &fallbacks[i], epochs[i])
        {
            outcomes[i] = o;
        }
    }
    Ok(())
}

/// Step 5: the frames still unsolved detected with the matched filter (the detections stage 3
/// made are kept: the same), and identified again (within their region, then lost in space,
/// the scale-free pass skipped where stage 3 has run it on those detections) when that finds
/// a star the first detection did not. A frame solved again keeps the new detections.
fn retry<K: Kernels + ?Sized>(
    kernels: &mut K,
    regional: &[Option<&Solver>],
    g: Option<&Solver>,
    dets: &mut [Vec<Detection>],
    epochs: &[Option<f64>],
    filtered: &mut [Option<Vec<Detection>>],
    outcomes: &mut [Outcome],
) -> Result<(), K::Error> {
    // The run's settings: any solver of the batch has them.
    let Some(lead) = g.or_else(|| regional.iter().flatten().next().copied()) else {
        return Ok(());
    };
    if lead.detection_stages() < 2 {
        return Ok(());
    }
    let unsolved: Vec<usize> = (0..dets.len()).filter(|&i| !solved(&outcomes[i])).collect();
    // Stage 3 has detected these again, and run the scale-free pass on what it found.
    let (passed, missing): (Vec<usize>, Vec<usize>) =
        (unsolved.iter()).partition(|&&i| filtered[i].is_some());
    let stars = kernels.detect_filtered(&missing, &lead.settings.detect.filtered())?;
    for (&i, s) in missing.iter().zip(stars) {
        filtered[i] = Some(s);
    }
    let again: Vec<usize> = (unsolved.into_iter())
        .filter(|&i| {
            let f = filtered[i].as_deref().unwrap_or(&[]);
            detect::adds_stars(&dets[i], f)
        })
        .collect();
    if again.is_empty() {
        return Ok(());
    }
    let second: Vec<Vec<Detection>> = (0..dets.len())
        .map(|i| match again.contains(&i) {
            true => filtered[i].take().unwrap_or_default(),
            false => Vec::new(),
        })
        .collect();
    let mut redone = within_regions(regional, &second, epochs, &again);
    match g {
        Some(g) => {
            pass_stage(kernels, g, &second, epochs, &again, &mut redone, &passed)?;
            walk(kernels, g, &second, epochs, &again, &mut redone)?;
        }
        None => unsolved_without_global(regional, &again, &mut redone),
    }
    for (i, (o, d)) in redone.into_iter().zip(second).enumerate() {
        if again.contains(&i) && solved(&o) {
            outcomes[i] = o;
            dets[i] = d;
        }
    }
    Ok(())
}

/// One star list on the CPU (no detection stage: star lists, `--streaks`): within `regional`'s
/// region first, then lost in space (`global`, made only when the region does not solve it).
pub fn identify_list_cpu<G: Deref<Target = Solver>>(
    regional: Option<&Solver>,
    global: impl FnOnce() -> Option<G>,
    detections: Vec<Detection>,
    epoch: Option<f64>,
) -> Solution {
    // The CPU twins cannot fail.
    let Ok(sols) = identify_batch(
        &mut CpuKernels::default(),
        &[regional],
        global,
        vec![detections],
        &[epoch],
        None,
    );
    only(sols)
}

/// The one solution of a one-frame batch (`identify_batch` gives one per frame).
fn only(mut sols: Vec<Solution>) -> Solution {
    sols.pop().expect("one solution per frame")
}

impl Solver {
    /// Identify the stars of a detection list on the CPU: the scale-free pass, then the walk.
    pub fn identify(&self, detections: Vec<Detection>, epoch: Option<f64>) -> Solution {
        identify_list_cpu(None, || Some(self), detections, epoch)
    }

    /// Solve a decoded frame on the CPU.
    pub fn solve_frame(&self, frame: &Frame) -> (Solution, f64, f64) {
        self.solve_frame_at(frame, None)
    }

    /// Solve a decoded frame on the CPU, with its own observation epoch if it has one: every
    /// step of the flow. Returns the solution, detection and identification times (ms).
    pub fn solve_frame_at(&self, frame: &Frame, epoch: Option<f64>) -> (Solution, f64, f64) {
        solve_frame_cpu(frame, &[None], || Some(self), &self.settings.detect, epoch)
    }
}

/// One frame on the CPU through the whole flow, `regional` its region's solver: the solution,
/// detection and identification times (ms).
pub fn solve_frame_cpu<G: Deref<Target = Solver>>(
    frame: &Frame,
    regional: &[Option<&Solver>; 1],
    global: impl FnOnce() -> Option<G>,
    detect: &detect::DetectSettings,
    epoch: Option<f64>,
) -> (Solution, f64, f64) {
    let t0 = Instant::now();
    let (mut k, first) = CpuKernels::detect(&[frame], detect);
    let first_ms = t0.elapsed().as_secs_f64() * 1e3;
    let sizes = [(frame.width, frame.height)];
    // The CPU twins cannot fail.
    let Ok(sols) = identify_batch(&mut k, regional, global, first, &[epoch], Some(&sizes));
    let total_ms = t0.elapsed().as_secs_f64() * 1e3;
    let detect_ms = first_ms + k.detect_ms;
    (only(sols), detect_ms, total_ms - detect_ms)
}
