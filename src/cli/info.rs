//! `gpustar info`: what a camera sees of the catalog and which identifier it gets.

use super::args::{CameraOpts, CatalogOpts};
use super::config::camera_config;
use super::console::print_all;
use anyhow::{Context, Result, bail};
use gpustar::catalog::Catalog;
use gpustar::pipeline::{Backend, BackendChoice, BackendNote, CameraSource};
use gpustar::solve::{PassKind, Solver, scaled};
use std::process::ExitCode;

pub(crate) fn info(c: &CameraOpts, size: Option<(u32, u32)>, o: &CatalogOpts) -> Result<ExitCode> {
    use std::fmt::Write as _;
    // Written at the end in one piece, so that `| head` ends it quietly (see `print_all`).
    let mut out = String::new();
    let adapters = gpustar::gpu::adapters();
    writeln!(out, "GPU adapters: {}", adapters.len())?;
    for a in &adapters {
        writeln!(
            out,
            "  {} ({}, {}, driver {})",
            a.name, a.backend, a.device_type, a.driver
        )?;
    }
    // What each --backend runs on: `auto`, the default, leaves a software rasterizer to the
    // CPU twins, so naming only the adapter would say the GPU where `batch` uses the CPU.
    match gpustar::gpu::Gpu::new(std::env::var("GPUSTAR_ADAPTER").ok().as_deref()) {
        Ok(g) => {
            let name = g.backend_name();
            writeln!(out, "--backend gpu: {}", name.trim_start_matches("gpu: "))?;
            writeln!(
                out,
                "  limits: Limits::default() with max_storage_buffer_binding_size {} MB, \
                 max_buffer_size {} MB (the adapter's); no optional features",
                g.limits.max_storage_buffer_binding_size >> 20,
                g.limits.max_buffer_size >> 20
            )?;
        }
        Err(e) => writeln!(out, "--backend gpu: none ({e:#})")?,
    }
    let auto = match Backend::open(BackendChoice::Auto) {
        Ok((backend, None)) => backend.name(),
        Ok((backend, Some(BackendNote::Info(why) | BackendNote::Warning(why)))) => {
            format!("{} ({why})", backend.name())
        }
        Err(e) => format!("none ({e:#})"),
    };
    writeln!(out, "--backend auto (the default): {auto}")?;
    let catalog = Catalog::load(o.catalog.as_deref())?;
    writeln!(out, "catalog: {}", catalog.source)?;
    let (e0, e1) = catalog
        .stars
        .iter()
        .fold((f64::MAX, f64::MIN), |(a, b), s| {
            (a.min(s.epoch), b.max(s.epoch))
        });
    let epochs = if e0 == e1 {
        format!("J{e0}")
    } else {
        format!("J{e0} to J{e1} (each star's own)")
    };
    writeln!(
        out,
        "  stars: {} (mag {:.2} to {:.2}), positions at {epochs}, propagated to epoch {}",
        catalog.stars.len(),
        catalog.stars.iter().map(|s| s.mag).fold(f64::MAX, f64::min),
        catalog.faintest(),
        o.epoch
    )?;
    if c.camera.is_none() && c.fov_deg.is_none() && c.scale_arcsec.is_none() {
        writeln!(
            out,
            "(give --camera FILE, or --fov-deg DEG (or --scale-arcsec S) --size WxH, to see the \
             distance table)"
        )?;
        return print_all(&out);
    }
    let cfg = camera_config(c, o)?;
    let choice = cfg.camera_source(None)?;
    let s = cfg.settings(&choice);
    let source = choice.0;
    let camera = match source {
        CameraSource::Fixed(cam) => cam,
        CameraSource::None | CameraSource::Header => {
            bail!("give the camera: --camera FILE, --fov-deg DEG or --scale-arcsec S")
        }
        sized @ (CameraSource::Fov { .. } | CameraSource::Scale { .. }) => {
            let (w, h) =
                size.context("--fov-deg and --scale-arcsec need --size WIDTHxHEIGHT here")?;
            sized.camera_for(w, h, None)?
        }
    };
    writeln!(
        out,
        "camera: {}x{} px, FOV {:.4} x {:.4} deg, diagonal {:.4} deg, {:.2} arcsec/px",
        camera.width,
        camera.height,
        camera.fov_x_deg(),
        camera.fov_y_deg(),
        camera.diagonal_rad().to_degrees(),
        camera.ifov_rad().to_degrees() * 3600.0
    )?;
    // What a run with these options votes with: the solver's own selections and tables.
    let solver = Solver::new(&catalog, camera.clone(), s)?;
    for (k, band) in solver.bands.iter().enumerate() {
        if Some(k) == solver.shallow_band {
            writeln!(
                out,
                "shallow pass (frames that show few stars): {} stars in view on average",
                gpustar::solve::SHALLOW_STARS_IN_VIEW
            )?;
        } else if s.scale_range.is_some() {
            writeln!(
                out,
                "scale band: FOV {:.4} to {:.4} deg ({} scales tried)",
                scaled(&camera, band.hi).fov_x_deg(),
                scaled(&camera, band.lo).fov_x_deg(),
                solver
                    .passes
                    .iter()
                    .filter(|p| p.band == k && p.kind == PassKind::First)
                    .filter(|p| p.method == solver.passes[0].method)
                    .count()
            )?;
        }
        let (refs, t, origin) = (&band.refs, band.table(), band.table_origin());
        writeln!(
            out,
            "reference stars: {} with Hp <= {}{}; double stars ({:?}, < {} px): {} removed",
            refs.len(),
            refs.selection.mag_limit,
            if s.mag_limit.is_none() {
                " (chosen from the FOV)"
            } else {
                ""
            },
            s.double_stars,
            s.double_star_px,
            refs.doubles_removed
        )?;
        writeln!(
            out,
            "distance table: {} rows, {} bytes (keys + pairs + k-vector of {} bins), pairs closer than {:.4} deg",
            t.len(),
            t.bytes(),
            t.kvector.len() - 1,
            t.max_sep_rad.to_degrees()
        )?;
        writeln!(
            out,
            "  {} in {:.1} ms{}",
            if origin.built {
                "built"
            } else {
                "read from cache"
            },
            origin.seconds * 1e3,
            origin
                .cache_file
                .as_ref()
                .map(|f| format!("; cache {}", f.display()))
                .unwrap_or_default()
        )?;
        if let Some(n) = &origin.cache_note {
            writeln!(out, "  note: {n}")?;
        }
        // What `--method radial` would keep besides: built here from the table.
        let t0 = std::time::Instant::now();
        let middle = scaled(&camera, 0.5 * (band.lo + band.hi));
        let radial = gpustar::solve::radial::RadialTable::build(
            refs,
            t,
            s.identify.pair_tol_px * middle.ifov_rad(),
            s.identify.scale_tol,
        );
        writeln!(
            out,
            "radial features (--method radial): {} bytes ({} rings of {:.2} arcsec to {:.4} deg), built in {:.1} ms",
            radial.bytes(),
            gpustar::solve::radial::BITS,
            radial.ring_rad.to_degrees() * 3600.0,
            radial.radius_rad.to_degrees(),
            t0.elapsed().as_secs_f64() * 1e3
        )?;
    }
    if let Some(sf) = &solver.scale_free {
        writeln!(
            out,
            "pattern index (the scale-free pass, first): {} quads of {} levels, {} in {:.1} ms",
            sf.index.keys.len(),
            sf.index.levels.len(),
            if sf.built { "built" } else { "read from cache" },
            sf.seconds * 1e3
        )?;
    }
    if solver.passes.is_empty() {
        writeln!(
            out,
            "scale walk: off (the searched range is wider than ±5 %; --fov-walk walks it)"
        )?;
    }
    print_all(&out)
}
