//! The pattern index of the scale-free first pass (`solve/scale_free.rs`): quads of bright
//! reference stars keyed by their sorted edge ratios, which do not depend on the focal length,
//! so that a frame of unknown field of view is looked up once instead of voted at every scale.
//!
//! Catalog side (tetra3's idea, our own layout): for each level, a field diameter `D`, the sky
//! is covered by disc centres about `D / OVERSAMPLE` apart (a Fibonacci lattice); each disc of
//! diameter `D` gives every quad of its [`FIELD_STARS`] brightest stars. Levels step down by
//! [`LEVEL_RATIO`] from the shortest side of the widest field to below that of the narrowest,
//! so a frame of any field in the range holds a disc of some level whose brightest stars are
//! among the frame's brightest. The quads are stored as a sorted u32 key array (binary
//! searched: GPU-friendly, like the distance table) with the four star ids of each.
//!
//! Keys: the six chords sorted, the five smaller divided by the largest, each quantised into
//! [`BINS`] bins, packed 6 bits each: `key = Σ bin_i << (6 i)`. Made in f64 on the CPU.

use crate::catalog::table::{CacheReader, write_cache};
use crate::catalog::{RefCatalog, Words};
use crate::error::{Error, IntoKind, Result, fail};
use nalgebra::Vector3;
use std::path::Path;
use std::time::Instant;

/// Bins per edge ratio (6 bits each; five ratios make a 30-bit key).
pub const BINS: u32 = 64;

/// Brightest stars of a disc that form its quads (70 quads).
pub const FIELD_STARS: usize = 8;

/// Disc centres per disc diameter along the sky: neighbouring discs overlap by two thirds, so
/// a frame's field holds one close to its own centre.
pub const OVERSAMPLE: f64 = 3.0;

/// Ratio of the disc diameters of neighbouring levels.
pub const LEVEL_RATIO: f64 = 1.5;

/// The largest key (five ratios of [`BINS`] bins).
pub const MAX_KEY: u32 = (1 << 30) - 1;

/// The sorted pattern keys and their quads.
#[derive(Clone, Debug, PartialEq)]
pub struct PatternIndex {
    /// Keys, ascending.
    pub keys: Words<u32>,
    /// The four reference-star ids of each key, ascending.
    pub quads: Words<[u32; 4]>,
    /// Disc diameters (radians), widest first.
    pub levels: Vec<f64>,
}

/// The six chords of four directions, in the order (0,1), (0,2), (0,3), (1,2), (1,3), (2,3).
pub fn chords(v: &[Vector3<f64>; 4]) -> [f64; 6] {
    QUAD_EDGES.map(|(i, j)| chord(&v[i], &v[j]))
}

/// A quad's edges as pairs of its corners, in the order of [`chords`].
pub const QUAD_EDGES: [(usize, usize); 6] = [(0, 1), (0, 2), (0, 3), (1, 2), (1, 3), (2, 3)];

/// The chord between two directions.
#[inline]
pub fn chord(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    (a - b).norm()
}

/// The five edge ratios of six edge lengths: the sorted smaller five over the largest (0 for
/// a degenerate quad).
pub fn ratios(edges: &[f64; 6]) -> [f64; 5] {
    let mut s = *edges;
    s.sort_by(f64::total_cmp);
    let mut r = [0.0; 5];
    if s[5] > 0.0 {
        for i in 0..5 {
            r[i] = s[i] / s[5];
        }
    }
    r
}

/// The bin of a ratio in [0, 1].
pub fn bin(r: f64) -> u32 {
    ((r * BINS as f64).floor()).clamp(0.0, (BINS - 1) as f64) as u32
}

/// The key of five bins.
pub fn key_of(bins: &[u32; 5]) -> u32 {
    bins.iter()
        .enumerate()
        .fold(0, |k, (i, &b)| k | (b.min(BINS - 1) << (6 * i)))
}

/// The key of a quad's directions.
pub fn pattern_key(v: &[Vector3<f64>; 4]) -> u32 {
    let r = ratios(&chords(v));
    key_of(&r.map(bin))
}

/// The disc diameters for frames whose shortest side spans `narrowest..=widest` radians:
/// from `widest` down by [`LEVEL_RATIO`] to the first at or below `narrowest`, so every field
/// in the range has a level within a factor [`LEVEL_RATIO`] below it.
pub fn levels_for(narrowest: f64, widest: f64) -> Vec<f64> {
    let (lo, hi) = (narrowest.min(widest), narrowest.max(widest));
    let mut out = vec![hi];
    while *out.last().expect("one level") > lo && out.len() < 16 {
        out.push(out.last().expect("one level") / LEVEL_RATIO);
    }
    out
}

/// Point `i` of `n` spread evenly over the unit sphere (a Fibonacci lattice), from +z down.
fn lattice_point(i: usize, n: usize) -> Vector3<f64> {
    let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
    let z = 1.0 - (2.0 * i as f64 + 1.0) / n as f64;
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = golden * i as f64;
    Vector3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Disc centres of a level of diameter `d` (radians): one per `(d / OVERSAMPLE)²` of sphere.
pub fn discs_of(d: f64) -> f64 {
    let spacing = d / OVERSAMPLE;
    (4.0 * std::f64::consts::PI / (spacing * spacing))
        .ceil()
        .max(12.0)
}

/// The most disc centres an index visits, all levels together: beyond, a frame's field is
/// too narrow for a pattern index of this sky (a blind 0.01° field over the whole sky would
/// take 4·10⁹ of them and 89 GB).
pub const MAX_DISCS: f64 = 64.0e6;

/// The largest index gpustar builds (bytes of keys and quads, before duplicates go).
pub const MAX_INDEX_BYTES: f64 = 4.0 * (1u64 << 30) as f64;

/// What an index of `levels` over `cat` (whose stars cover `sky_sr` steradians) would take:
/// the disc centres visited and the bytes of its patterns, at most [`FIELD_STARS`]'s quads
/// per disc, fewer where the discs hold fewer stars on average.
pub fn estimate(cat: &RefCatalog, levels: &[f64], sky_sr: f64) -> (f64, f64) {
    let n = cat.len() as f64;
    let (mut discs, mut bytes) = (0.0, 0.0);
    let region = Region::of(cat);
    for &d in levels {
        let all = discs_of(d);
        let visited = all * region.share(d);
        let per_disc = n * std::f64::consts::PI * (d / 2.0).powi(2) / sky_sr.max(1e-12);
        let m = per_disc.min(FIELD_STARS as f64).floor();
        let quads = if m >= 4.0 {
            m * (m - 1.0) * (m - 2.0) * (m - 3.0) / 24.0
        } else {
            0.0
        };
        discs += visited;
        bytes += visited * quads * 20.0;
    }
    (discs, bytes)
}

/// The cap of sky a catalog's stars lie in (its centre and radius), for a region's catalog
/// (a pointing hint's): the lattice is then turned to put the cap about its first points, and
/// only those are visited. The whole sky (radius π) for a catalog spread wider than a
/// hemisphere, or none.
struct Region {
    /// Rotation taking the cap's centre to +z.
    to_pole: nalgebra::Rotation3<f64>,
    radius: f64,
}

impl Region {
    fn of(cat: &RefCatalog) -> Region {
        let whole = Region {
            to_pole: nalgebra::Rotation3::identity(),
            radius: std::f64::consts::PI,
        };
        let sum: Vector3<f64> = (0..cat.len()).map(|i| cat.v(i)).sum();
        if cat.is_empty() || sum.norm() < 1e-9 {
            return whole;
        }
        let centre = sum.normalize();
        // A star more than 120° from the centre makes it the whole sky (its angle is past 90°
        // whatever the rounding): a whole-sky catalog is known by its first few stars, not by
        // the angle of all of them (0.05 s for Tycho-2's 1.9 million).
        if (0..cat.len()).any(|i| cat.v(i).dot(&centre) < -0.5) {
            return whole;
        }
        let radius = (0..cat.len())
            .map(|i| crate::camera::angle(&cat.v(i), &centre))
            .fold(0.0, f64::max);
        if radius > std::f64::consts::FRAC_PI_2 {
            return whole;
        }
        let to_pole =
            nalgebra::Rotation3::rotation_between(&centre, &Vector3::z()).unwrap_or_else(|| {
                nalgebra::Rotation3::from_axis_angle(&Vector3::x_axis(), std::f64::consts::PI)
            });
        Region { to_pole, radius }
    }

    /// The share of a level's lattice (discs of diameter `d`) that can hold its stars: the
    /// cap widened by a disc's radius.
    fn share(&self, d: f64) -> f64 {
        if self.radius >= std::f64::consts::PI {
            return 1.0;
        }
        let r = (self.radius + d / 2.0).min(std::f64::consts::PI);
        (1.0 - r.cos()) / 2.0
    }
}

impl PatternIndex {
    /// The quads of every level's discs among `cat`'s stars (ids are in brightness order,
    /// brightest first).
    pub fn build(cat: &RefCatalog, levels: &[f64]) -> PatternIndex {
        let stars: Vec<_> = cat.stars().collect();
        let mut rows: Vec<(u32, [u32; 4])> = Vec::new();
        let region = Region::of(cat);
        let from_pole = region.to_pole.inverse();
        for &d in levels {
            let radius = d / 2.0;
            let max_chord = crate::catalog::table::chord_of_angle(radius);
            // Cubes of side max_chord: a star within the radius of a centre lies in its cube
            // or a neighbouring one (as the distance table's build).
            let side = max_chord.max(1e-9);
            let cell_of = |v: &Vector3<f64>| {
                let c = |x: f64| (x / side).floor() as i32;
                (c(v.x), c(v.y), c(v.z))
            };
            let mut cells: rustc_hash::FxHashMap<(i32, i32, i32), Vec<u32>> = Default::default();
            for (id, s) in stars.iter().enumerate() {
                cells.entry(cell_of(&s.v)).or_default().push(id as u32);
            }
            let n = discs_of(d) as usize;
            // The lattice from the pole of the catalog's cap down to where its discs can hold
            // none of its stars (the whole lattice for a catalog of the whole sky).
            let visited = ((n as f64 * region.share(d)).ceil() as usize).min(n);
            let mut near: Vec<u32> = Vec::new();
            for i in 0..visited {
                let c = from_pole * lattice_point(i, n);
                near.clear();
                let (cx, cy, cz) = cell_of(&c);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for dz in -1..=1 {
                            if let Some(ids) = cells.get(&(cx + dx, cy + dy, cz + dz)) {
                                near.extend(
                                    ids.iter().filter(|&&id| {
                                        (stars[id as usize].v - c).norm() < max_chord
                                    }),
                                );
                            }
                        }
                    }
                }
                near.sort_unstable();
                near.truncate(FIELD_STARS);
                let m = near.len();
                for a in 0..m {
                    for b in a + 1..m {
                        for e in b + 1..m {
                            for f in e + 1..m {
                                let ids = [near[a], near[b], near[e], near[f]];
                                let v = ids.map(|id| stars[id as usize].v);
                                rows.push((pattern_key(&v), ids));
                            }
                        }
                    }
                }
            }
        }
        rows.sort_unstable();
        rows.dedup();
        PatternIndex {
            keys: rows.iter().map(|r| r.0).collect(),
            quads: rows.iter().map(|r| r.1).collect(),
            levels: levels.to_vec(),
        }
    }

    pub fn len(&self) -> usize {
        self.keys.len()
    }

    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Bytes held by keys and quads.
    pub fn bytes(&self) -> usize {
        4 * self.keys.len() + 16 * self.quads.len()
    }
}

/// What an index depends on, hashed into its cache file name.
pub fn cache_key(cat: &RefCatalog, catalog_hash: u64, levels: &[f64]) -> u64 {
    let text = format!(
        "gpustar-patterns-v{}|{}|{}|{:?}|{}|{}|{}",
        FORMAT_VERSION,
        super::selection_key_text(cat, catalog_hash),
        cat.stars.len(),
        levels,
        BINS,
        FIELD_STARS,
        OVERSAMPLE,
    );
    crate::catalog::fnv1a(text.as_bytes())
}

const FORMAT_VERSION: u32 = 1;
const MAGIC: &[u8; 8] = b"GPSPAT01";

/// Load the index from the cache ([`table::cache_dir`](crate::catalog::table::cache_dir)) or
/// build it (and try to store it); with the seconds it took and whether it was built.
pub fn load_or_build(
    cat: &RefCatalog,
    catalog_hash: u64,
    levels: &[f64],
    use_cache: bool,
) -> (PatternIndex, bool, f64) {
    let dir = crate::catalog::table::cache_dir().filter(|_| use_cache);
    load_or_build_in(dir.as_deref(), cat, catalog_hash, levels)
}

/// [`load_or_build`] with the cache in `dir` (None: no cache).
pub fn load_or_build_in(
    dir: Option<&Path>,
    cat: &RefCatalog,
    catalog_hash: u64,
    levels: &[f64],
) -> (PatternIndex, bool, f64) {
    let t0 = Instant::now();
    let key = cache_key(cat, catalog_hash, levels);
    let file = dir.map(|d| d.join(format!("patterns-{key:016x}.bin")));
    if let Some(f) = &file
        && f.exists()
    {
        match read_index(f, key, levels) {
            Ok(t) => return (t, false, t0.elapsed().as_secs_f64()),
            Err(e) => tracing::warn!(
                "the cached pattern index {} cannot be used ({e:#}): building it again",
                f.display()
            ),
        }
    }
    let index = PatternIndex::build(cat, levels);
    if let Some(f) = &file {
        let mut body = Vec::with_capacity(index.bytes() / 4);
        body.extend_from_slice(&index.keys);
        body.extend_from_slice(bytemuck::cast_slice(&index.quads));
        if let Err(e) = write_cache(f, MAGIC, key, &[index.keys.len() as u64], &body) {
            tracing::warn!("could not write the pattern index {}: {e:#}", f.display());
        }
    }
    (index, true, t0.elapsed().as_secs_f64())
}

/// The index of a cache file, mapped: its header, key and length checked, its body not read.
/// An index is mapped on every run (1.7 GB for Tycho-2 at 0.64–0.78°), and a frame reads a few
/// thousand of its rows: taking its checksum and checking its order took 0.4 s a run, more
/// than the frame. What a frame reads is checked as it is read instead, so a damaged file
/// cannot make a frame fail or solve wrong: the lookup stays within the keys (unsorted keys
/// only lose candidates), a quad naming a star the selection lacks is skipped
/// (`Solver::check_quad`), and every candidate still passes the false-match test.
fn read_index(path: &Path, key: u64, levels: &[f64]) -> Result<PatternIndex> {
    let (head, mut body) = CacheReader::open_unchecked(path, MAGIC, key, 1)?;
    let rows = usize::try_from(head[0]).into_kind(Error::Catalog)?;
    if rows.checked_mul(5) != Some(body.words_left) {
        fail!(
            Catalog,
            "{} words where {rows} patterns need {}",
            body.words_left,
            rows.saturating_mul(5)
        );
    }
    let index = PatternIndex {
        keys: body.read(rows)?,
        quads: body.read(rows)?,
        levels: levels.to_vec(),
    };
    body.finish()?;
    Ok(index)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_do_not_depend_on_scale_or_order() {
        let v = [
            Vector3::new(0.0, 0.0, 1.0),
            Vector3::new(0.01, 0.0, 1.0).normalize(),
            Vector3::new(0.0, 0.02, 1.0).normalize(),
            Vector3::new(0.015, 0.013, 1.0).normalize(),
        ];
        // The same shape at a tenth of the size (ratios agree to second order in the angle).
        let small = v.map(|x| Vector3::new(x.x / 10.0, x.y / 10.0, x.z).normalize());
        let swapped = [v[2], v[0], v[3], v[1]];
        assert_eq!(pattern_key(&v), pattern_key(&swapped));
        let (a, b) = (ratios(&chords(&v)), ratios(&chords(&small)));
        for i in 0..5 {
            assert!((a[i] - b[i]).abs() < 1e-3, "{a:?} {b:?}");
        }
        assert!(pattern_key(&v) <= MAX_KEY);
    }

    #[test]
    fn levels_cover_the_range() {
        let l = levels_for(0.1, 0.3);
        assert_eq!(l[0], 0.3);
        assert!(*l.last().unwrap() <= 0.1 && *l.last().unwrap() > 0.1 / LEVEL_RATIO);
        assert_eq!(levels_for(0.2, 0.2), vec![0.2]);
    }
}
