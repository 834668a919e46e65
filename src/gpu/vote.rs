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
    pub stars: u32,
    pub refs: u32,
    pub pairs_per_image: u32,
    pub k: u32,
    pub shift: u32,
    pub rows: u32,
    pub kvector_len: u32,
}

/// The most candidates per star the select kernel keeps (its workgroup array).
pub const MAX_K: usize = 64;

/// A distance table in GPU memory.
pub struct GpuTable {
    keys: wgpu::Buffer,
    pairs: wgpu::Buffer,
    kvector: wgpu::Buffer,
    rows: u32,
    shift: u32,
    kvector_len: u32,
    refs: u32,
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

impl Gpu {
    /// Upload a table for `refs` reference stars.
    pub fn upload_table(&self, t: &PairTable, refs: usize) -> Result<GpuTable> {
        let bytes = 4 * t.len() as u64;
        if bytes > self.max_binding() {
            fail!(
                Gpu,
                "the distance table ({} rows, {} MB) exceeds the GPU's largest buffer ({} MB): \
                 lower --mag-limit or use --backend cpu",
                t.len(),
                bytes >> 20,
                self.max_binding() >> 20
            );
        }
        Ok(GpuTable {
            keys: self.storage_owned("table keys", bytemuck::cast_slice(&t.keys)),
            pairs: self.storage_owned("table pairs", bytemuck::cast_slice(&t.pairs)),
            kvector: self.storage_owned("table k-vector", bytemuck::cast_slice(&t.kvector)),
            rows: t.len() as u32,
            shift: t.shift,
            kvector_len: t.kvector.len() as u32,
            refs: refs as u32,
        })
    }

    /// Vote and select for each job, as `identify::vote_cpu` does.
    pub fn vote(&self, table: &GpuTable, jobs: &[VoteJob]) -> Result<Vec<VoteResult>> {
        Ok(self.vote_with(table, jobs, false, 2)?.0)
    }

    /// For benchmarks: run the vote kernel only (`kernels` = 1) or vote and select (2).
    pub fn vote_prefix(&self, table: &GpuTable, jobs: &[VoteJob], kernels: usize) -> Result<()> {
        self.vote_with(table, jobs, false, kernels).map(|_| ())
    }

    /// As [`Gpu::vote`], with the vote counters read back (`votes[star · refs + id]` per job).
    pub fn vote_inspect(
        &self,
        table: &GpuTable,
        jobs: &[VoteJob],
    ) -> Result<(Vec<VoteResult>, Vec<Vec<u32>>)> {
        self.vote_with(table, jobs, true, 2)
    }

    fn vote_with(
        &self,
        table: &GpuTable,
        jobs: &[VoteJob],
        inspect: bool,
        kernels: usize,
    ) -> Result<(Vec<VoteResult>, Vec<Vec<u32>>)> {
        let stars = jobs.iter().map(|j| j.stars).max().unwrap_or(0).max(1);
        // Frames per submission so that the vote counters fit a binding.
        let per_image = 4 * stars as u64 * table.refs as u64;
        let chunk = ((self.max_binding() / per_image.max(1)) as usize).clamp(1, u16::MAX as usize);
        let mut results = Vec::with_capacity(jobs.len());
        let mut votes = Vec::new();
        for part in jobs.chunks(chunk) {
            let (r, v) = self.vote_chunk(table, part, stars, inspect, kernels)?;
            results.extend(r);
            votes.extend(v);
        }
        Ok((results, votes))
    }

    fn vote_chunk(
        &self,
        table: &GpuTable,
        jobs: &[VoteJob],
        stars: usize,
        inspect: bool,
        kernels: usize,
    ) -> Result<(Vec<VoteResult>, Vec<Vec<u32>>)> {
        let n = jobs.len();
        let k = jobs.iter().map(|j| j.k).max().unwrap_or(1).clamp(1, MAX_K);
        let pairs_per_image = (stars * stars.saturating_sub(1) / 2).max(1);
        let mut ranges = vec![
            PairRange {
                i: 0,
                j: 0,
                lo: 1,
                hi: 0
            };
            n * pairs_per_image
        ];
        for (f, job) in jobs.iter().enumerate() {
            if job.ranges.len() > pairs_per_image || job.stars > stars {
                fail!(Gpu, "a vote job has more pairs than its stars allow");
            }
            ranges[f * pairs_per_image..][..job.ranges.len()].copy_from_slice(&job.ranges);
        }
        let u = VoteUniform {
            images: n as u32,
            stars: stars as u32,
            refs: table.refs,
            pairs_per_image: pairs_per_image as u32,
            k: k as u32,
            shift: table.shift,
            rows: table.rows,
            kvector_len: table.kvector_len,
        };
        let uniform = self.uniform("vote params", &u);
        let range_buf = self.storage_init("pair ranges", bytemuck::cast_slice(&ranges));
        let vote_bytes = 4 * (n * stars) as u64 * table.refs as u64;
        let votes = self.storage("votes", vote_bytes);
        let hyp = self.storage("hypotheses", 8 * n as u64);
        let cand_bytes = 4 * (n * stars * k) as u64;
        let cands = self.storage("candidates", cand_bytes);
        let pl = &self.kernels;
        let bg_vote = self.bind_group(
            &pl.vote,
            &[
                &uniform,
                &table.keys,
                &table.pairs,
                &table.kvector,
                &range_buf,
                &votes,
                &hyp,
            ],
        );
        let bg_select = self.bind_group(&pl.select, &[&uniform, &votes, &cands]);
        let stage_votes = inspect.then(|| self.staging("votes out", vote_bytes));
        let stage_hyp = self.staging("hypotheses out", 8 * n as u64);
        let stage_cands = self.staging("candidates out", cand_bytes);

        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&votes, 0, Some(vote_bytes));
        enc.clear_buffer(&hyp, 0, Some(8 * n as u64));
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            let total = (n * pairs_per_image) as u32;
            if kernels >= 1 {
                super::dispatch_strided(&mut pass, &pl.vote, &bg_vote, total, 1);
            }
            if kernels >= 2 {
                pass.set_pipeline(&pl.select);
                pass.set_bind_group(0, &bg_select, &[]);
                pass.dispatch_workgroups(stars as u32, n as u32, 1);
            }
        }
        if let Some(sv) = &stage_votes {
            enc.copy_buffer_to_buffer(&votes, 0, sv, 0, vote_bytes);
        }
        enc.copy_buffer_to_buffer(&hyp, 0, &stage_hyp, 0, 8 * n as u64);
        enc.copy_buffer_to_buffer(&cands, 0, &stage_cands, 0, cand_bytes);
        self.submit(enc)?;

        let mut staged = vec![(&stage_hyp, 8 * n as u64), (&stage_cands, cand_bytes)];
        if let Some(v) = &stage_votes {
            staged.push((v, vote_bytes));
        }
        let bytes = self.read_all(&staged)?;
        let hyp: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[0]);
        let cands: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[1]);
        let results = jobs
            .iter()
            .enumerate()
            .map(|(f, job)| VoteResult {
                candidates: frame_candidates(&cands, f, stars, k, job.stars, job.k),
                k: job.k,
                hypotheses: hyp[2 * f] as u64 | (hyp[2 * f + 1] as u64) << 32,
            })
            .collect();
        let votes_out = match bytes.get(2) {
            Some(b) => {
                let v: Vec<u32> = bytemuck::pod_collect_to_vec(b);
                let per = stars * table.refs as usize;
                jobs.iter()
                    .enumerate()
                    .map(|(f, job)| v[f * per..][..job.stars * table.refs as usize].to_vec())
                    .collect()
            }
            None => Vec::new(),
        };
        Ok((results, votes_out))
    }
}

/// Frame `f`'s candidate lists from select's output (`k` slots per star, `stars` stars per
/// frame), for its own `own` stars, `want` per star: the k best of a best-first list of
/// K ≥ k are its first k (empty slots beyond K).
pub(super) fn frame_candidates(
    cands: &[u32],
    f: usize,
    stars: usize,
    k: usize,
    own: usize,
    want: usize,
) -> Vec<u32> {
    let mut out = Vec::with_capacity(own * want);
    for s in 0..own {
        let row = &cands[(f * stars + s) * k..][..k];
        out.extend_from_slice(&row[..want.min(k)]);
        out.extend(std::iter::repeat_n(0, want.saturating_sub(k)));
    }
    out
}
