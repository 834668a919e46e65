//! What `batch` takes (issue 47): several directories, image files, `@LIST` files and `-`
//! (a list on standard input); every input one record, named by its path as given.

use crate::common;
use std::io::Write;
use std::process::Stdio;

fn names(records: &[serde_json::Value]) -> Vec<(String, String)> {
    records
        .iter()
        .map(|r| {
            (
                r["file"].as_str().unwrap().to_string(),
                r["status"].as_str().unwrap().to_string(),
            )
        })
        .collect()
}

#[test]
fn batch_takes_folders_files_lists_and_stdin() {
    let tmp = tempfile::tempdir().unwrap();
    let (a, b) = (tmp.path().join("a"), tmp.path().join("b"));
    common::simulate_small(&a, 2);
    common::simulate_small(&b, 1);
    let batch = |args: &[&str], stdin: &str| {
        let mut c = common::gpustar();
        c.current_dir(tmp.path())
            .arg("batch")
            .args(args)
            .args(["--fov-deg", "18", "--backend", "cpu", "-q"])
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped());
        let mut child = c.spawn().unwrap();
        child
            .stdin
            .take()
            .unwrap()
            .write_all(stdin.as_bytes())
            .unwrap();
        let out = child.wait_with_output().unwrap();
        let records: Vec<serde_json::Value> = String::from_utf8(out.stdout.clone())
            .unwrap()
            .lines()
            .map(|l| serde_json::from_str(l).unwrap())
            .collect();
        (out.status.code(), names(&records), common::stderr(&out))
    };
    let solved = |n: &str| (n.to_string(), "solved".to_string());

    // One folder: names relative to it, as always.
    let (code, got, _) = batch(&["a"], "");
    assert_eq!(code, Some(0));
    assert_eq!(got, [solved("sim_00000.png"), solved("sim_00001.png")]);
    // Two folders, and a file: each by its path as given, sorted by name.
    let (code, got, _) = batch(&["b", "./a", "a/sim_00001.png"], "");
    assert_eq!(code, Some(0));
    assert_eq!(
        got,
        [
            solved("a/sim_00000.png"),
            solved("a/sim_00001.png"),
            solved("b/sim_00000.png")
        ],
        "a file given twice is taken once"
    );
    // A list file with a comment, a blank line and a file that is not there: its record is an
    // error (exit 1), the others are solved.
    std::fs::write(
        tmp.path().join("list.txt"),
        "# tonight's frames\nb/sim_00000.png\n\na/gone.png\r\n",
    )
    .unwrap();
    let (code, got, _) = batch(&["@list.txt"], "");
    assert_eq!(code, Some(1));
    assert_eq!(
        got,
        [
            ("a/gone.png".to_string(), "error".to_string()),
            solved("b/sim_00000.png")
        ]
    );
    // The list on standard input, beside a folder.
    let (code, got, _) = batch(&["-", "b"], "a/sim_00000.png\n");
    assert_eq!(code, Some(0));
    assert_eq!(got, [solved("a/sim_00000.png"), solved("b/sim_00000.png")]);
    // An argument that is not there stops the run before any work; so does a missing list.
    for args in [&["a", "nothere"][..], &["@nolist.txt"][..]] {
        let (code, got, err) = batch(args, "");
        assert_eq!(code, Some(2), "{args:?}: {err}");
        assert!(got.is_empty(), "{args:?}");
        assert!(
            err.contains("nothere") || err.contains("nolist.txt"),
            "{err}"
        );
    }
    // Images written where any of the folders is read (recursively) are refused before any
    // work, as for one folder: the next run would take them for frames.
    let (code, _, err) = batch(&["a", "b", "-r", "--annotate-dir", "b/marked"], "");
    assert_eq!(code, Some(2), "{err}");
    assert!(!tmp.path().join("b/marked").exists());
}
