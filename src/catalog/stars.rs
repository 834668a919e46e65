//! A catalog's stars: a vector when they were parsed or built, or the records of a mapped
//! binary catalog file (`store`), turned into [`Star`]s only when something
//! reads them all. A run whose star selection comes from the cache (`refs_cache`) reads only
//! the magnitudes: parsing Tycho-2's 1.9 million records took 90 ms of a narrow frame's
//! 230 ms; a catalog of tens of millions of stars is mapped in bounded time and memory.

use super::id::StarId;
use super::star::Star;
use std::fmt;
use std::ops::Deref;
use std::sync::{Arc, OnceLock};

pub struct Stars {
    len: usize,
    /// The records of a mapped file (checked by `store::read_mapped`), from byte `at`.
    mapped: Option<(Arc<memmap2::Mmap>, usize)>,
    parsed: OnceLock<Vec<Star>>,
}

impl Stars {
    /// The `len` records from byte `at` of `map`, each already checked to decode.
    pub(super) fn mapped(map: Arc<memmap2::Mmap>, at: usize, len: usize) -> Stars {
        Stars {
            len,
            mapped: Some((map, at)),
            parsed: OnceLock::new(),
        }
    }

    /// The number of stars (without parsing them).
    pub fn len(&self) -> usize {
        self.len
    }

    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Star `i`'s magnitude (read from its record where the stars are not parsed yet).
    pub fn mag(&self, i: usize) -> f64 {
        match (&self.mapped, self.parsed.get()) {
            (Some((map, at)), None) => record_mag(&map[at + RECORD * i..]),
            _ => self[i].mag,
        }
    }
}

impl From<Vec<Star>> for Stars {
    fn from(v: Vec<Star>) -> Self {
        let parsed = OnceLock::new();
        let len = v.len();
        let _ = parsed.set(v);
        Stars {
            len,
            mapped: None,
            parsed,
        }
    }
}

impl FromIterator<Star> for Stars {
    fn from_iter<I: IntoIterator<Item = Star>>(iter: I) -> Self {
        iter.into_iter().collect::<Vec<Star>>().into()
    }
}

impl Deref for Stars {
    type Target = [Star];
    fn deref(&self) -> &[Star] {
        self.parsed.get_or_init(|| match &self.mapped {
            Some((map, at)) => parse_records(&map[*at..*at + RECORD * self.len]),
            None => Vec::new(),
        })
    }
}

impl PartialEq for Stars {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

impl fmt::Debug for Stars {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Stars({})", self.len)
    }
}

/// Bytes of a star's record.
pub(super) const RECORD: usize = 64;

/// The star of a record whose id decodes.
pub(super) fn record_star(r: &[u8]) -> Option<Star> {
    let id = StarId::decode(r[60], u64_at(r, 48))?;
    let hip = u32_at(r, 56);
    Some(Star {
        id,
        hip: (hip != 0).then_some(hip),
        ra_rad: f64_at(r, 0),
        dec_rad: f64_at(r, 8),
        pmra_mas_yr: f64_at(r, 16),
        pmdec_mas_yr: f64_at(r, 24),
        mag: f64_at(r, 32),
        epoch: f64_at(r, 40),
    })
}

/// The stars of records checked by [`check`].
pub(super) fn parse_records(records: &[u8]) -> Vec<Star> {
    (records.chunks_exact(RECORD))
        .map(|r| record_star(r).expect("records are checked when read or mapped"))
        .collect()
}

/// A record's magnitude.
pub(super) fn record_mag(r: &[u8]) -> f64 {
    f64_at(r, 32)
}

pub(super) fn u32_at(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes(b[o..o + 4].try_into().expect("4 bytes"))
}
pub(super) fn u64_at(b: &[u8], o: usize) -> u64 {
    u64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"))
}
pub(super) fn f64_at(b: &[u8], o: usize) -> f64 {
    f64::from_le_bytes(b[o..o + 8].try_into().expect("8 bytes"))
}
