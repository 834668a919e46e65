//! The GPU backend: every wgpu call of gpustar lives under this module, so a wgpu upgrade
//! touches one place.
//!
//! [`Gpu`] holds the adapter, device, queue and the compute pipelines, built once. Work comes in
//! batches of frames: one queue submission and one round of buffer maps per batch for
//! detection ([`detect`]), and the same for voting ([`vote`]), never one per frame.
//! Each kernel in `shaders/` has its CPU twin in `src/cpu/` with the same name.

pub mod detect;
pub mod pattern;
pub mod psf_fit;
pub mod radial;
pub mod vote;

use crate::error::{Context, Error, IntoKind, Result, error, fail};
use std::cell::Cell;
use std::sync::Arc;

/// WGSL shared by the detection kernels.
const SHARED_DETECT: &str = include_str!("../../shaders/shared/detect.wgsl");
/// WGSL shared by the streak kernels (after the detection prelude, whose structs they use).
const SHARED_STREAK: &str = concat!(
    include_str!("../../shaders/shared/detect.wgsl"),
    "\n",
    include_str!("../../shaders/shared/streak.wgsl")
);
/// WGSL shared by the identification kernels.
const SHARED_VOTE: &str = include_str!("../../shaders/shared/vote.wgsl");

/// Every kernel: (name = file in `shaders/`, shared prelude, body).
pub const KERNELS: &[(&str, &str, &str)] = &[
    (
        "threshold_tiles",
        SHARED_DETECT,
        include_str!("../../shaders/threshold_tiles.wgsl"),
    ),
    (
        "tile_clip_sky",
        SHARED_DETECT,
        include_str!("../../shaders/tile_clip_sky.wgsl"),
    ),
    (
        "tile_clip",
        SHARED_DETECT,
        include_str!("../../shaders/tile_clip.wgsl"),
    ),
    (
        "threshold",
        SHARED_DETECT,
        include_str!("../../shaders/threshold.wgsl"),
    ),
    (
        "components_merge",
        SHARED_DETECT,
        include_str!("../../shaders/components_merge.wgsl"),
    ),
    (
        "components_compress",
        SHARED_DETECT,
        include_str!("../../shaders/components_compress.wgsl"),
    ),
    (
        "centroid_count",
        SHARED_DETECT,
        include_str!("../../shaders/centroid_count.wgsl"),
    ),
    (
        "centroid_scan",
        SHARED_DETECT,
        include_str!("../../shaders/centroid_scan.wgsl"),
    ),
    (
        "centroid",
        SHARED_DETECT,
        include_str!("../../shaders/centroid.wgsl"),
    ),
    (
        "streak_rows",
        SHARED_STREAK,
        include_str!("../../shaders/streak_rows.wgsl"),
    ),
    (
        "streak_filter",
        SHARED_STREAK,
        include_str!("../../shaders/streak_filter.wgsl"),
    ),
    ("vote", SHARED_VOTE, include_str!("../../shaders/vote.wgsl")),
    (
        "select",
        SHARED_VOTE,
        include_str!("../../shaders/select.wgsl"),
    ),
    ("psf_fit", "", include_str!("../../shaders/psf_fit.wgsl")),
    ("radial", "", include_str!("../../shaders/radial.wgsl")),
    ("pattern", "", include_str!("../../shaders/pattern.wgsl")),
];

/// The full WGSL source of a kernel (shared prelude + body).
pub fn kernel_source(name: &str) -> Option<String> {
    KERNELS
        .iter()
        .find(|k| k.0 == name)
        .map(|(_, shared, body)| format!("{shared}\n{body}"))
}

/// Workgroups per dispatch row of the striding kernels (threads stride over the rest).
const STRIDE_GROUPS: u32 = 1024;

/// How many submissions and buffer maps the context has made: batches must cost O(1) of each.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    pub submissions: u64,
    pub maps: u64,
}

/// An adapter as `gpustar info` lists it.
#[derive(Clone, Debug)]
pub struct AdapterSummary {
    pub name: String,
    pub backend: String,
    pub device_type: String,
    /// A software rasterizer (lavapipe, llvmpipe, SwiftShader): the kernels run on the CPU.
    pub software: bool,
    pub driver: String,
}

impl AdapterSummary {
    fn of(info: &wgpu::AdapterInfo) -> AdapterSummary {
        AdapterSummary {
            name: info.name.clone(),
            backend: format!("{:?}", info.backend),
            device_type: format!("{:?}", info.device_type),
            software: info.device_type == wgpu::DeviceType::Cpu,
            driver: format!("{} {}", info.driver, info.driver_info)
                .trim()
                .to_string(),
        }
    }
}

/// The compute pipelines, one per kernel.
struct Kernels {
    threshold_tiles: wgpu::ComputePipeline,
    tile_clip_sky: wgpu::ComputePipeline,
    tile_clip: wgpu::ComputePipeline,
    threshold: wgpu::ComputePipeline,
    components_merge: wgpu::ComputePipeline,
    components_compress: wgpu::ComputePipeline,
    centroid_count: wgpu::ComputePipeline,
    centroid_scan: wgpu::ComputePipeline,
    centroid: wgpu::ComputePipeline,
    streak_rows: wgpu::ComputePipeline,
    streak_filter: wgpu::ComputePipeline,
    vote: wgpu::ComputePipeline,
    select: wgpu::ComputePipeline,
    psf_fit: wgpu::ComputePipeline,
    radial: wgpu::ComputePipeline,
    pattern: wgpu::ComputePipeline,
}

/// The GPU context: built once, used for every batch.
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    kernels: Kernels,
    /// The adapter in use, as the records' `backend` field names it.
    pub adapter: AdapterSummary,
    /// Limits granted: the defaults, with buffer sizes raised to the adapter's.
    pub limits: wgpu::Limits,
    counters: Cell<Counters>,
    /// Buffers kept between batches, by name: reusing them spares wgpu zeroing new ones.
    cache: std::cell::RefCell<std::collections::HashMap<&'static str, wgpu::Buffer>>,
}

fn instance() -> wgpu::Instance {
    wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle())
}

/// Every adapter wgpu finds.
pub fn adapters() -> Vec<AdapterSummary> {
    pollster::block_on(instance().enumerate_adapters(wgpu::Backends::all()))
        .iter()
        .map(|a| AdapterSummary::of(&a.get_info()))
        .collect()
}

/// Rank of a device type when no adapter is named: real GPUs first.
fn preference(t: wgpu::DeviceType) -> u8 {
    match t {
        wgpu::DeviceType::DiscreteGpu => 0,
        wgpu::DeviceType::IntegratedGpu => 1,
        wgpu::DeviceType::VirtualGpu => 2,
        wgpu::DeviceType::Cpu => 3,
        wgpu::DeviceType::Other => 4,
    }
}

/// The adapter [`Gpu::new`] would open, without opening it (no device is made).
pub fn best_adapter(name: Option<&str>) -> Result<AdapterSummary> {
    Ok(AdapterSummary::of(
        &pick_adapter(&instance(), name)?.get_info(),
    ))
}

/// The first adapter whose name contains `name`, else the best device type.
fn pick_adapter(instance: &wgpu::Instance, name: Option<&str>) -> Result<wgpu::Adapter> {
    let mut all = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
    if all.is_empty() {
        fail!(Gpu, "{NO_ADAPTER_HELP}");
    }
    all.sort_by_key(|a| preference(a.get_info().device_type));
    Ok(match name {
        Some(n) => {
            let n = n.to_lowercase();
            let found = all
                .iter()
                .position(|a| a.get_info().name.to_lowercase().contains(&n));
            match found {
                Some(i) => all.swap_remove(i),
                None => fail!(
                    Gpu,
                    "no GPU adapter's name contains {n:?} (GPUSTAR_ADAPTER); found: {}",
                    all.iter()
                        .map(|a| a.get_info().name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            }
        }
        None => all.swap_remove(0),
    })
}

/// The message when no adapter is found.
pub const NO_ADAPTER_HELP: &str = "no GPU adapter found: install a Vulkan driver (on Debian/Ubuntu \
     `apt-get install mesa-vulkan-drivers libvulkan1` gives lavapipe, a software one), or run \
     with --backend cpu";

impl Gpu {
    /// Pick an adapter (the first whose name contains `name`, case-insensitive, when given;
    /// else the best device type) and build the device and pipelines.
    pub fn new(name: Option<&str>) -> Result<Gpu> {
        let adapter = pick_adapter(&instance(), name)?;
        let info = adapter.get_info();
        let granted = adapter.limits();
        // The defaults, so that what passes here runs on any GPU; only buffer sizes grow, to
        // what the adapter offers, since they bound the batch size.
        let limits = wgpu::Limits {
            max_storage_buffer_binding_size: granted.max_storage_buffer_binding_size,
            max_buffer_size: granted.max_buffer_size,
            ..wgpu::Limits::default()
        };
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gpustar"),
            required_features: wgpu::Features::empty(),
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .into_kind(Error::Gpu)
        .with_context(|| format!("cannot open the GPU device {}", info.name))?;
        // Errors outside an error scope are logged, not raised as panics.
        device.on_uncaptured_error(Arc::new(|e| eprintln!("gpustar: GPU error: {e}")));
        let scope = device.push_error_scope(wgpu::ErrorFilter::Validation);
        let kernels = Kernels {
            threshold_tiles: pipeline(&device, "threshold_tiles"),
            tile_clip_sky: pipeline(&device, "tile_clip_sky"),
            tile_clip: pipeline(&device, "tile_clip"),
            threshold: pipeline(&device, "threshold"),
            components_merge: pipeline(&device, "components_merge"),
            components_compress: pipeline(&device, "components_compress"),
            centroid_count: pipeline(&device, "centroid_count"),
            centroid_scan: pipeline(&device, "centroid_scan"),
            centroid: pipeline(&device, "centroid"),
            streak_rows: pipeline(&device, "streak_rows"),
            streak_filter: pipeline(&device, "streak_filter"),
            vote: pipeline(&device, "vote"),
            select: pipeline(&device, "select"),
            psf_fit: pipeline(&device, "psf_fit"),
            radial: pipeline(&device, "radial"),
            pattern: pipeline(&device, "pattern"),
        };
        if let Some(e) = pollster::block_on(scope.pop()) {
            fail!(Gpu, "building the GPU kernels failed on {}: {e}", info.name);
        }
        Ok(Gpu {
            device,
            queue,
            kernels,
            adapter: AdapterSummary::of(&info),
            limits,
            counters: Cell::new(Counters::default()),
            cache: Default::default(),
        })
    }

    /// The `backend` field of records made here, e.g. `gpu: llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan)`.
    pub fn backend_name(&self) -> String {
        format!("gpu: {} ({})", self.adapter.name, self.adapter.backend)
    }

    /// Submissions and maps so far.
    pub fn counters(&self) -> Counters {
        self.counters.get()
    }

    /// The largest storage buffer a kernel may bind.
    pub fn max_binding(&self) -> u64 {
        self.limits
            .max_storage_buffer_binding_size
            .min(self.limits.max_buffer_size)
    }

    /// A buffer of at least `size` bytes, reused from earlier batches when big enough. Its
    /// contents are whatever the last batch left: kernels clear or overwrite what they read.
    fn reused(&self, label: &'static str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        let size = size.max(4).next_multiple_of(4);
        let mut cache = self.cache.borrow_mut();
        if let Some(b) = cache.get(label)
            && b.size() >= size
            && b.usage() == usage
        {
            return b.clone();
        }
        let b = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        });
        cache.insert(label, b.clone());
        b
    }

    /// A storage buffer (reused between batches) that can be cleared, written and copied.
    fn storage(&self, label: &'static str, size: u64) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::STORAGE
            | wgpu::BufferUsages::COPY_DST
            | wgpu::BufferUsages::COPY_SRC;
        self.reused(label, size, usage)
    }

    /// A storage buffer holding `bytes`.
    fn storage_init(&self, label: &'static str, bytes: &[u8]) -> wgpu::Buffer {
        let buf = self.storage(label, bytes.len() as u64);
        if !bytes.is_empty() {
            self.queue.write_buffer(&buf, 0, bytes);
        }
        buf
    }

    /// A storage buffer of its own (not reused), holding `bytes`: for data kept across batches.
    fn storage_owned(&self, label: &str, bytes: &[u8]) -> wgpu::Buffer {
        let buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: (bytes.len() as u64).max(4).next_multiple_of(4),
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        if !bytes.is_empty() {
            self.queue.write_buffer(&buf, 0, bytes);
        }
        buf
    }

    fn uniform<T: bytemuck::Pod>(&self, label: &'static str, value: &T) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST;
        let buf = self.reused(label, std::mem::size_of::<T>() as u64, usage);
        self.queue.write_buffer(&buf, 0, bytemuck::bytes_of(value));
        buf
    }

    /// A uniform buffer of its own: for dispatches of one submission that each need their
    /// own values (a reused one holds only the last value written before the submission).
    fn uniform_owned<T: bytemuck::Pod>(&self, label: &'static str, value: &T) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some(label),
                contents: bytemuck::bytes_of(value),
                usage: wgpu::BufferUsages::UNIFORM,
            })
    }

    /// A buffer to copy results into and map (reused between batches).
    fn staging(&self, label: &'static str, size: u64) -> wgpu::Buffer {
        let usage = wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST;
        self.reused(label, size, usage)
    }

    fn bind_group(
        &self,
        pipeline: &wgpu::ComputePipeline,
        buffers: &[&wgpu::Buffer],
    ) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &pipeline.get_bind_group_layout(0),
            entries: &entries,
        })
    }

    /// Submit an encoder, inside a validation and out-of-memory error scope.
    fn submit(&self, encoder: wgpu::CommandEncoder) -> Result<()> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        self.queue.submit([encoder.finish()]);
        let mut c = self.counters.get();
        c.submissions += 1;
        self.counters.set(c);
        if let Some(e) = pollster::block_on(oom.pop()) {
            fail!(
                Gpu,
                "the GPU ran out of memory: {e}; use smaller batches or --backend cpu"
            );
        }
        if let Some(e) = pollster::block_on(scope.pop()) {
            fail!(Gpu, "GPU error: {e}");
        }
        Ok(())
    }

    /// Map the first `len` bytes of every staging buffer, wait once, and copy them out.
    fn read_all(&self, buffers: &[(&wgpu::Buffer, u64)]) -> Result<Vec<Vec<u8>>> {
        let results: Vec<MapSlot> = buffers.iter().map(|_| Default::default()).collect();
        for ((b, len), r) in buffers.iter().zip(&results) {
            let r = r.clone();
            b.map_async(
                wgpu::MapMode::Read,
                ..(*len).max(4).next_multiple_of(4),
                move |res| {
                    *r.lock().unwrap() = Some(res);
                },
            );
        }
        let mut c = self.counters.get();
        c.maps += 1;
        self.counters.set(c);
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| error!(Gpu, "waiting for the GPU failed: {e}"))?;
        let mut out = Vec::with_capacity(buffers.len());
        for ((b, len), r) in buffers.iter().zip(&results) {
            match r.lock().unwrap().take() {
                Some(Ok(())) => {}
                Some(Err(e)) => fail!(Gpu, "reading GPU results failed: {e}"),
                None => fail!(Gpu, "reading GPU results did not complete"),
            }
            let mut bytes = b
                .get_mapped_range(..(*len).max(4).next_multiple_of(4))
                .map_err(|e| error!(Gpu, "reading GPU results failed: {e}"))?
                .to_vec();
            bytes.truncate(*len as usize);
            b.unmap();
            out.push(bytes);
        }
        Ok(out)
    }
}

/// Where a map callback leaves its result.
type MapSlot = Arc<std::sync::Mutex<Option<Result<(), wgpu::BufferAsyncError>>>>;

fn pipeline(device: &wgpu::Device, name: &str) -> wgpu::ComputePipeline {
    let source = kernel_source(name).expect("every pipeline has a kernel");
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(name),
        source: wgpu::ShaderSource::Wgsl(source.into()),
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(name),
        layout: None,
        module: &module,
        entry_point: Some("main"),
        compilation_options: Default::default(),
        cache: None,
    })
}

/// Dispatch a striding kernel over `items` per image (x) and `images` (y).
fn dispatch_strided(
    pass: &mut wgpu::ComputePass<'_>,
    pipeline: &wgpu::ComputePipeline,
    bind: &wgpu::BindGroup,
    items: u32,
    images: u32,
) {
    pass.set_pipeline(pipeline);
    pass.set_bind_group(0, bind, &[]);
    pass.dispatch_workgroups(items.div_ceil(256).clamp(1, STRIDE_GROUPS), images, 1);
}
