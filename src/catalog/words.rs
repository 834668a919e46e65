//! The storage of a table's columns: a vector when the table was built in this run, the
//! bytes of its cache file mapped read-only when it was loaded.
//!
//! Why map: reading a 38 MB table into a new vector cost 20 ms, nearly all of it the page
//! faults of fresh memory; the same file mapped and checksummed costs 3 ms, the pages coming
//! straight from the page cache (docs/speed.md, "Cached tables mapped"). Cache files are
//! written under a temporary name and renamed (`table::write_cache`), never rewritten in
//! place, so a mapping always sees the file that was checked.

use bytemuck::Pod;
use std::fmt;
use std::ops::Deref;
use std::sync::Arc;

/// A read-only column of `T`: dereferences to `&[T]`.
pub struct Words<T: Pod> {
    repr: Repr<T>,
}

enum Repr<T> {
    Owned(Vec<T>),
    /// `len` values from byte `start` of the map, aligned for `T` (checked by [`Words::mapped`]).
    Mapped {
        map: Arc<memmap2::Mmap>,
        start: usize,
        len: usize,
    },
}

impl<T: Pod> Words<T> {
    /// `len` values of `T` at byte `start` of `map`, or None where they do not fit in the map
    /// or are not aligned for `T`.
    pub(crate) fn mapped(map: &Arc<memmap2::Mmap>, start: usize, len: usize) -> Option<Self> {
        let bytes = len.checked_mul(std::mem::size_of::<T>())?;
        let slice = map.get(start..start.checked_add(bytes)?)?;
        bytemuck::try_cast_slice::<u8, T>(slice).ok()?;
        Some(Words {
            repr: Repr::Mapped {
                map: Arc::clone(map),
                start,
                len,
            },
        })
    }

    /// The values as a vector (a copy where they are mapped).
    pub fn into_vec(self) -> Vec<T> {
        match self.repr {
            Repr::Owned(v) => v,
            Repr::Mapped { .. } => self.to_vec(),
        }
    }
}

impl<T: Pod> Deref for Words<T> {
    type Target = [T];
    #[inline]
    fn deref(&self) -> &[T] {
        match &self.repr {
            Repr::Owned(v) => v,
            Repr::Mapped { map, start, len } => {
                // SAFETY: `mapped` checked that these bytes lie in the map and are aligned for
                // T; T is Pod, so any bytes are a valid T; the map lives as long as self.
                unsafe { std::slice::from_raw_parts(map.as_ptr().add(*start).cast::<T>(), *len) }
            }
        }
    }
}

impl<T: Pod> From<Vec<T>> for Words<T> {
    fn from(v: Vec<T>) -> Self {
        Words {
            repr: Repr::Owned(v),
        }
    }
}

impl<T: Pod> FromIterator<T> for Words<T> {
    fn from_iter<I: IntoIterator<Item = T>>(iter: I) -> Self {
        iter.into_iter().collect::<Vec<T>>().into()
    }
}

impl<T: Pod> Clone for Words<T> {
    fn clone(&self) -> Self {
        let repr = match &self.repr {
            Repr::Owned(v) => Repr::Owned(v.clone()),
            Repr::Mapped { map, start, len } => Repr::Mapped {
                map: Arc::clone(map),
                start: *start,
                len: *len,
            },
        };
        Words { repr }
    }
}

impl<T: Pod + fmt::Debug> fmt::Debug for Words<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(&**self, f)
    }
}

impl<T: Pod + PartialEq> PartialEq for Words<T> {
    fn eq(&self, other: &Self) -> bool {
        **self == **other
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Write;

    #[test]
    fn mapped_words_read_the_file_and_refuse_what_does_not_fit() {
        let mut f = tempfile::NamedTempFile::new().unwrap();
        let values: Vec<u32> = (0..10).map(|i| i * 7 + 1).collect();
        f.write_all(bytemuck::cast_slice(&values)).unwrap();
        f.flush().unwrap();
        // SAFETY: a temporary file of this test only.
        let map = Arc::new(unsafe { memmap2::Mmap::map(f.as_file()) }.unwrap());
        let w = Words::<u32>::mapped(&map, 8, 5).unwrap();
        assert_eq!(&*w, &values[2..7]);
        assert_eq!(w.clone(), Words::from(values[2..7].to_vec()));
        assert_eq!(w.into_vec(), values[2..7].to_vec());
        let pairs = Words::<[u32; 2]>::mapped(&map, 0, 5).unwrap();
        assert_eq!(pairs[4], [values[8], values[9]]);
        assert!(Words::<u32>::mapped(&map, 8, 9).is_none(), "past the end");
        assert!(Words::<u32>::mapped(&map, 2, 1).is_none(), "misaligned");
        assert!(
            Words::<u32>::mapped(&map, usize::MAX - 1, 1).is_none(),
            "overflow"
        );
    }
}
