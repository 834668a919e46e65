//! The command line (clap derive): [`Cli`] and [`Command`] here, one file per command beside
//! them, option groups in `args.rs`, stop/progress/logging in `console.rs`. `main` calls
//! [`main_with_args`]. Only the binary uses anyhow; the library returns `gpustar::Error`.

use anyhow::Result;
use args::{CameraOpts, CatalogCommand, CatalogOpts, RunArgs, SimulateArgs, SolveOpts, parse_size};
use calibrate::calibrate_cmd;
use catalog::import_cmd;
use clap::{CommandFactory, FromArgMatches, Parser, Subcommand};
use console::{give_the_driver_a_runtime_dir, init_logging};
use evaluate::evaluate_cmd;
use exit::Exit;
use gpustar::io::inputs::{self, Input};
use merge::merge_cmd;
use report::{ReportArgs, report_cmd};
use simulate::simulate_cmd;
use solve::run_solve;
use std::path::PathBuf;
use std::process::ExitCode;

mod alloc;
mod args;
mod calibrate;
mod catalog;
mod config;
mod console;
mod evaluate;
mod exit;
mod info;
mod merge;
mod report;
mod simulate;
mod solve;

const AFTER_HELP: &str = "\
Examples:
  gpustar simulate --out sim -n 20 --fov-deg 18      # 20 synthetic frames + truth.jsonl
  gpustar batch sim --camera sim/camera.toml -o results.jsonl
  gpustar evaluate --truth sim/truth.jsonl results.jsonl
  gpustar solve frame.png --fov-deg 11.4 --epoch 2019.58
  gpustar batch tracking/ --camera cam.toml --streaks --station 35.7,51.4,1200 --tdm obs.tdm

Exit status: 0 when every input got a record and none is an error record (with --resume: none
in the whole file); 1 when some input has an error record; 2 when the run could not start (bad
options, unreadable camera or catalog, GPU asked for but absent, an --output that is not
gpustar's or that another gpustar is writing, an output on an input or on another output, a file
gpustar did not write at an output path without --overwrite, a folder that cannot be read or
holds no image files) or merge found inputs missing, repeated or torn;
3 when the records could not be written (a full disk: those written are whole; --resume
continues); 4 when `solve`'s frame was read but not solved; 130 when interrupted (Ctrl-C, SIGTERM: the records written so far are complete;
--resume continues).";

/// Identify the stars in sky images and find the camera's attitude (lost in space).
#[derive(Parser, Debug)]
#[command(name = "gpustar", version, about, long_about = None, after_help = AFTER_HELP,
          disable_help_flag = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
    /// Log more to stderr (-v: info, -vv: debug, -vvv: trace, e.g. every detection of a
    /// sequence with what it was judged).
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    pub verbose: u8,
    /// Print help: the options most runs need (--help-all: every option, in full).
    #[arg(short = 'h', long = "help", global = true, action = clap::ArgAction::HelpShort)]
    help: Option<bool>,
    /// Print help with every option, in full.
    #[arg(long = "help-all", global = true, action = clap::ArgAction::HelpLong)]
    help_all: Option<bool>,
}

/// What `-h` says below the options most runs need.
const MORE_OPTIONS: &str = "\
More options (the scale search, detection and identification, the streaks' reduction, retries,
sequences): --help-all. What each does and the records: README.md and docs/.";

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Solve every image in DIR (sorted by name); one record per file, in that order.
    #[command(after_help = MORE_OPTIONS, after_long_help = "")]
    Batch {
        /// Directories of images (PNG, JPEG, TIFF, FITS, .fits.gz, .fits.fz), image files,
        /// @LIST (a file naming one image a line) or - (that list on standard input). One
        /// directory alone names its frames relative to it; otherwise each is named by its
        /// path as given.
        #[arg(value_name = "DIR", required = true)]
        dir: Vec<PathBuf>,
        #[command(flatten)]
        opts: SolveOpts,
        #[command(flatten)]
        run: RunArgs,
    },
    /// Solve one image; one record.
    #[command(after_help = MORE_OPTIONS, after_long_help = "")]
    Solve {
        /// The image file.
        image: PathBuf,
        #[command(flatten)]
        opts: SolveOpts,
    },
    /// Catalog summary and, for a camera, the reference stars and the distance table (of each
    /// band of a scale search).
    Info {
        #[command(flatten)]
        camera: CameraOpts,
        /// Image size for --fov-deg, as WIDTHxHEIGHT.
        #[arg(long, value_parser = parse_size)]
        size: Option<(u32, u32)>,
        #[command(flatten)]
        catalog: CatalogOpts,
    },
    /// Write synthetic frames, truth.jsonl and camera.toml into a directory.
    Simulate(SimulateArgs),
    /// Compare result records with a truth file: solved, correct, wrong, attitude errors.
    Evaluate {
        /// Results (JSON Lines, as written by batch).
        results: PathBuf,
        /// Truth file (truth.jsonl of simulate, or of ../shared/data/real/*).
        #[arg(long)]
        truth: PathBuf,
        /// A solution is correct when its attitude is within this angle of the truth.
        #[arg(long, default_value_t = 0.1)]
        tolerance_deg: f64,
        /// A star ID is false when the star is not within this many pixels of where the truth
        /// puts it (its listed position; for a star off the truth's list, its catalog position
        /// through the truth attitude and the lens the truth's list implies).
        #[arg(long, default_value_t = 3.0)]
        id_tolerance_px: f64,
        /// Also print one line per frame: status, correct, error_arcsec (rotation matrices),
        /// centre_error_arcsec and roll_error_arcsec (against the truth's ra/dec and
        /// roll_tetra3_deg), false_ids, correct_ids, identify_ms, stars_in_view.
        #[arg(long)]
        per_frame: bool,
    },
    /// Combine the outputs of `batch --shard K/N` runs into one, in input order, checking that
    /// every input of DIR appears exactly once.
    Merge {
        /// The shard outputs (JSON Lines).
        parts: Vec<PathBuf>,
        /// The directory the shards ran over: its inputs must each appear exactly once
        /// (required unless --no-check).
        #[arg(long, required_unless_present = "no_check")]
        dir: Option<PathBuf>,
        /// Combine the parts without a directory to check them against (duplicates are still
        /// refused; a missing input goes unnoticed).
        #[arg(long, conflicts_with = "dir")]
        no_check: bool,
        /// The shards ran with --recursive.
        #[arg(long)]
        recursive: bool,
        /// Write the merged records here (default: stdout).
        #[arg(short, long)]
        output: Option<PathBuf>,
    },
    /// Fit the camera (fx, fy, cx, cy, k1, k2) to the identified stars of all solvable frames
    /// of DIR together (camera and attitudes adjusted jointly), re-identify with the fitted
    /// camera, fit again, and write a camera file `batch --camera` reads; residuals before and
    /// after on stderr.
    Calibrate {
        /// The directory of frames (one camera).
        dir: PathBuf,
        /// The camera file to start from (a focal length or FOV is enough).
        #[arg(long)]
        camera: PathBuf,
        /// The focal length is only known to within this fraction: search the scale at first.
        #[arg(long)]
        fov_tolerance: Option<f64>,
        /// Frames in subdirectories too.
        #[arg(short, long)]
        recursive: bool,
        /// Keep the principal point where the camera file puts it.
        #[arg(long)]
        fixed_centre: bool,
        /// Fit the principal point however loosely the frames fix it (by default one known to
        /// worse than 1 px stays where the camera file puts it). The camera frame is defined
        /// through it: every attitude turns with it.
        #[arg(long, conflicts_with = "fixed_centre")]
        fit_centre: bool,
        /// Fit k1 only (k2 stays as the camera file gives it).
        #[arg(long)]
        no_k2: bool,
        /// Write the fitted camera here (TOML).
        #[arg(short, long)]
        output: PathBuf,
        #[command(flatten)]
        catalog: CatalogOpts,
    },
    /// Summarise result records without a truth file; --html: a page of plots.
    ///
    /// Outcomes (unsolved by reason, errors by message), availability per folder, the residual,
    /// match-count, solve-time and scale distributions, and the attitude over time.
    Report(ReportArgs),
    /// Catalog maintenance.
    #[command(subcommand)]
    Catalog(CatalogCommand),
}

/// Run the command line; errors are printed once by `main`. `given`: the options the command
/// line gives (they win over a --config file's).
pub fn execute(cli: Cli, given: &[String]) -> Result<ExitCode> {
    init_logging(cli.verbose);
    if cli.verbose == 0 {
        give_the_driver_a_runtime_dir();
    }
    match cli.command {
        Command::Batch { dir, opts, run } => {
            let accept = if opts.xyls {
                inputs::is_star_list_path
            } else {
                gpustar::io::frame::is_image_path
            };
            let gathered =
                inputs::gather(&dir, run.recursive, accept, &mut std::io::stdin().lock())?;
            let mut inputs = gathered.inputs;
            // A batch never ends "0 files", exit 0, having read nothing.
            if inputs.is_empty() {
                anyhow::bail!(
                    "{} holds no {}{}",
                    dir.iter()
                        .map(|d| d.display().to_string())
                        .collect::<Vec<_>>()
                        .join(", "),
                    if opts.xyls {
                        "star lists (.xyls, .axy, FITS tables)"
                    } else {
                        "image files (PNG, JPEG, TIFF, FITS)"
                    },
                    if run.recursive {
                        ""
                    } else {
                        "; --recursive reads its subdirectories too"
                    }
                );
            }
            if let Some(shard) = run.shard {
                // A sequence goes to one shard whole: its frames depend on each other.
                inputs.retain(|i| {
                    shard.takes(if run.sequence {
                        gpustar::sequence::sequence_of(&i.name)
                    } else {
                        &i.name
                    })
                });
            }
            run_solve(inputs, Some(&gathered.dirs), &opts, &run, given)
        }
        Command::Solve { image, opts } => {
            let name = image.display().to_string();
            let run = RunArgs {
                recursive: false,
                resume: false,
                retry_errors: false,
                shard: None,
                threads: Some(1),
                sequence: false,
                frame_interval: None,
            };
            run_solve(
                vec![Input {
                    path: image,
                    name,
                    replay: false,
                }],
                None,
                &opts,
                &run,
                given,
            )
        }
        Command::Merge {
            parts,
            dir,
            no_check: _,
            recursive,
            output,
        } => merge_cmd(&parts, dir.as_deref(), recursive, output.as_deref()),
        Command::Info {
            camera,
            size,
            catalog,
        } => info::info(&camera, size, &catalog),
        Command::Simulate(a) => simulate_cmd(a),
        Command::Calibrate {
            dir,
            camera,
            fov_tolerance,
            recursive,
            fixed_centre,
            fit_centre,
            no_k2,
            output,
            catalog,
        } => calibrate_cmd(
            &dir,
            &camera,
            fov_tolerance,
            recursive,
            gpustar::calibrate::FitOptions {
                fit_principal_point: !fixed_centre,
                keep_loose_centre: !fit_centre,
                fit_k2: !no_k2,
                ..Default::default()
            },
            &output,
            &catalog,
        ),
        Command::Evaluate {
            results,
            truth,
            tolerance_deg,
            id_tolerance_px,
            per_frame,
        } => evaluate_cmd(&results, &truth, tolerance_deg, id_tolerance_px, per_frame),
        Command::Report(a) => report_cmd(a),
        Command::Catalog(CatalogCommand::Import {
            input,
            format,
            max_mag,
            output,
        }) => import_cmd(&input, format, max_mag, output.as_deref()),
    }
}

/// The ids of the options given on the command line (of the innermost subcommand).
fn given_options(m: &clap::ArgMatches) -> Vec<String> {
    match m.subcommand() {
        Some((_, sub)) => given_options(sub),
        None => m
            .ids()
            .filter(|id| {
                m.value_source(id.as_str()) == Some(clap::parser::ValueSource::CommandLine)
            })
            .map(|id| id.as_str().to_string())
            .collect(),
    }
}

/// Used by tests and `main`: parse arguments and run.
pub fn main_with_args<I, T>(args: I) -> ExitCode
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    alloc::keep_frame_buffers();
    let parsed = Cli::command()
        .try_get_matches_from(args)
        .and_then(|m| Ok((Cli::from_arg_matches(&m)?, given_options(&m))));
    let (cli, given) = match parsed {
        Ok(c) => c,
        Err(e) => {
            let _ = e.print();
            return if e.use_stderr() {
                Exit::NotStarted
            } else {
                Exit::Ok
            }
            .into();
        }
    };
    match execute(cli, &given) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("gpustar: error: {e:#}");
            Exit::NotStarted.into()
        }
    }
}
