//! `-h`/`--help` show the options most runs need, grouped; `--help-all` every option in full
//! (issue 50: `batch --help` was 244 lines).

use crate::common;

fn help(args: &[&str]) -> String {
    let out = common::gpustar().args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", common::stderr(&out));
    String::from_utf8(out.stdout).unwrap()
}

#[test]
fn short_help_is_the_common_options_grouped() {
    for cmd in ["batch", "solve"] {
        let short = help(&[cmd, "--help"]);
        assert_eq!(short, help(&[cmd, "-h"]), "{cmd}");
        let lines = short.lines().count();
        assert!(lines <= 80, "{cmd} --help is {lines} lines:\n{short}");
        for heading in ["Camera and sky:", "Output:", "Run:", "Streaks:"] {
            assert!(short.contains(heading), "{cmd}: no {heading}\n{short}");
        }
        for common in [
            "--camera",
            "--fov-deg",
            "--catalog",
            "--hint",
            "--backend",
            "--wcs-dir",
        ] {
            assert!(short.contains(common), "{cmd}: {common} missing\n{short}");
        }
        // Rare options wait for --help-all, which the short help names.
        for rare in [
            "--scale-tol",
            "--wide-min-stars",
            "--tle-cross",
            "--pixel-aspect",
        ] {
            assert!(!short.contains(rare), "{cmd}: {rare} in the short help");
        }
        assert!(short.contains("--help-all"), "{cmd}\n{short}");
    }
}

#[test]
fn help_all_lists_every_option_in_full() {
    let all = help(&["batch", "--help-all"]);
    for opt in [
        "--scale-tol",
        "--wide-min-stars",
        "--tle-cross",
        "--pixel-aspect",
        "--max-megapixels",
        "--retry-errors",
        "--frame-interval",
    ] {
        assert!(all.contains(opt), "{opt} missing from --help-all");
    }
    // The full text, not only the summary line.
    assert!(
        all.contains("an incomplete last line, left by a crash"),
        "{all}"
    );
    // Every option the README's table names is there.
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let table = &readme[readme.find("Options of `batch` and `solve`").unwrap()..];
    let table = &table[..table.find("Exit status").unwrap()];
    for opt in table
        .split('`')
        .filter_map(|w| w.strip_prefix("--"))
        .map(|w| w.split([' ', '=']).next().unwrap())
    {
        assert!(
            all.contains(&format!("--{opt}")),
            "README's --{opt} is not in --help-all"
        );
    }
}
