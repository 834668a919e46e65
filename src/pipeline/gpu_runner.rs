//! The GPU side of a batch: frames grouped by size, detected, voted and fitted in few submissions; a failure moves the rest of the run to the CPU.

use super::camera_source::CameraSource;
use super::cpu_runner::{decoded_frame, solve_with};
use super::solvers::{BACKEND_CPU, Decoded, DetectKey, Detected, Global, Solvers};
use crate::cpu::centroid::Blob;
use crate::cpu::pattern::Rows;
use crate::cpu::threshold::DetectParams;
use crate::error::Result;
use crate::gpu::Gpu;
use crate::gpu::pattern::GpuPatterns;
use crate::gpu::radial::{GpuRadial, RadialJob};
use crate::gpu::vote::{GpuTable, VoteJob};
use crate::io::frame::Frame;
use crate::record::{Record, Timing};
use crate::solve::detect::{self, DetectSettings, Detection};
use crate::solve::driver::identify_batch;
use crate::solve::identify::VoteResult;
use crate::solve::kernels::Kernels;
use crate::solve::radial;
use crate::solve::scale_free::Lookup;
use crate::solve::{Prepared, Solver};
use crate::streaks::{self, fit::StreakFit};
use std::collections::HashMap;
use std::time::Instant;

/// The GPU side of a run: the context and the tables uploaded to it. It lives on one thread.
pub struct GpuRunner {
    pub gpu: Gpu,
    /// By frame size and band of the solver for that size.
    pub(crate) tables: HashMap<(u32, u32, usize), Result<GpuTable>>,
    /// The bands' radial features (`--method radial`), uploaded like the tables.
    pub(crate) radial: HashMap<(u32, u32, usize), Result<GpuRadial>>,
    /// The pattern index keys of the scale-free pass, by frame size.
    pub(crate) patterns: HashMap<(u32, u32), Result<GpuPatterns>>,
    /// Set once the GPU failed: the rest of the run is on the CPU.
    pub(crate) failed: bool,
}

impl GpuRunner {
    pub fn new(gpu: Gpu) -> GpuRunner {
        GpuRunner {
            gpu,
            tables: HashMap::new(),
            radial: HashMap::new(),
            patterns: HashMap::new(),
            failed: false,
        }
    }

    /// Solve decoded frames: each size as one GPU batch (detection, then voting), the rest
    /// on the CPU. One record per frame, in the order given.
    pub fn solve(&mut self, solvers: &Solvers, frames: Vec<Decoded>) -> Vec<Record> {
        if matches!(solvers.camera, CameraSource::None | CameraSource::Header) {
            // Streaks alone, through the headers' WCS (see `streaks_only`), or each frame's
            // camera from its header (the GPU's tables are kept by frame size): the CPU twins.
            return frames.into_iter().map(|d| solvers.solve_cpu(d)).collect();
        }
        let mut records: Vec<Option<Record>> = (frames.iter())
            .map(|d| {
                (d.frame.as_ref().err()).map(|e| solvers.error_record(&d.name, e, &self.name()))
            })
            .collect();
        for ((w, h, _), indices) in size_groups(&frames) {
            let group: Vec<&Decoded> = indices.iter().map(|&i| &frames[i]).collect();
            let recs = self.solve_size(solvers, (w, h), &group);
            for (i, r) in indices.into_iter().zip(recs) {
                records[i] = Some(r);
            }
        }
        records
            .into_iter()
            .map(|r| r.expect("one record per frame"))
            .collect()
    }

    /// Frames of one size: each within its hint's region first, then lost in space; on the
    /// GPU unless it has failed.
    fn solve_size(
        &mut self,
        solvers: &Solvers,
        (w, h): (u32, u32),
        group: &[&Decoded],
    ) -> Vec<Record> {
        let regional: Vec<Option<Solver>> = (group.iter())
            .map(|d| solvers.regional(d, decoded_frame(d)))
            .collect();
        // When every frame has a hint, the lost-in-space solver (its distance table) is built
        // only if a region does not solve its frame.
        let global = if regional.iter().all(Option::is_some) {
            Global::Lazy(solvers, (w, h), None)
        } else {
            match solvers.get(w, h) {
                Ok(s) => Global::Ready(s),
                Err(e) => {
                    // No lost-in-space solver: frames with a hint are solved within its
                    // region, on the CPU; the others carry the reason.
                    let lazy = Global::Lazy(solvers, (w, h), None);
                    let recs = group.iter().zip(&regional).map(|(d, r)| match r {
                        Some(r) => solve_with(solvers, Some(r), &lazy, d),
                        None => solvers.error_record(&d.name, &e, &self.name()),
                    });
                    return recs.collect();
                }
            }
        };
        if let Some(records) = self.on_gpu(|g| g.gpu_group(solvers, &global, &regional, group)) {
            return records;
        }
        let recs = group.iter().zip(&regional);
        recs.map(|(d, r)| solve_with(solvers, r.as_ref(), &global, d))
            .collect()
    }

    /// `run` on the GPU, unless it has failed: on its first error (warned once) the rest of the
    /// run goes to the CPU. None: the CPU's turn.
    fn on_gpu<T>(&mut self, run: impl FnOnce(&mut Self) -> Result<T>) -> Option<T> {
        if self.failed {
            return None;
        }
        let out = run(self);
        if let Err(e) = &out {
            tracing::warn!("{e:#}; this batch and the rest of the run use the CPU");
            self.failed = true;
        }
        out.ok()
    }

    /// The pixel stages alone (`--sequence`): the brightest `max_stars`, completed by the matched
    /// filter's faint sources (`detect::faint`: both lists from the kernels, merged on the CPU);
    /// each size as one GPU batch; on a GPU error the CPU takes over for good. One result per
    /// frame, in the order given.
    pub fn detect(
        &mut self,
        solvers: &Solvers,
        frames: Vec<Decoded<'static>>,
        max_stars: usize,
    ) -> Vec<Detected> {
        let by_size = size_groups(&frames);
        let mut found: Vec<Option<(Vec<Detection>, f64)>> = vec![None; frames.len()];
        let s = &solvers.settings.detect.for_sequence(max_stars);
        for (_, group) in by_size {
            let batch: Vec<&Frame> = group.iter().map(|&i| decoded_frame(&frames[i])).collect();
            let t0 = Instant::now();
            if let Some(stars) = self.on_gpu(|g| g.detect_with_faint(&batch, s)) {
                let ms = t0.elapsed().as_secs_f64() * 1e3 / group.len() as f64;
                for (&i, d) in group.iter().zip(stars) {
                    found[i] = Some((d, ms));
                }
                continue;
            }
            for &i in &group {
                let t0 = Instant::now();
                let dets = detect::faint::detect_with_faint(decoded_frame(&frames[i]), s);
                found[i] = Some((dets, t0.elapsed().as_secs_f64() * 1e3));
            }
        }
        let backend = self.name();
        frames
            .into_iter()
            .zip(found)
            .map(|(decoded, found)| {
                let (detections, detect_ms) = match (&decoded.frame, found) {
                    (Err(e), _) => (Err(e.clone()), 0.0),
                    (Ok(_), Some((d, ms))) => (Ok(d), ms),
                    (Ok(_), None) => unreachable!("every decoded frame is in a group"),
                };
                Detected {
                    decoded,
                    detections,
                    detect_ms,
                    backend: backend.clone(),
                }
            })
            .collect()
    }

    /// A batch's detections under `s`, completed by the matched filter's (the filter's alone
    /// when `s` asks for it), as `detect::faint::detect_with_faint` makes them on the CPU: the
    /// PSF fits of each list in one submission.
    fn detect_with_faint(
        &self,
        batch: &[&Frame],
        s: &DetectSettings,
    ) -> Result<Vec<Vec<Detection>>> {
        let blobs = |s: &DetectSettings| by_gain(batch, s, |f, p| self.gpu.detect(f, p));
        let plain = gpu_stars(&self.gpu, batch, &blobs(s)?, s)?;
        if s.matched_filter {
            return Ok(plain);
        }
        let filtered = s.filtered();
        let blobs = blobs(&filtered)?;
        let blobs: Vec<&[Blob]> = blobs.iter().map(Vec::as_slice).collect();
        let candidates = detect::unfitted_stars(batch, &blobs, &filtered);
        detect::faint::complete(batch, plain, candidates, s, |w| self.gpu.psf_fit(w))
    }

    /// The records' `backend` field.
    pub fn name(&self) -> String {
        if self.failed {
            BACKEND_CPU.to_string()
        } else {
            self.gpu.backend_name()
        }
    }

    /// One batch on the GPU (frames of one size): detection (with the streak mask, when asked)
    /// in one submission, then the driver's flow (`identify_batch`) on the GPU's kernels, with
    /// streak fits, verification and refinement on the CPU. A record per frame.
    fn gpu_group(
        &mut self,
        solvers: &Solvers,
        global: &Global,
        regional: &[Option<Solver>],
        group: &[&Decoded],
    ) -> Result<Vec<Record>> {
        let frames: Vec<&Frame> = group.iter().map(|d| decoded_frame(d)).collect();
        let epochs: Vec<Option<f64>> = group.iter().map(|d| d.epoch).collect();
        let settings = &solvers.settings.detect;
        let t0 = Instant::now();
        let (blobs, found): (_, Vec<Option<Vec<StreakFit>>>) = match &solvers.streaks {
            None => (
                by_gain(&frames, settings, |f, p| self.gpu.detect(f, p))?,
                vec![None; frames.len()],
            ),
            Some(o) => by_gain(&frames, settings, |f, p| {
                let sp = o.settings.params(p, settings.k_sigma);
                let (blobs, pixels) = self.gpu.detect_streaks(f, p, &sp)?;
                Ok((blobs.iter().zip(&pixels).zip(f))
                    .map(|((b, px), f)| {
                        let s = streaks::measure(f, &px.tiles, &px.mask, p, &o.settings);
                        (streaks::off_streaks(b, &s), Some(s))
                    })
                    .collect())
            })?
            .into_iter()
            .unzip(),
        };
        let detections = gpu_stars(&self.gpu, &frames, &blobs, settings)?;
        let detect_ms = t0.elapsed().as_secs_f64() * 1e3;
        let t1 = Instant::now();
        let regions: Vec<Option<&Solver>> = regional.iter().map(Option::as_ref).collect();
        // With streaks, detection took them out first: no second detection stage.
        let sizes: Vec<(u32, u32)> = frames.iter().map(|f| (f.width, f.height)).collect();
        let sizes = solvers.streaks.is_none().then_some(sizes.as_slice());
        let mut kernels = GpuKernels {
            runner: self,
            frames: &frames,
        };
        let solutions = identify_batch(
            &mut kernels,
            &regions,
            || global.solver(),
            detections,
            &epochs,
            sizes,
        )?;
        let identify_ms = t1.elapsed().as_secs_f64() * 1e3;
        let backend = self.gpu.backend_name();
        let n = group.len() as f64;
        let each = group.iter().zip(solutions).zip(found).zip(regional);
        Ok(each
            .map(|(((d, sol), found), r)| {
                let timing = Timing::of(d.decode_ms, detect_ms / n, identify_ms / n);
                // Any solver of the size makes the record (they share the camera).
                let lead = r.as_ref().or(global.ready());
                let frame = decoded_frame(d);
                solvers.record(lead, d, frame, &sol, found.as_deref(), timing, &backend)
            })
            .collect())
    }
}

/// The star lists of a GPU batch's frames from their blobs, the PSF fits (`--centroid ml`) by
/// the GPU kernel in one submission.
pub(crate) fn gpu_stars(
    gpu: &Gpu,
    frames: &[&Frame],
    blobs: &[Vec<Blob>],
    s: &DetectSettings,
) -> Result<Vec<Vec<Detection>>> {
    let blobs: Vec<&[Blob]> = blobs.iter().map(|b| b.as_slice()).collect();
    detect::stars_with(frames, &blobs, s, |w| gpu.psf_fit(w))
}

/// The decoded frames (by index) grouped by size and saturation, in order of first
/// appearance; frames that failed to decode are in no group.
pub(crate) fn size_groups(frames: &[Decoded]) -> Vec<(DetectKey, Vec<usize>)> {
    let mut groups: Vec<(DetectKey, Vec<usize>)> = Vec::new();
    for (i, d) in frames.iter().enumerate() {
        if let Ok(f) = &d.frame {
            let size = (f.width, f.height, f.saturation);
            match groups.iter_mut().find(|(s, _)| *s == size) {
                Some((_, v)) => v.push(i),
                None => groups.push((size, vec![i])),
            }
        }
    }
    groups
}

/// What `upload` put on the GPU for `key`, uploaded on first use; a failed upload is kept and
/// told again (not retried for every batch).
fn uploaded<K: std::hash::Hash + Eq, T>(
    cache: &mut HashMap<K, Result<T>>,
    key: K,
    upload: impl FnOnce() -> Result<T>,
) -> Result<&T> {
    cache
        .entry(key)
        .or_insert_with(upload)
        .as_ref()
        .map_err(Clone::clone)
}

/// `run` (a GPU detection of frames of one size under one uniform) on the frames of each
/// matched-filter gain apart ([`detect::gain_groups`]: one group without the filter, and
/// mostly one with it), its results back in the frames' order.
fn by_gain<T>(
    frames: &[&Frame],
    s: &DetectSettings,
    mut run: impl FnMut(&[&Frame], &DetectParams) -> Result<Vec<T>>,
) -> Result<Vec<T>> {
    let groups = detect::gain_groups(frames, s);
    if let [(gain, _)] = groups.as_slice() {
        return run(frames, &detect::params_at(frames[0], s, *gain));
    }
    let mut out: Vec<Option<T>> = (0..frames.len()).map(|_| None).collect();
    for (gain, which) in groups {
        let sub: Vec<&Frame> = which.iter().map(|&i| frames[i]).collect();
        let found = run(&sub, &detect::params_at(sub[0], s, gain))?;
        for (i, t) in which.into_iter().zip(found) {
            out[i] = Some(t);
        }
    }
    Ok(out
        .into_iter()
        .map(|t| t.expect("every frame is in a group"))
        .collect())
}

/// A GPU batch's kernels: its frames (one size) and the runner's uploads, made on first use.
struct GpuKernels<'r, 'f> {
    runner: &'r mut GpuRunner,
    frames: &'r [&'f Frame<'f>],
}

impl Kernels for GpuKernels<'_, '_> {
    type Error = crate::Error;

    fn detect_filtered(
        &mut self,
        which: &[usize],
        s: &DetectSettings,
    ) -> Result<Vec<Vec<Detection>>> {
        let subset: Vec<&Frame> = which.iter().map(|&i| self.frames[i]).collect();
        if subset.is_empty() {
            return Ok(Vec::new());
        }
        let blobs = by_gain(&subset, s, |f, p| self.runner.gpu.detect(f, p))?;
        gpu_stars(&self.runner.gpu, &subset, &blobs, s)
    }

    fn rounds_per_lookup(&self) -> usize {
        usize::MAX
    }

    fn pattern(&mut self, solver: &Solver, lookups: &[&Lookup]) -> Result<Vec<Vec<Rows>>> {
        let Some(sf) = &solver.scale_free else {
            return Ok(vec![Vec::new(); lookups.len()]);
        };
        let r = &mut *self.runner;
        let key = (solver.camera.width, solver.camera.height);
        let index = uploaded(&mut r.patterns, key, || r.gpu.upload_patterns(&sf.index))?;
        let queries: Vec<u32> = (lookups.iter())
            .flat_map(|l| l.queries.iter().copied())
            .collect();
        let mut rows = r.gpu.pattern(index, &queries)?.into_iter();
        Ok(lookups
            .iter()
            .map(|l| rows.by_ref().take(l.queries.len()).collect())
            .collect())
    }

    fn vote(
        &mut self,
        solver: &Solver,
        band: usize,
        jobs: &[&Prepared],
    ) -> Result<Vec<VoteResult>> {
        let r = &mut *self.runner;
        let b = &solver.bands[band];
        let key = (solver.camera.width, solver.camera.height, band);
        let table = uploaded(&mut r.tables, key, || {
            r.gpu.upload_table(b.table(), b.refs.len())
        })?;
        let jobs: Vec<VoteJob> = jobs.iter().map(|p| VoteJob::of(p)).collect();
        r.gpu.vote(b.table(), table, &jobs)
    }

    fn radial(
        &mut self,
        solver: &Solver,
        band: usize,
        jobs: &[&Prepared],
    ) -> Result<Vec<VoteResult>> {
        let Some(features) = &solver.bands[band].radial else {
            return Ok(Vec::new());
        };
        let r = &mut *self.runner;
        let key = (solver.camera.width, solver.camera.height, band);
        let table = uploaded(&mut r.radial, key, || r.gpu.upload_radial(features))?;
        let jobs: Vec<RadialJob> = jobs
            .iter()
            .map(|p| RadialJob {
                features: radial::image_features(&p.vectors[..p.n_vote], features),
                k: radial::CANDIDATES,
            })
            .collect();
        r.gpu.radial(table, &jobs)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::catalog::Catalog;
    use crate::error::error;
    use crate::sequence::DETECT_STARS;
    use crate::simulate::{SimSettings, render};

    /// A GPU error hands the rest of the run to the CPU, and only to it: the records then are
    /// the CPU backend's, and the sequences' detections the CPU twins'.
    #[test]
    fn after_a_gpu_error_the_cpu_takes_the_run() {
        let gpu = match Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref()) {
            Ok(g) => g,
            Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => {
                panic!("no GPU adapter in CI: {e:#}")
            }
            Err(e) => return eprintln!("SKIPPED after_a_gpu_error_the_cpu_takes_the_run: {e:#}"),
        };
        let mut runner = GpuRunner::new(gpu);
        assert_eq!(runner.on_gpu(|_| Ok(1)), Some(1));
        assert_ne!(runner.name(), BACKEND_CPU);
        assert_eq!(runner.on_gpu(|_| Err::<u8, _>(error!(Gpu, "lost"))), None);
        assert_eq!(runner.name(), BACKEND_CPU);
        let not_run = |_: &mut GpuRunner| -> Result<u8> { panic!("the GPU ran after it failed") };
        assert_eq!(runner.on_gpu(not_run), None);

        let s = SimSettings {
            width: 512,
            height: 512,
            fov_x_deg: 18.0,
            seed: 3,
            ..Default::default()
        };
        let camera = s.camera().unwrap();
        let frames = || -> Vec<Decoded<'static>> {
            (0..2)
                .map(|k| {
                    let (pixels, _) = render(&Catalog::builtin(), &s, k).unwrap();
                    let frame = Frame {
                        width: 512,
                        height: 512,
                        pixels: pixels.into(),
                        saturation: 65535,
                    };
                    let name = format!("f{k}");
                    Decoded::in_memory(&name, Ok((frame, Vec::new())), None, Default::default())
                })
                .collect()
        };
        let solvers = Solvers::new(
            Catalog::builtin(),
            crate::solve::Settings::default(),
            CameraSource::Fixed(camera),
        );
        let untimed = |mut r: Record| {
            r.timing_ms = Timing::default();
            r
        };
        let after = runner.solve(&solvers, frames());
        let cpu: Vec<Record> = frames().into_iter().map(|d| solvers.solve_cpu(d)).collect();
        assert_eq!(after.len(), 2);
        assert!(
            after
                .iter()
                .all(|r| r.status == crate::record::Status::Solved)
        );
        assert_eq!(
            after.into_iter().map(untimed).collect::<Vec<_>>(),
            cpu.into_iter().map(untimed).collect::<Vec<_>>()
        );
        let detected = runner.detect(&solvers, frames(), DETECT_STARS);
        for (d, f) in detected.iter().zip(frames()) {
            assert_eq!(d.backend, BACKEND_CPU);
            let cpu = solvers.detect_cpu(f, DETECT_STARS);
            assert_eq!(
                d.detections.as_ref().unwrap(),
                cpu.detections.as_ref().unwrap()
            );
        }
    }
}
