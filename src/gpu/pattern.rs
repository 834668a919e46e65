//! The scale-free first pass's lookup on the GPU: every query key of a batch of frames
//! against the sorted pattern keys in one submission (`shaders/pattern.wgsl`; CPU twin
//! `cpu::pattern`), reading back each query's rows.

use super::Gpu;
use crate::catalog::patterns::PatternIndex;
use crate::cpu::pattern::Rows;
use crate::error::{Result, fail};
use bytemuck::{Pod, Zeroable};

/// The pattern kernel's uniform. Keep in sync with `shaders/pattern.wgsl` (PatternUniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PatternUniform {
    pub queries: u32,
    pub keys: u32,
    pub pad0: u32,
    pub pad1: u32,
}

/// A pattern index's keys in GPU memory (the quads stay on the CPU, which reads the rows).
pub struct GpuPatterns {
    keys: wgpu::Buffer,
    len: u32,
}

/// Workgroups of 64 over the queries at most; threads stride over the rest.
const MAX_GROUPS: u32 = 1024;

impl Gpu {
    /// Upload an index's keys.
    pub fn upload_patterns(&self, index: &PatternIndex) -> Result<GpuPatterns> {
        if 4 * index.len() as u64 > self.max_binding() || index.len() > u32::MAX as usize {
            fail!(
                Gpu,
                "the pattern index ({} MB of keys) exceeds the GPU's largest buffer",
                (4 * index.len()) >> 20
            );
        }
        Ok(GpuPatterns {
            keys: self.storage_owned("pattern keys", bytemuck::cast_slice(&index.keys)),
            len: index.len() as u32,
        })
    }

    /// The rows of every query, as `cpu::pattern::pattern` finds them.
    pub fn pattern(&self, index: &GpuPatterns, queries: &[u32]) -> Result<Vec<Rows>> {
        let per = (self.max_binding() / 8).clamp(1, u32::MAX as u64) as usize;
        let mut out = Vec::with_capacity(queries.len());
        for part in queries.chunks(per) {
            out.extend(self.pattern_chunk(index, part)?);
        }
        Ok(out)
    }

    fn pattern_chunk(&self, index: &GpuPatterns, queries: &[u32]) -> Result<Vec<Rows>> {
        if queries.is_empty() {
            return Ok(Vec::new());
        }
        let u = PatternUniform {
            queries: queries.len() as u32,
            keys: index.len,
            ..Default::default()
        };
        let ub = self.uniform("pattern params", &u);
        let qb = self.storage_init("pattern queries", bytemuck::cast_slice(queries));
        let bytes = 8 * queries.len() as u64;
        let rows = self.storage("pattern rows", bytes);
        let stage = self.staging("pattern rows out", bytes);
        let pl = &self.kernels.pattern;
        let bg = self.bind_group(pl, &[&ub, &index.keys, &qb, &rows]);
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(pl);
            pass.set_bind_group(0, &bg, &[]);
            let groups = (queries.len() as u32).div_ceil(64).clamp(1, MAX_GROUPS);
            pass.dispatch_workgroups(groups, 1, 1);
        }
        enc.copy_buffer_to_buffer(&rows, 0, &stage, 0, bytes);
        self.submit(enc)?;
        let read = self.read_all(&[(&stage, bytes)])?;
        Ok(bytemuck::pod_collect_to_vec(&read[0]))
    }
}
