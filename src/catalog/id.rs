//! A catalog star's identity, and the `catalog_id` string records carry.

/// Which catalog a star comes from, with its number there. Ordered by kind, then number, so
/// that ties broken by id are stable (for Hipparcos catalogs: by HIP, as before).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum StarId {
    /// Hipparcos (HIP number).
    Hip(u32),
    /// Gaia DR3 `source_id`.
    GaiaDr3(u64),
    /// Tycho-2: TYC1-TYC2-TYC3.
    Tycho2 { tyc1: u16, tyc2: u16, tyc3: u8 },
    /// A user catalog's id: an index into the catalog's `names`.
    Name(u32),
    /// A star of an astrometry.net index file: the file's INDEXID and the star's place in it.
    AnIndex { index: u32, star: u32 },
}

impl StarId {
    /// The id as records print it: "HIP 71683", "Gaia DR3 1576683529448755328",
    /// "TYC 4424-1234-1", or a user catalog's id verbatim (`names` is the catalog's).
    pub fn display(&self, names: &[String]) -> String {
        match *self {
            StarId::Hip(n) => format!("HIP {n}"),
            StarId::GaiaDr3(n) => format!("Gaia DR3 {n}"),
            StarId::Tycho2 { tyc1, tyc2, tyc3 } => format!("TYC {tyc1}-{tyc2}-{tyc3}"),
            StarId::Name(i) => names.get(i as usize).cloned().unwrap_or_default(),
            StarId::AnIndex { index, star } => format!("AN {index}:{star}"),
        }
    }

    /// (kind, number): the binary catalog file's encoding.
    pub(crate) fn encode(&self) -> (u8, u64) {
        match *self {
            StarId::Hip(n) => (KIND_HIP, n as u64),
            StarId::GaiaDr3(n) => (KIND_GAIA, n),
            StarId::Tycho2 { tyc1, tyc2, tyc3 } => (
                KIND_TYCHO,
                (tyc1 as u64) << 32 | (tyc2 as u64) << 8 | tyc3 as u64,
            ),
            StarId::Name(i) => (KIND_NAME, i as u64),
            StarId::AnIndex { index, star } => (KIND_AN_INDEX, (index as u64) << 32 | star as u64),
        }
    }

    /// The inverse of [`StarId::encode`]; None for a kind or number no encoder makes.
    pub(crate) fn decode(kind: u8, n: u64) -> Option<StarId> {
        Some(match kind {
            KIND_HIP => StarId::Hip(u32::try_from(n).ok()?),
            KIND_GAIA => StarId::GaiaDr3(n),
            KIND_TYCHO => StarId::Tycho2 {
                tyc1: u16::try_from(n >> 32).ok()?,
                tyc2: (n >> 8) as u16,
                tyc3: n as u8,
            },
            KIND_NAME => StarId::Name(u32::try_from(n).ok()?),
            KIND_AN_INDEX => StarId::AnIndex {
                index: (n >> 32) as u32,
                star: n as u32,
            },
            _ => return None,
        })
    }
}

pub(crate) const KIND_HIP: u8 = 1;
pub(crate) const KIND_GAIA: u8 = 2;
pub(crate) const KIND_TYCHO: u8 = 3;
pub(crate) const KIND_NAME: u8 = 4;
pub(crate) const KIND_AN_INDEX: u8 = 5;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_print_as_catalogs_write_them_and_survive_encoding() {
        let names = vec!["my star 7".to_string()];
        for (id, s) in [
            (StarId::Hip(71683), "HIP 71683"),
            (
                StarId::GaiaDr3(1576683529448755328),
                "Gaia DR3 1576683529448755328",
            ),
            (
                StarId::Tycho2 {
                    tyc1: 4424,
                    tyc2: 1234,
                    tyc3: 1,
                },
                "TYC 4424-1234-1",
            ),
            (StarId::Name(0), "my star 7"),
            (
                StarId::AnIndex {
                    index: 4107,
                    star: 1_870_999,
                },
                "AN 4107:1870999",
            ),
        ] {
            assert_eq!(id.display(&names), s);
            let (k, n) = id.encode();
            assert_eq!(StarId::decode(k, n), Some(id));
        }
        assert_eq!(StarId::decode(9, 1), None);
        assert_eq!(StarId::decode(KIND_HIP, 1 << 40), None);
    }
}
