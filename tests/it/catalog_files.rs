//! `gpustar catalog import` and `--catalog` with the binary catalog file, through the binary.

use crate::common::{self, gpustar, run_ok};

/// `gpustar ARGS…`, which must fail; its stderr.
fn run_err(args: &[&str]) -> String {
    let out = gpustar().args(args).output().unwrap();
    assert!(!out.status.success(), "gpustar {args:?} succeeded");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn a_user_csv_imported_is_read_by_catalog_and_a_cut_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mine.csv");
    let mut text = String::from("# my stars\nid,ra_deg,dec_deg,mag,epoch\n");
    for k in 0..12 {
        text.push_str(&format!(
            "star {k},{},{},{},2005.5\n",
            30.0 * k as f64,
            5.0 * k as f64 - 30.0,
            2.0 + 0.5 * k as f64
        ));
    }
    std::fs::write(&csv, text).unwrap();
    let bin = dir.path().join("mine.gpustarcat");
    let (csv, bin) = (csv.to_str().unwrap(), bin.to_str().unwrap());
    run_ok(&["catalog", "import", csv, "--max-mag", "6.5", "-o", bin]);
    let info = run_ok(&["info", "--catalog", bin]);
    let info = String::from_utf8_lossy(&info.stdout);
    assert!(info.contains(&format!("catalog: {bin}")), "{info}");
    assert!(
        info.contains("stars: 10 (mag 2.00 to 6.50), positions at J2005.5"),
        "{info}"
    );
    // The CSV output is for hip2.dat only; a truncated binary file is refused, by name.
    let e = run_err(&["catalog", "import", csv, "-o", &format!("{bin}.csv")]);
    assert!(e.contains("hip2.dat only"), "{e}");
    let bytes = std::fs::read(bin).unwrap();
    std::fs::write(bin, &bytes[..bytes.len() - 10]).unwrap();
    let e = run_err(&["info", "--catalog", bin]);
    assert!(e.contains("truncated") && e.contains(bin), "{e}");
}

#[test]
fn the_shipped_catalog_as_a_binary_file_identifies_the_same_stars() {
    let dir = tempfile::tempdir().unwrap();
    let bin = dir.path().join("hip.gpustarcat");
    let bin = bin.to_str().unwrap();
    run_ok(&["catalog", "import", "catalog/hip2_hp9.csv", "-o", bin]);
    let sim = dir.path().join("sim");
    common::simulate_small(&sim, 2);
    let records = |catalog: Option<&str>| {
        let out = dir.path().join(format!("r{}.jsonl", catalog.is_some()));
        let mut args = common::batch18_args(&sim, &out);
        if let Some(c) = catalog {
            args.extend(["--catalog".to_string(), c.to_string()]);
        }
        run_ok(&args.iter().map(String::as_str).collect::<Vec<_>>());
        gpustar::record::read_jsonl::<gpustar::Record>(&out, "record").unwrap()
    };
    let (builtin, imported) = (records(None), records(Some(bin)));
    assert_eq!(builtin.len(), 2);
    for (a, b) in builtin.iter().zip(&imported) {
        assert_eq!(a.status, gpustar::record::Status::Solved, "{a:?}");
        let (ma, mb) = (a.matches.as_ref().unwrap(), b.matches.as_ref().unwrap());
        let ids = |m: &[gpustar::record::MatchRecord]| {
            m.iter()
                .map(|m| (m.hip, m.catalog_id.clone()))
                .collect::<Vec<_>>()
        };
        assert_eq!(ids(ma), ids(mb));
        for m in ma {
            assert_eq!(m.catalog_id, format!("HIP {}", m.hip.unwrap()));
        }
        assert!((a.ra_deg.unwrap() - b.ra_deg.unwrap()).abs() < 1e-9);
    }
}

/// A selection too deep for a lost-in-space table is refused before it is built, with what to
/// do instead (here 60,000 stars over a 120° field: about 850 million pairs).
#[test]
fn a_table_too_large_to_build_is_refused_with_the_remedy() {
    let tmp = tempfile::tempdir().unwrap();
    let csv = tmp.path().join("many.csv");
    let mut text = String::from("id,ra_deg,dec_deg,mag\n");
    for k in 0..60_000u32 {
        // A Fibonacci lattice: evenly spread, no randomness.
        let z = 1.0 - 2.0 * (k as f64 + 0.5) / 60_000.0;
        let ra = (k as f64 * 137.507_764_050_037_85) % 360.0;
        text.push_str(&format!("s{k},{ra:.6},{:.6},6.0\n", z.asin().to_degrees()));
    }
    std::fs::write(&csv, text).unwrap();
    let cat = tmp.path().join("many.cat");
    run_ok(&[
        "catalog",
        "import",
        csv.to_str().unwrap(),
        "-o",
        cat.to_str().unwrap(),
    ]);
    let err = run_err(&[
        "info",
        "--catalog",
        cat.to_str().unwrap(),
        "--fov-deg",
        "120",
        "--size",
        "1024x1024",
        "--mag-limit",
        "7",
    ]);
    assert!(
        err.contains("million pairs") && err.contains("--hint"),
        "{err}"
    );
}

/// The output of `catalog import` is written beside and renamed: never over an input, never
/// over a file that is not a catalog gpustar wrote (an image); a catalog gpustar wrote is
/// replaced; several inputs make one catalog with a star of two of them kept once.
#[test]
fn import_never_overwrites_inputs_or_other_files_and_merges_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mine.csv");
    let mut text = String::from("id,ra_deg,dec_deg,mag\n");
    for k in 0..12 {
        text.push_str(&format!(
            "s{k},{},{},{}\n",
            30.0 * k as f64,
            5.0 * k as f64 - 30.0,
            2.0 + 0.5 * k as f64
        ));
    }
    std::fs::write(&csv, &text).unwrap();
    // A second file: 4 of the same stars and 3 new ones.
    let csv2 = dir.path().join("more.csv");
    let mut more = String::from("id,ra_deg,dec_deg,mag\n");
    for k in 8..15 {
        more.push_str(&format!(
            "t{k},{},{},{}\n",
            30.0 * k as f64,
            5.0 * k as f64 - 30.0,
            2.0 + 0.5 * k as f64
        ));
    }
    std::fs::write(&csv2, &more).unwrap();
    let png = dir.path().join("frame.png");
    std::fs::write(&png, b"not really a png").unwrap();
    let p = |x: &std::path::Path| x.to_str().unwrap().to_string();
    let e = run_err(&["catalog", "import", &p(&csv), "-o", &p(&csv)]);
    assert!(e.contains("is an input"), "{e}");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), text);
    let e = run_err(&["catalog", "import", &p(&csv), "-o", &p(&png)]);
    assert!(e.contains("not a catalog gpustar wrote"), "{e}");
    assert_eq!(std::fs::read(&png).unwrap(), b"not really a png");
    let bin = dir.path().join("mine.gpustarcat");
    run_ok(&["catalog", "import", &p(&csv), "-o", &p(&bin)]);
    // Replacing a catalog gpustar wrote, from two inputs.
    let out = run_ok(&["catalog", "import", &p(&csv), &p(&csv2), "-o", &p(&bin)]);
    let said = String::from_utf8_lossy(&out.stderr);
    assert!(
        said.contains("15 stars (4 found in an earlier file left out)"),
        "{said}"
    );
    let info = run_ok(&["info", "--catalog", &p(&bin)]);
    assert!(
        String::from_utf8_lossy(&info.stdout).contains("15"),
        "{info:?}"
    );
}

/// Issue 45, item 1: rows whose values are not a star's (Dec 95, RA 1e300, proper motion,
/// epoch or magnitude ±1e300) and repeated ids are left out, counted, and the first of each
/// named, where they were taken silently; a file that starts with a UTF-8 byte-order mark is
/// read as without it, where it was refused.
#[test]
fn import_leaves_out_impossible_rows_and_repeated_ids_and_reads_a_bom() {
    let dir = tempfile::tempdir().unwrap();
    let text = "id,ra_deg,dec_deg,mag,pmra_mas_yr,pmdec_mas_yr,epoch\n\
                a,10,20,5,0,0,2000\n\
                b,10,95,5,0,0,2000\n\
                c,1e300,20,5,0,0,2000\n\
                d,20,20,5,1e300,0,2000\n\
                e,30,20,5,0,0,1e300\n\
                f,40,20,-1e300,0,0,2000\n\
                a,50,20,5,0,0,2000\n\
                g,-10,30,6,0,0,2000\n\
                h,360,-30,6,0,0,2000\n";
    for (name, bytes) in [
        ("plain", text.as_bytes().to_vec()),
        (
            "bom",
            [b"\xEF\xBB\xBF".as_slice(), text.as_bytes()].concat(),
        ),
    ] {
        let csv = dir.path().join(format!("{name}.csv"));
        std::fs::write(&csv, bytes).unwrap();
        let bin = dir.path().join(format!("{name}.gpustarcat"));
        let (csv, bin) = (csv.to_str().unwrap(), bin.to_str().unwrap());
        let out = run_ok(&["catalog", "import", csv, "-o", bin]);
        let e = String::from_utf8_lossy(&out.stderr);
        assert!(
            e.contains(&format!(
                "{csv}: CSV, 3 stars (5 out of range and 1 repeated ids left out)"
            )),
            "{e}"
        );
        assert!(
            e.contains("5 rows left out for a value out of its physical range (the first: line 3, Dec 95° is outside ±90)"),
            "{e}"
        );
        assert!(
            e.contains("1 rows left out for repeating an earlier row's id, whose first row is kept (the first: line 8, id \"a\")"),
            "{e}"
        );
        let info = run_ok(&["info", "--catalog", bin]);
        let info = String::from_utf8_lossy(&info.stdout);
        assert!(info.contains("stars: 3 (mag 5.00 to 6.00)"), "{info}");
    }
}
