//! Every kernel parses and validates with naga under default capabilities (no optional
//! features), and every host↔WGSL struct has the same field offsets and size on both sides.

use gpustar::cpu::centroid::Blob;
use gpustar::cpu::pattern::Rows;
use gpustar::cpu::streak_filter::StreakParams;
use gpustar::cpu::threshold::{DetectParams, TileStats};
use gpustar::gpu::detect::{BatchParams, DetectUniform, StreakUniform};
use gpustar::gpu::pattern::PatternUniform;
use gpustar::gpu::psf_fit::{FitOut, PsfUniform};
use gpustar::gpu::radial::RadialUniform;
use gpustar::gpu::vote::{RowSpan, VoteUniform};
use gpustar::gpu::{KERNELS, kernel_source};
use std::mem::{offset_of, size_of};

fn module(kernel: &str) -> naga::Module {
    naga::front::wgsl::parse_str(&kernel_source(kernel).unwrap()).unwrap_or_else(|e| {
        panic!(
            "{kernel}: {}",
            e.emit_to_string(&kernel_source(kernel).unwrap())
        )
    })
}

/// (member name, offset) and size of a WGSL struct.
fn layout(m: &naga::Module, name: &str) -> (Vec<(String, u32)>, u32) {
    for (_, ty) in m.types.iter() {
        if ty.name.as_deref() == Some(name)
            && let naga::TypeInner::Struct { members, span } = &ty.inner
        {
            let fields = members
                .iter()
                .map(|f| (f.name.clone().unwrap_or_default(), f.offset))
                .collect();
            return (fields, *span);
        }
    }
    panic!("no struct {name}");
}

#[test]
fn every_kernel_validates_without_optional_capabilities() {
    for (name, _, _) in KERNELS {
        let m = module(name);
        naga::valid::Validator::new(
            naga::valid::ValidationFlags::all(),
            naga::valid::Capabilities::default(),
        )
        .validate(&m)
        .unwrap_or_else(|e| panic!("{name}: {e:?}"));
        assert!(
            m.entry_points.iter().any(|e| e.name == "main"),
            "{name}: entry point main"
        );
    }
}

macro_rules! assert_layout {
    ($module:expr, $wgsl:literal, $rust:ty, [$($field:ident),*]) => {{
        let (fields, span) = layout(&$module, $wgsl);
        let rust: Vec<(String, u32)> =
            vec![$((stringify!($field).to_string(), offset_of!($rust, $field) as u32)),*];
        assert_eq!(fields, rust, "{} vs {}", $wgsl, stringify!($rust));
        assert_eq!(span as usize, size_of::<$rust>(), "size of {}", $wgsl);
    }};
}

#[test]
fn host_and_wgsl_structs_have_the_same_layout() {
    let detect = module("centroid");
    assert_layout!(
        detect,
        "DetectParams",
        DetectParams,
        [
            width, height, tile, tiles_x, tiles_y, saturation, k_mad, matched
        ]
    );
    assert_layout!(
        detect,
        "BatchParams",
        BatchParams,
        [
            images,
            pixels_per_image,
            words_per_image,
            blocks_per_image,
            tiles_per_image,
            max_blobs,
            mask_words,
            max_set
        ]
    );
    assert_layout!(detect, "DetectUniform", DetectUniform, [p, b]);
    assert_layout!(detect, "TileStats", TileStats, [background, offset]);
    // The GPU's blob keeps each u64 moment as a (lo, hi) pair of u32: the same bytes on a
    // little-endian host.
    let (fields, span) = layout(&detect, "BlobAtomic");
    let names: Vec<&str> = fields.iter().map(|f| f.0.as_str()).collect();
    assert_eq!(names, ["label", "area", "peak", "saturated", "moments"]);
    assert_eq!(fields[0].1 as usize, offset_of!(Blob, label));
    assert_eq!(fields[1].1 as usize, offset_of!(Blob, area));
    assert_eq!(fields[2].1 as usize, offset_of!(Blob, peak));
    assert_eq!(fields[3].1 as usize, offset_of!(Blob, saturated));
    assert_eq!(fields[4].1 as usize, offset_of!(Blob, m0));
    assert_eq!(offset_of!(Blob, mx), offset_of!(Blob, m0) + 8);
    assert_eq!(offset_of!(Blob, my), offset_of!(Blob, m0) + 16);
    assert_eq!(span as usize, size_of::<Blob>());

    let psf = module("psf_fit");
    assert_layout!(psf, "PsfUniform", PsfUniform, [windows, pad0, pad1, pad2]);
    assert_layout!(
        psf,
        "Fit",
        FitOut,
        [x, y, flux, background, sigma, sx, sy, settled]
    );

    let radial = module("radial");
    assert_layout!(
        radial,
        "RadialUniform",
        RadialUniform,
        [images, stars, refs, words]
    );

    let pattern = module("pattern");
    assert_layout!(
        pattern,
        "PatternUniform",
        PatternUniform,
        [queries, keys, pad0, pad1]
    );
    assert_layout!(pattern, "Rows", Rows, [start, end]);

    let vote = module("vote");
    assert_layout!(
        vote,
        "VoteUniform",
        VoteUniform,
        [
            images,
            stars,
            refs,
            pairs_per_image,
            k,
            star_lo,
            row_lo,
            row_hi
        ]
    );
    assert_layout!(vote, "RowSpan", RowSpan, [i, j, start, end]);

    let streak = module("streak_filter");
    assert_layout!(
        streak,
        "StreakParams",
        StreakParams,
        [
            level_num, level_den, width, height, words, _pad0, _pad1, _pad2
        ]
    );
    assert_layout!(streak, "StreakUniform", StreakUniform, [p, b, s]);
}

/// The value of a WGSL `const` of a kernel (integers and floats as f64).
fn wgsl_const(kernel: &str, name: &str) -> f64 {
    let m = module(kernel);
    let (_, c) = m
        .constants
        .iter()
        .find(|(_, c)| c.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("{kernel}: no const {name}"));
    match m.global_expressions[c.init] {
        naga::Expression::Literal(l) => match l {
            naga::Literal::U32(v) => f64::from(v),
            naga::Literal::I32(v) => f64::from(v),
            naga::Literal::F32(v) => f64::from(v),
            naga::Literal::AbstractInt(v) => v as f64,
            naga::Literal::AbstractFloat(v) => v,
            other => panic!("{kernel}: {name} is {other:?}"),
        },
        ref other => panic!("{kernel}: {name} is not a literal but {other:?}"),
    }
}

/// The constants a kernel and its CPU twin (or host code) must agree on, read from both sides
/// (struct layouts are checked above; these are the numbers).
#[test]
fn wgsl_constants_equal_the_rust_ones() {
    use gpustar::cpu::psf_fit;
    let cases: &[(&str, &str, f64)] = &[
        ("radial", "BITS", gpustar::cpu::radial::BITS as f64),
        ("select", "MAX_K", gpustar::gpu::vote::MAX_K as f64),
        ("psf_fit", "HALF", psf_fit::HALF as f64),
        ("psf_fit", "SIDE", psf_fit::SIDE as f64),
        ("psf_fit", "WINDOW", psf_fit::WINDOW as f64),
        ("psf_fit", "ITERATIONS", psf_fit::ITERATIONS as f64),
        ("psf_fit", "MIN_WIDTH", f64::from(psf_fit::MIN_WIDTH as f32)),
        (
            "psf_fit",
            "WIDTH_CLAMP",
            f64::from(psf_fit::WIDTH_CLAMP as f32),
        ),
        (
            "psf_fit",
            "SQRT_2",
            f64::from(std::f64::consts::SQRT_2 as f32),
        ),
        (
            "psf_fit",
            "SQRT_2PI",
            f64::from((2.0 * std::f64::consts::PI).sqrt() as f32),
        ),
        (
            "components_merge",
            "NO_LABEL",
            f64::from(gpustar::cpu::components::NO_LABEL),
        ),
        (
            "centroid",
            "NO_LABEL",
            f64::from(gpustar::cpu::components::NO_LABEL),
        ),
        ("centroid", "BLOCK", f64::from(gpustar::gpu::detect::BLOCK)),
    ];
    for &(kernel, name, rust) in cases {
        assert_eq!(wgsl_const(kernel, name), rust, "{kernel}: {name}");
    }
}
