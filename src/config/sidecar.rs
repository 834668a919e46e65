//! The configuration a run used, kept beside its records: `OUTPUT.run.toml` holds gpustar's
//! version, the catalog's identity and the [`RunConfig`]. `--resume` reads it back and refuses
//! to go on with another configuration or catalog, whose records would not be the same run's.
//! The file is written whole (`io::guard`), and one that gpustar did not write is not replaced.

use super::RunConfig;
use crate::catalog::Catalog;
use crate::error::{Context, Error, Result};
use crate::io::guard::{self, Kind, RUN_CONFIG_MARK};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// What a run's sidecar holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    /// The version of gpustar that wrote the records.
    pub gpustar: String,
    pub catalog: CatalogId,
    pub config: RunConfig,
}

/// Which catalog a run used.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CatalogId {
    /// Where it came from: a path, or the built-in catalog's name.
    pub source: String,
    /// Its content hash (hexadecimal; the distance tables' cache key).
    pub content_hash: String,
    pub stars: usize,
}

impl Sidecar {
    /// This gpustar's sidecar for a run of `config` over `catalog`.
    pub fn new(config: &RunConfig, catalog: &Catalog) -> Sidecar {
        Sidecar {
            gpustar: env!("CARGO_PKG_VERSION").to_string(),
            catalog: CatalogId {
                source: catalog.source.clone(),
                content_hash: format!("{:016x}", catalog.content_hash),
                stars: catalog.stars.len(),
            },
            config: config.clone(),
        }
    }

    /// The file's text: the mark, then TOML.
    pub fn to_text(&self) -> Result<String> {
        let body = toml::to_string(self)
            .map_err(|e| Error::Config(format!("cannot write the run configuration: {e}")))?;
        Ok(format!(
            "{RUN_CONFIG_MARK}: the options of the run whose records are beside it (--resume \
             compares them).\n{body}"
        ))
    }
}

/// Where the sidecar of the records at `output` goes: `OUTPUT.run.toml`.
pub fn path_for(output: &Path) -> PathBuf {
    let mut name = output.as_os_str().to_owned();
    name.push(".run.toml");
    PathBuf::from(name)
}

/// Refuse, before a run, a sidecar path that holds a file gpustar did not write.
pub fn check(output: &Path) -> Result<()> {
    guard::check_replaceable(&path_for(output), Kind::RunConfig, false)
}

/// Write the sidecar of the records at `output`, whole.
pub fn write(output: &Path, s: &Sidecar) -> Result<()> {
    guard::write_atomically(&path_for(output), s.to_text()?.as_bytes())
}

/// The sidecar of the records at `output`, None when there is none (records written before
/// gpustar kept one).
pub fn read(output: &Path) -> Result<Option<Sidecar>> {
    let path = path_for(output);
    let text = match std::fs::read_to_string(&path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", path.display())),
    };
    toml::from_str(&text).map(Some).map_err(|e| {
        Error::Config(format!(
            "{}: not a run configuration gpustar can read ({})",
            path.display(),
            e.message()
        ))
    })
}

/// `--resume`: the run `now` may go on with the records at `output` only when their sidecar
/// names the same configuration (less what cannot change a record) and catalog. Another
/// version of gpustar is allowed (the records say which wrote them), and so are records
/// without a sidecar.
pub fn check_resume(output: &Path, now: &Sidecar) -> Result<Option<String>> {
    let Some(then) = read(output)? else {
        return Ok(None);
    };
    let mut why = now.config.differences(&then.config);
    if then.catalog != now.catalog {
        why.push(format!(
            "catalog: {} ({} stars, {}) then, {} ({} stars, {}) now",
            then.catalog.source,
            then.catalog.stars,
            then.catalog.content_hash,
            now.catalog.source,
            now.catalog.stars,
            now.catalog.content_hash
        ));
    }
    if !why.is_empty() {
        return Err(Error::Config(format!(
            "--resume: {} was written with another configuration ({}): the records would not be \
             one run's; run again with those options, or write to another -o",
            output.display(),
            why.join("; ")
        )));
    }
    Ok((then.gpustar != now.gpustar).then(|| {
        format!(
            "{} was begun by gpustar {}; this is {}",
            output.display(),
            then.gpustar,
            now.gpustar
        )
    }))
}
