//! Which backend `auto` takes: the GPU, except that a software rasterizer (lavapipe, the only
//! adapter in CI) loses to the CPU twins; `--backend gpu` still takes it. And the Vulkan
//! driver's complaint about a missing runtime directory stays off stderr unless `-v`.

use crate::common;

use gpustar::pipeline::{Backend, BackendChoice, BackendNote};

#[test]
fn auto_prefers_the_cpu_twins_to_a_software_rasterizer() {
    let Some(g) = common::gpu("auto_prefers_the_cpu_twins_to_a_software_rasterizer") else {
        return;
    };
    let software = g.adapter.software;
    drop(g);
    if std::env::var_os("GPUSTAR_ADAPTER").is_some() {
        eprintln!(
            "SKIPPED auto_prefers_the_cpu_twins_to_a_software_rasterizer: GPUSTAR_ADAPTER is set"
        );
        return;
    }
    let (auto, note) = Backend::open(BackendChoice::Auto).unwrap();
    let (gpu, _) = Backend::open(BackendChoice::Gpu).unwrap();
    assert!(matches!(gpu, Backend::Gpu(_)));
    if software {
        assert!(matches!(auto, Backend::Cpu));
        assert!(matches!(note, Some(BackendNote::Info(i)) if i.contains("software rasterizer")));
    } else {
        assert!(matches!(auto, Backend::Gpu(_)));
        assert_eq!(note, None);
    }
}

#[test]
fn the_driver_says_nothing_on_stderr_without_v() {
    if common::gpu("the_driver_says_nothing_on_stderr_without_v").is_none() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("sim");
    common::simulate(&dir, &["-n", "1", "--size", "256x256"]);
    let frame = dir.join(gpustar::simulate::frame_name(0));
    for backend in ["auto", "gpu"] {
        let out = common::gpustar()
            .env_remove("XDG_RUNTIME_DIR")
            .arg("solve")
            .arg(&frame)
            .args(["--fov-deg", "18", "-q", "--backend", backend])
            .output()
            .unwrap();
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!stderr.contains("XDG_RUNTIME_DIR"), "{backend}: {stderr}");
    }
}

#[test]
fn info_says_what_each_backend_runs_on() {
    let Some(g) = common::gpu("info_says_what_each_backend_runs_on") else {
        return;
    };
    let software = g.adapter.software;
    drop(g);
    if std::env::var_os("GPUSTAR_ADAPTER").is_some() {
        eprintln!("SKIPPED info_says_what_each_backend_runs_on: GPUSTAR_ADAPTER is set");
        return;
    }
    let out = common::gpustar().arg("info").output().unwrap();
    assert!(out.status.success(), "{}", common::stderr(&out));
    let text = String::from_utf8(out.stdout).unwrap();
    let line = |start: &str| {
        text.lines()
            .find(|l| l.starts_with(start))
            .unwrap_or_else(|| panic!("no {start:?} line in:\n{text}"))
    };
    assert!(
        !line("--backend gpu: ").starts_with("--backend gpu: none"),
        "{text}"
    );
    // `auto` on a software rasterizer (lavapipe) is the CPU, as `batch` runs it.
    let auto = line("--backend auto (the default): ");
    assert_eq!(
        auto.contains(": cpu (") && auto.contains("software rasterizer"),
        software,
        "{text}"
    );
    assert!(!text.contains("chosen"), "{text}");
}
