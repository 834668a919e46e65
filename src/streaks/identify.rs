//! Which satellite a streak is (`--tle`): every object of the file predicted at the frame's
//! times from the frame's station, and the streak matched to the one whose path it lies on.
//!
//! The prediction is SGP4's TEME position, light time taken off, turned into the station's
//! topocentric direction ([`crate::sky::tle`]) and then into the astrometric RA/Dec a star
//! there would have (SOFA `atoc13`, airless): the inverse of the chain the streak's ends went
//! through, so that the comparison is made in the streak's own coordinates, where its ends lie
//! on one great circle whatever their times.
//!
//! A frame's prefilter is coarse: every object's position at the exposure's start and end
//! interpolated between shared coarse steps ([`TleCatalog::coarse_positions`]), kept when the
//! streak's visible middle is within its tolerances (plus the visible half-length and the
//! along-track tolerance at the object's rate) of that path. The objects kept are propagated
//! exactly and tested both ways along the streak (one frame does not say which end came
//! first): the ends' distance across the predicted path (`cross_track_arcsec`, the largest),
//! and the inside ends' time offset along it (`along_track_s`, positive when the object is
//! ahead of its elements), and, with both ends inside, the rate (within 10 %). The best match
//! within both tolerances names the streak; when only one way along the streak matches, it
//! also fixes the direction.

use crate::record::{SatelliteRecord, StreakRecord};
use crate::sky::tle::{Satellite, TleCatalog, Topocentre, az_el_of, seen};
use crate::sky::{Exposure, Station, Utc};

/// How close a streak must lie to an object's predicted path to be named for it.
#[derive(Clone, Copy, Debug)]
pub struct IdentifySettings {
    /// Largest distance of an end across the path (arcsec): elements days old are off by
    /// kilometres, a few arcminutes at a low orbit's range.
    pub cross_arcsec: f64,
    /// Largest time offset along the path (seconds): along-track errors grow fastest. The
    /// offset allowed grows with the elements' age up to this ([`along_tolerance_s`]).
    pub along_s: f64,
}

/// The time offset along the path allowed at the elements' epoch (seconds: 15 km at a low
/// orbit's 7.5 km/s; elements fitted to a day of tracking are off by a few km along-track)
/// and its growth per day of age (drag they model poorly: LEO elements drift a few km a day).
/// Two objects that pass one line in one frame (opposite ways, 85″ apart) were told apart only
/// by this: the wrong one's offset was 4 s against elements of that hour.
const ALONG_AT_EPOCH_S: f64 = 2.0;
const ALONG_PER_DAY_S: f64 = 1.0;

/// The along-track tolerance for elements `age_days` old: [`ALONG_AT_EPOCH_S`] growing by
/// [`ALONG_PER_DAY_S`] a day, up to `IdentifySettings::along_s`.
pub fn along_tolerance_s(s: &IdentifySettings, age_days: f64) -> f64 {
    (ALONG_AT_EPOCH_S + ALONG_PER_DAY_S * age_days).min(s.along_s)
}

impl IdentifySettings {
    /// The defaults (`Default`), as a constant: the run configuration's (`config`) come
    /// from here.
    pub const DEFAULT: IdentifySettings = IdentifySettings {
        cross_arcsec: 300.0,
        along_s: 5.0,
    };
}

impl Default for IdentifySettings {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Largest relative difference of the streak's rate from the predicted one.
const RATE_TOL: f64 = 0.10;
/// A streak with both ends inside that covers less of the predicted path than 1 − `RATE_TOL`
/// is a partial match when all of it lies on the path the exposure covers, widened by the
/// along-track tolerance: a tumbling object dark at the start or end of its exposure. Added to
/// its score, so that any whole match is the better.
const PARTIAL_PENALTY: f64 = 2.0;

/// A frame's view of the objects: its times and the station's frame at each.
pub struct FrameSky<'a> {
    pub catalog: &'a TleCatalog,
    pub station: Station,
    pub exposure: Exposure,
    pub dut1_s: f64,
    pub xp: f64,
    pub yp: f64,
}

fn unit(ra_deg: f64, dec_deg: f64) -> [f64; 3] {
    let (r, d) = (ra_deg.to_radians(), dec_deg.to_radians());
    [d.cos() * r.cos(), d.cos() * r.sin(), d.sin()]
}

fn dot(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn cross(a: &[f64; 3], b: &[f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn normalized(a: [f64; 3]) -> Option<[f64; 3]> {
    let n = dot(&a, &a).sqrt();
    (n > 1e-15).then(|| a.map(|v| v / n))
}

fn angle(a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let c = cross(a, b);
    dot(&c, &c).sqrt().atan2(dot(a, b))
}

/// One streak as the matcher reads it: its ends' directions and which have a time.
struct Observed {
    /// ICRS unit vectors of the two ends (edge ends too: they lie on the path).
    ends: [[f64; 3]; 2],
    /// Which ends are inside the frame (the object was there at the exposure's start or end).
    inside: [bool; 2],
}

/// The result of testing one object against one streak, one way along it.
#[derive(Clone, Copy, Debug)]
struct Fit {
    cross_arcsec: f64,
    along_s: f64,
    /// A partial match's share of the predicted path (see [`PARTIAL_PENALTY`]).
    seen_fraction: Option<f64>,
    reversed: bool,
    score: f64,
}

impl FrameSky<'_> {
    fn topo(&self, t: &Utc) -> Option<Topocentre> {
        Topocentre::new(t, &self.station, self.dut1_s, self.xp, self.yp)
    }

    /// The astrometric ICRS direction a star would have where `sat` is seen at `t`.
    fn predicted(&self, sat: &Satellite, t: &Utc, topo: &Topocentre) -> Option<[f64; 3]> {
        // atoc13 panics past its ephemeris' end (2100).
        t.plausible().ok()?;
        let (az, el) = az_el_of(&seen(sat, t, topo)?);
        let s = &self.station;
        let (ra, dec) = sofars::astro::atoc13(
            "A",
            az.to_radians(),
            (90.0 - el).to_radians(),
            t.jd1,
            t.jd2,
            self.dut1_s,
            s.lon_deg.to_radians(),
            s.lat_deg.to_radians(),
            s.height_m,
            self.xp,
            self.yp,
            0.0,
            0.0,
            0.0,
            0.55,
        )
        .ok()?;
        Some(unit(ra.to_degrees(), dec.to_degrees()))
    }

    /// Name the streaks of one frame (those with RA/Dec on both ends), fixing the direction
    /// of those only one way along matches. Streaks this frame cannot test (no RA/Dec) are
    /// left as they are.
    pub fn identify(&self, streaks: &mut [StreakRecord], s: &IdentifySettings) {
        let observed: Vec<Option<Observed>> = streaks.iter().map(observe).collect();
        if observed.iter().all(Option::is_none) {
            return;
        }
        let (t0, t1) = (self.exposure.start, self.exposure.end);
        let (Some(topo0), Some(topo1)) = (self.topo(&t0), self.topo(&t1)) else {
            return;
        };
        if let Some(w) = self.catalog.age_warning(&t0) {
            tracing::warn!("{w}");
        }
        let dt = self.exposure.duration_s().max(1e-3);
        let coarse0 = self.catalog.coarse_positions(&t0);
        let coarse1 = self.catalog.coarse_positions(&t1);
        for (rec, obs) in streaks.iter_mut().zip(&observed) {
            let Some(obs) = obs else { continue };
            // The visible middle, in the station's frame at mid-exposure (a star's Az/El
            // differ from a satellite's by aberration only: far inside the margin).
            let Some(mid_enu) = mid_direction(
                rec,
                &self.station,
                &self.exposure,
                self.dut1_s,
                self.xp,
                self.yp,
            ) else {
                continue;
            };
            let half = 0.5 * angle(&obs.ends[0], &obs.ends[1]);
            let mut best: Option<(usize, Fit, bool)> = None;
            for (k, sat) in self.catalog.satellites.iter().enumerate() {
                let (Some(p0), Some(p1)) = (coarse0[k], coarse1[k]) else {
                    continue;
                };
                let (a, b) = (topo0.direction(&p0).0, topo1.direction(&p1).0);
                if a[2] < -0.2 && b[2] < -0.2 {
                    continue;
                }
                let rate = angle(&a, &b) / dt;
                let margin = half
                    + (s.along_s + dt) * rate
                    + s.cross_arcsec.to_radians() / 3600.0
                    + 0.2f64.to_radians();
                let d = distance_to_arc(&mid_enu, &a, &b);
                // A path that cannot be measured (NaN) is no candidate either.
                if d.is_nan() || d > margin {
                    continue;
                }
                let (Some(q0), Some(q1)) = (
                    self.predicted(sat, &t0, &topo0),
                    self.predicted(sat, &t1, &topo1),
                ) else {
                    continue;
                };
                let aged = IdentifySettings {
                    along_s: along_tolerance_s(s, sat.age_days(&t0)),
                    ..*s
                };
                let fits = [false, true].map(|rev| fit(obs, &q0, &q1, dt, rev, &aged));
                let ok: Vec<Fit> = fits.iter().flatten().copied().collect();
                let Some(f) = ok
                    .iter()
                    .copied()
                    .min_by(|a, b| a.score.total_cmp(&b.score))
                else {
                    continue;
                };
                if best.is_none_or(|(_, b, _)| f.score < b.score) {
                    best = Some((k, f, ok.len() == 1));
                }
            }
            match best {
                Some((k, f, one_way)) => {
                    let sat = &self.catalog.satellites[k];
                    rec.satellite = Some(SatelliteRecord {
                        norad: sat.norad,
                        name: sat.name.clone(),
                        intl_des: sat.intl_des.clone(),
                        cross_track_arcsec: f.cross_arcsec,
                        along_track_s: f.along_s,
                        seen_fraction: f.seen_fraction,
                    });
                    rec.uncorrelated = Some(false);
                    if one_way && !rec.direction_known && (!f.reversed || rec.reverse()) {
                        rec.direction_known = true;
                    }
                }
                None => rec.uncorrelated = Some(true),
            }
        }
    }
}

/// The streak's ends as unit vectors, or `None` without RA/Dec on both.
fn observe(r: &StreakRecord) -> Option<Observed> {
    let e = |k: usize| Some(unit(r.ends[k].ra_deg?, r.ends[k].dec_deg?));
    Some(Observed {
        ends: [e(0)?, e(1)?],
        inside: [0, 1].map(|k| r.ends[k].edge != Some(true)),
    })
}

/// The visible middle of the streak as an (east, north, up) unit vector at mid-exposure.
fn mid_direction(
    r: &StreakRecord,
    station: &Station,
    exposure: &Exposure,
    dut1_s: f64,
    xp: f64,
    yp: f64,
) -> Option<[f64; 3]> {
    let (a, b) = (&r.ends[0], &r.ends[1]);
    let (u, v) = (unit(a.ra_deg?, a.dec_deg?), unit(b.ra_deg?, b.dec_deg?));
    let m = normalized([0, 1, 2].map(|i| u[i] + v[i]))?;
    let ra = m[1].atan2(m[0]).to_degrees().rem_euclid(360.0);
    let dec = m[2].clamp(-1.0, 1.0).asin().to_degrees();
    let (az, el) = crate::sky::az_el(ra, dec, &exposure.mid(), station, dut1_s, xp, yp).ok()?;
    Some(crate::sky::tle::enu_of(az, el))
}

/// Angular distance from `p` to the great-circle arc from `a` to `b`.
fn distance_to_arc(p: &[f64; 3], a: &[f64; 3], b: &[f64; 3]) -> f64 {
    let Some(n) = normalized(cross(a, b)) else {
        return angle(p, a);
    };
    // Inside the arc's span when p's projection falls between a and b.
    let c = cross(&n, p);
    let between = dot(&cross(a, p), &n) >= 0.0 && dot(&cross(p, b), &n) >= 0.0 && dot(&c, &c) > 0.0;
    if between {
        dot(p, &n).clamp(-1.0, 1.0).asin().abs()
    } else {
        angle(p, a).min(angle(p, b))
    }
}

/// How a streak lies on the path from `q0` (exposure start) to `q1` (end), with its end 0 at
/// the start (`reversed`: end 1); `None` outside the tolerances.
fn fit(
    o: &Observed,
    q0: &[f64; 3],
    q1: &[f64; 3],
    dt: f64,
    reversed: bool,
    s: &IdentifySettings,
) -> Option<Fit> {
    let n = normalized(cross(q0, q1))?;
    let arc = angle(q0, q1);
    let rate = arc / dt;
    if rate <= 0.0 {
        return None;
    }
    let along_dir = cross(&n, q0);
    // Where along the path (angle from q0) each end lies, and how far across.
    let phi = |v: &[f64; 3]| dot(v, &along_dir).atan2(dot(v, q0));
    let (first, second) = if reversed { (1, 0) } else { (0, 1) };
    let mut worst_cross: f64 = 0.0;
    let mut signed_cross = 0.0;
    for v in &o.ends {
        let c = dot(v, &n).clamp(-1.0, 1.0).asin().to_degrees() * 3600.0;
        signed_cross += 0.5 * c;
        worst_cross = worst_cross.max(c.abs());
    }
    let mut along = Vec::new();
    if o.inside[first] {
        along.push(phi(&o.ends[first]) / rate);
    }
    if o.inside[second] {
        along.push((phi(&o.ends[second]) - arc) / rate);
    }
    if along.is_empty() {
        return None;
    }
    let mut seen_fraction = None;
    let mut along_s = along.iter().sum::<f64>() / along.len() as f64;
    if o.inside[0] && o.inside[1] {
        let seen = (phi(&o.ends[second]) - phi(&o.ends[first])) / arc;
        if seen <= 0.0 || seen > 1.0 + RATE_TOL {
            return None;
        }
        if seen < 1.0 - RATE_TOL {
            // The offsets that keep the streak within the exposure's path: from its later
            // end's at the exposure's end (along[1]) to its earlier end's at the start.
            seen_fraction = Some(seen);
            along_s = 0f64.clamp(along[1], along[0]);
        }
    }
    if worst_cross > s.cross_arcsec || along_s.abs() > s.along_s {
        return None;
    }
    let penalty = if seen_fraction.is_some() {
        PARTIAL_PENALTY
    } else {
        0.0
    };
    Some(Fit {
        cross_arcsec: signed_cross,
        along_s,
        seen_fraction,
        reversed,
        score: worst_cross / s.cross_arcsec + along_s.abs() / s.along_s + penalty,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points along a path fitted both ways: the right way matches with the offsets put in,
    /// the wrong way is refused (its rate has the opposite sign).
    #[test]
    fn fit_tells_the_direction_and_offsets() {
        let q0 = unit(10.0, 20.0);
        let q1 = unit(10.5, 20.2);
        let dt = 4.0;
        let n = normalized(cross(&q0, &q1)).unwrap();
        // The object 0.3 s ahead and 20 arcsec across.
        let rate = angle(&q0, &q1) / dt;
        let along_dir = cross(&n, &q0);
        let at = |phi: f64, c: f64| {
            normalized([0, 1, 2].map(|i| {
                q0[i] * phi.cos() + along_dir[i] * phi.sin() + n[i] * (c / 3600f64).to_radians()
            }))
            .unwrap()
        };
        let o = Observed {
            ends: [at(0.3 * rate, 20.0), at(angle(&q0, &q1) + 0.3 * rate, 20.0)],
            inside: [true, true],
        };
        let s = IdentifySettings::default();
        let f = fit(&o, &q0, &q1, dt, false, &s).expect("the right way matches");
        assert!((f.along_s - 0.3).abs() < 1e-6, "{f:?}");
        assert!((f.cross_arcsec - 20.0).abs() < 1e-3, "{f:?}");
        assert!(fit(&o, &q0, &q1, dt, true, &s).is_none());
        // Beyond the along-track tolerance: refused.
        let far = Observed {
            ends: [at(6.0 * rate, 0.0), at(angle(&q0, &q1) + 6.0 * rate, 0.0)],
            inside: [true, true],
        };
        assert!(fit(&far, &q0, &q1, dt, false, &s).is_none());
    }

    /// The along-track tolerance: 2 s at the elements' epoch, a second more a day, at most
    /// `--tle-along`.
    #[test]
    fn the_along_track_tolerance_grows_with_the_elements_age() {
        let s = IdentifySettings::default();
        assert_eq!(along_tolerance_s(&s, 0.0), 2.0);
        assert_eq!(along_tolerance_s(&s, 1.5), 3.5);
        assert_eq!(along_tolerance_s(&s, 400.0), s.along_s);
        let tight = IdentifySettings { along_s: 1.0, ..s };
        assert_eq!(along_tolerance_s(&tight, 0.0), 1.0);
    }

    /// A streak lit over 40 % of the exposure's path (a tumbling object dark at the start):
    /// matched as partial, with its share and the least offset that keeps it on the path; the
    /// wrong way, past the along-track tolerance, or longer than the path, refused.
    #[test]
    fn a_streak_dark_over_part_of_its_exposure_is_a_partial_match() {
        let (q0, q1, dt) = (unit(10.0, 20.0), unit(10.5, 20.2), 4.0);
        let arc = angle(&q0, &q1);
        let n = normalized(cross(&q0, &q1)).unwrap();
        let along_dir = cross(&n, &q0);
        let at = |phi: f64| {
            normalized([0, 1, 2].map(|i| q0[i] * phi.cos() + along_dir[i] * phi.sin())).unwrap()
        };
        let seen = |a: f64, b: f64| Observed {
            ends: [at(a * arc), at(b * arc)],
            inside: [true, true],
        };
        let s = IdentifySettings::default();
        let f = fit(&seen(0.5, 0.9), &q0, &q1, dt, false, &s).expect("partial");
        assert!((f.seen_fraction.unwrap() - 0.4).abs() < 1e-9, "{f:?}");
        assert!(
            f.along_s.abs() < 1e-9 && f.score >= PARTIAL_PENALTY,
            "{f:?}"
        );
        assert!(fit(&seen(0.5, 0.9), &q0, &q1, dt, true, &s).is_none());
        // Beyond the exposure's end by 0.2 of the path (0.8 s): that much ahead at least.
        let late = fit(&seen(0.8, 1.2), &q0, &q1, dt, false, &s).expect("partial");
        assert!((late.along_s - 0.8).abs() < 1e-6, "{late:?}");
        // Beyond it by 1.5 paths (6 s, over the 5 s tolerance), or longer than the path.
        assert!(fit(&seen(2.2, 2.5), &q0, &q1, dt, false, &s).is_none());
        assert!(fit(&seen(0.0, 1.2), &q0, &q1, dt, false, &s).is_none());
        // A whole streak is no partial one.
        let whole = fit(&seen(0.0, 1.0), &q0, &q1, dt, false, &s).expect("whole");
        assert!(
            whole.seen_fraction.is_none() && whole.score < 1e-6,
            "{whole:?}"
        );
    }
}

#[cfg(test)]
mod chain_tests {
    use super::*;
    use crate::record::StreakEnd;

    const ISS: &str = "ISS (ZARYA)\n\
        1 25544U 98067A   24075.50000000  .00016717  00000-0  30306-3 0  9990\n\
        2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.49815795443217\n\
        OTHER\n\
        1 43013U 17073A   24075.50000000  .00000000  00000-0  10000-3 0  9996\n\
        2 43013  98.7000  10.0000 0012000  90.0000 200.0000 14.20000000    09\n";

    fn end(v: [f64; 3], t: &str) -> StreakEnd {
        StreakEnd {
            x: 0.0,
            y: 0.0,
            ra_deg: Some(v[1].atan2(v[0]).to_degrees().rem_euclid(360.0)),
            dec_deg: Some(v[2].asin().to_degrees()),
            edge: Some(false),
            time_utc: Some(t.to_string()),
            az_deg: None,
            el_deg: None,
        }
    }

    /// A streak where the ISS is predicted (read back from its own elements, written the
    /// wrong way round) is named for it, turned, and offset by nothing; 20 s further along
    /// its path it is no one's.
    #[test]
    fn names_the_object_and_its_direction() {
        let cat = TleCatalog::from_text(ISS, "test").unwrap();
        // Where the ISS is above Graz at some moment of that day.
        let station = Station {
            lat_deg: 47.0678,
            lon_deg: 15.4933,
            height_m: 493.0,
        };
        let (t0, sky) = (0..2880)
            .find_map(|k| {
                let t = Utc::parse("2024-03-15T12:00:00")
                    .unwrap()
                    .add_seconds(30.0 * k as f64);
                let topo = Topocentre::new(&t, &station, 0.0, 0.0, 0.0)?;
                let d = seen(&cat.satellites[0], &t, &topo)?;
                (d[2] > 0.5).then_some(t)
            })
            .map(|t| {
                let exposure = Exposure {
                    start: t,
                    end: t.add_seconds(2.0),
                };
                (
                    t,
                    FrameSky {
                        catalog: &cat,
                        station,
                        exposure,
                        dut1_s: 0.0,
                        xp: 0.0,
                        yp: 0.0,
                    },
                )
            })
            .expect("a pass in a day");
        let t1 = t0.add_seconds(2.0);
        let at = |t: &Utc| {
            let topo = sky.topo(t).unwrap();
            sky.predicted(&cat.satellites[0], t, &topo).unwrap()
        };
        let streak = |shift: f64| {
            let (a, b) = (t0.add_seconds(shift), t1.add_seconds(shift));
            let (p0, p1) = (at(&a), at(&b));
            // Written end first, as one frame may have it.
            StreakRecord::for_tests(
                [end(p1, &t0.iso()), end(p0, &t1.iso())],
                [end(p0, &t0.iso()), end(p1, &t1.iso())],
                100.0,
                None,
            )
        };
        let mut s = [streak(0.0), streak(20.0), streak(1.5), streak(3.5)];
        sky.identify(&mut s, &IdentifySettings::default());
        // Elements hours old: 1.5 s along is theirs, 3.5 s is beyond what such elements are
        // off by (the 5 s of `--tle-along` is for elements days old).
        let age = cat.satellites[0].age_days(&t0);
        assert!(age < 1.0, "{age}");
        let near = s[2].satellite.as_ref().expect("1.5 s along: named");
        assert!((near.along_track_s - 1.5).abs() < 0.05, "{near:?}");
        assert!(s[3].satellite.is_none(), "{:?}", s[3].satellite);
        let sat = s[0].satellite.as_ref().expect("named");
        assert_eq!((sat.norad, sat.name.as_str()), (25544, "ISS (ZARYA)"));
        assert!(
            sat.along_track_s.abs() < 0.01 && sat.cross_track_arcsec.abs() < 1.0,
            "{sat:?}"
        );
        assert!(s[0].direction_known);
        assert_eq!(s[0].ends[0].time_utc.as_deref(), Some(t0.iso().as_str()));
        assert_eq!(s[0].uncorrelated, Some(false));
        assert!(s[1].satellite.is_none(), "{:?}", s[1].satellite);
        assert_eq!(s[1].uncorrelated, Some(true));
    }
}
