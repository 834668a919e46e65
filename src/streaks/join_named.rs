//! Pieces of one broken streak joined by what `--tle` says of them: a tumbling object dark over
//! long stretches of its exposure leaves pieces further apart than one frame's geometry may
//! join ([`super::measure`] joins pieces apart by less than 1.5 times their lengths: further,
//! they could be a train of objects on one line). Two pieces that lie on one line and are both
//! partial matches ([`crate::record::SatelliteRecord::seen_fraction`]) to the same object's
//! predicted path are that object's: they are joined into one streak from the outermost end to
//! the other, which is then matched again (and kept apart when the whole does not match).

use super::fit::{StreakFit, length};
use crate::record::StreakRecord;

/// Largest angle between the pieces' lines (degrees) and distance of the shorter's ends from
/// the longer's line (pixels): as `measure` joins pieces.
const ANGLE_DEG: f64 = 2.0;
const ACROSS_PX: f64 = 3.0;

/// The fits with the pieces that `--tle` matched partially to one object, on one line, joined
/// (each joined streak where its longest piece was, the other pieces removed); `None` when
/// there are none. `records[k]` is the record of `found[k]`.
pub fn join_named_pieces(found: &[StreakFit], records: &[StreakRecord]) -> Option<Vec<StreakFit>> {
    let partial = |k: usize| {
        records[k]
            .satellite
            .as_ref()
            .filter(|m| m.seen_fraction.is_some())
            .map(|m| m.norad)
    };
    let mut out: Vec<Option<StreakFit>> = found.iter().copied().map(Some).collect();
    let mut joined = false;
    // Longest first, so that each piece joins the longest of its object's pieces on its line.
    let mut order: Vec<usize> = (0..found.len()).filter(|&k| partial(k).is_some()).collect();
    order.sort_by(|&a, &b| {
        length(&found[b])
            .total_cmp(&length(&found[a]))
            .then(a.cmp(&b))
    });
    for (i, &long) in order.iter().enumerate() {
        let Some(mut whole) = out[long] else { continue };
        for &short in &order[i + 1..] {
            if partial(short) != partial(long) || out[short].is_none() {
                continue;
            }
            if on_line(&whole, &found[short]) {
                whole = spanning(&whole, &found[short]);
                out[short] = None;
                joined = true;
            }
        }
        out[long] = Some(whole);
    }
    joined.then(|| out.into_iter().flatten().collect())
}

/// Does `b` lie on `a`'s line?
fn on_line(a: &StreakFit, b: &StreakFit) -> bool {
    let cos = (a.dir.0 * b.dir.0 + a.dir.1 * b.dir.1).abs();
    let (x0, y0) = a.ends[0];
    let across = |(x, y): (f64, f64)| (-(x - x0) * a.dir.1 + (y - y0) * a.dir.0).abs();
    cos > ANGLE_DEG.to_radians().cos() && b.ends.iter().all(|&e| across(e) < ACROSS_PX)
}

/// One streak from the outermost of two collinear pieces' ends along `a`'s line to the other:
/// each end (and its edge flag) as its own piece measured it; the light of both.
fn spanning(a: &StreakFit, b: &StreakFit) -> StreakFit {
    let (x0, y0) = a.ends[0];
    let t = |(x, y): (f64, f64)| (x - x0) * a.dir.0 + (y - y0) * a.dir.1;
    let ends = [(a.ends[0], a.edge[0]), (a.ends[1], a.edge[1])]
        .into_iter()
        .chain([(b.ends[0], b.edge[0]), (b.ends[1], b.edge[1])]);
    let (lo, hi) = ends.fold((None, None), |(lo, hi), e| {
        let lower = |m: &Option<((f64, f64), bool)>| m.is_none_or(|m| t(e.0) < t(m.0));
        let higher = |m: &Option<((f64, f64), bool)>| m.is_none_or(|m| t(e.0) > t(m.0));
        (
            if lower(&lo) { Some(e) } else { lo },
            if higher(&hi) { Some(e) } else { hi },
        )
    });
    let (lo, hi) = (lo.expect("four ends"), hi.expect("four ends"));
    // Keep `a`'s order of its ends: its end 0 is the one at the low end of the line.
    let (first, second) = if t(a.ends[0]) <= t(a.ends[1]) {
        (lo, hi)
    } else {
        (hi, lo)
    };
    StreakFit {
        ends: [first.0, second.0],
        edge: [first.1, second.1],
        flux: a.flux + b.flux,
        snr: a.snr.hypot(b.snr),
        fit_rms_px: a.fit_rms_px.max(b.fit_rms_px),
        ..*a
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::{SatelliteRecord, StreakEnd};
    use crate::streaks::chain::Chain;

    fn piece(from: (f64, f64), to: (f64, f64)) -> StreakFit {
        let l = (to.0 - from.0).hypot(to.1 - from.1);
        StreakFit {
            ends: [from, to],
            edge: [false, false],
            sigma_px: 1.2,
            amplitude: 100.0,
            noise: 5.0,
            flux: 1000.0,
            snr: 30.0,
            fit_rms_px: 0.1,
            gap_fraction: 0.0,
            modulation: 0.0,
            local_snr: 20.0,
            chain: Chain {
                peaks: 0,
                explained: 0.0,
                excess: 0.0,
                dips: 0.0,
                is_chain: false,
            },
            dir: ((to.0 - from.0) / l, (to.1 - from.1) / l),
            axis_angle_deg: 30.0,
        }
    }

    fn record(norad: Option<u64>, seen_fraction: Option<f64>) -> StreakRecord {
        let end = StreakEnd {
            x: 0.0,
            y: 0.0,
            ra_deg: None,
            dec_deg: None,
            edge: Some(false),
            time_utc: None,
            az_deg: None,
            el_deg: None,
        };
        let mut r =
            StreakRecord::for_tests([end.clone(), end.clone()], [end.clone(), end], 1.0, None);
        r.satellite = norad.map(|norad| SatelliteRecord {
            norad,
            name: String::new(),
            intl_des: None,
            cross_track_arcsec: 0.0,
            along_track_s: 0.0,
            seen_fraction,
        });
        r
    }

    /// Two partial pieces of object 7 on one line, 133 px apart (beyond the frame's own
    /// joining), become one streak from the outer ends; a piece of another object on that
    /// line, a whole match and a piece off the line stay as they are.
    #[test]
    fn partial_pieces_of_one_object_on_one_line_are_one_streak() {
        let found = [
            piece((639.0, 546.0), (602.0, 544.0)),
            piece((470.0, 537.0), (424.0, 535.0)),
            piece((300.0, 528.0), (260.0, 526.0)),
            piece((100.0, 100.0), (200.0, 300.0)),
            piece((470.0, 560.0), (424.0, 558.0)),
        ];
        let records = [
            record(Some(7), Some(0.2)),
            record(Some(7), Some(0.2)),
            record(Some(8), Some(0.2)),
            record(Some(7), None),
            record(Some(7), Some(0.2)),
        ];
        let out = join_named_pieces(&found, &records).expect("a join");
        assert_eq!(out.len(), 4, "{out:?}");
        assert_eq!(out[0].ends, [(639.0, 546.0), (424.0, 535.0)]);
        assert_eq!(out[0].flux, 2000.0);
        assert_eq!(&out[1..], &found[2..]);
        // Nothing to join: None.
        assert!(join_named_pieces(&found[..1], &records[..1]).is_none());
        let whole = [record(Some(7), None), record(Some(7), None)];
        assert!(join_named_pieces(&found[..2], &whole).is_none());
    }
}
