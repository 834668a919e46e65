//! Streaming a run: inputs → parallel decode (and, on the CPU backend, solve) → the GPU in
//! batches → one writer that emits records in input order.
//!
//! Memory stays bounded whatever the number of inputs: at most `window` inputs are between
//! being handed out and being written (the writer returns a ticket for each record it writes,
//! and the feeder needs one to hand out the next input).

pub mod claims;

use crate::error::Result;
use crate::io::inputs::Input;
use crate::io::output::RecordWriter;
use crate::pipeline::{Backend, Counts, Decoded, Solvers};
use crate::record::Record;
use crate::sequence::{Detected, SequenceOptions, Sequencer};
use crossbeam_channel::{Receiver, Sender, bounded};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

/// How a run goes.
#[derive(Clone, Copy, Debug)]
pub struct RunOptions {
    /// Worker threads (decode, and solve on the CPU backend).
    pub threads: usize,
    /// Frames per GPU batch.
    pub batch_size: usize,
    /// Hand records to the file at least this often, and every `FLUSH_RECORDS` records.
    pub flush_every: Duration,
    /// `--sequence`: each directory's frames are solved as one sequence, in input order.
    pub sequence: Option<SequenceOptions>,
    /// `--streaks`: link the streaks of consecutive frames of a directory into tracklets
    /// ([`crate::streaks::tracklet`]); each record is then written when the next one is done.
    pub tracklets: bool,
    /// `--xyls`: the inputs are star lists, solved on the CPU.
    pub star_lists: Option<crate::pipeline::star_lists::StarLists>,
}

impl RunOptions {
    /// Inputs handed out and not yet written, at most: what bounds a run's memory.
    pub fn window(&self) -> usize {
        (4 * self.batch_size.max(1)).max(8 * self.threads.max(1))
    }
}

/// Records written between flushes at most: a crash loses at most this many (plus those the
/// last `flush_every` produced), and `--resume` redoes them.
pub const FLUSH_RECORDS: usize = 64;

/// What happened in a run.
#[derive(Clone, Debug, Default)]
pub struct RunSummary {
    pub counts: Counts,
    pub seconds: f64,
    /// Stopped early by an interrupt (Ctrl-C, SIGTERM): inputs after the last record have none.
    pub interrupted: bool,
    /// Stopped early because the records could not be written (a full disk): why. The file
    /// holds whole lines up to the failure (`--resume` cuts a torn one).
    pub write_error: Option<String>,
}

/// The inputs still to do after an earlier run recorded `done`. Sequences are tracked frame
/// to frame, so an unfinished sequence is taken from its first frame, the recorded ones marked
/// `replay` (tracked, not written): the records that follow are those of an uninterrupted run.
pub fn resumed_inputs(
    inputs: Vec<Input>,
    done: &std::collections::HashSet<String>,
    sequence: bool,
) -> Vec<Input> {
    use crate::sequence::sequence_of;
    let unfinished: std::collections::HashSet<&str> = inputs
        .iter()
        .filter(|i| sequence && !done.contains(&i.name))
        .map(|i| sequence_of(&i.name))
        .collect();
    inputs
        .iter()
        .filter(|i| !done.contains(&i.name) || unfinished.contains(sequence_of(&i.name)))
        .map(|i| Input {
            replay: done.contains(&i.name),
            ..i.clone()
        })
        .collect()
}

/// Process `inputs` and write one record per input, in order, until done or `stop` is set
/// (then no input is started; those in flight are written when they finish). Inputs marked
/// `replay` are processed for their sequence's state, their records not written.
/// `on_record` sees every record as it is written (progress).
pub fn run(
    inputs: Vec<Input>,
    solvers: &Solvers,
    backend: &mut Backend,
    writer: &mut RecordWriter,
    opts: RunOptions,
    stop: &AtomicBool,
    on_record: impl FnMut(&Record, &Counts),
) -> Result<RunSummary> {
    let replay: std::collections::HashSet<usize> = inputs
        .iter()
        .enumerate()
        .filter(|(_, i)| i.replay)
        .map(|(k, _)| k)
        .collect();
    let work = inputs.into_iter().map(Work::File);
    run_work(
        work,
        replay,
        solvers,
        backend,
        Some(writer),
        opts,
        stop,
        on_record,
    )
}

/// Frames the caller holds in memory (a camera's, an array library's), streamed through the
/// workers (or the GPU in batches) as [`run`] streams files: `on_record` sees each record in
/// the order of `frames`, as soon as it and those before it are done. The frames are taken
/// from the iterator on a thread of their own, at most a window ahead of the records.
pub fn run_frames(
    frames: impl Iterator<Item = Decoded<'static>> + Send,
    solvers: &Solvers,
    backend: &mut Backend,
    opts: RunOptions,
    stop: &AtomicBool,
    on_record: impl FnMut(&Record, &Counts),
) -> Result<RunSummary> {
    let work = frames.map(Work::Frame);
    let replay = std::collections::HashSet::new();
    run_work(work, replay, solvers, backend, None, opts, stop, on_record)
}

/// What a worker is handed: a file to decode, or a frame already in memory.
enum Work {
    File(Input),
    Frame(Decoded<'static>),
}

impl Work {
    /// The input as its record names it, and its path (for the record of a panic).
    fn input(&self) -> Input {
        match self {
            Work::File(i) => i.clone(),
            Work::Frame(d) => Input {
                path: d.path.clone(),
                name: d.name.clone(),
                replay: false,
            },
        }
    }

    fn decode(self, solvers: &Solvers) -> Decoded<'static> {
        match self {
            Work::File(i) => solvers.decode(&i.path, &i.name),
            Work::Frame(d) => d,
        }
    }
}

/// [`run`] and [`run_frames`]: `work` handed out one per ticket, records written (when there
/// is a writer) and seen in input order.
#[allow(clippy::too_many_arguments)]
fn run_work(
    inputs: impl Iterator<Item = Work> + Send,
    replay: std::collections::HashSet<usize>,
    solvers: &Solvers,
    backend: &mut Backend,
    writer: Option<&mut RecordWriter>,
    opts: RunOptions,
    stop: &AtomicBool,
    mut on_record: impl FnMut(&Record, &Counts),
) -> Result<RunSummary> {
    let t0 = Instant::now();
    let threads = opts.threads.max(1);
    let batch = opts.batch_size.max(1);
    let window = opts.window();
    let star_lists = opts.star_lists;
    let (work_tx, work_rx) = bounded::<(usize, Work)>(window);
    let (done_tx, done_rx) = bounded::<(usize, Record)>(window);
    let (ticket_tx, ticket_rx) = bounded::<()>(window);
    for _ in 0..window {
        ticket_tx.send(()).expect("room for every ticket");
    }
    let mut summary = RunSummary::default();
    std::thread::scope(|scope| -> Result<()> {
        // The feeder: one input per ticket, until the inputs end or a stop is asked.
        scope.spawn(move || {
            for item in inputs.enumerate() {
                if ticket_rx.recv().is_err() || stop.load(Ordering::SeqCst) {
                    break;
                }
                if work_tx.send(item).is_err() {
                    break;
                }
            }
        });
        if let Some(seq) = opts.sequence {
            // Sequences: the pixel stages in parallel (or batched on the GPU), then one thread
            // that takes the frames in input order.
            let (det_tx, det_rx) = bounded::<(usize, Detected)>(window);
            match backend {
                Backend::Cpu => {
                    for _ in 0..threads {
                        let (rx, tx) = (work_rx.clone(), det_tx.clone());
                        scope.spawn(move || {
                            for (i, work) in until_stop(&rx, stop) {
                                let input = work.input();
                                let d = guarded_detect(&input, || {
                                    solvers.detect_cpu(work.decode(solvers), seq.detect_stars)
                                });
                                if tx.send((i, d)).is_err() {
                                    break;
                                }
                            }
                        });
                    }
                }
                Backend::Gpu(runner) => {
                    let frame_rx = spawn_decoders(scope, solvers, &work_rx, threads, window, stop);
                    let tx = det_tx.clone();
                    scope.spawn(move || {
                        gpu_detect_loop(runner, solvers, frame_rx, tx, batch, seq.detect_stars)
                    });
                }
            }
            drop(det_tx);
            let tx = done_tx.clone();
            scope.spawn(move || sequence_loop(solvers, seq, det_rx, tx));
        } else {
            match backend {
                Backend::Cpu => {
                    for _ in 0..threads {
                        let (rx, tx) = (work_rx.clone(), done_tx.clone());
                        scope.spawn(move || {
                            for (i, work) in until_stop(&rx, stop) {
                                let name = match &work {
                                    Work::File(input) => input.name.clone(),
                                    Work::Frame(d) => d.name.clone(),
                                };
                                let r = guarded(solvers, &name, || match (&work, star_lists) {
                                    (Work::File(i), Some(l)) => {
                                        solvers.solve_star_list(&i.path, &i.name, l)
                                    }
                                    _ => solvers.solve_cpu(work.decode(solvers)),
                                });
                                if tx.send((i, r)).is_err() {
                                    break;
                                }
                            }
                        });
                    }
                }
                Backend::Gpu(runner) => {
                    let frame_rx = spawn_decoders(scope, solvers, &work_rx, threads, window, stop);
                    let tx = done_tx.clone();
                    scope.spawn(move || gpu_loop(runner, solvers, frame_rx, tx, batch));
                }
            }
        }
        drop(work_rx);
        drop(done_tx);
        summary = write_in_order(
            done_rx,
            ticket_tx,
            writer,
            &opts,
            stop,
            &replay,
            &mut on_record,
        )?;
        Ok(())
    })?;
    summary.seconds = t0.elapsed().as_secs_f64();
    summary.interrupted = stop.load(Ordering::SeqCst);
    Ok(summary)
}

/// The GPU thread: gather decoded frames into batches (as many as are ready, up to `batch`)
/// and solve them.
fn gpu_loop(
    runner: &mut crate::pipeline::GpuRunner,
    solvers: &Solvers,
    frames: Receiver<(usize, Decoded<'static>)>,
    done: Sender<(usize, Record)>,
    batch: usize,
) {
    while let Some(items) = next_batch(&frames, batch) {
        let (indices, decoded): (Vec<usize>, Vec<Decoded<'static>>) = items.into_iter().unzip();
        let names: Vec<String> = decoded.iter().map(|d| d.name.clone()).collect();
        let records = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            runner.solve(solvers, decoded)
        }))
        .unwrap_or_else(|p| {
            let msg = panic_message(&p);
            names
                .iter()
                .map(|n| solvers.error_record(n, &msg, &runner.name()))
                .collect()
        });
        for (i, r) in indices.into_iter().zip(records) {
            if done.send((i, r)).is_err() {
                return;
            }
        }
    }
}

/// The next GPU batch: as many decoded frames as are ready, up to `batch`, after waiting
/// briefly for the decoders so batches are full while they keep up; None when the decoders are
/// done.
fn next_batch(
    frames: &Receiver<(usize, Decoded<'static>)>,
    batch: usize,
) -> Option<Vec<(usize, Decoded<'static>)>> {
    let mut items = vec![frames.recv().ok()?];
    let deadline = Instant::now() + Duration::from_millis(50);
    while items.len() < batch {
        match frames.recv_deadline(deadline) {
            Ok(item) => items.push(item),
            Err(_) => break,
        }
    }
    Some(items)
}

/// Decoder threads for the GPU paths: decoded frames, in any order.
fn spawn_decoders<'s, 'e: 's>(
    scope: &'s std::thread::Scope<'s, 'e>,
    solvers: &'e Solvers,
    work: &Receiver<(usize, Work)>,
    threads: usize,
    window: usize,
    stop: &'e AtomicBool,
) -> Receiver<(usize, Decoded<'static>)> {
    let (frame_tx, frame_rx) = bounded::<(usize, Decoded<'static>)>(window);
    for _ in 0..threads {
        let (rx, tx) = (work.clone(), frame_tx.clone());
        scope.spawn(move || {
            for (i, work) in until_stop(&rx, stop) {
                let input = work.input();
                let d =
                    std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| work.decode(solvers)))
                        .unwrap_or_else(|p| panicked_decode(&input, &p));
                if tx.send((i, d)).is_err() {
                    break;
                }
            }
        });
    }
    frame_rx
}

/// The decoded frame of an input whose decoding panicked: its error record says so.
fn panicked_decode(input: &Input, p: &Box<dyn std::any::Any + Send>) -> Decoded<'static> {
    Decoded {
        name: input.name.clone(),
        path: input.path.clone(),
        epoch: None,
        keywords: Default::default(),
        warnings: Vec::new(),
        frame: Err(panic_message(p)),
        decode_ms: 0.0,
    }
}

/// The GPU thread of a sequence run: batches of decoded frames through the pixel stages.
fn gpu_detect_loop(
    runner: &mut crate::pipeline::GpuRunner,
    solvers: &Solvers,
    frames: Receiver<(usize, Decoded<'static>)>,
    done: Sender<(usize, Detected)>,
    batch: usize,
    max_stars: usize,
) {
    while let Some(items) = next_batch(&frames, batch) {
        let (indices, decoded): (Vec<usize>, Vec<Decoded<'static>>) = items.into_iter().unzip();
        let inputs: Vec<Input> = decoded
            .iter()
            .map(|d| Input {
                path: d.path.clone(),
                name: d.name.clone(),
                replay: false,
            })
            .collect();
        let found = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
            runner.detect(solvers, decoded, max_stars)
        }))
        .unwrap_or_else(|p| {
            let backend = runner.name();
            inputs
                .iter()
                .map(|i| Detected {
                    decoded: panicked_decode(i, &p),
                    detections: Err(panic_message(&p)),
                    detect_ms: 0.0,
                    backend: backend.clone(),
                })
                .collect()
        });
        for (i, d) in indices.into_iter().zip(found) {
            if done.send((i, d)).is_err() {
                return;
            }
        }
    }
}

/// The sequence thread: frames in input order through the sequence stage (a panic on one frame
/// becomes its error record, and its sequence starts again at the next frame).
fn sequence_loop(
    solvers: &Solvers,
    opts: SequenceOptions,
    detected: Receiver<(usize, Detected)>,
    done: Sender<(usize, Record)>,
) {
    let mut seq = Sequencer::new(solvers, opts);
    let mut waiting: BTreeMap<usize, Detected> = BTreeMap::new();
    let mut next = 0usize;
    for (i, d) in detected {
        waiting.insert(i, d);
        while let Some(d) = waiting.remove(&next) {
            let (name, backend) = (d.decoded.name.clone(), d.backend.clone());
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| seq.next(d)))
                .unwrap_or_else(|p| {
                    seq = Sequencer::new(solvers, opts);
                    solvers.error_record(&name, &panic_message(&p), &backend)
                });
            if done.send((next, r)).is_err() {
                return;
            }
            next += 1;
        }
    }
}

/// The pixel stages of one input; a panic becomes its error.
fn guarded_detect(input: &Input, f: impl FnOnce() -> Detected) -> Detected {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|p| Detected {
        decoded: panicked_decode(input, &p),
        detections: Err(panic_message(&p)),
        detect_ms: 0.0,
        backend: crate::pipeline::BACKEND_CPU.to_string(),
    })
}

/// Run `f` for one input; a panic (a bug, in gpustar or a decoder) becomes that input's
/// error record instead of ending the run.
fn guarded(solvers: &Solvers, name: &str, f: impl FnOnce() -> Record) -> Record {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f)).unwrap_or_else(|p| {
        solvers.error_record(name, &panic_message(&p), crate::pipeline::BACKEND_CPU)
    })
}

fn panic_message(p: &Box<dyn std::any::Any + Send>) -> crate::Error {
    let what = p
        .downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown".into());
    crate::Error::Internal(format!(
        "internal error while processing this file ({what}); please report it with the file"
    ))
}

/// The inputs of a worker until a stop is asked: queued inputs are then left without a
/// record (`--resume` does them) rather than making the user wait for them.
fn until_stop<'a, T>(rx: &'a Receiver<T>, stop: &'a AtomicBool) -> impl Iterator<Item = T> + 'a {
    rx.iter().take_while(move |_| !stop.load(Ordering::SeqCst))
}

/// The writer: records come in any order; they leave in input order. Whole lines are handed
/// to the file at least every `flush_every`, and at once after a stop is asked, so that the
/// process can be ended soon after without losing a record it finished.
fn write_in_order(
    done: Receiver<(usize, Record)>,
    tickets: Sender<()>,
    mut writer: Option<&mut RecordWriter>,
    opts: &RunOptions,
    stop: &AtomicBool,
    replay: &std::collections::HashSet<usize>,
    on_record: &mut impl FnMut(&Record, &Counts),
) -> Result<RunSummary> {
    let flush_every = opts.flush_every;
    let mut summary = RunSummary::default();
    let mut linker = opts.tracklets.then(crate::streaks::tracklet::Linker::new);
    let mut emit =
        |r: Record, w: Option<&mut RecordWriter>, summary: &mut RunSummary, n: &mut usize| {
            summary.counts.add(&r);
            if let Some(w) = w {
                w.write(&r);
            }
            on_record(&r, &summary.counts);
            *n += 1;
        };
    let mut waiting: BTreeMap<usize, Record> = BTreeMap::new();
    let mut next = 0usize;
    let mut last_flush = Instant::now();
    let mut unflushed = 0usize;
    loop {
        match done.recv_timeout(flush_every) {
            Ok((i, r)) => {
                waiting.insert(i, r);
            }
            Err(crossbeam_channel::RecvTimeoutError::Timeout) => {}
            Err(crossbeam_channel::RecvTimeoutError::Disconnected) => break,
        }
        while let Some(r) = waiting.remove(&next) {
            // A replayed input's record is already in the file.
            if !replay.contains(&next) {
                let ready = match linker.as_mut() {
                    Some(l) => l.push(r),
                    None => Some(r),
                };
                if let Some(r) = ready {
                    emit(r, writer.as_deref_mut(), &mut summary, &mut unflushed);
                }
            }
            next += 1;
            // The feeder may hand out one more input.
            let _ = tickets.try_send(());
        }
        let stopping = stop.load(Ordering::SeqCst);
        // Nothing more comes before a flush forced by a stop: the held record goes too.
        if stopping && let Some(r) = linker.as_mut().and_then(|l| l.finish()) {
            emit(r, writer.as_deref_mut(), &mut summary, &mut unflushed);
        }
        if unflushed > 0
            && (stopping || unflushed >= FLUSH_RECORDS || last_flush.elapsed() >= flush_every)
        {
            if let Some(Err(e)) = writer.as_deref_mut().map(RecordWriter::flush) {
                // Returning drops the channels: the workers and the feeder end.
                summary.write_error = Some(format!("{e:#}"));
                return Ok(summary);
            }
            last_flush = Instant::now();
            unflushed = 0;
        }
    }
    if let Some(r) = linker.as_mut().and_then(|l| l.finish()) {
        emit(r, writer.as_deref_mut(), &mut summary, &mut unflushed);
    }
    if let Some(Err(e)) = writer.map(RecordWriter::flush) {
        summary.write_error = Some(format!("{e:#}"));
    }
    Ok(summary)
}
