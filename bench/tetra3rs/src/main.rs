//! t3bench: tetra3rs (the `tetra3` crate, pinned at 0.14.0) as a command-line batch solver,
//! so that `scripts/bench_vs_tetra3rs.py` can time it against gpustar on the same frames,
//! whole process against whole process.
//!
//! ```text
//! t3bench db --hip2 FILE --min-fov-deg A --max-fov-deg B [--epoch YEAR] -o DB
//! t3bench solve --db DB --fov-deg F [--fov-max-error-deg E] [--threads N]
//!               [--extractor default|fast] [--limit N] DIR
//! ```
//!
//! `db` builds a database with `SolverDatabase::generate_from_hipparcos` (tetra3's defaults
//! for everything but the FOV range and the proper-motion epoch) and saves it.
//!
//! `solve` loads the database, then for every image in DIR (sorted by name; `.fits`, `.fit`,
//! `.fts`, `.png`, `.jpg`/`.jpeg`; other files are skipped) decodes it, extracts centroids with tetra3's own
//! extractor and calls `solve_from_centroids`. One JSON line per frame on stdout, in file
//! order; a summary line on stderr. A frame that cannot be read or solved gets
//! `"solved": false` (and an `"error"` when it could not be read); nothing panics on a bad
//! file, and the exit status is 0 unless the arguments, the database or DIR are unusable.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use serde_json::{json, Value};
use tetra3::{
    extract_centroids_fast, CentroidExtractionConfig, CentroidExtractor, FastCentroidConfig,
    GenerateDatabaseConfig, SolveConfig, SolveStatus, SolverDatabase,
};

const USAGE: &str = "\
usage:
  t3bench db --hip2 FILE --min-fov-deg A --max-fov-deg B [--epoch YEAR] -o DB
      Build a tetra3 database from Hipparcos hip2.dat (tetra3's defaults otherwise) and save it.
  t3bench solve --db DB --fov-deg F [--fov-max-error-deg E] [--threads N]
                [--extractor default|fast] [--limit N] DIR
      Solve every image in DIR (FITS, PNG, JPEG; sorted by name). One JSON line per frame on stdout,
      a summary on stderr. --fov-max-error-deg: the solver sweeps and filters F +- E (default:
      none, tetra3's default). --threads: frames spread over N threads (default 1).
      --extractor: tetra3's default CCL extractor (default) or extract_centroids_fast.
      --limit: only the first N images (for a warm-up).";

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("db") => cmd_db(&args[1..]),
        Some("solve") => cmd_solve(&args[1..]),
        Some("-h") | Some("--help") | Some("help") => {
            println!("{USAGE}");
            return ExitCode::SUCCESS;
        }
        _ => Err(format!("expected a subcommand\n{USAGE}")),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("t3bench: {e}");
            ExitCode::from(2)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Arguments
// ---------------------------------------------------------------------------------------------

/// `--name value` options and positional arguments, parsed by hand (no dependency).
struct Args {
    opts: Vec<(String, String)>,
    positional: Vec<String>,
}

impl Args {
    fn parse(args: &[String], known: &[&str]) -> Result<Self, String> {
        let mut opts = Vec::new();
        let mut positional = Vec::new();
        let mut it = args.iter();
        while let Some(a) = it.next() {
            if a.starts_with('-') && a.len() > 1 {
                let (name, inline) = match a.split_once('=') {
                    Some((n, v)) => (n.to_string(), Some(v.to_string())),
                    None => (a.clone(), None),
                };
                if !known.contains(&name.as_str()) {
                    return Err(format!("unknown option {name}\n{USAGE}"));
                }
                let value = match inline {
                    Some(v) => v,
                    None => it
                        .next()
                        .ok_or_else(|| format!("{name} needs a value"))?
                        .clone(),
                };
                opts.push((name, value));
            } else {
                positional.push(a.clone());
            }
        }
        Ok(Self { opts, positional })
    }

    fn get(&self, name: &str) -> Option<&str> {
        self.opts
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_str())
    }

    fn req(&self, name: &str) -> Result<&str, String> {
        self.get(name)
            .ok_or_else(|| format!("{name} is required\n{USAGE}"))
    }

    fn num<T: std::str::FromStr>(&self, name: &str) -> Result<Option<T>, String> {
        self.get(name)
            .map(|v| {
                v.parse::<T>()
                    .map_err(|_| format!("{name}: cannot parse {v:?}"))
            })
            .transpose()
    }
}

// ---------------------------------------------------------------------------------------------
// t3bench db
// ---------------------------------------------------------------------------------------------

fn cmd_db(args: &[String]) -> Result<(), String> {
    let a = Args::parse(
        args,
        &[
            "--hip2",
            "--min-fov-deg",
            "--max-fov-deg",
            "--epoch",
            "-o",
            "--output",
        ],
    )?;
    let hip2 = a.req("--hip2")?;
    let min_fov: f32 = a.num("--min-fov-deg")?.ok_or("--min-fov-deg is required")?;
    let max_fov: f32 = a.num("--max-fov-deg")?.ok_or("--max-fov-deg is required")?;
    let epoch: f64 = a.num("--epoch")?.unwrap_or(2025.0);
    let out = a
        .get("-o")
        .or(a.get("--output"))
        .ok_or("-o DB is required")?;
    let config = GenerateDatabaseConfig {
        max_fov_deg: max_fov,
        min_fov_deg: Some(min_fov),
        epoch_proper_motion_year: Some(epoch),
        ..Default::default()
    };
    let t0 = Instant::now();
    let db = SolverDatabase::generate_from_hipparcos(hip2, &config)
        .map_err(|e| format!("generating the database from {hip2}: {e}"))?;
    let t_gen = t0.elapsed().as_secs_f64();
    db.save_to_file(out)
        .map_err(|e| format!("saving {out}: {e}"))?;
    let size = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    let p = &db.props;
    let line = json!({
        "database": out,
        "catalog": hip2,
        "stars": db.star_catalog.len(),
        "patterns": p.num_patterns,
        "pattern_table_slots": db.pattern_catalog.len(),
        "bytes": size,
        "generate_s": t_gen,
        "min_fov_deg": p.min_fov_rad.to_degrees(),
        "max_fov_deg": p.max_fov_rad.to_degrees(),
        "star_max_magnitude": p.star_max_magnitude,
        "pattern_max_error": p.pattern_max_error,
        "pattern_bins": p.pattern_bins,
        "epoch_proper_motion_year": p.epoch_proper_motion_year,
        "verification_stars_per_fov": p.verification_stars_per_fov,
        "lattice_field_oversampling": p.lattice_field_oversampling,
        "patterns_per_lattice_field": p.patterns_per_lattice_field,
        "multiscale_step": config.multiscale_step,
        "catalog_nside": config.catalog_nside,
        "tetra3": "0.14.0",
    });
    println!("{line}");
    eprintln!(
        "t3bench db: {} stars (mag <= {:.2}), {} patterns, {:.1} MB, FOV {}-{} deg, epoch {}, {:.1} s",
        db.star_catalog.len(),
        p.star_max_magnitude,
        p.num_patterns,
        size as f64 / 1e6,
        min_fov,
        max_fov,
        epoch,
        t_gen
    );
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// t3bench solve
// ---------------------------------------------------------------------------------------------

#[derive(Clone, Copy, PartialEq)]
enum Extractor {
    /// `CentroidExtractor` (the pipeline of `extract_centroids_from_*`) with
    /// `CentroidExtractionConfig::default()`.
    Default,
    /// `extract_centroids_fast` with `FastCentroidConfig::default()`.
    Fast,
}

struct SolveSetup {
    db: SolverDatabase,
    fov_rad: f32,
    fov_max_error_rad: Option<f32>,
    extractor: Extractor,
}

fn cmd_solve(args: &[String]) -> Result<(), String> {
    let t_process = Instant::now();
    let a = Args::parse(
        args,
        &[
            "--db",
            "--fov-deg",
            "--fov-max-error-deg",
            "--threads",
            "-j",
            "--extractor",
            "--limit",
        ],
    )?;
    let db_path = a.req("--db")?;
    let fov_deg: f32 = a.num("--fov-deg")?.ok_or("--fov-deg is required")?;
    if !(fov_deg.is_finite() && fov_deg > 0.0 && fov_deg < 180.0) {
        return Err(format!("--fov-deg must be in (0, 180), got {fov_deg}"));
    }
    let fov_err_deg: Option<f32> = a.num("--fov-max-error-deg")?;
    if let Some(e) = fov_err_deg {
        if !(e.is_finite() && e > 0.0) {
            return Err(format!("--fov-max-error-deg must be > 0, got {e}"));
        }
    }
    let threads: usize = match a.num::<usize>("--threads")? {
        Some(n) => n,
        None => a.num::<usize>("-j")?.unwrap_or(1),
    };
    let threads = threads.max(1);
    let extractor = match a.get("--extractor").unwrap_or("default") {
        "default" => Extractor::Default,
        "fast" => Extractor::Fast,
        other => {
            return Err(format!(
                "--extractor must be default or fast, got {other:?}"
            ))
        }
    };
    let limit: Option<usize> = a.num("--limit")?;
    let dir = match a.positional.as_slice() {
        [d] => PathBuf::from(d),
        _ => return Err(format!("expected one DIR\n{USAGE}")),
    };

    let mut files = list_images(&dir)?;
    if let Some(n) = limit {
        files.truncate(n);
    }

    let t_db = Instant::now();
    let db =
        SolverDatabase::load_from_file(db_path).map_err(|e| format!("loading {db_path}: {e}"))?;
    let db_load_s = t_db.elapsed().as_secs_f64();
    let db_desc = {
        let p = &db.props;
        format!(
            "database {} stars mag <= {:.2}, {} patterns, FOV {:.1}-{:.1} deg, epoch {}",
            db.star_catalog.len(),
            p.star_max_magnitude,
            p.num_patterns,
            p.min_fov_rad.to_degrees(),
            p.max_fov_rad.to_degrees(),
            p.epoch_proper_motion_year
        )
    };
    let setup = SolveSetup {
        db,
        fov_rad: fov_deg.to_radians(),
        fov_max_error_rad: fov_err_deg.map(f32::to_radians),
        extractor,
    };

    // Workers take the next frame index from a shared counter; each keeps its own extractor
    // buffers. Records are stored by index and printed in file order at the end.
    let t_frames = Instant::now();
    let next = AtomicUsize::new(0);
    let workers = threads.min(files.len()).max(1);
    let mut records: Vec<Option<Value>> = vec![None; files.len()];
    let results: Vec<Vec<(usize, Value)>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..workers)
            .map(|_| {
                s.spawn(|| {
                    let mut ex = CentroidExtractor::new();
                    let mut out = Vec::new();
                    loop {
                        let i = next.fetch_add(1, Ordering::Relaxed);
                        if i >= files.len() {
                            break;
                        }
                        let rec = solve_frame(&setup, &mut ex, &dir, &files[i]);
                        out.push((i, rec));
                    }
                    out
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join().unwrap_or_else(|_| {
                    // solve_frame catches panics itself; this is only a backstop.
                    Vec::new()
                })
            })
            .collect()
    });
    for (i, rec) in results.into_iter().flatten() {
        records[i] = Some(rec);
    }
    let frames_s = t_frames.elapsed().as_secs_f64();

    let mut solved = 0usize;
    let mut errors = 0usize;
    {
        use std::io::Write;
        let stdout = std::io::stdout();
        let mut w = std::io::BufWriter::new(stdout.lock());
        for (i, rec) in records.into_iter().enumerate() {
            let rec = rec.unwrap_or_else(
                || json!({"file": files[i], "solved": false, "error": "worker thread died"}),
            );
            if rec["solved"] == Value::Bool(true) {
                solved += 1;
            }
            if rec.get("error").is_some() {
                errors += 1;
            }
            writeln!(w, "{rec}").map_err(|e| format!("writing stdout: {e}"))?;
        }
        w.flush().map_err(|e| format!("writing stdout: {e}"))?;
    }
    let wall = t_process.elapsed().as_secs_f64();
    let n = files.len();
    eprintln!(
        "t3bench: {n} frames, {solved} solved, {errors} unreadable, {wall:.3} s wall \
         ({:.2} images/s; database load {db_load_s:.3} s, frames {frames_s:.3} s), {workers} thread(s), \
         extractor {}, fov {fov_deg} deg, fov_max_error {}; {db_desc}",
        if wall > 0.0 { n as f64 / wall } else { 0.0 },
        match extractor {
            Extractor::Default => "default (CentroidExtractionConfig::default)",
            Extractor::Fast => "fast (FastCentroidConfig::default)",
        },
        fov_err_deg.map_or("none".to_string(), |e| format!("{e} deg")),
    );
    Ok(())
}

/// Image files in DIR (not recursive), sorted by name: the same order `gpustar batch` uses.
fn list_images(dir: &Path) -> Result<Vec<String>, String> {
    let rd = std::fs::read_dir(dir).map_err(|e| format!("reading {}: {e}", dir.display()))?;
    let mut files: Vec<String> = rd
        .filter_map(|e| e.ok())
        .filter(|e| e.file_type().map(|t| !t.is_dir()).unwrap_or(false))
        .filter_map(|e| e.file_name().into_string().ok())
        .filter(|name| kind_of(name).is_some())
        .collect();
    files.sort();
    Ok(files)
}

#[derive(Clone, Copy)]
enum Kind {
    Fits,
    Png,
    Jpeg,
}

fn kind_of(name: &str) -> Option<Kind> {
    let lower = name.to_ascii_lowercase();
    if lower.ends_with(".fits") || lower.ends_with(".fit") || lower.ends_with(".fts") {
        Some(Kind::Fits)
    } else if lower.ends_with(".png") {
        Some(Kind::Png)
    } else if lower.ends_with(".jpg") || lower.ends_with(".jpeg") {
        Some(Kind::Jpeg)
    } else {
        None
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// One frame: decode, extract, solve. Never panics (a panic inside tetra3 or the decoders
/// becomes an error record).
fn solve_frame(setup: &SolveSetup, ex: &mut CentroidExtractor, dir: &Path, name: &str) -> Value {
    let path = dir.join(name);
    match std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        solve_frame_inner(setup, ex, &path, name)
    })) {
        Ok(v) => v,
        Err(p) => {
            let msg = p
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| p.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "panic".into());
            *ex = CentroidExtractor::new();
            json!({"file": name, "solved": false, "error": format!("panic: {msg}")})
        }
    }
}

fn solve_frame_inner(
    setup: &SolveSetup,
    ex: &mut CentroidExtractor,
    path: &Path,
    name: &str,
) -> Value {
    let fail = |what: String| json!({"file": name, "solved": false, "error": what});

    // Decode.
    let t0 = Instant::now();
    let decoded = match kind_of(name) {
        Some(Kind::Fits) => read_fits(path).map(Pixels::Raw),
        Some(Kind::Png | Kind::Jpeg) => image::ImageReader::open(path)
            .map_err(|e| e.to_string())
            .and_then(|r| r.with_guessed_format().map_err(|e| e.to_string()))
            .and_then(|r| r.decode().map_err(|e| e.to_string()))
            .map(Pixels::Image),
        None => Err("not an image".into()),
    };
    let decode_ms = ms(t0);
    let pixels = match decoded {
        Ok(p) => p,
        Err(e) => return fail(format!("decode: {e}")),
    };

    // Extract.
    let t1 = Instant::now();
    let extracted = match (&pixels, setup.extractor) {
        (Pixels::Image(img), Extractor::Default) => {
            ex.extract_from_image(img, &CentroidExtractionConfig::default())
        }
        (Pixels::Raw(r), Extractor::Default) => ex.extract_from_raw(
            &r.data,
            r.width,
            r.height,
            &CentroidExtractionConfig::default(),
        ),
        (Pixels::Image(img), Extractor::Fast) => {
            let (w, h) = (img.width(), img.height());
            let gray: Vec<f32> = match img {
                image::DynamicImage::ImageLuma16(g) => {
                    g.as_raw().iter().map(|&v| v as f32).collect()
                }
                _ => img.to_luma32f().into_raw(),
            };
            extract_centroids_fast(&gray, w, h, &FastCentroidConfig::default())
        }
        (Pixels::Raw(r), Extractor::Fast) => {
            extract_centroids_fast(&r.data, r.width, r.height, &FastCentroidConfig::default())
        }
    };
    let extract_ms = ms(t1);
    let extracted = match extracted {
        Ok(x) => x,
        Err(e) => return fail(format!("extract: {e}")),
    };
    let (width, height) = (extracted.image_width, extracted.image_height);
    let n_stars = extracted.centroids.len();

    // Solve.
    let config = SolveConfig {
        fov_max_error_rad: setup.fov_max_error_rad,
        ..SolveConfig::new(setup.fov_rad, width, height)
    };
    let t2 = Instant::now();
    let result = setup.db.solve_from_centroids(&extracted.centroids, &config);
    let solve_ms = ms(t2);

    match result {
        Ok(sol) => {
            // Boresight: the WCS reference point, which is the centre pixel's direction
            // (crpix = 0) and the boresight of qicrs2cam.
            let ra = sol.crval_rad[0].to_degrees().rem_euclid(360.0);
            let dec = sol.crval_rad[1].to_degrees();
            // tetra3's roll: from image up (-Y) to celestial north, counter-clockwise, i.e.
            // atan2(-n_x, -n_y) with n the ICRS +Z axis in camera coordinates. qicrs2cam
            // maps into the x-negated frame when parity_flip is set; undo that for n_x.
            let r = sol.qicrs2cam.to_rotation_matrix();
            let (mut nx, ny) = (r[(0, 2)] as f64, r[(1, 2)] as f64);
            if sol.parity_flip {
                nx = -nx;
            }
            let roll = ((-nx).atan2(-ny).to_degrees()).rem_euclid(360.0);
            json!({
                "file": name, "solved": true,
                "ra_deg": ra, "dec_deg": dec, "roll_deg": roll,
                "fov_deg": (sol.fov_rad as f64).to_degrees(),
                "stars": n_stars, "matches": sol.num_matches,
                "prob": sol.prob, "rmse_arcsec": (sol.rmse_rad as f64).to_degrees() * 3600.0,
                "parity_flip": sol.parity_flip,
                "decode_ms": decode_ms, "extract_ms": extract_ms, "solve_ms": solve_ms,
            })
        }
        Err(f) => json!({
            "file": name, "solved": false, "status": status_name(f.status),
            "stars": n_stars, "matches": 0,
            "decode_ms": decode_ms, "extract_ms": extract_ms, "solve_ms": solve_ms,
        }),
    }
}

fn status_name(s: SolveStatus) -> &'static str {
    match s {
        SolveStatus::NoMatch => "no_match",
        SolveStatus::Timeout => "timeout",
        SolveStatus::TooFew => "too_few",
        SolveStatus::InvalidConfig => "invalid_config",
    }
}

// ---------------------------------------------------------------------------------------------
// Decoding
// ---------------------------------------------------------------------------------------------

enum Pixels {
    Image(image::DynamicImage),
    Raw(RawImage),
}

/// Grey pixels, row-major, physical values (BZERO + BSCALE * stored).
struct RawImage {
    data: Vec<f32>,
    width: u32,
    height: u32,
}

/// A small reader for the primary HDU of a FITS file: a 2-D image (a third axis of length 1
/// is allowed) with BITPIX 8, 16, 32, -32 or -64, BZERO and BSCALE applied. Rows are kept in
/// file order (the first row stored is image row 0, the top), which is how the simulator
/// writes its frames and how gpustar reads them.
fn read_fits(path: &Path) -> Result<RawImage, String> {
    let bytes = std::fs::read(path).map_err(|e| e.to_string())?;
    const BLOCK: usize = 2880;
    const CARD: usize = 80;
    let mut bitpix: Option<i64> = None;
    let mut naxis: Option<usize> = None;
    let mut dims = [0usize; 3];
    let mut bzero = 0.0f64;
    let mut bscale = 1.0f64;
    let mut pos = 0usize;
    let mut end = None;
    'blocks: while pos + BLOCK <= bytes.len() {
        for c in 0..BLOCK / CARD {
            let card = &bytes[pos + c * CARD..pos + (c + 1) * CARD];
            let card = std::str::from_utf8(card).map_err(|_| "header is not ASCII".to_string())?;
            if pos == 0 && c == 0 && !card.starts_with("SIMPLE") {
                return Err("not a FITS file (no SIMPLE card)".into());
            }
            let key = card[..8].trim_end();
            if key == "END" {
                end = Some(pos + BLOCK);
                break 'blocks;
            }
            if card.as_bytes().get(8..10) != Some(b"= ") {
                continue;
            }
            let value = card[10..].split('/').next().unwrap_or("").trim();
            let int = || {
                value
                    .parse::<i64>()
                    .map_err(|_| format!("{key} = {value:?}"))
            };
            let float = || {
                value
                    .replace(['D', 'd'], "E")
                    .parse::<f64>()
                    .map_err(|_| format!("{key} = {value:?}"))
            };
            match key {
                "BITPIX" => bitpix = Some(int()?),
                "NAXIS" => naxis = Some(int()? as usize),
                "NAXIS1" => dims[0] = int()?.max(0) as usize,
                "NAXIS2" => dims[1] = int()?.max(0) as usize,
                "NAXIS3" => dims[2] = int()?.max(0) as usize,
                "BZERO" => bzero = float()?,
                "BSCALE" => bscale = float()?,
                _ => {}
            }
        }
        pos += BLOCK;
    }
    let data_start = end.ok_or("no END card in the header")?;
    let bitpix = bitpix.ok_or("no BITPIX")?;
    match naxis {
        Some(2) => {}
        Some(3) if dims[2] == 1 => {}
        other => {
            return Err(format!(
                "need a 2-D image, NAXIS = {other:?} (NAXIS3 = {})",
                dims[2]
            ))
        }
    }
    let (w, h) = (dims[0], dims[1]);
    if w == 0 || h == 0 || w > 1 << 16 || h > 1 << 16 {
        return Err(format!("image size {w}x{h}"));
    }
    let bpp = match bitpix {
        8 => 1,
        16 => 2,
        32 | -32 => 4,
        -64 => 8,
        b => return Err(format!("BITPIX {b} not supported")),
    };
    let n = w * h;
    let raw = bytes
        .get(data_start..data_start + n * bpp)
        .ok_or_else(|| format!("data truncated: need {} bytes after the header", n * bpp))?;
    let phys = |v: f64| (bzero + bscale * v) as f32;
    let data: Vec<f32> = match bitpix {
        8 => raw.iter().map(|&b| phys(b as f64)).collect(),
        16 => raw
            .chunks_exact(2)
            .map(|c| phys(i16::from_be_bytes([c[0], c[1]]) as f64))
            .collect(),
        32 => raw
            .chunks_exact(4)
            .map(|c| phys(i32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64))
            .collect(),
        -32 => raw
            .chunks_exact(4)
            .map(|c| phys(f32::from_be_bytes([c[0], c[1], c[2], c[3]]) as f64))
            .collect(),
        _ => raw
            .chunks_exact(8)
            .map(|c| phys(f64::from_be_bytes(c.try_into().unwrap_or([0; 8]))))
            .collect(),
    };
    if data.iter().any(|v| !v.is_finite()) {
        return Err("non-finite pixel values".into());
    }
    Ok(RawImage {
        data,
        width: w as u32,
        height: h as u32,
    })
}
