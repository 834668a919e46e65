//! Radial-feature identification on the GPU: radial → select for a batch of frames in one
//! submission, reading back only the candidate lists (`--method radial`).

use super::Gpu;
use super::vote::VoteUniform;
use crate::error::{Result, fail};
use crate::solve::identify::VoteResult;
use crate::solve::radial::{FEATURE_STARS, RadialTable, WORDS};
use bytemuck::{Pod, Zeroable};

/// The radial kernel's uniform. Keep in sync with `shaders/radial.wgsl` (RadialUniform).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RadialUniform {
    pub images: u32,
    pub stars: u32,
    pub refs: u32,
    /// Slots per image star in the sparse image features ([`FEATURE_STARS`]).
    pub words: u32,
}

/// A band's catalog features in GPU memory.
pub struct GpuRadial {
    features: wgpu::Buffer,
    counts: wgpu::Buffer,
    refs: u32,
}

/// One frame's part of a radial batch: its image stars' features (`WORDS` words each) and the
/// candidates to keep per star.
#[derive(Clone, Debug)]
pub struct RadialJob {
    pub features: Vec<u32>,
    pub k: usize,
}

/// Workgroups of 64 over the catalog at most; threads stride over the rest.
const MAX_GROUPS: u32 = 1024;

impl Gpu {
    /// Upload a band's features.
    pub fn upload_radial(&self, t: &RadialTable) -> Result<GpuRadial> {
        if t.bytes() as u64 > self.max_binding() {
            fail!(
                Gpu,
                "the radial features ({} MB) exceed the GPU's largest buffer",
                t.bytes() >> 20
            );
        }
        Ok(GpuRadial {
            features: self.storage_owned("radial features", bytemuck::cast_slice(&t.features)),
            counts: self.storage_owned("radial counts", bytemuck::cast_slice(&t.counts)),
            refs: t.stars as u32,
        })
    }

    /// Score and select for each job, as `radial::candidates_cpu` does.
    pub fn radial(&self, table: &GpuRadial, jobs: &[RadialJob]) -> Result<Vec<VoteResult>> {
        let stars = jobs
            .iter()
            .map(|j| j.features.len() / WORDS)
            .max()
            .unwrap_or(0)
            .max(1);
        let per_image = 4 * stars as u64 * table.refs as u64;
        let chunk = ((self.max_binding() / per_image.max(1)) as usize).clamp(1, u16::MAX as usize);
        let mut out = Vec::with_capacity(jobs.len());
        for part in jobs.chunks(chunk) {
            out.extend(self.radial_chunk(table, part, stars)?);
        }
        Ok(out)
    }

    fn radial_chunk(
        &self,
        table: &GpuRadial,
        jobs: &[RadialJob],
        stars: usize,
    ) -> Result<Vec<VoteResult>> {
        let n = jobs.len();
        let k = jobs
            .iter()
            .map(|j| j.k)
            .max()
            .unwrap_or(1)
            .clamp(1, super::vote::MAX_K);
        // Each star's set words as (word, bits), at most one per neighbour; frames with fewer
        // stars, and stars with fewer words, are padded with (0, 0), which adds nothing.
        let slots = FEATURE_STARS;
        let mut image = vec![[0u32; 2]; n * stars * slots];
        for (f, job) in jobs.iter().enumerate() {
            for (s, feature) in job.features.chunks_exact(WORDS).enumerate() {
                let set = feature.iter().enumerate().filter(|(_, w)| **w != 0);
                let out = &mut image[(f * stars + s) * slots..][..slots];
                for (slot, (w, &bits)) in out.iter_mut().zip(set) {
                    *slot = [w as u32, bits];
                }
            }
        }
        let ru = RadialUniform {
            images: n as u32,
            stars: stars as u32,
            refs: table.refs,
            words: slots as u32,
        };
        let vu = VoteUniform {
            images: n as u32,
            stars: stars as u32,
            refs: table.refs,
            k: k as u32,
            ..Default::default()
        };
        let radial_u = self.uniform("radial params", &ru);
        let select_u = self.uniform("radial select params", &vu);
        let image_buf = self.storage_init("radial image features", bytemuck::cast_slice(&image));
        let score_bytes = 4 * (n * stars) as u64 * table.refs as u64;
        let scores = self.storage("votes", score_bytes);
        let cand_bytes = 8 * (n * stars * k) as u64;
        let cands = self.storage("candidates", cand_bytes);
        let pl = &self.kernels;
        let bg_radial = self.bind_group(
            &pl.radial,
            &[
                &radial_u,
                &table.features,
                &table.counts,
                &image_buf,
                &scores,
            ],
        );
        let bg_select = self.bind_group(&pl.select, &[&select_u, &scores, &cands]);
        let stage = self.staging("candidates out", cand_bytes);
        let mut enc = self.device.create_command_encoder(&Default::default());
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pl.radial);
            pass.set_bind_group(0, &bg_radial, &[]);
            let groups = table.refs.div_ceil(64).clamp(1, MAX_GROUPS);
            pass.dispatch_workgroups(groups, stars as u32, n as u32);
            pass.set_pipeline(&pl.select);
            pass.set_bind_group(0, &bg_select, &[]);
            pass.dispatch_workgroups(stars as u32, n as u32, 1);
        }
        enc.copy_buffer_to_buffer(&cands, 0, &stage, 0, cand_bytes);
        self.submit(enc)?;
        let bytes = self.read_all(&[(&stage, cand_bytes)])?;
        let cands: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[0]);
        Ok(jobs
            .iter()
            .enumerate()
            .map(|(f, job)| {
                let own = job.features.len() / WORDS;
                VoteResult {
                    candidates: super::vote::frame_candidates(&cands, f, stars, k, own, job.k),
                    k: job.k,
                    hypotheses: 0,
                }
            })
            .collect())
    }
}
