//! The star catalog: stars (Hipparcos-2, Gaia DR3, Tycho-2 or a user's list), propagated to the
//! observation epoch, cut to the camera's limiting magnitude, with the double stars the camera
//! cannot separate handled.
//!
//! The repository ships `catalog/hip2_hp8.csv` (made by `gpustar catalog import`, see
//! [`import_hip2`]); it is compiled into the binary so `gpustar` works with no files beside it.
//! Other catalogs are imported ([`formats`]) into gpustar's binary catalog file ([`store`]),
//! which `--catalog` reads as it reads the CSV.

pub mod cells;
mod checked;
pub mod formats;
mod id;
mod import;
pub mod patterns;
mod ref_record;
mod refs_cache;
mod stars;
pub mod store;
pub mod table;
pub mod words;

pub use cells::{Cells, SkyIndex};
pub use id::StarId;
pub use import::import_hip2;
pub use refs_cache::{load_or_select, load_sorted_mags};
pub use stars::Stars;

use ref_record::RefRecord;
pub use words::Words;

use crate::error::{Context, Error, IntoKind, Result, error, fail};
use nalgebra::Vector3;
use std::path::Path;
use std::sync::{Arc, OnceLock};

/// The catalog compiled into the binary (Hipparcos-2, Hp ≤ 8.0).
pub const BUILTIN_CSV: &str = include_str!("../../catalog/hip2_hp8.csv");
/// Name of the compiled-in catalog, as `gpustar info` prints it.
pub const BUILTIN_NAME: &str = "builtin:hip2_hp8.csv";

/// [`BUILTIN_CSV`] as parsed at build time (`build.rs`): 44 bytes a star, little-endian, the
/// HIP number (u32) then ra_rad, dec_rad, pmra_mas_yr, pmdec_mas_yr and hp_mag (f64).
const BUILTIN_STARS: &[u8] = include_bytes!(concat!(env!("OUT_DIR"), "/hip2_hp8.bin"));

/// [`fnv1a`] of [`BUILTIN_CSV`], written down: hashing its 2 MB a byte at a time took an eighth
/// of a one-frame run (rustc refuses to compute it as a constant). A test checks it against the
/// file: a new catalog file needs the new value, which the test prints.
const BUILTIN_HASH: u64 = 0x3989_1ee3_075c_4bcc;

/// Epoch of the Hipparcos-2 positions (Julian year).
pub const HIPPARCOS_EPOCH: f64 = 1991.25;

const MAS_TO_RAD: f64 = std::f64::consts::PI / (180.0 * 3600.0 * 1000.0);

/// One catalog star as stored: ICRS position at its own epoch and proper motion.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Star {
    /// Its identity in the catalog it came from (records print it as `catalog_id`).
    pub id: StarId,
    /// Its Hipparcos number, where it has one (every Hipparcos star; Tycho-2 and Gaia stars
    /// that the catalog cross-identifies).
    pub hip: Option<u32>,
    /// Right ascension at `epoch`, radians.
    pub ra_rad: f64,
    /// Declination at `epoch`, radians.
    pub dec_rad: f64,
    /// Proper motion in RA·cos(Dec), mas/yr.
    pub pmra_mas_yr: f64,
    /// Proper motion in Dec, mas/yr.
    pub pmdec_mas_yr: f64,
    /// The catalog's own magnitude: Hp (Hipparcos), G (Gaia), V from BT/VT (Tycho-2), or a
    /// user catalog's.
    pub mag: f64,
    /// Julian year of the position (1991.25 for Hipparcos-2, 2016.0 for Gaia DR3).
    pub epoch: f64,
}

impl Star {
    /// Unit vector (ICRS) at `epoch` (Julian year), propagated from the star's own epoch
    /// linearly along the tangent plane and renormalised. Neglects radial velocity and
    /// parallax: for a few decades the error stays far below an arcsecond (it grows as
    /// (μ·Δt)²/2).
    pub fn vector_at(&self, epoch: f64) -> Vector3<f64> {
        self.vector_and_motion_at(epoch).0
    }

    /// [`Star::vector_at`] and [`Star::motion`] from one evaluation of the trigonometry (a
    /// catalog selection makes both for every star it keeps).
    pub fn vector_and_motion_at(&self, epoch: f64) -> (Vector3<f64>, Vector3<f64>) {
        let (sa, ca) = self.ra_rad.sin_cos();
        let (sd, cd) = self.dec_rad.sin_cos();
        let motion = Self::motion_from((sa, ca), (sd, cd), self.pmra_mas_yr, self.pmdec_mas_yr);
        let v = (Vector3::new(cd * ca, cd * sa, sd) + motion * (epoch - self.epoch)).normalize();
        (v, motion)
    }

    /// Unit vector (ICRS) at the star's own epoch.
    pub fn position(&self) -> Vector3<f64> {
        let (sa, ca) = self.ra_rad.sin_cos();
        let (sd, cd) = self.dec_rad.sin_cos();
        Vector3::new(cd * ca, cd * sa, sd)
    }

    /// Proper motion as a tangent vector of the unit sphere, radians per year.
    pub fn motion(&self) -> Vector3<f64> {
        let ra = self.ra_rad.sin_cos();
        let dec = self.dec_rad.sin_cos();
        Self::motion_from(ra, dec, self.pmra_mas_yr, self.pmdec_mas_yr)
    }

    fn motion_from(
        (sa, ca): (f64, f64),
        (sd, cd): (f64, f64),
        pmra_mas_yr: f64,
        pmdec_mas_yr: f64,
    ) -> Vector3<f64> {
        let e_ra = Vector3::new(-sa, ca, 0.0);
        let e_dec = Vector3::new(-sd * ca, -sd * sa, cd);
        (e_ra * pmra_mas_yr + e_dec * pmdec_mas_yr) * MAS_TO_RAD
    }
}

/// The full catalog as loaded (in the file's order: by HIP for the CSV, by sky cell for a
/// binary catalog file).
#[derive(Clone, Debug)]
pub struct Catalog {
    /// Shared by the catalog's clones (a solver keeps one for deeper selections); a binary
    /// catalog file's are parsed when first read ([`Stars`]).
    pub stars: Arc<Stars>,
    /// The ids of a user catalog ([`StarId::Name`] indexes them); empty otherwise.
    pub names: Arc<Vec<String>>,
    /// Where it came from (a path, or [`BUILTIN_NAME`]).
    pub source: String,
    /// FNV-1a hash of the text it was parsed from (of a binary file's header, which holds the
    /// checksum of the rest): part of the distance-table cache key.
    pub content_hash: u64,
    /// The stars by sky cell: read from a binary file, built on the first cone query otherwise.
    index: Arc<OnceLock<SkyIndex>>,
    /// The stars' magnitudes in ascending order, sorted on first use.
    mags: Arc<OnceLock<Vec<f64>>>,
}

impl Catalog {
    /// The catalog compiled into the binary: [`BUILTIN_CSV`]'s stars, parsed at build time
    /// (parsing its text took a third of a one-frame run).
    pub fn builtin() -> Catalog {
        let f64_at =
            |b: &[u8], k: usize| f64::from_le_bytes(b[4 + 8 * k..12 + 8 * k].try_into().unwrap());
        let stars = BUILTIN_STARS
            .chunks_exact(44)
            .map(|b| {
                let hip = u32::from_le_bytes(b[..4].try_into().unwrap());
                Star {
                    id: StarId::Hip(hip),
                    hip: Some(hip),
                    ra_rad: f64_at(b, 0),
                    dec_rad: f64_at(b, 1),
                    pmra_mas_yr: f64_at(b, 2),
                    pmdec_mas_yr: f64_at(b, 3),
                    mag: f64_at(b, 4),
                    epoch: HIPPARCOS_EPOCH,
                }
            })
            .collect();
        Catalog::new(stars, Vec::new(), BUILTIN_NAME, BUILTIN_HASH)
    }

    /// A catalog of these stars; the sky index is built when first needed.
    pub fn new(stars: Vec<Star>, names: Vec<String>, source: &str, content_hash: u64) -> Catalog {
        Catalog::of_stars(stars.into(), names, source, content_hash)
    }

    fn of_stars(stars: Stars, names: Vec<String>, source: &str, content_hash: u64) -> Catalog {
        Catalog {
            stars: Arc::new(stars),
            names: Arc::new(names),
            source: source.to_string(),
            content_hash,
            index: Arc::default(),
            mags: Arc::default(),
        }
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

    /// The sky index (cells of about equal area), built now if the catalog has none yet.
    pub fn index(&self) -> &SkyIndex {
        self.index.get_or_init(|| {
            SkyIndex::build(
                Cells::for_stars(self.stars.len()),
                self.stars.iter().map(|s| (s.ra_rad, s.dec_rad)),
            )
        })
    }

    /// The magnitude of the `n`-th brightest star (`n` from 1, clamped to the catalog; NaN
    /// for an empty catalog). The faintest needs no sort: a narrow field's automatic limit
    /// takes every star, and sorting Tycho-2's 1.9 million magnitudes for it took 35 ms a run.
    pub fn mag_of_rank(&self, n: usize) -> f64 {
        let len = self.stars.len();
        if len == 0 {
            return f64::NAN;
        }
        let n = n.clamp(1, len);
        match self.mags.get() {
            None if n == len => ((0..len).map(|i| self.stars.mag(i)))
                .max_by(f64::total_cmp)
                .unwrap_or(f64::NAN),
            _ => self.sorted_mags()[n - 1],
        }
    }

    /// The stars' magnitudes, brightest first. Sorted once: the automatic magnitude limit
    /// reads it for every frame whose focal length was fitted (a field searched in scale).
    pub fn sorted_mags(&self) -> &[f64] {
        self.mags.get_or_init(|| {
            let mut mags: Vec<f64> = (0..self.stars.len()).map(|i| self.stars.mag(i)).collect();
            // Unstable: under a total order equal values are the same bits, so the result is
            // the stable sort's, in about half the time.
            mags.sort_unstable_by(f64::total_cmp);
            mags
        })
    }

    /// The stars at `indices` as a catalog of their own (a hinted region's), sharing the names.
    pub fn subset(&self, indices: &[u32], source: &str) -> Catalog {
        Catalog {
            stars: Arc::new(indices.iter().map(|&i| self.stars[i as usize]).collect()),
            names: self.names.clone(),
            source: source.to_string(),
            content_hash: 0,
            index: Arc::default(),
            mags: Arc::default(),
        }
    }

    /// Use `index` (read from a file) as the catalog's sky index.
    pub(crate) fn with_index(self, index: SkyIndex) -> Catalog {
        let cell = OnceLock::new();
        let _ = cell.set(index);
        Catalog {
            index: Arc::new(cell),
            ..self
        }
    }

    /// Indices into `stars` of every star within `radius_rad` of `centre` (a unit vector,
    /// ICRS), ascending. Exact: positions at the stars' own epochs, compared as unit vectors
    /// (angle ≤ radius); for another epoch widen the radius by the fastest proper motion
    /// times the years between.
    pub fn cone(&self, centre: &Vector3<f64>, radius_rad: f64) -> Vec<u32> {
        let index = self.index();
        let centre = centre.normalize();
        let cos_r = radius_rad.min(std::f64::consts::PI).cos();
        let mut out = Vec::new();
        for c in index.cells.cone_cells(&centre, radius_rad) {
            let (a, b) = (index.starts[c as usize], index.starts[c as usize + 1]);
            for &i in &index.order[a as usize..b as usize] {
                if self.stars[i as usize].position().dot(&centre) >= cos_r {
                    out.push(i);
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// The id of star `i` as records print it (`catalog_id`).
    pub fn catalog_id(&self, i: usize) -> String {
        self.stars[i].id.display(&self.names)
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

    /// Faintest magnitude in the catalog.
    pub fn faintest(&self) -> f64 {
        self.stars.iter().map(|s| s.mag).fold(f64::MIN, f64::max)
    }
}

/// How stars closer together than the camera can separate are treated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum DoubleStars {
    /// Replace the group by one star at its flux-weighted photocentre with the summed flux:
    /// that is what the detector sees (one blob), so the pair still serves identification.
    Merge,
    /// Remove every star of the group (seed 000's choice).
    Drop,
    /// Keep them as they are.
    Keep,
}

/// What a run selects from the catalog.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Selection {
    /// Julian year of the observation.
    pub epoch: f64,
    /// Faintest magnitude kept, in the catalog's own band (Hp, G, V).
    pub mag_limit: f64,
    pub double_stars: DoubleStars,
    /// Separation below which two stars count as one for the camera, radians.
    pub double_sep_rad: f64,
}

/// A catalog star ready for matching: index = its id in the distance table.
#[derive(Clone, Copy, Debug)]
pub struct RefStar {
    /// Catalog id of the star, or of the brightest star of a merged group.
    pub id: StarId,
    /// HIP of that same star, where it has one.
    pub hip: Option<u32>,
    /// ICRS unit vector at the selection's epoch.
    pub v: Vector3<f64>,
    /// Proper motion, radians per year along the sphere (flux-weighted for a merged group):
    /// moves `v` to a frame's own epoch (see [`RefCatalog::at_epoch`]).
    pub motion: Vector3<f64>,
    pub mag: f64,
    /// Number of catalog stars merged into this one (1 for a single star).
    pub members: u32,
}

/// The stars a run matches against, brightest first; a star's index is its 32-bit id in the
/// distance table. Positions are read at `selection.epoch` ([`RefCatalog::v`],
/// [`RefCatalog::star`]): a catalog moved to a frame's own date shares the stars and moves
/// each by its proper motion when read.
#[derive(Clone, Debug)]
pub struct RefCatalog {
    /// The stars at `stars_epoch`: made by [`RefCatalog::select`], or mapped from the cache
    /// file of an earlier run's selection ([`load_or_select`]).
    stars: Arc<Words<RefRecord>>,
    /// The epoch `stars` hold positions for (Julian year).
    stars_epoch: f64,
    /// The largest proper motion of any star (radians per year): how far a move of a year
    /// takes any star at most, for cone tests on the stored positions ([`RefCatalog::within`]).
    max_motion: f64,
    pub selection: Selection,
    /// Stars the double-star rule merged away or dropped.
    pub doubles_removed: usize,
    /// The catalog's user ids ([`Catalog::names`]), for [`RefCatalog::catalog_id`].
    pub names: Arc<Vec<String>>,
    /// The stored positions' cone searches, for [`RefCatalog::within`]; shared, as the stars
    /// are, by the catalog at other epochs.
    cones: Arc<cells::ConeIndex>,
}

/// The largest number of stars a reference catalog may hold: ids are 32-bit.
pub const MAX_REF_STARS: usize = u32::MAX as usize;

impl RefCatalog {
    /// Select stars at or brighter than the magnitude limit, propagate them, and apply the
    /// double-star rule.
    pub fn select(catalog: &Catalog, selection: Selection) -> Result<RefCatalog> {
        let mut stars: Vec<RefStar> = catalog
            .stars
            .iter()
            .filter(|s| s.mag <= selection.mag_limit)
            .map(|s| {
                let (v, motion) = s.vector_and_motion_at(selection.epoch);
                RefStar {
                    id: s.id,
                    hip: s.hip,
                    v,
                    motion,
                    mag: s.mag,
                    members: 1,
                }
            })
            .collect();
        let before = stars.len();
        if selection.double_stars != DoubleStars::Keep && selection.double_sep_rad > 0.0 {
            stars = resolve_doubles(&stars, selection);
        }
        let doubles_removed = before - stars.len();
        // Brightest first, ties by id (HIP for Hipparcos): an order that does not depend on
        // the file.
        // The order is found on (mag, id, place) keys, not by moving the 88-byte stars.
        let mut order: Vec<(f64, StarId, usize)> = (stars.iter().enumerate())
            .map(|(k, s)| (s.mag, s.id, k))
            .collect();
        // The place breaks ties: a total order, so the unstable sort gives the stable one's.
        order.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let stars: Vec<RefRecord> = order.iter().map(|o| RefRecord::of(&stars[o.2])).collect();
        if stars.len() > MAX_REF_STARS {
            fail!(
                Catalog,
                "{} catalog stars are brighter than magnitude {}: at most {} fit the distance \
                 table's 32-bit ids; lower --mag-limit",
                stars.len(),
                selection.mag_limit,
                MAX_REF_STARS
            );
        }
        if stars.len() < 3 {
            fail!(
                Catalog,
                "only {} catalog stars are brighter than magnitude {}; raise --mag-limit",
                stars.len(),
                selection.mag_limit
            );
        }
        Ok(RefCatalog {
            max_motion: (stars.iter())
                .map(|s| Vector3::from(s.motion).norm())
                .fold(0.0, f64::max),
            stars: Arc::new(stars.into()),
            stars_epoch: selection.epoch,
            selection,
            doubles_removed,
            names: catalog.names.clone(),
            cones: Arc::default(),
        })
    }

    /// The same stars (same ids) at another epoch: for a frame that carries its own date (FITS
    /// DATE-OBS) while the distance table was made for the run's epoch. Pair distances change
    /// by far less than the vote's tolerance over decades; positions do not. The stars are
    /// shared, not copied: a frame reads only the positions it needs, where a moved copy of
    /// every star for each date was a tenth of a sparse 10° run (docs/speed.md).
    pub fn at_epoch(&self, epoch: f64) -> RefCatalog {
        RefCatalog {
            selection: Selection {
                epoch,
                ..self.selection
            },
            ..self.clone()
        }
    }

    /// Years from the stored positions to `selection.epoch`.
    fn dt(&self) -> f64 {
        self.selection.epoch - self.stars_epoch
    }

    /// The ICRS unit vector of star `id` at `selection.epoch`.
    #[inline]
    pub fn v(&self, id: usize) -> Vector3<f64> {
        let s = &self.stars[id];
        let dt = self.dt();
        if dt == 0.0 {
            s.v.into()
        } else {
            (Vector3::from(s.v) + Vector3::from(s.motion) * dt).normalize()
        }
    }

    /// Star `id` with its position at `selection.epoch`.
    pub fn star(&self, id: usize) -> RefStar {
        RefStar {
            v: self.v(id),
            ..self.stars[id].star()
        }
    }

    /// Every star, in id order, with its position at `selection.epoch`.
    pub fn stars(&self) -> impl ExactSizeIterator<Item = RefStar> + '_ {
        (0..self.len()).map(|id| self.star(id))
    }

    /// The ids, rising, of the stars within `reach` radians of the unit vector `axis` at
    /// `selection.epoch`: those with `v(id) · axis >= reach.cos()`. The stored positions are
    /// searched first ([`cells::ConeIndex`]) with the reach widened by how far the stars can
    /// have moved, so only the few near the axis are moved.
    pub fn within(&self, axis: &Vector3<f64>, reach: f64) -> Vec<u32> {
        // A move of |motion · dt| turns a star by at most that angle; a microradian more
        // covers rounding, so the stars kept first are a superset of those within the reach.
        let dt = self.dt();
        let margin = if dt == 0.0 {
            0.0
        } else {
            self.max_motion * dt.abs() + 1e-6
        };
        let near = self.cones.cone(
            self.stars.len(),
            |id| self.stars[id].v.into(),
            axis,
            reach + margin,
        );
        let cos_reach = reach.cos();
        (near.into_iter())
            .filter(|&id| self.v(id as usize).dot(axis) >= cos_reach)
            .collect()
    }

    /// The catalog id of reference star `ref_id` as records print it (`catalog_id`).
    pub fn catalog_id(&self, ref_id: usize) -> String {
        self.stars[ref_id].star().id.display(&self.names)
    }

    pub fn len(&self) -> usize {
        self.stars.len()
    }

    pub fn is_empty(&self) -> bool {
        self.stars.is_empty()
    }
}

/// Group stars closer than `double_sep_rad` (transitively) and merge or drop each group.
fn resolve_doubles(stars: &[RefStar], selection: Selection) -> Vec<RefStar> {
    let n = stars.len();
    let chord_max = 2.0 * (selection.double_sep_rad / 2.0).sin();
    // Sort by z so that neighbours are found in a narrow z band: chord ≥ |Δz|. The keys sit
    // beside the indices (ties in index order), not read through them.
    let mut by_z: Vec<(f64, usize)> = stars.iter().map(|s| s.v.z).zip(0..n).collect();
    by_z.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(parent: &mut [usize], mut i: usize) -> usize {
        while parent[i] != i {
            parent[i] = parent[parent[i]];
            i = parent[i];
        }
        i
    }
    for (k, &(za, a)) in by_z.iter().enumerate() {
        for &(zb, b) in &by_z[k + 1..] {
            if zb - za > chord_max {
                break;
            }
            if (stars[a].v - stars[b].v).norm() < chord_max {
                let (ra, rb) = (find(&mut parent, a), find(&mut parent, b));
                if ra != rb {
                    parent[ra.max(rb)] = ra.min(rb);
                }
            }
        }
    }
    // Each group under its root, the least index of its members (unions keep the lesser
    // root): groups in the order of their first member, members rising.
    let mut groups: Vec<Vec<usize>> = vec![Vec::new(); n];
    for i in 0..n {
        let r = find(&mut parent, i);
        groups[r].push(i);
    }
    let mut out = Vec::with_capacity(n);
    for members in groups.iter().filter(|g| !g.is_empty()) {
        if members.len() == 1 {
            out.push(stars[members[0]]);
            continue;
        }
        if selection.double_stars == DoubleStars::Drop {
            continue;
        }
        let flux = |s: &RefStar| 10f64.powf(-0.4 * s.mag);
        let total: f64 = members.iter().map(|&i| flux(&stars[i])).sum();
        let centre: Vector3<f64> = members
            .iter()
            .map(|&i| stars[i].v * flux(&stars[i]))
            .sum::<Vector3<f64>>()
            .normalize();
        let brightest = members
            .iter()
            .copied()
            .min_by(|&a, &b| stars[a].mag.total_cmp(&stars[b].mag))
            .unwrap();
        let motion = members
            .iter()
            .map(|&i| stars[i].motion * flux(&stars[i]))
            .sum::<Vector3<f64>>()
            / total;
        out.push(RefStar {
            id: stars[brightest].id,
            hip: stars[brightest].hip,
            v: centre,
            motion,
            mag: -2.5 * total.log10(),
            members: members.len() as u32,
        });
    }
    out
}

/// What a cache made from the selection `cat` depends on, as the text its key hashes: the
/// catalog's content hash and the selection (the distance table and the pattern index add
/// their own parts around it).
pub(crate) fn selection_key_text(cat: &RefCatalog, catalog_hash: u64) -> String {
    selection_text(&cat.selection, catalog_hash)
}

fn selection_text(s: &Selection, catalog_hash: u64) -> String {
    format!(
        "{:016x}|{}|{}|{:?}|{}",
        catalog_hash, s.epoch, s.mag_limit, s.double_stars, s.double_sep_rad
    )
}

/// 64-bit FNV-1a: a stable hash for cache keys (std's hasher may change between releases).
pub fn fnv1a(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Unit vector of (RA, Dec) in degrees.
pub fn radec_to_vector(ra_deg: f64, dec_deg: f64) -> Vector3<f64> {
    let (sa, ca) = ra_deg.to_radians().sin_cos();
    let (sd, cd) = dec_deg.to_radians().sin_cos();
    Vector3::new(cd * ca, cd * sa, sd)
}

/// (RA in [0, 360), Dec) in degrees of a unit vector.
pub fn vector_to_radec(v: &Vector3<f64>) -> (f64, f64) {
    let ra = v.y.atan2(v.x).to_degrees().rem_euclid(360.0);
    let dec = v.z.clamp(-1.0, 1.0).asin().to_degrees();
    (ra, dec)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The built-in catalog, as `build.rs` parsed it, is its file's, star by star.
    #[test]
    fn the_builtin_stars_are_the_file_s() {
        let parsed = Catalog::parse(BUILTIN_CSV, BUILTIN_NAME).unwrap();
        let built = Catalog::builtin();
        assert_eq!(built.stars.len(), parsed.stars.len());
        assert!(built.stars.len() > 37_000);
        assert!(
            built.stars == parsed.stars,
            "build.rs parses the CSV as Catalog::parse"
        );
        assert_eq!(
            (built.source, built.content_hash),
            (parsed.source, parsed.content_hash)
        );
    }

    /// `within` keeps exactly the stars whose position at the catalog's epoch is within the
    /// reach, however far the epoch is from the stored positions' (centuries here, so that the
    /// fastest stars cross the cone's edge), as at the stored epoch.
    #[test]
    fn within_is_the_cone_at_the_epoch() {
        let selection = Selection {
            epoch: 2000.0,
            mag_limit: 6.5,
            double_stars: DoubleStars::Keep,
            double_sep_rad: 0.0,
        };
        let refs = RefCatalog::select(&Catalog::builtin(), selection).unwrap();
        // Axes on the fastest stars (their moves decide the edge), and elsewhere.
        let mut fastest: Vec<usize> = (0..refs.len()).collect();
        fastest.sort_by(|&a, &b| {
            Vector3::from(refs.stars[b].motion)
                .norm()
                .total_cmp(&Vector3::from(refs.stars[a].motion).norm())
        });
        // The scans first, then the cells (indexed after SCANS_BEFORE_INDEX searches; the
        // catalog at each epoch shares the index).
        let mut zoned = 0;
        for epoch in [2000.0, 1500.0, 2026.9, 2600.0] {
            let at = refs.at_epoch(epoch);
            for (k, &star) in fastest[..6].iter().enumerate() {
                let axis = if k % 2 == 0 {
                    refs.stars[star].v.into()
                } else {
                    Vector3::new(1.0, k as f64, -2.0).normalize()
                };
                for reach in [0.0, 1e-4, 0.01, 0.2, 1.5, 3.1, std::f64::consts::PI] {
                    let definition: Vec<u32> = (0..at.len())
                        .filter(|&id| at.v(id).dot(&axis) >= reach.cos())
                        .map(|id| id as u32)
                        .collect();
                    zoned += usize::from(at.cones.indexed());
                    assert_eq!(at.within(&axis, reach), definition, "{epoch} {k} {reach}");
                }
            }
        }
        // 4 epochs × 6 axes × 7 reaches: all but the scans and the search that made them.
        assert_eq!(zoned, 4 * 6 * 7 - cells::SCANS_BEFORE_INDEX as usize - 1);
    }

    /// A magnitude's rank is the sorted magnitudes' (the faintest found before they are
    /// sorted, the others after).
    #[test]
    fn ranks_are_the_sorted_magnitudes() {
        let sorted = Catalog::builtin().sorted_mags().to_vec();
        let c = Catalog::builtin();
        let len = sorted.len();
        for n in [len + 9, len, 0, 1, 2, 17, len / 2, len - 1, len] {
            let want = sorted[n.clamp(1, len) - 1];
            assert_eq!(c.mag_of_rank(n).to_bits(), want.to_bits(), "rank {n}");
        }
        assert!(
            Catalog::new(Vec::new(), Vec::new(), "e", 0)
                .mag_of_rank(1)
                .is_nan()
        );
    }

    /// The built-in catalog's hash is its file's (cache keys depend on it).
    #[test]
    fn the_builtin_hash_is_the_file_s() {
        let hash = fnv1a(BUILTIN_CSV.as_bytes());
        assert_eq!(
            BUILTIN_HASH, hash,
            "catalog/hip2_hp8.csv changed: set BUILTIN_HASH to {hash:#018x}"
        );
    }
}
