//! Tracklets: the streaks of one object in consecutive frames of one station, linked.
//!
//! The frames of one directory (with `-r`, of each subdirectory) are one station's frames in
//! time order (input order). A streak whose two ends are inside its frame fixes a motion: a
//! great circle through its ends at the rate that covers it in the exposure, either way along.
//! A streak of the next frame is the same object when, for one choice of the two streaks'
//! directions, its ends lie where that motion puts the object at that frame's start and end
//! (and the other way round when both are whole): within 10 % of the distance extrapolated plus
//! 10 pixels' worth of angle. The choice that fits says which end of each streak was the
//! exposure's start: the streaks are turned so that `ends[0]` is the start, and
//! `direction_known` is set. A pair that fits both ways is not linked; two streaks that leave
//! the frame are not linked (neither fixes a rate).
//!
//! Records are written in input order as frames finish: the linker holds back one record
//! (the last of its directory) until the next arrives, so that every record is written with
//! its links to both neighbours. A streak's tracklet is named by its first streak
//! (`FILE#N`), so names do not change when later frames join it, and a resumed run (which
//! starts linking afresh at its first new frame) names its tracklets the same way.

use crate::record::{Record, StreakRecord};
use crate::sky::Utc;

/// Extrapolation error allowed, as a share of the angle extrapolated: a low object's rate on
/// the sky changes by up to a fifth from one frame to the next (independent passes).
const REL_TOL: f64 = 0.10;
/// And in pixels of the streak that extrapolates (the ends' own errors, a bent path).
const PX_TOL: f64 = 10.0;

/// Links streaks of consecutive records of a directory; see the module's text.
#[derive(Debug, Default)]
pub struct Linker {
    held: Option<Record>,
}

impl Linker {
    pub fn new() -> Linker {
        Linker::default()
    }

    /// Take the next record in input order; returns the record now ready to be written.
    pub fn push(&mut self, mut r: Record) -> Option<Record> {
        for (k, s) in r.streaks.iter_mut().flatten().enumerate() {
            if s.tracklet.is_none() {
                s.tracklet = Some(format!("{}#{}", r.file, k + 1));
                s.tracklet_index = Some(0);
            }
        }
        if let Some(prev) = self.held.as_mut()
            && directory(&prev.file) == directory(&r.file)
        {
            link(prev, &mut r);
        }
        self.held.replace(r)
    }

    /// The record still held, at the end of a run.
    pub fn finish(&mut self) -> Option<Record> {
        self.held.take()
    }
}

fn directory(file: &str) -> &str {
    file.rfind(['/', '\\']).map_or("", |i| &file[..i])
}

/// A frame's exposure start and end (seconds from J2000 UTC), as its streaks carry them.
fn frame_times(r: &Record) -> Option<(f64, f64)> {
    let j2000 = Utc {
        jd1: 2_451_545.0,
        jd2: 0.0,
    };
    let secs = |t: &str| Utc::parse(t).ok().map(|u| u.seconds_since(&j2000));
    let [a, b] = r
        .streaks
        .as_ref()?
        .iter()
        .find_map(|s| s.exposure_utc.clone())?;
    Some((secs(&a)?, secs(&b)?)).filter(|(a, b)| b > a)
}

type V3 = [f64; 3];

fn unit(ra: f64, dec: f64) -> V3 {
    let (r, d) = (ra.to_radians(), dec.to_radians());
    [d.cos() * r.cos(), d.cos() * r.sin(), d.sin()]
}

fn dot(a: &V3, b: &V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: &V3, b: &V3) -> V3 {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn angle(a: &V3, b: &V3) -> f64 {
    let c = cross(a, b);
    dot(&c, &c).sqrt().atan2(dot(a, b))
}

/// A streak one way along: where the object was at the exposure's start and end (`None` for
/// an end on the frame's edge).
struct Way {
    at: [Option<V3>; 2],
    times: (f64, f64),
    /// Angle per pixel along the streak.
    scale: f64,
}

/// The streak's two ways along (`[as written, reversed]`), or `None` without RA/Dec on
/// both ends. A streak whose direction is known has only its own way.
fn ways(s: &StreakRecord, times: (f64, f64)) -> Option<[Option<Way>; 2]> {
    let v = |k: usize| Some(unit(s.ends[k].ra_deg?, s.ends[k].dec_deg?));
    let (a, b) = (v(0)?, v(1)?);
    let inside = |k: usize| s.ends[k].edge != Some(true);
    let scale = angle(&a, &b) / s.length_px.max(1.0);
    let pos = [a, b];
    let way = |first: usize| Way {
        at: [first, 1 - first].map(|k| inside(k).then_some(pos[k])),
        times,
        scale,
    };
    Some([Some(way(0)), (!s.direction_known).then(|| way(1))])
}

/// Where a whole streak's motion puts the object at time `t`.
fn predict(w: &Way, t: f64) -> Option<V3> {
    let (a, b) = (w.at[0]?, w.at[1]?);
    let c = cross(&a, &b);
    let len = dot(&c, &c).sqrt();
    if len < 1e-15 {
        return None;
    }
    let n = c.map(|x| x / len);
    let rate = angle(&a, &b) / (w.times.1 - w.times.0);
    let phi = rate * (t - w.times.0);
    let u = cross(&n, &a);
    Some([0, 1, 2].map(|i| a[i] * phi.cos() + u[i] * phi.sin()))
}

/// How far `to`'s ends lie from where `from`'s motion puts them, as a share of the tolerance
/// (below 1 fits); `None` when `from` is not whole or `to` has no end inside.
fn miss(from: &Way, to: &Way) -> Option<f64> {
    let start = from.at[0]?;
    let mut worst: Option<f64> = None;
    for (k, p) in to.at.iter().enumerate() {
        let Some(p) = p else { continue };
        let t = if k == 0 { to.times.0 } else { to.times.1 };
        let q = predict(from, t)?;
        let tol = REL_TOL * angle(&start, &q) + PX_TOL * from.scale;
        let m = angle(p, &q) / tol;
        worst = Some(worst.map_or(m, |w| w.max(m)));
    }
    worst
}

/// How well two streaks fit one motion each way: the worst of the misses each whole one
/// predicts for the other.
fn fits(a: &Way, b: &Way) -> Option<f64> {
    match (miss(a, b), miss(b, a)) {
        (Some(x), Some(y)) => Some(x.max(y)),
        (x, y) => x.or(y),
    }
}

/// Link the streaks of `b` (the next frame) to those of `a`.
fn link(a: &mut Record, b: &mut Record) {
    let (Some(ta), Some(tb)) = (frame_times(a), frame_times(b)) else {
        return;
    };
    if tb.0 < ta.0 {
        return;
    }
    let (Some(sa), Some(sb)) = (a.streaks.as_mut(), b.streaks.as_mut()) else {
        return;
    };
    // Every pair that fits one way only, with how well: (miss, i, j, a reversed, b reversed).
    let mut pairs = Vec::new();
    for (i, x) in sa.iter().enumerate() {
        let Some(wx) = ways(x, ta) else { continue };
        for (j, y) in sb.iter().enumerate() {
            let Some(wy) = ways(y, tb) else { continue };
            let mut ok = Vec::new();
            for (ra, wa) in wx.iter().enumerate() {
                for (rb, wb) in wy.iter().enumerate() {
                    if let (Some(wa), Some(wb)) = (wa, wb)
                        && let Some(m) = fits(wa, wb).filter(|m| *m < 1.0)
                    {
                        ok.push((m, ra == 1, rb == 1));
                    }
                }
            }
            if let [(m, ra, rb)] = ok[..] {
                pairs.push((m, i, j, ra, rb));
            }
        }
    }
    pairs.sort_by(|p, q| p.0.total_cmp(&q.0));
    let (mut used_a, mut used_b) = (vec![false; sa.len()], vec![false; sb.len()]);
    for (_, i, j, ra, rb) in pairs {
        // A streak already continued, or one that cannot be turned, is not linked again.
        if used_a[i] || used_b[j] || sa[i].tracklet_index.is_none() {
            continue;
        }
        if (ra && sa[i].reversed.is_none()) || (rb && sb[j].reversed.is_none()) {
            continue;
        }
        if sb[j].tracklet_index != Some(0) {
            continue;
        }
        used_a[i] = true;
        used_b[j] = true;
        if ra {
            sa[i].reverse();
        }
        if rb {
            sb[j].reverse();
        }
        sa[i].direction_known = true;
        sb[j].direction_known = true;
        sb[j].tracklet = sa[i].tracklet.clone();
        sb[j].tracklet_index = sa[i].tracklet_index.map(|k| k + 1);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::record::StreakEnd;

    /// A point `phi` radians along the great circle from (RA 30°, Dec 10°) towards the north
    /// east, and `across` radians off it.
    fn along(phi: f64, across: f64) -> (f64, f64) {
        let a = unit(30.0, 10.0);
        let n = {
            let c = cross(&a, &unit(31.0, 10.6));
            let l = dot(&c, &c).sqrt();
            c.map(|v| v / l)
        };
        let u = cross(&n, &a);
        let p: V3 = [0, 1, 2]
            .map(|i| (a[i] * phi.cos() + u[i] * phi.sin()) * across.cos() + n[i] * across.sin());
        (
            p[1].atan2(p[0]).to_degrees().rem_euclid(360.0),
            p[2].asin().to_degrees(),
        )
    }

    fn end(phi: f64, across: f64, edge: bool, t: Option<&str>) -> StreakEnd {
        let (ra, dec) = along(phi, across);
        StreakEnd {
            x: phi.to_degrees() * 100.0,
            y: across.to_degrees() * 100.0,
            ra_deg: Some(ra),
            dec_deg: Some(dec),
            edge: Some(edge),
            time_utc: if edge { None } else { t.map(str::to_string) },
            az_deg: None,
            el_deg: None,
        }
    }

    /// A streak from `phi0` (exposure start) to `phi1` (end), written in the order `swap`
    /// says (one frame does not know which end came first); `edge0` puts the start off the
    /// frame.
    fn streak(
        phi0: f64,
        phi1: f64,
        across: f64,
        times: [&str; 2],
        swap: bool,
        edge0: bool,
    ) -> StreakRecord {
        let fwd = [
            end(phi0, across, edge0, Some(times[0])),
            end(phi1, across, false, Some(times[1])),
        ];
        let rev = [
            end(phi1, across, false, Some(times[0])),
            end(phi0, across, edge0, Some(times[1])),
        ];
        let (ends, reversed) = if swap { (rev, fwd) } else { (fwd, rev) };
        StreakRecord::for_tests(
            ends,
            reversed,
            (phi1 - phi0).abs().to_degrees() * 100.0,
            Some(times.map(str::to_string)),
        )
    }

    fn frame(name: &str, streaks: Vec<StreakRecord>) -> Record {
        let mut r = Record::empty(name, "cpu");
        r.streaks = Some(streaks);
        r
    }

    const T: [[&str; 2]; 3] = [
        ["2025-01-01T20:00:00.000", "2025-01-01T20:00:02.000"],
        ["2025-01-01T20:00:03.000", "2025-01-01T20:00:05.000"],
        ["2025-01-01T20:00:06.000", "2025-01-01T20:00:08.000"],
    ];

    /// Two objects over three frames, their streaks written either way round: one moving
    /// 0.01 rad/s along the circle, the other the opposite way 0.02 rad off it; a third
    /// streak in the last frame at another rate is no one's continuation.
    #[test]
    fn links_objects_and_fixes_directions() {
        let rate = 0.01;
        let (mut linker, mut out) = (Linker::new(), Vec::new());
        for (k, t) in T.iter().enumerate() {
            let t0 = 3.0 * k as f64;
            let mut s = vec![
                streak(rate * t0, rate * (t0 + 2.0), 0.0, *t, k % 2 == 0, k == 0),
                streak(-rate * t0, -rate * (t0 + 2.0), 0.02, *t, k == 1, false),
            ];
            if k == 2 {
                s.push(streak(0.3, 0.3 + 3.0 * rate * 2.0, -0.02, *t, false, false));
            }
            out.extend(linker.push(frame(&format!("night/f{k}.fits"), s)));
        }
        out.extend(linker.finish());
        assert_eq!(out.len(), 3);
        for (k, r) in out.iter().enumerate() {
            let s = r.streaks.as_ref().unwrap();
            // Object 1 (its first streak leaves the frame at its start: linked all the same).
            assert_eq!(
                s[0].tracklet.as_deref(),
                Some("night/f0.fits#1"),
                "frame {k}"
            );
            assert_eq!(s[0].tracklet_index, Some(k));
            assert_eq!(
                s[1].tracklet.as_deref(),
                Some("night/f0.fits#2"),
                "frame {k}"
            );
            for (j, sign) in [(0, 1.0), (1, -1.0)] {
                assert!(s[j].direction_known, "frame {k} streak {j}");
                // ends[0] is the start: x grows with phi, so the motion's sign shows.
                let dx = s[j].ends[1].x - s[j].ends[0].x;
                assert!(dx * sign > 0.0, "frame {k} streak {j}: {dx}");
                // Times stay where they were: ends[0] at the exposure start (or edge).
                assert!(s[j].ends[1].time_utc.as_deref() == Some(T[k][1]));
            }
        }
        let last = &out[2].streaks.as_ref().unwrap()[2];
        assert_eq!(last.tracklet.as_deref(), Some("night/f2.fits#3"));
        assert!(!last.direction_known);
    }

    /// Frames of another directory are another station's: nothing links across.
    #[test]
    fn directories_are_not_linked() {
        let mut linker = Linker::new();
        let a = frame(
            "a/f0.fits",
            vec![streak(0.0, 0.02, 0.0, T[0], false, false)],
        );
        let b = frame(
            "b/f1.fits",
            vec![streak(0.03, 0.05, 0.0, T[1], false, false)],
        );
        assert!(linker.push(a).is_none());
        let a = linker.push(b).unwrap();
        let b = linker.finish().unwrap();
        assert_eq!(a.streaks.unwrap()[0].tracklet_index, Some(0));
        let s = &b.streaks.unwrap()[0];
        assert_eq!((s.tracklet_index, s.direction_known), (Some(0), false));
    }
}
