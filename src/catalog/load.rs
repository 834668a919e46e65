//! Where a catalog comes from: the built-in Hipparcos subset, a binary catalog file (mapped and
//! checked once per change), or CSV text.

use super::id::StarId;
use super::loaded::Catalog;
use super::star::{HIPPARCOS_EPOCH, Star, fnv1a};
use super::stars::Stars;
use super::{checked, formats, store, table};
use crate::error::{Context, Error, IntoKind, Result, error, fail};
use std::path::Path;
use std::sync::Arc;

/// The catalog compiled into the binary (Hipparcos-2, Hp ≤ 9.0).
pub const BUILTIN_CSV: &str = include_str!("../../catalog/hip2_hp9.csv");

/// Name of the compiled-in catalog, as `gpustar info` prints it.
pub const BUILTIN_NAME: &str = "builtin:hip2_hp9.csv";

/// [`BUILTIN_CSV`] as parsed at build time (`build.rs`): 44 bytes a star, little-endian, the
/// HIP number (u32) then ra_rad, dec_rad, pmra_mas_yr, pmdec_mas_yr and hp_mag (f64).
pub(super) const BUILTIN_STARS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/hip2_hp9.bin"));

/// The magnitude to which the built-in catalog holds nearly every star: Hipparcos is complete
/// to V 7.3–9.0 by galactic latitude and colour (ESA 1997, SP-1200 vol. 1). Its stars fainter
/// than this serve only fields that hold too few of the brighter ones
/// ([`Catalog::complete_mag`]).
pub const BUILTIN_COMPLETE_MAG: f64 = 8.0;

/// [`fnv1a`] of [`BUILTIN_CSV`], written down: hashing its 4 MB a byte at a time took an eighth
/// of a one-frame run (rustc refuses to compute it as a constant). A test checks it against the
/// file: a new catalog file needs the new value, which the test prints.
pub(super) const BUILTIN_HASH: u64 = 0x5423_0b16_ad9f_f372;

/// Bytes of a built-in star's record (build.rs): HIP (u32), then RA, Dec (rad), the proper
/// motions (mas/yr) and Hp (f64), little-endian.
const BUILTIN_RECORD: usize = 44;

/// The `k`-th f64 of a built-in record.
fn builtin_f64(b: &[u8], k: usize) -> f64 {
    f64::from_le_bytes(b[4 + 8 * k..12 + 8 * k].try_into().expect("8 bytes"))
}

/// The star of a built-in record.
fn builtin_star(b: &[u8]) -> Star {
    let hip = u32::from_le_bytes(b[..4].try_into().expect("4 bytes"));
    Star {
        id: StarId::Hip(hip),
        hip: Some(hip),
        ra_rad: builtin_f64(b, 0),
        dec_rad: builtin_f64(b, 1),
        pmra_mas_yr: builtin_f64(b, 2),
        pmdec_mas_yr: builtin_f64(b, 3),
        mag: builtin_f64(b, 4),
        epoch: HIPPARCOS_EPOCH,
    }
}

impl Catalog {
    /// The catalog compiled into the binary: [`BUILTIN_CSV`]'s stars, parsed at build time
    /// (parsing its text would take most of a one-frame run).
    ///
    /// Its records are parsed when something reads the stars whole: a run whose selection
    /// is cached reads only their magnitudes.
    pub fn builtin() -> Catalog {
        let stars = Stars::compiled(BUILTIN_STARS, BUILTIN_RECORD, builtin_star, |b| {
            builtin_f64(b, 4)
        });
        Catalog::of_stars(stars, Vec::new(), BUILTIN_NAME, BUILTIN_HASH)
            .complete_to(BUILTIN_COMPLETE_MAG)
    }

    /// The built-in catalog, or the file at `path` when given: a binary catalog file
    /// ([`store`], told by its magic number) or gpustar's catalog CSV.
    pub fn load(path: Option<&Path>) -> Result<Catalog> {
        Catalog::load_with(path, false)
    }

    /// [`Catalog::load`]; with `use_cache`, a binary catalog that passed its whole check in an
    /// earlier run and has not changed since (`checked`: a stamp in the cache directory) is
    /// mapped with only its header and tables checked.
    pub fn load_with(path: Option<&Path>, use_cache: bool) -> Result<Catalog> {
        match path {
            None => Ok(Catalog::builtin()),
            Some(p) => {
                let start = std::time::Instant::now();
                let source = p.display().to_string();
                // A binary catalog is mapped; anything else (text, a file that is not regular
                // or cannot be mapped) is read, and refused there with the reason.
                let map = crate::files::map_regular_file(p, "catalog")
                    .ok()
                    .filter(|m| store::is_store(m));
                if let Some(map) = map {
                    let dir = table::cache_dir().filter(|_| use_cache);
                    let before = dir.as_deref().is_some_and(|d| checked::passed(d, p));
                    let c = store::read_mapped(Arc::new(map), &source, before)?;
                    if let (Some(d), false) = (dir.as_deref(), before) {
                        checked::mark(d, p);
                    }
                    tracing::info!(
                        "{source}: {} stars loaded in {:.1} ms",
                        c.stars.len(),
                        start.elapsed().as_secs_f64() * 1e3
                    );
                    return Ok(c);
                }
                let bytes = crate::files::read_regular_file(p, "catalog")?;
                let text = String::from_utf8(bytes)
                    .into_kind(Error::Catalog)
                    .with_context(|| {
                        format!(
                            "{source}: neither a gpustar catalog file nor text (make one with \
                             `gpustar catalog import`)"
                        )
                    })?;
                Catalog::parse(&text, &source)
            }
        }
    }

    /// Parse gpustar's catalog CSV (`hip,ra_rad,dec_rad,pmra_mas_yr,pmdec_mas_yr,hp_mag`,
    /// `#` comment lines, one header line).
    pub fn parse(text: &str, source: &str) -> Result<Catalog> {
        Catalog::parse_counted(text, source).map(|(c, _)| c)
    }

    /// [`Catalog::parse`], with how many rows were left out of range (and warned of).
    pub(crate) fn parse_counted(text: &str, source: &str) -> Result<(Catalog, usize)> {
        let mut stars = Vec::new();
        let mut header_seen = false;
        let mut out_of_range = formats::Tally::default();
        for (n, line) in text.trim_start_matches('\u{feff}').lines().enumerate() {
            let line = line.trim();
            if line.is_empty() || line.starts_with('#') {
                continue;
            }
            if !header_seen {
                if !line.starts_with("hip,") {
                    fail!(
                        Catalog,
                        "{source}: line {}: expected the header 'hip,ra_rad,...'",
                        n + 1
                    );
                }
                header_seen = true;
                continue;
            }
            // Six fields, without a vector per line.
            let mut f = [""; 6];
            let mut count = 0;
            for field in line.split(',') {
                if let Some(slot) = f.get_mut(count) {
                    *slot = field;
                }
                count += 1;
            }
            if count != 6 {
                fail!(
                    Catalog,
                    "{source}: line {}: expected 6 fields, found {}",
                    n + 1,
                    count
                );
            }
            let num = |i: usize| -> Result<f64> {
                f[i].parse::<f64>().map_err(|e| {
                    error!(
                        Catalog,
                        "{source}: line {}: bad number {:?}: {e}",
                        n + 1,
                        f[i]
                    )
                })
            };
            let hip = f[0].parse::<u32>().map_err(|e| {
                error!(Catalog, "{source}: line {}: bad HIP {:?}: {e}", n + 1, f[0])
            })?;
            let mut star = Star {
                id: StarId::Hip(hip),
                hip: Some(hip),
                ra_rad: num(1)?,
                dec_rad: num(2)?,
                pmra_mas_yr: num(3)?,
                pmdec_mas_yr: num(4)?,
                mag: num(5)?,
                epoch: HIPPARCOS_EPOCH,
            };
            match formats::out_of_range(&mut star) {
                None => stars.push(star),
                Some(why) => out_of_range.add(n + 1, || why),
            }
        }
        out_of_range.warn(source, "line", formats::OUT_OF_RANGE);
        if stars.is_empty() {
            fail!(Catalog, "{source}: no stars");
        }
        let catalog = Catalog::new(stars, Vec::new(), source, fnv1a(text.as_bytes()));
        Ok((catalog, out_of_range.count))
    }
}
