//! Identification on the GPU: vote → select for a batch of frames in one submission, reading
//! back only the candidate lists and the hypothesis counts.

use super::Gpu;
use crate::catalog::table::PairTable;
use crate::cpu::vote::PairRange;
use crate::error::{Result, fail};
use crate::solve::identify::VoteResult;
use bytemuck::{Pod, Zeroable};

/// The identification kernels' uniform. Keep in sync with `shaders/shared/vote.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct VoteUniform {
    pub images: u32,
    /// Voting stars counted in this dispatch (the stride of the vote counters).
    pub stars: u32,
    pub refs: u32,
    pub pairs_per_image: u32,
    pub k: u32,
    /// First voting star counted: stars `star_lo .. star_lo + stars`.
    pub star_lo: u32,
    /// The table rows bound to this dispatch: `row_lo .. row_hi`.
    pub row_lo: u32,
    pub row_hi: u32,
}

/// One image-star pair and the table rows `start .. end` of its key range (found on the CPU
/// with [`PairTable::range`], as the CPU twin does). Keep in sync with `shaders/shared/vote.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct RowSpan {
    pub i: u32,
    pub j: u32,
    pub start: u32,
    pub end: u32,
}

/// The most candidates per star the select kernel keeps (its workgroup array).
pub const MAX_K: usize = 64;

/// A distance table in GPU memory: its pairs, in slices that each fit one binding.
pub struct GpuTable {
    slices: Vec<(std::ops::Range<u32>, wgpu::Buffer)>,
    refs: u32,
}

impl GpuTable {
    /// How many bindings the table's pairs take.
    pub fn slices(&self) -> usize {
        self.slices.len()
    }
}

/// One frame's part of a vote batch.
#[derive(Clone, Debug)]
pub struct VoteJob {
    /// Its voting stars' pair ranges (see `identify::pair_ranges`).
    pub ranges: Vec<PairRange>,
    /// How many stars vote.
    pub stars: usize,
    /// Candidates kept per star for this frame (≤ [`MAX_K`]).
    pub k: usize,
}

impl VoteJob {
    /// The vote of a prepared pass.
    pub fn of(p: &crate::solve::Prepared) -> VoteJob {
        VoteJob {
            ranges: p.ranges.clone(),
            stars: p.n_vote,
            k: p.k,
        }
    }
}

impl Gpu {
    /// Upload a table for `refs` reference stars, its pairs split into slices of at most one
    /// binding each (a deep catalog's table is larger than `Limits::default()` allows one).
    pub fn upload_table(&self, t: &PairTable, refs: usize) -> Result<GpuTable> {
        if t.len() > u32::MAX as usize || refs > u32::MAX as usize {
            fail!(
                Gpu,
                "the distance table has more rows or stars than 32-bit ids hold"
            );
        }
        let per_slice = (self.max_binding() / 8).clamp(1, u32::MAX as u64) as usize;
        let slices = (0..t.len().max(1))
            .step_by(per_slice)
            .map(|lo| {
                let hi = (lo + per_slice).min(t.len());
                let bytes: &[u8] = bytemuck::cast_slice(&t.pairs[lo..hi]);
                (
                    lo as u32..hi as u32,
                    self.storage_owned("table pairs", bytes),
                )
            })
            .collect();
        Ok(GpuTable {
            slices,
            refs: refs as u32,
        })
    }

    /// Vote and select for each job, as `identify::vote_cpu` does.
    pub fn vote(
        &self,
        table: &PairTable,
        gpu: &GpuTable,
        jobs: &[VoteJob],
    ) -> Result<Vec<VoteResult>> {
        Ok(self.vote_with(table, gpu, jobs, false, 2)?.0)
    }

    /// For benchmarks: run the vote kernel only (`kernels` = 1) or vote and select (2).
    pub fn vote_prefix(
        &self,
        table: &PairTable,
        gpu: &GpuTable,
        jobs: &[VoteJob],
        kernels: usize,
    ) -> Result<()> {
        self.vote_with(table, gpu, jobs, false, kernels).map(|_| ())
    }

    /// As [`Gpu::vote`], with the vote counters read back (`votes[star · refs + id]` per job).
    pub fn vote_inspect(
        &self,
        table: &PairTable,
        gpu: &GpuTable,
        jobs: &[VoteJob],
    ) -> Result<(Vec<VoteResult>, Vec<Vec<u32>>)> {
        self.vote_with(table, gpu, jobs, true, 2)
    }

    fn vote_with(
        &self,
        table: &PairTable,
        gpu: &GpuTable,
        jobs: &[VoteJob],
        inspect: bool,
        kernels: usize,
    ) -> Result<(Vec<VoteResult>, Vec<Vec<u32>>)> {
        let stars = jobs.iter().map(|j| j.stars).max().unwrap_or(0).max(1);
        let k = jobs.iter().map(|j| j.k).max().unwrap_or(1).clamp(1, MAX_K);
        let refs = gpu.refs as usize;
        let pairs_per_image = (stars * stars.saturating_sub(1) / 2).max(1);
        // The vote counters of one star of one frame take `4 · refs` bytes: frames per
        // submission, or for a catalog too deep for one frame's counters, stars per dispatch.
        let fit = (self.max_binding() / (4 * refs.max(1) as u64)).max(1) as usize;
        let window = stars.min(fit);
        let frames = (fit / stars).clamp(1, u16::MAX as usize);
        let mut results = Vec::with_capacity(jobs.len());
        let mut votes = Vec::new();
        for part in jobs.chunks(frames) {
            let n = part.len();
            // Row spans found on the CPU, as `cpu::vote` finds them; padding spans are empty.
            let mut spans = vec![RowSpan::default(); n * pairs_per_image];
            for (f, job) in part.iter().enumerate() {
                if job.ranges.len() > pairs_per_image || job.stars > stars || job.k > MAX_K {
                    fail!(Gpu, "a vote job has more pairs than its stars allow");
                }
                for (slot, r) in spans[f * pairs_per_image..].iter_mut().zip(&job.ranges) {
                    let rows = table.range(r.lo, r.hi);
                    *slot = RowSpan {
                        i: r.i,
                        j: r.j,
                        start: rows.start as u32,
                        end: rows.end as u32,
                    };
                }
            }
            let mut cands = vec![0u64; n * stars * k];
            let mut counters = vec![Vec::new(); if inspect { n } else { 0 }];
            // Uploaded once for every window of voting stars.
            let span_buf = self.storage_init("row spans", bytemuck::cast_slice(&spans));
            for lo in (0..stars).step_by(window) {
                let count = window.min(stars - lo);
                let (c, v) = self.vote_window(
                    gpu,
                    &span_buf,
                    n,
                    pairs_per_image,
                    (lo, count),
                    k,
                    inspect,
                    kernels,
                )?;
                for f in 0..n {
                    let at = (f * stars + lo) * k;
                    cands[at..at + count * k].copy_from_slice(&c[f * count * k..][..count * k]);
                    if inspect {
                        counters[f].extend_from_slice(&v[f * count * refs..][..count * refs]);
                    }
                }
            }
            for (f, job) in part.iter().enumerate() {
                let hypotheses = spans[f * pairs_per_image..][..job.ranges.len()]
                    .iter()
                    .map(|s| u64::from(s.end - s.start))
                    .sum();
                results.push(VoteResult {
                    candidates: frame_candidates(&cands, f, stars, k, job.stars, job.k),
                    k: job.k,
                    hypotheses,
                });
            }
            for (f, job) in part.iter().enumerate().filter(|_| inspect) {
                counters[f].truncate(job.stars * refs);
                votes.push(std::mem::take(&mut counters[f]));
            }
        }
        Ok((results, votes))
    }

    /// Vote and select for the voting stars `lo .. lo + count` of `n` frames: one vote
    /// dispatch per table slice into the same counters, then select. Returns the candidates
    /// (`count · k` per frame) and, with `inspect`, the counters (`count · refs` per frame).
    #[allow(clippy::too_many_arguments)]
    fn vote_window(
        &self,
        gpu: &GpuTable,
        span_buf: &wgpu::Buffer,
        n: usize,
        pairs_per_image: usize,
        (lo, count): (usize, usize),
        k: usize,
        inspect: bool,
        kernels: usize,
    ) -> Result<(Vec<u64>, Vec<u32>)> {
        let uniform_of = |rows: &std::ops::Range<u32>| VoteUniform {
            images: n as u32,
            stars: count as u32,
            refs: gpu.refs,
            pairs_per_image: pairs_per_image as u32,
            k: k as u32,
            star_lo: lo as u32,
            row_lo: rows.start,
            row_hi: rows.end,
        };
        let vote_bytes = 4 * (n * count) as u64 * gpu.refs as u64;
        let votes = self.storage("votes", vote_bytes);
        let cand_bytes = 8 * (n * count * k) as u64;
        let cands = self.storage("candidates", cand_bytes);
        let pl = &self.kernels;
        // A uniform of its own per slice: they are all written before the one submission.
        let uniforms: Vec<wgpu::Buffer> = gpu
            .slices
            .iter()
            .map(|(rows, _)| self.uniform_owned("vote params", &uniform_of(rows)))
            .collect();
        let bg_votes: Vec<wgpu::BindGroup> = gpu
            .slices
            .iter()
            .zip(&uniforms)
            .map(|((_, pairs), u)| self.bind_group(&pl.vote, &[u, pairs, span_buf, &votes]))
            .collect();
        let bg_select = self.bind_group(&pl.select, &[&uniforms[0], &votes, &cands]);
        let stage_votes = inspect.then(|| self.staging("votes out", vote_bytes));
        let stage_cands = self.staging("candidates out", cand_bytes);

        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&votes, 0, Some(vote_bytes));
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let total = (n * pairs_per_image) as u32;
            if kernels >= 1 {
                for bg in &bg_votes {
                    super::dispatch_strided(&mut pass, &pl.vote, bg, total, 1);
                }
            }
            if kernels >= 2 {
                pass.set_pipeline(&pl.select);
                pass.set_bind_group(0, &bg_select, &[]);
                pass.dispatch_workgroups(count as u32, n as u32, 1);
            }
        }
        if let Some(sv) = &stage_votes {
            enc.copy_buffer_to_buffer(&votes, 0, sv, 0, vote_bytes);
        }
        enc.copy_buffer_to_buffer(&cands, 0, &stage_cands, 0, cand_bytes);
        self.submit(enc)?;

        let mut staged = vec![(&stage_cands, cand_bytes)];
        if let Some(v) = &stage_votes {
            staged.push((v, vote_bytes));
        }
        let bytes = self.read_all(&staged)?;
        let cands: Vec<u64> = bytemuck::pod_collect_to_vec(&bytes[0]);
        let votes = bytes
            .get(1)
            .map(|b| bytemuck::pod_collect_to_vec(b))
            .unwrap_or_default();
        Ok((cands, votes))
    }
}

/// Frame `f`'s candidate lists from select's output (`k` slots per star, `stars` stars per
/// frame), for its own `own` stars, `want` per star: the k best of a best-first list of
/// K ≥ k are its first k (empty slots beyond K).
pub(super) fn frame_candidates(
    cands: &[u64],
    f: usize,
    stars: usize,
    k: usize,
    own: usize,
    want: usize,
) -> Vec<u64> {
    let mut out = Vec::with_capacity(own * want);
    for s in 0..own {
        let row = &cands[(f * stars + s) * k..][..k];
        out.extend_from_slice(&row[..want.min(k)]);
        out.extend(std::iter::repeat_n(0, want.saturating_sub(k)));
    }
    out
}
