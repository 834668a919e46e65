//! The terminal side of a run: stop requests, progress, logging, and printing to a pipe.

use super::exit::Exit;
use anyhow::Result;
use gpustar::io::output::{self};
use std::io::Write;
use std::path::Path;
use std::process::ExitCode;

/// How long frames in flight may take to finish after a stop request before the process ends
/// without them (their inputs get no record; `--resume` does them).
pub(crate) const STOP_GRACE: std::time::Duration = std::time::Duration::from_secs(5);

/// Set by Ctrl-C (SIGINT) or SIGTERM: the run stops handing out inputs, leaves queued ones
/// without a record, and writes the records of frames in flight that finish within
/// [`STOP_GRACE`]; after that the process ends with 130 whatever a frame is doing, as it does
/// at once on a second signal. Either way it ends between two whole lines of the output.
pub(crate) fn interrupt_flag() -> &'static std::sync::atomic::AtomicBool {
    static STOP: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);
    static ONCE: std::sync::Once = std::sync::Once::new();
    fn exit_between_lines(why: &str) -> ! {
        let _writing = output::WRITING.lock().unwrap_or_else(|e| e.into_inner());
        eprintln!("gpustar: {why}; inputs without a record are done by --resume");
        std::process::exit(Exit::Interrupted as i32);
    }
    ONCE.call_once(|| {
        let _ = ctrlc::set_handler(|| {
            if STOP.swap(true, std::sync::atomic::Ordering::SeqCst) {
                exit_between_lines("interrupted again: exiting without waiting");
            }
            std::thread::spawn(|| {
                std::thread::sleep(STOP_GRACE);
                exit_between_lines(&format!(
                    "interrupted: frames still in flight after {} s were abandoned",
                    STOP_GRACE.as_secs()
                ));
            });
        });
    });
    &STOP
}

/// Progress on stderr: a bar (rate, ETA, counts) on a terminal; elsewhere (a Slurm log, a
/// pipe) a line every `every` seconds, so that a long run's log shows it alive; nothing with
/// -q (or `every` 0 off a terminal).
pub(crate) enum Progress {
    Bar(indicatif::ProgressBar),
    Lines {
        total: u64,
        done: u64,
        start: std::time::Instant,
        last: std::time::Instant,
        every: std::time::Duration,
    },
    Hidden,
}

impl Progress {
    pub(crate) fn new(total: u64, quiet: bool, every_s: f64) -> Progress {
        use std::io::IsTerminal;
        if quiet {
            return Progress::Hidden;
        }
        if std::io::stderr().is_terminal() {
            return Progress::Bar(progress_bar(total));
        }
        if every_s <= 0.0 {
            return Progress::Hidden;
        }
        let now = std::time::Instant::now();
        Progress::Lines {
            total,
            done: 0,
            start: now,
            last: now,
            every: std::time::Duration::from_secs_f64(every_s),
        }
    }

    /// One more input done; `c` the counts so far.
    pub(crate) fn tick(&mut self, c: &gpustar::pipeline::Counts) {
        match self {
            Progress::Bar(bar) => {
                bar.inc(1);
                bar.set_message(format!(
                    "{} solved, {} unsolved, {} errors",
                    c.solved, c.unsolved, c.errors
                ));
            }
            Progress::Lines {
                total,
                done,
                start,
                last,
                every,
            } => {
                *done += 1;
                if last.elapsed() < *every || *done == *total {
                    return;
                }
                *last = std::time::Instant::now();
                let seconds = start.elapsed().as_secs_f64();
                let rate = *done as f64 / seconds.max(1e-9);
                eprintln!(
                    "gpustar: {done}/{total} files ({:.0} %): {} solved, {} unsolved, {} errors; \
                     {rate:.1} images/s, {:.0} s, about {:.0} s to go",
                    100.0 * *done as f64 / (*total).max(1) as f64,
                    c.solved,
                    c.unsolved,
                    c.errors,
                    seconds,
                    total.saturating_sub(*done) as f64 / rate.max(1e-9),
                );
            }
            Progress::Hidden => {}
        }
    }

    pub(crate) fn finish(&self) {
        if let Progress::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// The terminal's progress bar.
fn progress_bar(len: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    bar.set_style(
        indicatif::ProgressStyle::with_template(
            "{elapsed_precise} [{bar:30}] {pos}/{len} {rate} ETA {eta} {msg}",
        )
        .expect("a valid template")
        .with_key(
            "rate",
            |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.0} images/s", s.per_sec());
            },
        )
        .progress_chars("=> "),
    );
    bar
}

/// Mesa's Vulkan drivers print "error: XDG_RUNTIME_DIR is invalid or not set in the
/// environment." on stderr, twice, where the environment has no runtime directory (containers,
/// batch jobs, cron): give them one of gpustar's own in the temp directory. Left alone with
/// `-v`, so that the driver's own words can be seen.
pub(crate) fn give_the_driver_a_runtime_dir() {
    let set = std::env::var_os("XDG_RUNTIME_DIR").is_some_and(|d| Path::new(&d).is_dir());
    if set {
        return;
    }
    let dir = std::env::temp_dir().join("gpustar-runtime");
    if std::fs::create_dir_all(&dir).is_err() {
        return;
    }
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        let _ = std::fs::set_permissions(&dir, std::fs::Permissions::from_mode(0o700));
    }
    // SAFETY: called first thing in `execute`, before any thread of gpustar's exists, so no other
    // thread can read the environment while it changes.
    unsafe { std::env::set_var("XDG_RUNTIME_DIR", &dir) };
}

/// Logs to stderr: warnings by default, more with -v.
pub(crate) fn init_logging(verbose: u8) {
    let level = match verbose {
        0 => tracing::Level::WARN,
        1 => tracing::Level::INFO,
        2 => tracing::Level::DEBUG,
        _ => tracing::Level::TRACE,
    };
    use std::io::IsTerminal;
    let terminal = std::io::stderr().is_terminal();
    let _ = tracing_subscriber::fmt()
        .with_max_level(level)
        .with_writer(std::io::stderr)
        .with_ansi(terminal)
        .with_target(false)
        .without_time()
        .try_init();
    // A panic on one frame becomes that frame's error record; into a log file (stderr not a
    // terminal) it is said in one line, without the backtrace RUST_BACKTRACE would add
    // (-vv keeps Rust's own report).
    if !terminal && verbose < 2 {
        std::panic::set_hook(Box::new(|info| {
            let at = info
                .location()
                .map(|l| format!(" at {}:{}", l.file(), l.line()))
                .unwrap_or_default();
            let what = info
                .payload()
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| info.payload().downcast_ref::<String>().cloned())
                .unwrap_or_default();
            eprintln!("gpustar: internal error{at}: {what} (-vv for Rust's report)");
        }));
    }
}

/// Print `text` to stdout; a reader that stops early (`| head`) is not an error.
pub(crate) fn print_all(text: &str) -> Result<ExitCode> {
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() != std::io::ErrorKind::BrokenPipe => Err(e.into()),
        _ => Ok(ExitCode::SUCCESS),
    }
}
