//! The PSF fits on the GPU (`shaders/psf_fit.wgsl`, CPU twin `cpu::psf_fit`): every window of a
//! batch of frames in one submission, after detection has chosen the stars. Only the windows go
//! up (324 bytes a star), not the frames again.

use super::Gpu;
use crate::cpu::psf_fit::{PsfFit, WINDOW, Window};
use crate::error::Result;
use bytemuck::{Pod, Zeroable};

/// The kernel's uniform. Keep in sync with `shaders/psf_fit.wgsl` (PsfUniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PsfUniform {
    pub windows: u32,
    pub pad0: u32,
    pub pad1: u32,
    pub pad2: u32,
}

/// One fit as the kernel writes it, relative to the window's centre pixel. Keep in sync with
/// `shaders/psf_fit.wgsl` (Fit).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FitOut {
    pub x: f32,
    pub y: f32,
    pub flux: f32,
    pub background: f32,
    pub sigma: f32,
    pub sx: f32,
    pub sy: f32,
    pub settled: u32,
}

/// Workgroups of 64 threads at most per dispatch; threads stride over the rest.
const MAX_GROUPS: u32 = 1024;

impl Gpu {
    /// Fit every window, as `cpu::psf_fit::psf_fit` does (None where it does not settle).
    pub fn psf_fit(&self, windows: &[Window]) -> Result<Vec<Option<PsfFit>>> {
        if windows.is_empty() {
            return Ok(Vec::new());
        }
        let n = windows.len();
        let mut pixels = Vec::with_capacity(n * WINDOW);
        let mut starts = Vec::with_capacity(2 * n);
        for w in windows {
            pixels.extend_from_slice(&w.pixels);
            starts.extend([w.start[0] as f32, w.start[1] as f32]);
        }
        let u = PsfUniform {
            windows: n as u32,
            ..Default::default()
        };
        let uniform = self.uniform("psf_fit params", &u);
        let pixel_buf = self.storage_init("psf windows", bytemuck::cast_slice(&pixels));
        let start_buf = self.storage_init("psf starts", bytemuck::cast_slice(&starts));
        let out_bytes = (n * std::mem::size_of::<FitOut>()) as u64;
        let out = self.storage("psf fits", out_bytes);
        let stage = self.staging("psf fits out", out_bytes);
        let bg = self.bind_group(
            &self.kernels.psf_fit,
            &[&uniform, &pixel_buf, &start_buf, &out],
        );
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&self.kernels.psf_fit);
            pass.set_bind_group(0, &bg, &[]);
            pass.dispatch_workgroups((n as u32).div_ceil(64).min(MAX_GROUPS), 1, 1);
        }
        enc.copy_buffer_to_buffer(&out, 0, &stage, 0, out_bytes);
        self.submit(enc)?;
        let bytes = self.read_all(&[(&stage, out_bytes)])?;
        let fits: Vec<FitOut> = bytemuck::pod_collect_to_vec(&bytes[0]);
        Ok(windows
            .iter()
            .zip(fits)
            .map(|(w, f)| {
                (f.settled == 1).then_some(PsfFit {
                    x: w.cx as f64 + f.x as f64,
                    y: w.cy as f64 + f.y as f64,
                    flux: f.flux as f64,
                    background: f.background as f64,
                    sigma: f.sigma as f64,
                    sx: f.sx as f64,
                    sy: f.sy as f64,
                })
            })
            .collect())
    }
}
