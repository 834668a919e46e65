//! A catalog's stars: a vector when they were parsed or built, or the records of a mapped
//! binary catalog file ([`store`](super::store)), turned into [`Star`]s only when something
//! reads them all. A run whose star selection comes from the cache (`refs_cache`) reads only
//! the magnitudes: parsing Tycho-2's 1.9 million records took 90 ms of a narrow frame's
//! 230 ms; a catalog of tens of millions of stars is mapped in bounded time and memory.

use super::Star;
use super::store;
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
            (Some((map, at)), None) => store::record_mag(&map[at + store::RECORD * i..]),
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
            Some((map, at)) => store::parse_records(&map[*at..*at + store::RECORD * self.len]),
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
