//! `gpustar solve` and `gpustar batch`: the camera and settings from the options, then one run.

use super::args::*;
use super::console::*;
use super::exit::Exit;
use anyhow::{Context, Result, bail};
use gpustar::batch::{self, RunOptions};
use gpustar::camera::Camera;
use gpustar::catalog::Catalog;
use gpustar::io::dark::Darks;
use gpustar::io::inputs::Input;
use gpustar::io::output::{self, RecordWriter};
use gpustar::pipeline::star_lists::StarLists;
use gpustar::pipeline::{Backend, BackendChoice, BackendNote, CameraSource, Solvers};
use gpustar::products::Products;
use gpustar::sequence::SequenceOptions;
use gpustar::sky::tle::TleCatalog;
use gpustar::solve::{Parity, Settings};
use gpustar::streaks::identify::IdentifySettings;
use gpustar::streaks::reduce::Astrometry;
use gpustar::streaks::{StreakOptions, StreakSettings, export::Exports};
use std::io::Write;
use std::process::ExitCode;

/// Range of focal-length factors (low, high) to search when the scale is uncertain.
pub(crate) type ScaleRange = (f64, f64);

/// The camera source, its optional magnitude limit, and the scale range to search. With
/// `header_only` (`--streaks --astrometry header`) no camera is needed.
pub(crate) fn camera_source(
    c: &CameraOpts,
    header_only: bool,
) -> Result<(CameraSource, Option<f64>, Option<ScaleRange>)> {
    let tolerance = match c.fov_tolerance {
        Some(t) if !(t > 0.0 && t < 0.5) => bail!("--fov-tolerance must be between 0 and 0.5"),
        Some(t) => Some((1.0 - t, 1.0 + t)),
        None => None,
    };
    let aspect = c.pixel_aspect.unwrap_or(1.0);
    if c.pixel_aspect.is_some() && c.fov_deg.is_none() && c.scale_arcsec.is_none() {
        bail!("--pixel-aspect goes with --fov-deg or --scale-arcsec (a camera file gives fy_px)");
    }
    let fov = |fov_x_deg| CameraSource::Fov {
        fov_x_deg,
        pixel_aspect: aspect,
    };
    let scale = |arcsec_per_px| CameraSource::Scale {
        arcsec_per_px,
        pixel_aspect: aspect,
    };
    // A range searches the scale around the camera of its middle value: focal lengths scale as
    // 1 / tan(FOV / 2), and as 1 / tan(pixel scale).
    let factors =
        |f: &dyn Fn(f64) -> f64, lo: f64, mid: f64, hi: f64| (f(hi) / f(mid), f(lo) / f(mid));
    match (&c.camera, c.fov_deg, c.scale_arcsec) {
        (Some(path), ..) => {
            let (cam, mag) = Camera::from_toml_file(path)?;
            Ok((CameraSource::Fixed(cam), mag, tolerance))
        }
        (None, Some(FovArg::Exact(deg)), _) => Ok((fov(deg), None, tolerance)),
        (None, Some(FovArg::Range(lo, hi)), _) => {
            let mid = (lo + hi) / 2.0;
            let f = |fov: f64| 1.0 / (fov.to_radians() / 2.0).tan();
            Ok((fov(mid), None, Some(factors(&f, lo, mid, hi))))
        }
        (None, None, Some(FovArg::Exact(s))) => Ok((scale(s), None, tolerance)),
        (None, None, Some(FovArg::Range(lo, hi))) => {
            let mid = (lo + hi) / 2.0;
            let f = |s: f64| 1.0 / (s / 3600.0).to_radians().tan();
            Ok((scale(mid), None, Some(factors(&f, lo, mid, hi))))
        }
        (None, None, None) if header_only => Ok((CameraSource::None, None, None)),
        // Nothing given: each frame's header states its scale, as ASTAP reads it; a nominal
        // focal length or pixel size is a few per cent off (the Seestar S50's: 1 %).
        (None, None, None) => Ok((
            CameraSource::Header,
            None,
            tolerance.or(Some(HEADER_SCALE_RANGE)),
        )),
    }
}

/// The focal-length factors searched around a header's scale, unless --fov-tolerance says.
const HEADER_SCALE_RANGE: ScaleRange = (0.97, 1.03);

/// The parity setting of `--parity`, or its default for the camera's source: open with
/// `--fov-deg` (which says nothing of it), the camera file's with `--camera`.
pub(crate) fn parity(c: &CameraOpts, source: &CameraSource) -> Parity {
    match (c.parity, source) {
        (Some(ParityArg::Either), _)
        | (None, CameraSource::Fov { .. } | CameraSource::Scale { .. } | CameraSource::Header) => {
            Parity::Either
        }
        _ => Parity::AsCamera,
    }
}

pub(crate) fn settings(c: &CatalogOpts, camera_mag: Option<f64>) -> Settings {
    Settings {
        epoch: c.epoch,
        mag_limit: c.mag_limit.or(camera_mag),
        double_stars: c.double_stars,
        double_star_px: c.double_star_px,
        table_cache: !c.no_cache,
        ..Settings::default()
    }
}

/// `--xyls` runs have stars, not pixels: the options that need pixels are refused.
fn check_star_list_options(o: &SolveOpts, b: &RunArgs) -> Result<()> {
    let pixels = [
        (b.sequence, "--sequence"),
        (o.streaks.streaks, "--streaks"),
        (o.hint.is_some(), "--hint"),
        (
            o.dark.is_some() || o.dark_median,
            "--dark and --dark-median",
        ),
        (o.new_fits.is_some(), "--new-fits"),
        (o.axy.is_some(), "--axy"),
        (o.annotate_dir.is_some(), "--annotate-dir"),
        (o.backend == BackendChoice::Gpu, "--backend gpu"),
    ];
    if let Some((_, what)) = pixels.iter().find(|(given, _)| *given) {
        bail!("{what} needs the frames' pixels: not with --xyls (star lists)");
    }
    Ok(())
}

/// Run `batch` over `inputs`, listed from the directories `Some(dirs)` (with their
/// subdirectories when the flag is set), or `solve` over its one frame (None).
pub(crate) fn run_solve(
    inputs: Vec<Input>,
    dirs: Option<&[std::path::PathBuf]>,
    o: &SolveOpts,
    b: &RunArgs,
) -> Result<ExitCode> {
    if b.sequence && o.streaks.streaks {
        anyhow::bail!(
            "--sequence and --streaks do not go together yet: run the sequences and the \
             streak frames separately"
        );
    }
    if b.sequence && o.hint.is_some() {
        anyhow::bail!(
            "--hint is not used with --sequence: a sequence's frames are identified lost-in-space \
             and then tracked from frame to frame"
        );
    }
    if o.xyls {
        check_star_list_options(o, b)?;
    } else if o.image_size.is_some() {
        bail!("--image-size is the size of star lists: it goes with --xyls");
    }
    let header_only = o.streaks.streaks && o.streaks.astrometry == Astrometry::Header;
    let (camera, camera_mag, scale_range) = camera_source(&o.camera, header_only)?;
    let catalog = Catalog::load_with(o.catalog.catalog.as_deref(), !o.catalog.no_cache)?;
    let mut s = settings(&o.catalog, camera_mag);
    s.detect.k_sigma = o.sigma;
    s.detect.matched_filter = o.detect_filter == DetectFilter::Binomial;
    s.detect.centroid = o.centroid;
    s.method = o.method;
    s.identify.vote_stars = o.vote_stars;
    s.retry = !o.no_retry;
    s.wide_min_stars = o.wide_min_stars;
    s.identify.pair_tol_px = o.pair_tol_px;
    s.identify.scale_tol = o.scale_tol;
    s.refine.match_radius_px = o.match_radius_px;
    s.refine.max_false_prob = o.max_false_prob;
    s.refine.fit = o.camera.fit;
    s.scale_range = scale_range;
    s.walk_wide = o.camera.fov_walk;
    s.parity = parity(&o.camera, &camera);
    let so = &o.streaks;
    // Read before the run, so that a bad file stops it before any frame is done.
    let tle = match &so.tle {
        Some(p) => {
            let c = TleCatalog::load(p)?;
            if !o.quiet {
                eprintln!(
                    "gpustar: --tle {}: {} objects",
                    p.display(),
                    c.satellites.len()
                );
            }
            Some(c)
        }
        None => None,
    };
    let mut exports = Exports::new(so.tdm.clone(), so.iod.clone(), so.iod_station);
    let mut products = Products {
        wcs_dir: o.wcs_dir.clone(),
        annotate_dir: o.annotate_dir.clone(),
        new_fits_dir: o.new_fits.clone(),
        corr_dir: o.corr.clone(),
        axy_dir: o.axy.clone(),
        overwrite: o.overwrite,
        ..Products::default()
    };
    // Every output checked before any work, and before -o is emptied.
    let read = [
        (o.catalog.catalog.as_deref(), "the --catalog"),
        (o.camera.camera.as_deref(), "the --camera file"),
        (o.dark.as_deref(), "the --dark frame"),
        (so.tle.as_deref(), "the --tle file"),
    ];
    batch::claims::check_outputs(
        &batch::claims::RunFiles {
            dirs: dirs
                .unwrap_or_default()
                .iter()
                .map(|d| (d.as_path(), b.recursive))
                .collect(),
            inputs: &inputs,
            read: read
                .iter()
                .filter_map(|(p, w)| p.map(|p| (p, *w)))
                .collect(),
            records: o.output.as_deref(),
            stdout: true,
            resume: b.resume,
        },
        &exports,
        &mut products,
    )?;
    // The output, and what an earlier run already wrote to it.
    let mut inputs = inputs;
    let mut header = true;
    let mut errors_before = 0;
    // With error records taken out to be redone: every input's name in order, to put their
    // new records back in their places when the run ends.
    let mut retried_order: Option<Vec<String>> = None;
    let out: Box<dyn Write + Send> = match &o.output {
        Some(p) => {
            let opened = output::open_output(p, o.format, b.resume, b.retry_errors)?;
            let prev = opened.previous;
            if prev.retried > 0 {
                retried_order = Some(inputs.iter().map(|i| i.name.clone()).collect());
            }
            let before = inputs.len();
            let already = inputs
                .iter()
                .filter(|i| prev.done.contains(&i.name))
                .count();
            inputs = batch::resumed_inputs(inputs, &prev.done, b.sequence);
            if b.resume && !o.quiet {
                if prev.truncated > 0 {
                    eprintln!(
                        "gpustar: cut an incomplete last record ({} bytes) off {}",
                        prev.truncated,
                        p.display()
                    );
                }
                let replayed = inputs.iter().filter(|i| i.replay).count();
                eprintln!(
                    "gpustar: resuming: {already} of {before} inputs already have a record{}{}{}",
                    match prev.errors {
                        0 => String::new(),
                        n => format!(" ({n} of them errors; --retry-errors tries them again)"),
                    },
                    match prev.retried {
                        0 => String::new(),
                        n => format!("; {n} error records taken out to be tried again"),
                    },
                    match replayed {
                        0 => String::new(),
                        n => format!(
                            "; {n} of those are tracked again, unwritten, so that unfinished \
                             sequences go on as an uninterrupted run does"
                        ),
                    }
                );
            }
            // The exports are written whole at the end: they take the streaks of the records
            // already in the file too, or a resumed run's TDM would hold only its own part.
            if b.resume && exports.wanted() {
                for r in &prev.streaks {
                    exports.add(r);
                }
            }
            errors_before = prev.errors;
            header = !prev.has_header;
            Box::new(opened.file)
        }
        None => Box::new(std::io::stdout()),
    };
    // Star lists have no pixels for the GPU's stages.
    let (mut backend, note) = Backend::open(if o.xyls {
        BackendChoice::Cpu
    } else {
        o.backend
    })?;
    match note {
        Some(BackendNote::Warning(w)) => tracing::warn!("{w}"),
        Some(BackendNote::Info(i)) => tracing::info!("{i}"),
        None => {}
    }
    // A camera file fixes the frames' size, and so the dark's.
    let expect = match &camera {
        CameraSource::Fixed(c) => Some((c.width, c.height)),
        _ => None,
    };
    if !(o.max_megapixels > 0.0 && o.max_megapixels <= 4300.0) {
        bail!("--max-megapixels must be above 0 and at most 4300 (2^32 pixels)");
    }
    let mut solvers = Solvers::new(catalog, s, camera);
    solvers.max_pixels = (o.max_megapixels * 1e6) as u64;
    if let Some(h) = o.hint {
        solvers = solvers.with_hints(h);
    }
    solvers.darks = match (&o.dark, o.dark_median) {
        (Some(path), _) => Darks::from_file(path, expect).context("--dark")?,
        (None, true) => Darks::directory_median(),
        (None, false) => Darks::None,
    };
    solvers.products = products;
    solvers.streaks = so.streaks.then_some(StreakOptions {
        settings: StreakSettings {
            k_sigma: so.streak_sigma,
            ..StreakSettings::default()
        },
        station: so.station,
        dut1_s: so.dut1,
        astrometry: so.astrometry,
        tle: tle.map(std::sync::Arc::new),
        identify: IdentifySettings {
            cross_arcsec: so.tle_cross,
            along_s: so.tle_along,
        },
    });
    let mut writer = RecordWriter::new(out, o.format, header);
    let stop = interrupt_flag();
    let to_do = inputs.iter().filter(|i| !i.replay).count();
    let mut progress = Progress::new(to_do as u64, o.quiet, o.progress_every);
    let threads = b
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let opts = RunOptions {
        threads,
        batch_size: o.batch_size,
        flush_every: std::time::Duration::from_millis(250),
        sequence: b.sequence.then(|| SequenceOptions {
            frame_interval_s: b.frame_interval,
            ..SequenceOptions::default()
        }),
        tracklets: so.streaks,
        star_lists: o.xyls.then_some(StarLists { size: o.image_size }),
    };
    let summary = batch::run(
        inputs,
        &solvers,
        &mut backend,
        &mut writer,
        opts,
        stop,
        |r, c| {
            exports.add(r);
            progress.tick(c);
            tracing::debug!("{}: {:?}", r.file, r.status);
        },
    )?;
    progress.finish();
    if let (Some(order), Some(p), None, false) = (
        &retried_order,
        &o.output,
        &summary.write_error,
        summary.interrupted,
    ) {
        writer.flush()?;
        output::restore_input_order(p, o.format, order)?;
    }
    if exports.wanted() && summary.write_error.is_none() {
        let said = exports.finish(&gpustar::sky::now_utc_iso())?;
        if !o.quiet {
            eprintln!("gpustar: wrote {said}");
        }
    }
    let c = summary.counts;
    if !o.quiet {
        eprintln!(
            "gpustar: {} files: {} solved, {} unsolved, {} errors in {:.2} s ({:.1} images/s, {}){}",
            c.total(),
            c.solved,
            c.unsolved,
            c.errors,
            summary.seconds,
            c.total() as f64 / summary.seconds.max(1e-9),
            backend.name(),
            match (&summary.write_error, summary.interrupted, c.total() < to_do) {
                (Some(e), ..) => format!(
                    "; stopped: {e}; records before it are whole: make room and rerun with \
                     --resume"
                ),
                (None, true, true) => "; interrupted: rerun with --resume to finish".into(),
                (None, true, false) => {
                    "; interrupted after the last input: every input has a record".into()
                }
                (None, false, _) => String::new(),
            }
        );
    }
    Ok(if summary.write_error.is_some() {
        Exit::WriteFailed
    } else if summary.interrupted {
        Exit::Interrupted
    } else if c.errors + errors_before > 0 {
        Exit::ErrorRecords
    } else if dirs.is_none() && c.unsolved > 0 {
        // `solve`'s one frame was read but not solved: said in the status, as ASTAP does, so
        // that a script need not parse the record (`batch` keeps 0: unsolved frames are part
        // of an archive's normal result).
        Exit::Unsolved
    } else {
        Exit::Ok
    }
    .into())
}
