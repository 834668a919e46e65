// Stage psf_fit (CPU twin: src/cpu/psf_fit.rs, in f64): the maximum-likelihood fit of a
// pixel-integrated Gaussian (x0, y0, flux, background, sigma) to a star's 9x9 window, a fixed
// number of damped Fisher-scoring steps, each solved by Cholesky on the Jacobi-scaled
// information; the position's 1-sigma from the inverse information. One thread per window;
// threads stride over all windows of the batch. Positions are relative to the window's centre
// pixel, so f32 keeps ~1e-6 px.

// Keep in sync with src/gpu/psf_fit.rs (PsfUniform).
struct PsfUniform {
    windows: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

// Keep in sync with src/gpu/psf_fit.rs (FitOut).
struct Fit {
    x: f32,
    y: f32,
    flux: f32,
    background: f32,
    sigma: f32,
    sx: f32,
    sy: f32,
    settled: u32,
}

// Keep in sync with src/cpu/psf_fit.rs (HALF, SIDE, WINDOW, ITERATIONS, MIN_WIDTH, WIDTH_CLAMP).
const HALF: i32 = 4;
const SIDE: u32 = 9u;
const WINDOW: u32 = 81u;
const ITERATIONS: u32 = 6u;
const MIN_WIDTH: f32 = 0.15;
const WIDTH_CLAMP: f32 = 0.1;
const SQRT_2: f32 = 1.4142135;
const SQRT_2PI: f32 = 2.5066283;

@group(0) @binding(0) var<uniform> u: PsfUniform;
@group(0) @binding(1) var<storage, read> pixels: array<u32>;
@group(0) @binding(2) var<storage, read> starts: array<vec2<f32>>;
@group(0) @binding(3) var<storage, read_write> fits: array<Fit>;

// erfc(z) for z >= 0, relative error < 1.2e-7 (Numerical Recipes' erfcc, a Chebyshev fit).
fn erfc_pos(z: f32) -> f32 {
    let t = 1.0 / (1.0 + 0.5 * z);
    let p = -1.26551223 + t * (1.00002368 + t * (0.37409196 + t * (0.09678418 + t * (-0.18628806
        + t * (0.27886807 + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223
        + t * 0.17087277))))))));
    return t * exp(-z * z + p);
}

fn pdf(v: f32, s: f32) -> f32 {
    let r = v / s;
    return exp(-0.5 * r * r) / (s * SQRT_2PI);
}

// Per column (or row) k: (P_k, dP_k/dcentre, dP_k/dsigma) from the 10 pixel edges
// e_j = j - 4.5 - centre, with q_j the tail beyond |e_j| (no cancellation) and g_j the density.
fn axis(centre: f32, s: f32) -> array<vec3<f32>, 9> {
    var e: array<f32, 10>;
    var q: array<f32, 10>;
    var g: array<f32, 10>;
    for (var j = 0u; j <= SIDE; j++) {
        e[j] = f32(i32(j) - HALF) - 0.5 - centre;
        q[j] = 0.5 * erfc_pos(abs(e[j]) / (s * SQRT_2));
        g[j] = pdf(e[j], s);
    }
    var out: array<vec3<f32>, 9>;
    for (var k = 0u; k < SIDE; k++) {
        var share: f32;
        if (e[k] >= 0.0) {
            share = q[k] - q[k + 1u];
        } else if (e[k + 1u] <= 0.0) {
            share = q[k + 1u] - q[k];
        } else {
            share = 1.0 - q[k + 1u] - q[k];
        }
        out[k] = vec3<f32>(share, g[k] - g[k + 1u], (e[k] * g[k] - e[k + 1u] * g[k + 1u]) / s);
    }
    return out;
}

// Solve F z = g (F symmetric, 5x5, row-major): Cholesky of D^-1/2 F D^-1/2; false when F is
// not positive definite.
fn solve(f: ptr<function, array<f32, 25>>, g: ptr<function, array<f32, 5>>,
         z: ptr<function, array<f32, 5>>) -> bool {
    var dinv: array<f32, 5>;
    for (var i = 0u; i < 5u; i++) {
        let fii = (*f)[i * 5u + i];
        if (!(fii > 0.0)) {
            return false;
        }
        dinv[i] = 1.0 / sqrt(fii);
    }
    var l: array<f32, 25>;
    for (var i = 0u; i < 5u; i++) {
        for (var j = 0u; j <= i; j++) {
            var sum = (*f)[i * 5u + j] * dinv[i] * dinv[j];
            for (var k = 0u; k < j; k++) {
                sum -= l[i * 5u + k] * l[j * 5u + k];
            }
            if (i == j) {
                if (!(sum > 0.0)) {
                    return false;
                }
                l[i * 5u + i] = sqrt(sum);
            } else {
                l[i * 5u + j] = sum / l[j * 5u + j];
            }
        }
    }
    var y: array<f32, 5>;
    for (var i = 0u; i < 5u; i++) {
        var sum = (*g)[i] * dinv[i];
        for (var k = 0u; k < i; k++) {
            sum -= l[i * 5u + k] * y[k];
        }
        y[i] = sum / l[i * 5u + i];
    }
    for (var ii = 0u; ii < 5u; ii++) {
        let i = 4u - ii;
        var sum = y[i];
        for (var k = i + 1u; k < 5u; k++) {
            sum -= l[k * 5u + i] * (*z)[k];
        }
        (*z)[i] = sum / l[i * 5u + i];
    }
    for (var i = 0u; i < 5u; i++) {
        (*z)[i] *= dinv[i];
    }
    return true;
}

// Insertion sort of the 32 border values.
fn sort32(a: ptr<function, array<f32, 32>>) {
    for (var i = 1u; i < 32u; i++) {
        let v = (*a)[i];
        var j = i;
        while (j > 0u && (*a)[j - 1u] > v) {
            (*a)[j] = (*a)[j - 1u];
            j--;
        }
        (*a)[j] = v;
    }
}

fn finite(v: f32) -> bool {
    // NaN fails every comparison; f32 max is 3.4e38.
    return abs(v) <= 3.0e38;
}

fn fit_window(w: u32) -> Fit {
    var out = Fit(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0u);
    var d: array<f32, 81>;
    for (var i = 0u; i < WINDOW; i++) {
        d[i] = f32(pixels[w * WINDOW + i]);
    }
    // Background and its noise from the border (32 pixels, the upper median).
    var border: array<f32, 32>;
    var nb = 0u;
    for (var i = 0u; i < WINDOW; i++) {
        let x = i % SIDE;
        let y = i / SIDE;
        if (x == 0u || y == 0u || x == SIDE - 1u || y == SIDE - 1u) {
            border[nb] = d[i];
            nb++;
        }
    }
    sort32(&border);
    let b0 = border[16];
    for (var i = 0u; i < 32u; i++) {
        border[i] = abs(border[i] - b0);
    }
    sort32(&border);
    let sb = max(1.4826 * border[16], 0.5);
    let var_b = sb * sb;
    let kappa = select(1.0, var_b / b0, b0 > var_b);
    var flux0 = 0.0;
    for (var i = 0u; i < WINDOW; i++) {
        flux0 += d[i] - b0;
    }
    flux0 = max(flux0, 1.0);
    let start = starts[w];
    var t = array<f32, 5>(start.x, start.y, flux0, b0, 1.0);
    var info: array<f32, 25>;
    for (var it = 0u; it < ITERATIONS; it++) {
        let s = t[4];
        var ax = axis(t[0], s);
        var ay = axis(t[1], s);
        var score: array<f32, 5>;
        for (var a = 0u; a < 25u; a++) {
            info[a] = 0.0;
        }
        let n = t[2];
        for (var i = 0u; i < WINDOW; i++) {
            let px = ax[i % SIDE];
            let py = ay[i / SIDE];
            let signal = n * px.x * py.x;
            let mu = t[3] + signal;
            let wt = 1.0 / (var_b + kappa * max(signal, 0.0));
            let j = array<f32, 5>(n * px.y * py.x, n * px.x * py.y, px.x * py.x, 1.0,
                                  n * (px.z * py.x + px.x * py.z));
            for (var a = 0u; a < 5u; a++) {
                let wa = j[a] * wt;
                score[a] += wa * (d[i] - mu);
                for (var c = a; c < 5u; c++) {
                    info[a * 5u + c] += wa * j[c];
                }
            }
        }
        for (var a = 0u; a < 5u; a++) {
            for (var c = 0u; c < a; c++) {
                info[a * 5u + c] = info[c * 5u + a];
            }
        }
        var step: array<f32, 5>;
        if (!solve(&info, &score, &step)) {
            return out;
        }
        // Damped: at most half a pixel, a third of the width, half the flux a step.
        var limits = array<f32, 5>(0.5, 0.5, 0.5 * t[2], 3.0e38, t[4] / 3.0);
        var scale = 1.0;
        for (var a = 0u; a < 5u; a++) {
            scale = min(scale, limits[a] / max(abs(step[a]), 1e-12));
        }
        var ok = true;
        for (var a = 0u; a < 5u; a++) {
            t[a] += step[a] * scale;
            ok = ok && finite(t[a]);
        }
        if (!ok || t[2] <= 0.0) {
            return out;
        }
        t[4] = clamp(t[4], WIDTH_CLAMP, 5.0);
    }
    var e0 = array<f32, 5>(1.0, 0.0, 0.0, 0.0, 0.0);
    var e1 = array<f32, 5>(0.0, 1.0, 0.0, 0.0, 0.0);
    var cx: array<f32, 5>;
    var cy: array<f32, 5>;
    if (!solve(&info, &e0, &cx) || !solve(&info, &e1, &cy)) {
        return out;
    }
    let settled = abs(t[0] - start.x) <= 1.0 && abs(t[1] - start.y) <= 1.0
        && t[4] >= MIN_WIDTH && t[4] <= 4.0;
    out = Fit(t[0], t[1], t[2], t[3], t[4], sqrt(max(cx[0], 0.0)), sqrt(max(cy[1], 0.0)),
              select(0u, 1u, settled));
    return out;
}

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    for (var w = gid.x; w < u.windows; w += nwg.x * 64u) {
        fits[w] = fit_window(w);
    }
}
