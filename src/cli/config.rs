//! The options as the library's run configuration (`gpustar::config::RunConfig`): the command
//! line's options over a `--config` file's.

use super::args::{CameraOpts, CatalogOpts, RunArgs, SolveOpts};
use anyhow::Context;
use gpustar::config::RunConfig;

/// The catalog options (`calibrate`'s) as a run configuration, the others at their defaults.
pub(crate) fn catalog_config(o: &CatalogOpts) -> anyhow::Result<RunConfig> {
    let cfg = RunConfig {
        catalog: o.catalog.clone(),
        epoch: o.epoch,
        mag_limit: o.mag_limit,
        double_stars: o.double_stars,
        double_star_px: o.double_star_px,
        no_cache: o.no_cache,
        ..RunConfig::default()
    };
    cfg.validate()?;
    Ok(cfg)
}

/// The camera and catalog options (`info`'s) as a run configuration.
pub(crate) fn camera_config(c: &CameraOpts, o: &CatalogOpts) -> anyhow::Result<RunConfig> {
    let cfg = RunConfig {
        camera: c.camera.clone(),
        fov_deg: c.fov_deg,
        scale_arcsec: c.scale_arcsec,
        pixel_aspect: c.pixel_aspect,
        fov_tolerance: c.fov_tolerance,
        fov_walk: c.fov_walk,
        fit: c.fit,
        parity: c.parity,
        ..catalog_config(o)?
    };
    cfg.validate()?;
    Ok(cfg)
}

/// Options that stand for one another: one given on the command line takes the others out of
/// a --config file.
const ALTERNATIVES: [&[&str]; 2] = [
    &["camera", "fov_deg", "scale_arcsec"],
    &["dark", "dark_median"],
];

/// The run's configuration: the command line's options, over a --config file's where the
/// command line does not give them (`given`: the options it gives).
pub(crate) fn run_config(
    o: &SolveOpts,
    b: &RunArgs,
    given: &[String],
) -> anyhow::Result<RunConfig> {
    let so = &o.streaks;
    let cli = RunConfig {
        hint: o.hint.clone(),
        sigma: o.sigma,
        detect_filter: o.detect_filter,
        centroid: o.centroid,
        method: o.method,
        vote_stars: o.vote_stars,
        pair_tol_px: o.pair_tol_px,
        no_retry: o.no_retry,
        wide_min_stars: o.wide_min_stars,
        scale_tol: o.scale_tol,
        match_radius_px: o.match_radius_px,
        max_false_prob: o.max_false_prob,
        dark: o.dark.clone(),
        dark_median: o.dark_median,
        xyls: o.xyls,
        image_size: o.image_size,
        backend: o.backend,
        batch_size: o.batch_size,
        max_megapixels: o.max_megapixels,
        sequence: b.sequence,
        frame_interval: b.frame_interval,
        streaks: so.streaks,
        station: so.station.clone(),
        astrometry: so.astrometry,
        dut1: so.dut1,
        streak_sigma: so.streak_sigma,
        tle: so.tle.clone(),
        tle_cross: so.tle_cross,
        tle_along: so.tle_along,
        ..camera_config(&o.camera, &o.catalog)?
    };
    let Some(path) = &o.config else {
        cli.validate()?;
        return Ok(cli);
    };
    let text = gpustar::files::read_regular_text(path, "the --config file")?;
    RunConfig::from_toml(&text, path)?;
    let mut merged: toml::Table = toml::from_str(&text)?;
    let ours = toml::Table::try_from(&cli)?;
    for group in ALTERNATIVES {
        if group.iter().any(|k| given.iter().any(|g| g == k)) {
            for k in group {
                merged.remove(*k);
            }
        }
    }
    for (k, v) in ours {
        if given.contains(&k) || !merged.contains_key(&k) {
            merged.insert(k, v);
        }
    }
    let cfg: RunConfig = merged
        .try_into()
        .with_context(|| format!("{} with the command line's options", path.display()))?;
    cfg.validate()?;
    Ok(cfg)
}
