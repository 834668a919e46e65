//! A catalog's stars: a vector when they were parsed or built, or records (of a mapped binary
//! catalog file, `store`, or the built-in catalog's, compiled into the binary) turned into
//! [`Star`]s only when something reads them all. A run whose star selection comes from the
//! cache (`refs_cache`) reads only the magnitudes: parsing Tycho-2's 1.9 million records took
//! 90 ms of a narrow frame's 230 ms, and the built-in catalog's 78,352 a quarter of a one-frame
//! run; a catalog of tens of millions of stars is mapped in bounded time and memory.

use super::id::StarId;
use super::star::Star;
use std::fmt;
use std::ops::Deref;
use std::sync::{Arc, OnceLock};

pub struct Stars {
    len: usize,
    /// What the stars are parsed from when first read whole (None: parsed already).
    records: Option<Records>,
    parsed: OnceLock<Vec<Star>>,
}

/// Records of stars not parsed yet.
enum Records {
    /// A mapped file's (checked by `store::read_mapped`), from byte `at`.
    Mapped(Arc<memmap2::Mmap>, usize),
    /// Records compiled into the binary, `size` bytes each, read by `star` and `mag`.
    Compiled {
        bytes: &'static [u8],
        size: usize,
        star: fn(&[u8]) -> Star,
        mag: fn(&[u8]) -> f64,
    },
}

impl Stars {
    /// The `len` records from byte `at` of `map`, each already checked to decode.
    pub(super) fn mapped(map: Arc<memmap2::Mmap>, at: usize, len: usize) -> Stars {
        Stars {
            len,
            records: Some(Records::Mapped(map, at)),
            parsed: OnceLock::new(),
        }
    }

    /// The records of `size` bytes in `bytes` (compiled into the binary, each known to
    /// decode), `star` and `mag` reading one.
    pub(super) fn compiled(
        bytes: &'static [u8],
        size: usize,
        star: fn(&[u8]) -> Star,
        mag: fn(&[u8]) -> f64,
    ) -> Stars {
        Stars {
            len: bytes.len() / size,
            records: Some(Records::Compiled {
                bytes,
                size,
                star,
                mag,
            }),
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
        match (&self.records, self.parsed.get()) {
            (Some(Records::Mapped(map, at)), None) => record_mag(&map[at + RECORD * i..]),
            (
                Some(Records::Compiled {
                    bytes, size, mag, ..
                }),
                None,
            ) => mag(&bytes[size * i..size * (i + 1)]),
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
            records: None,
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
        self.parsed.get_or_init(|| match &self.records {
            Some(Records::Mapped(map, at)) => parse_records(&map[*at..*at + RECORD * self.len]),
            Some(Records::Compiled {
                bytes, size, star, ..
            }) => bytes.chunks_exact(*size).map(star).collect(),
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

#[cfg(test)]
mod tests {
    use crate::catalog::Catalog;

    /// The built-in catalog's magnitudes are read from its records, unparsed, and equal the
    /// stars they parse into (the first and last included).
    #[test]
    fn the_builtin_records_read_as_their_stars() {
        let c = Catalog::builtin();
        let mags: Vec<u64> = (0..c.stars.len())
            .map(|i| c.stars.mag(i).to_bits())
            .collect();
        assert!(
            c.stars.parsed.get().is_none(),
            "reading magnitudes parses nothing"
        );
        let stars = &c.stars[..];
        assert_eq!(stars.len(), mags.len());
        assert!(stars.iter().zip(&mags).all(|(s, &m)| s.mag.to_bits() == m));
        assert_eq!(stars.len(), 78_352);
    }
}
