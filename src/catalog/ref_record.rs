//! A reference star as a run's selection stores it: plain numbers that a cache file maps
//! (`refs_cache`), turned back into a [`RefStar`] when read.

use super::id::StarId;
use nalgebra::Vector3;

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

/// A [`RefStar`] as stored, in a form a cache file maps (plain numbers, no padding).
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub(super) struct RefRecord {
    pub(super) v: [f64; 3],
    pub(super) motion: [f64; 3],
    pub(super) mag: f64,
    /// [`StarId::encode`]'s number and kind.
    pub(super) id: u64,
    pub(super) kind: u32,
    /// 0: none.
    pub(super) hip: u32,
    pub(super) members: u32,
    pub(super) zero: u32,
}

impl RefRecord {
    pub(super) fn of(s: &RefStar) -> RefRecord {
        let (kind, id) = s.id.encode();
        RefRecord {
            v: s.v.into(),
            motion: s.motion.into(),
            mag: s.mag,
            id,
            kind: kind.into(),
            hip: s.hip.unwrap_or(0),
            members: s.members,
            zero: 0,
        }
    }

    /// The id, if the kind and number are one (every record made here or loaded is checked).
    pub(super) fn star_id(&self) -> Option<StarId> {
        StarId::decode(u8::try_from(self.kind).ok()?, self.id)
    }

    pub(super) fn star(&self) -> RefStar {
        RefStar {
            id: self
                .star_id()
                .expect("ids are checked when records are made or loaded"),
            hip: (self.hip != 0).then_some(self.hip),
            v: self.v.into(),
            motion: self.motion.into(),
            mag: self.mag,
            members: self.members,
        }
    }
}
