//! Detection on the GPU: threshold_tiles → tile_clip_sky → tile_clip → threshold →
//! components_merge → components_compress → centroid_count → centroid_scan → centroid, for a
//! batch of frames of one size in one submission, reading back only the blob lists.

use super::{Gpu, dispatch_strided};
use crate::cpu::centroid::Blob;
use crate::cpu::components::NO_LABEL;
use crate::cpu::streak_filter::StreakParams;
use crate::cpu::threshold::{DetectParams, TileStats};
use crate::error::{Result, fail};
use crate::io::frame::Frame;
use bytemuck::{Pod, Zeroable};

/// How a batch lies in the buffers. Keep in sync with `shaders/shared/detect.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct BatchParams {
    pub images: u32,
    pub pixels_per_image: u32,
    pub words_per_image: u32,
    pub blocks_per_image: u32,
    pub tiles_per_image: u32,
    pub max_blobs: u32,
    pub mask_words: u32,
    pub max_set: u32,
}

/// The detection kernels' uniform. Keep in sync with `shaders/shared/detect.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct DetectUniform {
    pub p: DetectParams,
    pub b: BatchParams,
}

/// The streak kernels' uniform. Keep in sync with `shaders/shared/streak.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Pod, Zeroable)]
pub struct StreakUniform {
    pub p: DetectParams,
    pub b: BatchParams,
    pub s: StreakParams,
}

/// What the streak kernels leave for the CPU's streak fits, per frame.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct StreakPixels {
    /// The tile statistics (background and noise) of detection.
    pub tiles: Vec<TileStats>,
    /// The streak mask, words of 32 pixels in raster order (`cpu::streak_filter`).
    pub mask: Vec<u32>,
}

/// Components per frame the blob buffer holds at first; a frame with more is rerun with room
/// for all of them (the count is exact even when the buffer is full).
pub const INITIAL_MAX_BLOBS: u32 = 4096;

/// Room for set (above-threshold) pixels per frame at first: a sixteenth of the frame, at
/// least 65536; more is rerun with room for all (the count is exact).
fn initial_max_set(pixels: u32) -> u32 {
    (pixels / 16).max(65536).min(pixels)
}

/// The detection kernels in dispatch order.
pub const DETECT_KERNELS: [&str; 9] = [
    "threshold_tiles",
    "tile_clip_sky",
    "tile_clip",
    "threshold",
    "components_merge",
    "components_compress",
    "centroid_count",
    "centroid_scan",
    "centroid",
];

/// Intermediate results of every stage, for the GPU = CPU tests.
#[derive(Clone, Debug, Default)]
pub struct DetectInspect {
    /// Per frame: the tile statistics (clipped).
    pub tiles: Vec<Vec<TileStats>>,
    /// Per frame: the mask (1 = set) as threshold wrote it.
    pub mask: Vec<Vec<u32>>,
    /// Per frame: the labels after components.
    pub labels: Vec<Vec<u32>>,
}

/// Pixels per block of the centroid compaction (`BLOCK` in `shaders/shared/detect.wgsl`).
pub const BLOCK: u32 = 256;

/// Workgroups per frame of the kernels that walk the set list.
const LIST_GROUPS: u32 = 64;

/// A chunk's blobs, the room it needed, what inspection read back, and the streak masks.
type ChunkOut = (Vec<Vec<Blob>>, Room, DetectInspect, Vec<StreakPixels>);

/// Room per frame in the buffers whose contents cannot be sized in advance.
#[derive(Clone, Copy, Debug)]
struct Room {
    blobs: u32,
    set: u32,
}

impl Gpu {
    /// The blobs of each frame (label order), as `cpu::centroid` gives them.
    pub fn detect(&self, frames: &[&Frame], p: &DetectParams) -> Result<Vec<Vec<Blob>>> {
        Ok(self
            .detect_with(frames, p, false, DETECT_KERNELS.len(), None)?
            .0)
    }

    /// As [`Gpu::detect`], and in the same submission the streak mask of each frame
    /// (`streak_rows` → `streak_filter`) with the tiles it was made from.
    pub fn detect_streaks(
        &self,
        frames: &[&Frame],
        p: &DetectParams,
        sp: &StreakParams,
    ) -> Result<(Vec<Vec<Blob>>, Vec<StreakPixels>)> {
        let (blobs, _, streaks) =
            self.detect_with(frames, p, false, DETECT_KERNELS.len(), Some(sp))?;
        Ok((blobs, streaks))
    }

    /// For benchmarks: run only the first `kernels` of [`DETECT_KERNELS`] (the results are
    /// then meaningless; the time is what counts).
    pub fn detect_prefix(&self, frames: &[&Frame], p: &DetectParams, kernels: usize) -> Result<()> {
        self.detect_with(frames, p, false, kernels, None)
            .map(|_| ())
    }

    /// As [`Gpu::detect`], with every stage's output read back.
    pub fn detect_inspect(
        &self,
        frames: &[&Frame],
        p: &DetectParams,
    ) -> Result<(Vec<Vec<Blob>>, DetectInspect)> {
        self.detect_with(frames, p, true, DETECT_KERNELS.len(), None)
            .map(|(b, i, _)| (b, i))
    }

    /// Frames per submission so that every buffer fits a binding.
    pub fn detect_chunk_len(&self, p: &DetectParams) -> usize {
        let per_image = 4 * p.width as u64 * p.height as u64;
        ((self.max_binding() / per_image.max(1)) as usize).clamp(1, u16::MAX as usize)
    }

    fn detect_with(
        &self,
        frames: &[&Frame],
        p: &DetectParams,
        inspect: bool,
        kernels: usize,
        streaks: Option<&StreakParams>,
    ) -> Result<(Vec<Vec<Blob>>, DetectInspect, Vec<StreakPixels>)> {
        for f in frames {
            if (f.width, f.height) != (p.width, p.height) {
                fail!(Gpu, "a GPU batch holds frames of one size");
            }
        }
        let mut blobs = Vec::with_capacity(frames.len());
        let mut all = DetectInspect::default();
        let mut streak_out = Vec::new();
        for chunk in frames.chunks(self.detect_chunk_len(p)) {
            let mut room = Room {
                blobs: INITIAL_MAX_BLOBS,
                set: initial_max_set(p.width * p.height),
            };
            loop {
                let (b, need, ins, st) =
                    self.detect_chunk(chunk, p, room, inspect, kernels, streaks)?;
                if need.blobs <= room.blobs && need.set <= room.set {
                    blobs.extend(b);
                    streak_out.extend(st);
                    all.tiles.extend(ins.tiles);
                    all.mask.extend(ins.mask);
                    all.labels.extend(ins.labels);
                    break;
                }
                // Some frame overflowed a buffer (nothing was written out of bounds): rerun
                // the chunk with room for everything.
                room.blobs = room.blobs.max(need.blobs.next_power_of_two());
                room.set = room
                    .set
                    .max(need.set.next_power_of_two().min(p.width * p.height));
            }
        }
        Ok((blobs, all, streak_out))
    }

    fn detect_chunk(
        &self,
        frames: &[&Frame],
        p: &DetectParams,
        room: Room,
        inspect: bool,
        kernels: usize,
        streaks: Option<&StreakParams>,
    ) -> Result<ChunkOut> {
        let run = |k: usize| k < kernels;
        let max_blobs = room.blobs;
        let n = frames.len() as u32;
        let pixels_per_image = p.width * p.height;
        let words_per_image = pixels_per_image.div_ceil(2);
        let blocks_per_image = pixels_per_image.div_ceil(BLOCK);
        let tiles_per_image = p.tiles_x * p.tiles_y;
        let mask_words = pixels_per_image.div_ceil(32);
        let b = BatchParams {
            images: n,
            pixels_per_image,
            words_per_image,
            blocks_per_image,
            tiles_per_image,
            max_blobs,
            mask_words,
            max_set: room.set,
        };
        let uniform = self.uniform("detect params", &DetectUniform { p: *p, b });
        // Two u16 pixels per u32 word (WGSL has no u16 storage).
        let mut words = vec![0u32; (words_per_image * n) as usize];
        for (k, f) in frames.iter().enumerate() {
            let w = &mut words[k * words_per_image as usize..][..words_per_image as usize];
            for (i, pair) in f.pixels.chunks(2).enumerate() {
                w[i] = pair[0] as u32 | (pair.get(1).copied().unwrap_or(0) as u32) << 16;
            }
        }
        let pixels = self.storage_init("pixels", bytemuck::cast_slice(&words));
        let tiles_raw = self.storage("tiles raw", 8 * (tiles_per_image * n) as u64);
        let sky = self.storage("tile sky", 8 * (tiles_per_image * n) as u64);
        let tiles = self.storage("tiles", 8 * (tiles_per_image * n) as u64);
        let mask = self.storage("mask", 4 * (mask_words * n) as u64);
        let labels = self.storage("labels", 4 * (pixels_per_image as u64) * n as u64);
        let set_list = self.storage("set list", 4 * room.set as u64 * n as u64);
        let set_count = self.storage("set count", 4 * n as u64);
        let root_bytes = 32 * (blocks_per_image * n) as u64;
        let root_bits = self.storage("root bits", root_bytes);
        let offsets = self.storage("block offsets", 4 * (blocks_per_image * n) as u64);
        let counts = self.storage("blob counts", 4 * n as u64);
        let blob_bytes = std::mem::size_of::<Blob>() as u64 * max_blobs as u64 * n as u64;
        let blobs = self.storage("blobs", blob_bytes);

        let pl = &self.kernels;
        let bg_tiles = self.bind_group(&pl.threshold_tiles, &[&uniform, &pixels, &tiles_raw]);
        let bg_sky = self.bind_group(&pl.tile_clip_sky, &[&uniform, &tiles_raw, &sky]);
        let bg_clip = self.bind_group(&pl.tile_clip, &[&uniform, &tiles_raw, &sky, &tiles]);
        let bg_threshold = self.bind_group(
            &pl.threshold,
            &[
                &uniform, &pixels, &tiles, &mask, &labels, &set_list, &set_count,
            ],
        );
        let list = [&set_list, &set_count];
        let bg_merge = self.bind_group(
            &pl.components_merge,
            &[&uniform, &mask, &labels, list[0], list[1]],
        );
        let bg_compress = self.bind_group(
            &pl.components_compress,
            &[&uniform, &labels, list[0], list[1]],
        );
        let bg_count = self.bind_group(
            &pl.centroid_count,
            &[&uniform, &labels, &root_bits, list[0], list[1]],
        );
        let bg_scan = self.bind_group(
            &pl.centroid_scan,
            &[&uniform, &root_bits, &offsets, &counts],
        );
        let bg_centroid = self.bind_group(
            &pl.centroid,
            &[
                &uniform, &pixels, &tiles, &labels, &root_bits, &offsets, &blobs, list[0], list[1],
            ],
        );

        // The streak mask: two more kernels over the pixels and tiles already uploaded.
        let streak = streaks.map(|sp| {
            let su = self.uniform("streak params", &StreakUniform { p: *p, b, s: *sp });
            let blocks = (sp.width * sp.height) as u64;
            let rows = self.storage("streak rows", 4 * blocks * n as u64);
            let smask = self.storage("streak mask", 4 * (sp.words * n) as u64);
            let bg_rows = self.bind_group(&pl.streak_rows, &[&su, &pixels, &tiles, &rows]);
            let bg_filter = self.bind_group(&pl.streak_filter, &[&su, &rows, &tiles, &smask]);
            (smask, bg_rows, bg_filter)
        });
        let tile_bytes = 8 * (tiles_per_image * n) as u64;
        let stage_tiles =
            (inspect || streaks.is_some()).then(|| self.staging("tiles out", tile_bytes));
        let label_bytes = 4 * pixels_per_image as u64 * n as u64;
        let mask_bytes = 4 * (mask_words * n) as u64;
        let stage_mask = inspect.then(|| self.staging("mask out", mask_bytes));
        let streak_bytes = streaks.map_or(0, |sp| 4 * (sp.words * n) as u64);
        let stage_streak = streaks.map(|_| self.staging("streak mask out", streak_bytes));
        let stage_labels = inspect.then(|| self.staging("labels out", label_bytes));
        let stage_counts = self.staging("blob counts out", 4 * n as u64);
        let stage_set_count = self.staging("set count out", 4 * n as u64);
        let stage_blobs = self.staging("blobs out", blob_bytes);

        let mut enc = self.device.create_command_encoder(&Default::default());
        enc.clear_buffer(&blobs, 0, Some(blob_bytes));
        enc.clear_buffer(&root_bits, 0, Some(root_bytes));
        enc.clear_buffer(&set_count, 0, Some(4 * n as u64));
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            pass.set_pipeline(&pl.threshold_tiles);
            pass.set_bind_group(0, &bg_tiles, &[]);
            if run(0) {
                pass.dispatch_workgroups(p.tiles_x, p.tiles_y, n);
            }
            if run(1) {
                dispatch_strided(&mut pass, &pl.tile_clip_sky, &bg_sky, tiles_per_image, n);
            }
            if run(2) {
                dispatch_strided(&mut pass, &pl.tile_clip, &bg_clip, tiles_per_image, n);
            }
            if run(3) {
                dispatch_strided(&mut pass, &pl.threshold, &bg_threshold, mask_words, n);
            }
            if let (Some((_, bg_rows, bg_filter)), Some(sp)) = (&streak, streaks) {
                let row_runs = sp.width.div_ceil(32) * sp.height;
                dispatch_strided(&mut pass, &pl.streak_rows, bg_rows, row_runs, n);
                dispatch_strided(&mut pass, &pl.streak_filter, bg_filter, sp.words, n);
            }
        }
        if let Some(st) = &stage_tiles {
            enc.copy_buffer_to_buffer(&tiles, 0, st, 0, tile_bytes);
        }
        if let Some(sm) = &stage_mask {
            enc.copy_buffer_to_buffer(&mask, 0, sm, 0, mask_bytes);
        }
        if let (Some(ss), Some((smask, _, _))) = (&stage_streak, &streak) {
            enc.copy_buffer_to_buffer(smask, 0, ss, 0, streak_bytes);
        }
        // The list kernels stride over at most `max_set` entries per frame.
        let list_items = room.set.min(LIST_GROUPS * 256);
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            if run(4) {
                dispatch_strided(&mut pass, &pl.components_merge, &bg_merge, list_items, n);
            }
            if run(5) {
                dispatch_strided(
                    &mut pass,
                    &pl.components_compress,
                    &bg_compress,
                    list_items,
                    n,
                );
            }
        }
        if let Some(sl) = &stage_labels {
            enc.copy_buffer_to_buffer(&labels, 0, sl, 0, label_bytes);
        }
        {
            let mut pass = enc.begin_compute_pass(&Default::default());
            if run(6) {
                dispatch_strided(&mut pass, &pl.centroid_count, &bg_count, list_items, n);
            }
            if run(7) {
                pass.set_pipeline(&pl.centroid_scan);
                pass.set_bind_group(0, &bg_scan, &[]);
                pass.dispatch_workgroups(n, 1, 1);
            }
            if run(8) {
                dispatch_strided(&mut pass, &pl.centroid, &bg_centroid, list_items, n);
            }
        }
        enc.copy_buffer_to_buffer(&counts, 0, &stage_counts, 0, 4 * n as u64);
        enc.copy_buffer_to_buffer(&set_count, 0, &stage_set_count, 0, 4 * n as u64);
        enc.copy_buffer_to_buffer(&blobs, 0, &stage_blobs, 0, blob_bytes);
        self.submit(enc)?;

        let mut staged = vec![
            (&stage_counts, 4 * n as u64),
            (&stage_blobs, blob_bytes),
            (&stage_set_count, 4 * n as u64),
        ];
        if let (Some(m), Some(l)) = (&stage_mask, &stage_labels) {
            staged.extend([(m, mask_bytes), (l, label_bytes)]);
        }
        if let Some(t) = &stage_tiles {
            staged.push((t, tile_bytes));
        }
        if let Some(ss) = &stage_streak {
            staged.push((ss, streak_bytes));
        }
        let bytes = self.read_all(&staged)?;
        let counts: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[0]);
        // (lo, hi) word pairs read as u64: GPU buffers are little-endian, as are the hosts wgpu
        // runs on.
        let all: Vec<Blob> = bytemuck::pod_collect_to_vec(&bytes[1]);
        let set_counts: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[2]);
        let need = Room {
            blobs: counts.iter().copied().max().unwrap_or(0),
            set: set_counts.iter().copied().max().unwrap_or(0),
        };
        let blobs_out = counts
            .iter()
            .enumerate()
            .map(|(k, &c)| {
                let start = k * max_blobs as usize;
                all[start..start + c.min(max_blobs) as usize].to_vec()
            })
            .collect();
        let per_frame_tiles = |b: &[u8]| -> Vec<Vec<TileStats>> {
            let t: Vec<TileStats> = bytemuck::pod_collect_to_vec(b);
            t.chunks(tiles_per_image as usize)
                .map(|c| c.to_vec())
                .collect()
        };
        // Staged after the inspection buffers: tiles, then the streak mask.
        let tiles_at = if inspect { 5 } else { 3 };
        let mut streak_out = Vec::new();
        if let Some(sp) = streaks {
            let words: Vec<u32> = bytemuck::pod_collect_to_vec(&bytes[tiles_at + 1]);
            streak_out = per_frame_tiles(&bytes[tiles_at])
                .into_iter()
                .zip(words.chunks(sp.words as usize))
                .map(|(tiles, m)| StreakPixels {
                    tiles,
                    mask: m.to_vec(),
                })
                .collect();
        }
        let mut ins = DetectInspect::default();
        if inspect {
            let split = |b: &[u8], per: usize| -> Vec<Vec<u32>> {
                let v: Vec<u32> = bytemuck::pod_collect_to_vec(b);
                v.chunks(per).map(|c| c.to_vec()).collect()
            };
            ins.tiles = per_frame_tiles(&bytes[tiles_at]);
            let px = pixels_per_image as usize;
            ins.mask = split(&bytes[3], mask_words as usize)
                .into_iter()
                .map(|words| (0..px).map(|i| words[i / 32] >> (i % 32) & 1).collect())
                .collect();
            // Labels are only written at set pixels.
            ins.labels = split(&bytes[4], px)
                .into_iter()
                .zip(&ins.mask)
                .map(|(l, m)| {
                    l.iter()
                        .zip(m)
                        .map(|(&l, &m)| if m == 1 { l } else { NO_LABEL })
                        .collect()
                })
                .collect();
        }
        Ok((blobs_out, need, ins, streak_out))
    }
}
