//! The reference stars of a run: a selection of the catalog (magnitude limit, double stars
//! resolved) at an epoch, as the solvers read it.

use super::cells;
use super::id::StarId;
use super::loaded::Catalog;
use super::ref_record::{RefRecord, RefStar};
use super::words::Words;
use crate::error::{Result, fail};
use nalgebra::Vector3;
use std::sync::Arc;

crate::choice! {
    /// How stars closer together than the camera can separate are treated.
    #[derive(Clone, Copy, Debug, PartialEq, Eq)]
    pub enum DoubleStars {
        Merge = "merge", "Replace the group by one star at its flux-weighted photocentre with the \
            summed flux: that is what the detector sees (one blob), so the pair still serves \
            identification",
        Drop = "drop", "Remove every star of the group (seed 000's choice)",
        Keep = "keep", "Keep them as they are",
    }
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

/// The stars a run matches against, brightest first; a star's index is its 32-bit id in the
/// distance table. Positions are read at `selection.epoch` ([`RefCatalog::v`],
/// [`RefCatalog::star`]): a catalog moved to a frame's own date shares the stars and moves
/// each by its proper motion when read.
#[derive(Clone, Debug)]
pub struct RefCatalog {
    /// The stars at `stars_epoch`: made by [`RefCatalog::select`], or mapped from the cache
    /// file of an earlier run's selection ([`load_or_select`]).
    pub(super) stars: Arc<Words<RefRecord>>,
    /// The epoch `stars` hold positions for (Julian year).
    pub(super) stars_epoch: f64,
    /// The largest proper motion of any star (radians per year): how far a move of a year
    /// takes any star at most, for cone tests on the stored positions ([`RefCatalog::within`]).
    pub(super) max_motion: f64,
    pub selection: Selection,
    /// Stars the double-star rule merged away or dropped.
    pub doubles_removed: usize,
    /// The catalog's user ids ([`Catalog::names`]), for [`RefCatalog::catalog_id`].
    pub names: Arc<Vec<String>>,
    /// The stored positions' cone searches, for [`RefCatalog::within`]; shared, as the stars
    /// are, by the catalog at other epochs.
    pub(super) cones: Arc<cells::ConeIndex>,
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
pub(super) fn resolve_doubles(stars: &[RefStar], selection: Selection) -> Vec<RefStar> {
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

pub(super) fn selection_text(s: &Selection, catalog_hash: u64) -> String {
    format!(
        "{:016x}|{}|{}|{:?}|{}",
        catalog_hash, s.epoch, s.mag_limit, s.double_stars, s.double_sep_rad
    )
}
