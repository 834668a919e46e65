//! `batch --streaks --tle` through the real binary: the records' tracklet and name fields, the
//! exports' objects, and element files gpustar cannot use. How well streaks are linked and
//! named is measured on independent passes (scripts/sim_passes.py, docs/streaks.md).

use crate::common;

use common::{gpustar, run_records};
use std::path::Path;

/// One LEO object (checksums valid), nowhere near the simulated frames' streaks.
const TLE: &str = "ISS (ZARYA)\n\
    1 25544U 98067A   24075.50000000  .00016717  00000-0  30306-3 0  9990\n\
    2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.49815795443217\n";

#[test]
fn tle_runs_flag_uncorrelated_streaks_and_tracklets() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = common::simulated_streaks(tmp.path(), 4);
    let d = dir.to_str().unwrap();
    let tle = tmp.path().join("objects.tle");
    std::fs::write(&tle, TLE).unwrap();
    let (tdm, iod) = (tmp.path().join("out.tdm"), tmp.path().join("out.iod"));
    let batch = |tle: &Path| {
        let mut cmd = gpustar();
        cmd.args(["batch", d, "--streaks", "--backend", "cpu", "--tle"])
            .arg(tle)
            .args(["--camera", dir.join("camera.toml").to_str().unwrap()])
            .args([
                "--tdm",
                tdm.to_str().unwrap(),
                "--iod",
                iod.to_str().unwrap(),
            ]);
        cmd
    };
    let records = run_records(&mut batch(&tle));
    assert_eq!(records.len(), 4);
    let mut streaks = 0;
    for r in &records {
        for s in r["streaks"].as_array().unwrap() {
            streaks += 1;
            // Every streak is in a tracklet; with a station and times it was tested.
            assert!(s["tracklet"].as_str().unwrap().contains(".fits#"), "{s}");
            assert!(s["tracklet_index"].is_u64(), "{s}");
            assert_eq!(s["uncorrelated"], true, "{s}");
            assert!(s.get("satellite").is_none(), "{s}");
        }
    }
    assert!(streaks > 0, "the set has streaks");
    // Each tracklet one unidentified object in the IOD lines.
    let lines = std::fs::read_to_string(&iod).unwrap();
    let mut objects: Vec<&str> = lines.lines().map(|l| &l[..15]).collect();
    objects.dedup();
    let tracklets: std::collections::BTreeSet<&str> = records
        .iter()
        .flat_map(|r| r["streaks"].as_array().unwrap())
        .filter(|s| !s["mid"].is_null() || s["direction_known"] == true)
        .map(|s| s["tracklet"].as_str().unwrap())
        .collect();
    assert_eq!(objects.len(), tracklets.len(), "{lines}");
    assert!(objects.iter().all(|o| o.starts_with("999")), "{objects:?}");

    // Files that hold no usable elements stop the run before any frame, exit 2.
    for (name, text) in [
        ("empty.tle", ""),
        ("bad.json", "[{\"NORAD_CAT_ID\": 5}]"),
        ("bad.xml", "<ndm><omm><EPOCH>x</EPOCH></omm></ndm>"),
        ("garbage.tle", "1 25544U\n2 25544\n"),
    ] {
        let p = tmp.path().join(name);
        std::fs::write(&p, text).unwrap();
        let out = batch(&p).output().unwrap();
        assert_eq!(out.status.code(), Some(2), "{name}");
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            err.contains("no object with usable elements"),
            "{name}: {err}"
        );
    }
}
