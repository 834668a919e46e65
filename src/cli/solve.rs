//! `gpustar solve` and `gpustar batch`: the camera and settings from the options, then one run.

use super::args::{RunArgs, SolveOpts};
use super::config::run_config;
use super::console::{Progress, interrupt_flag};
use super::exit::Exit;
use anyhow::{Result, bail};
use gpustar::CameraSource;
use gpustar::batch::{self, RunOptions};
use gpustar::catalog::Catalog;
use gpustar::config::RunConfig;
use gpustar::config::sidecar::{self, Sidecar};
use gpustar::io::inputs::Input;
use gpustar::io::output::{self, RecordWriter};
use gpustar::pipeline::star_lists::StarLists;
use gpustar::pipeline::{Backend, BackendChoice, BackendNote};
use gpustar::products::Products;
use gpustar::sequence::SequenceOptions;
use gpustar::solve::{FEW_STARS_IN_VIEW, stars_in_view};
use gpustar::streaks::export::Exports;
use std::io::Write;
use std::process::ExitCode;

/// `--xyls` runs have stars, not pixels: the options that need pixels are refused.
fn check_star_list_options(o: &SolveOpts, cfg: &RunConfig) -> Result<()> {
    let pixels = [
        (cfg.sequence, "--sequence"),
        (cfg.streaks, "--streaks"),
        (cfg.hint.is_some(), "--hint"),
        (
            cfg.dark.is_some() || cfg.dark_median,
            "--dark and --dark-median",
        ),
        (o.new_fits.is_some(), "--new-fits"),
        (o.axy.is_some(), "--axy"),
        (o.annotate_dir.is_some(), "--annotate-dir"),
        (cfg.backend == BackendChoice::Gpu, "--backend gpu"),
    ];
    if let Some((_, what)) = pixels.iter().find(|(given, _)| *given) {
        bail!("{what} needs the frames' pixels: not with --xyls (star lists)");
    }
    Ok(())
}

/// Run `batch` over `inputs`, listed from the directories `Some(dirs)` (with their
/// subdirectories when the flag is set), or `solve` over its one frame (None); `given`: the
/// options the command line gives (over a --config file's).
pub(crate) fn run_solve(
    inputs: Vec<Input>,
    dirs: Option<&[std::path::PathBuf]>,
    o: &SolveOpts,
    b: &RunArgs,
    given: &[String],
) -> Result<ExitCode> {
    let cfg = run_config(o, b, given)?;
    if cfg.sequence && cfg.streaks {
        anyhow::bail!(
            "--sequence and --streaks do not go together yet: run the sequences and the \
             streak frames separately"
        );
    }
    if cfg.sequence && cfg.hint.is_some() {
        anyhow::bail!(
            "--hint is not used with --sequence: a sequence's frames are identified lost-in-space \
             and then tracked from frame to frame"
        );
    }
    if cfg.frame_interval.is_some() && !cfg.sequence {
        bail!("--frame-interval is an option of --sequence");
    }
    let so = &o.streaks;
    let streak_outputs = [(so.tdm.is_some(), "--tdm"), (so.iod.is_some(), "--iod")];
    if let (false, Some((_, what))) = (cfg.streaks, streak_outputs.iter().find(|s| s.0)) {
        bail!("{what} is an option of --streaks");
    }
    if cfg.xyls {
        check_star_list_options(o, &cfg)?;
    } else if cfg.image_size.is_some() {
        bail!("--image-size is the size of star lists: it goes with --xyls");
    }
    let choice = cfg.camera_source(None)?;
    let catalog = Catalog::load_with(cfg.catalog.as_deref(), !cfg.no_cache)?;
    // A catalog or a magnitude limit the user chose is theirs to judge.
    if cfg.catalog.is_none() && cfg.mag_limit.or(choice.1).is_none() {
        warn_if_catalog_shallow(&catalog, &choice.0);
    }
    // Read before the run, so that a bad file stops it before any frame is done.
    let streak_options = cfg.streak_options()?;
    if let (Some(p), Some(t), false) = (
        &cfg.tle,
        streak_options.as_ref().and_then(|s| s.tle.as_ref()),
        o.quiet,
    ) {
        eprintln!(
            "gpustar: --tle {}: {} objects",
            p.display(),
            t.satellites.len()
        );
    }
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
        (cfg.catalog.as_deref(), "the --catalog"),
        (cfg.camera.as_deref(), "the --camera file"),
        (cfg.dark.as_deref(), "the --dark frame"),
        (cfg.tle.as_deref(), "the --tle file"),
        (o.config.as_deref(), "the --config file"),
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
    // The configuration the records are made with, kept beside them: a resumed run must be
    // the same run (checked before the records are touched).
    let side = Sidecar::new(&cfg, &catalog);
    if let Some(p) = &o.output {
        sidecar::check(p)?;
        if b.resume
            && let Some(note) = sidecar::check_resume(p, &side)?
            && !o.quiet
        {
            eprintln!("gpustar: {note}");
        }
    }
    let out: Box<dyn Write + Send> = match &o.output {
        Some(p) => {
            let opened = output::open_output(p, o.format, b.resume, b.retry_errors)?;
            sidecar::write(p, &side)?;
            let prev = opened.previous;
            if prev.retried > 0 {
                retried_order = Some(inputs.iter().map(|i| i.name.clone()).collect());
            }
            let before = inputs.len();
            let already = inputs
                .iter()
                .filter(|i| prev.done.contains(&i.name))
                .count();
            inputs = batch::resumed_inputs(inputs, &prev.done, cfg.sequence);
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
    let (mut backend, note) = Backend::open(if cfg.xyls {
        BackendChoice::Cpu
    } else {
        cfg.backend
    })?;
    match note {
        Some(BackendNote::Warning(w)) => tracing::warn!("{w}"),
        Some(BackendNote::Info(i)) => tracing::info!("{i}"),
        None => {}
    }
    let mut solvers = cfg.solvers(catalog, choice, streak_options)?;
    solvers.products = products;
    let mut writer = RecordWriter::new(out, o.format, header);
    let stop = interrupt_flag();
    let to_do = inputs.iter().filter(|i| !i.replay).count();
    let mut progress = Progress::new(to_do as u64, o.quiet, o.progress_every);
    let threads = b
        .threads
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
    let opts = RunOptions {
        threads,
        batch_size: cfg.batch_size,
        flush_every: std::time::Duration::from_millis(250),
        sequence: cfg.sequence.then(|| SequenceOptions {
            frame_interval_s: cfg.frame_interval,
            ..SequenceOptions::default()
        }),
        tracklets: cfg.streaks,
        star_lists: cfg.xyls.then_some(StarLists {
            size: cfg.image_size,
        }),
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

/// Say so when the built-in catalog holds few stars in the camera's field on average (a camera
/// file's, or `--fov-deg`'s taken as square): the frames toward sparse sky then show too few
/// catalog stars to identify, where a deeper catalog solves them (docs/radial.md).
fn warn_if_catalog_shallow(catalog: &Catalog, source: &CameraSource) {
    let (fx, fy) = match source {
        CameraSource::Fixed(c) => (c.fov_x_deg(), c.fov_y_deg()),
        CameraSource::Fov { fov_x_deg, .. } => (*fov_x_deg, *fov_x_deg),
        _ => return,
    };
    let n = stars_in_view(catalog, fx, fy);
    if n < FEW_STARS_IN_VIEW {
        tracing::warn!(
            "the built-in catalog holds {n:.0} stars on average in this {fx:.1}°×{fy:.1}° field \
             (to Hp {:.1}): frames toward sparse sky may show too few to identify; a deeper \
             catalog (`gpustar catalog import`, README § Catalogs) solves more",
            catalog.faintest()
        );
    }
}
