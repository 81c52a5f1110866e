//! The GPU device layer, with wgpu compute shaders (`shaders/`): the device, kernels and
//! buffers every GPU user shares, the renderer, and the resident forward half. It knows
//! no stage; each stage keeps its GPU twin beside its CPU code and asks this layer for its
//! kernels (`Gpu::kernels`). Its error is [`Error`].
//!
//! - [`Gpu::render`] gives the pixels of [`mod@gsi_render::render`]: projection and tile binning
//!   are the CPU's own ([`project_scene`], `render::tiles`), and the shader evaluates spec
//!   §6 per pixel in the same `f32` order, so the only difference is the rounding of `exp`
//!   (within 1/255 after 8-bit conversion; `cli/tests/gpu.rs` holds it to that).
//! - [`GpuScene`] draws a decoded scene again and again with the resident forward half
//!   (projection, deterministic binning by a stable radix sort, render).
//! - Stage 1's backward pass (`fit::backward_gpu`) and whole optimizer step on the GPU
//!   (`fit::resident`: that forward half, then L2 loss, backward, chain rule, Adam), and
//!   stage 2's per-Gaussian mixture (`enhance::gpu`), live in their stages' crates with
//!   their WGSL (`shaders/fit/`, `shaders/enhance/`).
//!
//! The adapter is headless (no surface) and honours wgpu's environment variables:
//! `WGPU_BACKEND` (e.g. `vulkan`), `WGPU_ADAPTER_NAME` (a substring of the adapter's
//! name) and `WGPU_POWER_PREF`. [`Gpu::render`] splits large outputs and long tile lists
//! into bands of tile rows so that no buffer exceeds the adapter's limits; the resident
//! pipelines keep whole images and refuse, with [`ErrorKind::LimitExceeded`], what does
//! not fit (the fitter then continues on the CPU).

use gsi_format::format::Limits;
use gsi_format::model::{Blend, Scene};
use gsi_render::render::{project_scene, Projected, RgbImage, TileLists, TILE};
use wgpu::util::DeviceExt;

/// A shader's source: the contract constants ([`contract`]), then the named files of the
/// workspace's `shaders/` in order (WGSL has no includes), each named by its folder:
/// `device/` for this crate's kernels, `fit/` and `enhance/` for the stages' GPU twins.
/// Exported for the stage crates, whose manifests sit two folders below the workspace.
#[doc(hidden)]
#[macro_export]
macro_rules! shader {
    ($($name:literal),+) => {
        $crate::gpu::with_contract(&[$(include_str!(concat!(
            env!("CARGO_MANIFEST_DIR"), "/../../shaders/", $name, ".wgsl"
        ))),+])
    };
    // A stage's own constants (WGSL source) ahead of its files.
    (prelude = $prelude:expr; $($name:literal),+) => {
        $crate::gpu::with_contract(&[$prelude, $(include_str!(concat!(
            env!("CARGO_MANIFEST_DIR"), "/../../shaders/", $name, ".wgsl"
        ))),+])
    };
}
pub use crate::shader;

/// How long a call waits for the GPU by default: far above any step or frame this crate
/// submits on a working device (a whole 12-MP render is well under a second), short of
/// leaving a hung one to block a program forever.
pub const DEFAULT_WAIT_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(60);

/// The constants of the pixel contract (format-spec.md §6), of the model and of the
/// buffer layouts host and shaders share, written as WGSL from the Rust constants
/// themselves, so that no shader can drift from the CPU or the host.
fn contract() -> String {
    use gsi_format::contract::{
        ALPHA_MAX, ALPHA_MIN, CHOLESKY_MAX, COLOR_MAX, CORRELATION_MAX, EXTENT_SIGMAS,
        LN_SIGMA_MAX, LN_SIGMA_MIN, TRANSMITTANCE_MIN, VAR_MAX, VAR_MIN,
    };
    let floats = [
        ("ALPHA_MIN", ALPHA_MIN),
        ("ALPHA_MAX", ALPHA_MAX),
        ("TRANSMITTANCE_MIN", TRANSMITTANCE_MIN),
        ("VAR_MIN", VAR_MIN),
        ("VAR_MAX", VAR_MAX),
        ("CORRELATION_MAX", CORRELATION_MAX),
        ("EXTENT_SIGMAS", EXTENT_SIGMAS),
        ("COLOR_MAX", COLOR_MAX),
        ("LN_SIGMA_MIN", LN_SIGMA_MIN),
        ("LN_SIGMA_MAX", LN_SIGMA_MAX),
        ("CHOLESKY_MAX", CHOLESKY_MAX),
    ];
    let mut out = String::new();
    for (name, value) in [
        ("TILE", TILE),
        ("GROUP", forward::GROUP),
        ("SCAN_PER", forward::SCAN_PER),
        ("STRIDE", forward::STRIDE as u32),
        ("SLOT", SLOT as u32),
        ("SORT_BLOCK", sort::BLOCK),
        ("SORT_INDEX_BITS", sort::BLOCK.trailing_zeros()),
        ("SORT_MAX_BINS", 1 << sort::MAX_DIGIT_BITS),
    ] {
        out += &format!("const {name}: u32 = {value}u;\n");
    }
    for (name, value) in floats {
        // `{:?}` prints the shortest decimal that reads back as the same f32.
        out += &format!("const {name}: f32 = {value:?};\n");
    }
    out + &spec_exp()
}

/// The `exp` of spec §6.3 in WGSL, `spec_exp`, with the constants of
/// [`gsi_format::contract::exp`] as their exact bits. WGSL's `round` is ties-to-even, as the
/// CPU's rounding by `1.5·2^23` is. A GPU compiler may still fuse a product and a sum,
/// which is why the GPU's pixels are held to a bound rather than to the CPU's bits.
fn spec_exp() -> String {
    use gsi_format::contract::{EXP_LN2_HI, EXP_LN2_LO, EXP_LOG2E, EXP_MAX, EXP_MIN, EXP_POLY};
    let bits = |v: f32| format!("bitcast<f32>({:#010x}u)", v.to_bits());
    let mut horner = format!("    var p = {};\n", bits(EXP_POLY[0]));
    for c in &EXP_POLY[1..] {
        horner += &format!("    p = p * r + {};\n", bits(*c));
    }
    format!(
        "fn spec_exp(x_in: f32) -> f32 {{\n\
         \x20   let x = clamp(x_in, {min:?}, {max:?});\n\
         \x20   let n = round(x * {log2e});\n\
         \x20   let r = (x - n * {hi}) - n * {lo};\n\
         {horner}\
         \x20   let er = ((p * r) * r + r) + 1.0;\n\
         \x20   return er * bitcast<f32>(u32(i32(n) + 127) << 23u);\n\
         }}\n",
        min = EXP_MIN,
        max = EXP_MAX,
        log2e = bits(EXP_LOG2E),
        hi = bits(EXP_LN2_HI),
        lo = bits(EXP_LN2_LO),
    )
}

/// `contract`, the indexing helpers of `shaders/device/grid.wgsl`, then `parts`.
pub fn with_contract(parts: &[&str]) -> String {
    let mut source = contract();
    source.push_str(include_str!("../../../../shaders/device/grid.wgsl"));
    for part in parts {
        source.push_str(part);
    }
    #[cfg(any(test, feature = "test-support"))]
    if BREAK_SHADERS.with(std::cell::Cell::get) {
        // What a stricter compiler than lavapipe's would refuse, made certain.
        source.push_str("\nfn refused_by_every_compiler( {\n");
    }
    source
}

#[cfg(any(test, feature = "test-support"))]
thread_local! {
    static BREAK_SHADERS: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Make every shader built on this thread fail to compile (or stop doing so), to test the
/// paths a real driver's refusal takes (this crate's tests and the stages').
#[cfg(any(test, feature = "test-support"))]
pub fn break_shaders_on_this_thread(on: bool) {
    BREAK_SHADERS.with(|b| b.set(on));
}

mod error;
pub mod forward;
mod sort;

pub use error::{Error, ErrorKind, Result};

pub use forward::GpuScene;

/// Floats per tile-list entry written by the backward passes: d mean (2), d conic (3),
/// d opacity, d colour (3).
pub const SLOT: usize = 9;

/// A device with the render pipeline built, ready for any number of renders.
pub struct Gpu {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    render: Kernel,
    pub info: wgpu::AdapterInfo,
    /// Largest storage binding, bytes.
    pub max_binding: u64,
    /// Most workgroups of a dispatch along one dimension.
    pub max_groups: u32,
    /// The resident forward half's pipelines, built when first needed.
    forward: std::sync::OnceLock<forward::ForwardKernels>,
    /// Submissions and read-backs so far ([`Gpu::traffic`]).
    traffic: TrafficCounters,
    /// Staging buffers of earlier read-backs, for the next ones to reuse.
    staging: std::sync::Mutex<Vec<wgpu::Buffer>>,
    /// See [`Gpu::set_wait_timeout`].
    wait_timeout: std::sync::Mutex<std::time::Duration>,
    /// Errors wgpu raised outside every error scope; the next checked call reports them.
    uncaptured: std::sync::Arc<std::sync::Mutex<Option<String>>>,
    /// The stages' kernel sets, built on first use, one per type ([`Gpu::kernels`]).
    #[cfg_attr(not(feature = "encode"), allow(dead_code))]
    kernels: std::sync::Mutex<Vec<std::sync::Arc<dyn std::any::Any + Send + Sync>>>,
}

/// Host round trips of a device ([`Gpu::traffic`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Traffic {
    /// Command submissions.
    pub submissions: u64,
    /// Read-backs (each copies results into staging buffers and maps them).
    pub read_backs: u64,
    /// Read-backs the host waited for with nothing submitted after them: the device runs
    /// dry from the moment it finishes until the host submits again. A read-back collected
    /// after the next step was submitted (a progress report read one step late) is not one.
    pub stalls: u64,
    /// Staging buffers created for read-backs (reused from a ring after the first).
    pub staging_buffers: u64,
}

#[derive(Debug, Default)]
struct TrafficCounters {
    submissions: std::sync::atomic::AtomicU64,
    read_backs: std::sync::atomic::AtomicU64,
    stalls: std::sync::atomic::AtomicU64,
    staging_buffers: std::sync::atomic::AtomicU64,
}

/// Most staging buffers kept for reuse: the largest read-back takes three at once, and a
/// fit reading its reports a step late keeps two of those in flight.
const STAGING_RING: usize = 8;
/// Largest staging buffer kept for reuse (bytes): the ring holds at most 128 MiB.
const STAGING_KEEP_MAX: u64 = 16 << 20;

/// Uniform block of the shader (`Params` in `render.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    width: u32,
    height: u32,
    tiles_x: u32,
    blend: u32,
    tile_row0: u32,
    rows: u32,
    _pad: [u32; 2],
}

// The size of `Params` in `render.wgsl`, checked at compile time here and against the WGSL
// itself by `uniform_structs_match_their_wgsl_layouts`.
const _: () = assert!(std::mem::size_of::<Params>() == 32);

impl Gpu {
    /// Open the adapter the environment asks for (or the default one), software
    /// rasterizers such as lavapipe included, and build the pipeline. Fails, without
    /// panicking, when there is no usable adapter.
    pub fn new() -> Result<Gpu> {
        Self::open(true)
    }

    /// [`Gpu::new`], refusing an adapter that is itself a CPU rasterizer: what
    /// `--device auto` wants, since the CPU renderer beats an emulated GPU.
    pub fn new_hardware() -> Result<Gpu> {
        Self::open(false)
    }

    fn open(allow_software: bool) -> Result<Gpu> {
        let mut found = Err(Error::new(ErrorKind::Unavailable, "no GPU adapter"));
        for backends in backend_order(wgpu::Backends::from_env()) {
            let mut desc = wgpu::InstanceDescriptor::new_without_display_handle_from_env();
            desc.backends = backends;
            let instance = wgpu::Instance::new(desc);
            found = pollster::block_on(pick_adapter(&instance, backends));
            if found.is_ok() {
                break;
            }
        }
        let adapter = found?;
        let info = adapter.get_info();
        if !allow_software && info.device_type == wgpu::DeviceType::Cpu {
            return Err(Error::new(
                ErrorKind::Unavailable,
                format!("only a software adapter ({})", info.name),
            ));
        }
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gsi"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| Error::new(ErrorKind::Unavailable, format!("{}: {e}", info.name)))?;
        // wgpu's default for an error outside every scope is to panic; this crate scopes
        // every call, and keeps whatever escapes for the next call to report.
        let uncaptured = std::sync::Arc::new(std::sync::Mutex::new(None));
        let sink = uncaptured.clone();
        device.on_uncaptured_error(std::sync::Arc::new(move |e: wgpu::Error| {
            let mut last = sink.lock().unwrap_or_else(|e| e.into_inner());
            last.get_or_insert_with(|| e.to_string());
        }));
        // Real shader compilers refuse what lavapipe accepts: a kernel that does not build
        // makes the device unusable here, as an error (the caller then uses the CPU).
        let render = scoped(&device, || {
            Ok(Kernel::new(
                &device,
                "render",
                &shader!("device/render"),
                4,
                1,
            ))
        })
        .map_err(|e| Error::new(ErrorKind::Unavailable, format!("{}: {e}", info.name)))?;
        let max_binding = max_binding(&limits);
        Ok(Gpu {
            device,
            queue,
            render,
            info,
            max_binding,
            max_groups: limits.max_compute_workgroups_per_dimension,
            forward: std::sync::OnceLock::new(),
            wait_timeout: std::sync::Mutex::new(DEFAULT_WAIT_TIMEOUT),
            traffic: TrafficCounters::default(),
            staging: std::sync::Mutex::new(Vec::new()),
            uncaptured,
            kernels: std::sync::Mutex::new(Vec::new()),
        })
    }

    /// Submit command buffers, counted in [`Gpu::traffic`].
    pub fn submit<I: IntoIterator<Item = wgpu::CommandBuffer>>(
        &self,
        buffers: I,
    ) -> wgpu::SubmissionIndex {
        self.traffic
            .submissions
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        self.queue.submit(buffers)
    }

    /// How many submissions and blocking read-backs this device has made: the host round
    /// trips that bound a fast GPU's step time (a read-back is also a submission).
    pub fn traffic(&self) -> Traffic {
        let get = |c: &std::sync::atomic::AtomicU64| c.load(std::sync::atomic::Ordering::Relaxed);
        Traffic {
            submissions: get(&self.traffic.submissions),
            read_backs: get(&self.traffic.read_backs),
            stalls: get(&self.traffic.stalls),
            staging_buffers: get(&self.traffic.staging_buffers),
        }
    }

    /// Wait for submission `index` and those before it (all submitted work if `None`), at
    /// most the wait timeout: a hung or lost device gives [`ErrorKind::TimedOut`] (and the
    /// caller the CPU) instead of blocking forever.
    pub fn wait(&self, index: Option<wgpu::SubmissionIndex>) -> Result<()> {
        let timeout = *self.wait_timeout.lock().unwrap_or_else(|e| e.into_inner());
        match self.device.poll(wgpu::PollType::Wait {
            submission_index: index,
            timeout: Some(timeout),
        }) {
            Ok(_) => Ok(()),
            Err(wgpu::PollError::Timeout) => Err(Error::new(
                ErrorKind::TimedOut,
                format!("GPU: no answer from {} within {timeout:?}", self.info.name),
            )),
            Err(e) => Err(Error::new(ErrorKind::Device, format!("GPU: {e}"))),
        }
    }

    /// The longest wait for the GPU to finish submitted work (default
    /// [`DEFAULT_WAIT_TIMEOUT`]); past it the call fails with [`ErrorKind::TimedOut`].
    pub fn set_wait_timeout(&self, timeout: std::time::Duration) {
        *self.wait_timeout.lock().unwrap_or_else(|e| e.into_inner()) = timeout;
    }

    /// Pretend the adapter binds at most `bytes` per buffer (never raises the real
    /// limit), so that tests can exercise the band splitting on small images.
    #[doc(hidden)]
    pub fn limit_bindings(&mut self, bytes: u64) {
        self.max_binding = self.max_binding.min(bytes);
    }

    /// The adapter in use, e.g. `llvmpipe (LLVM 15.0.6, 256 bits) (Vulkan, Cpu)`.
    pub fn adapter(&self) -> String {
        format!(
            "{} ({:?}, {:?})",
            self.info.name, self.info.backend, self.info.device_type
        )
    }

    /// Render `scene` at `width × height`: the same pixels as [`gsi_render::render::render`],
    /// within the rounding of `exp`. The scene's tone curve (spec §6.6) is applied on the
    /// CPU to what the GPU blended, so it adds no difference of its own.
    pub fn render(&self, scene: &Scene, width: u32, height: u32) -> Result<RgbImage> {
        // Before projecting: a zero or oversized output is refused, not projected for.
        Limits::default().check_output(width, height)?;
        if !scene.gaussians.is_consistent() {
            return Err(Error::new(
                ErrorKind::InvalidValue,
                "inconsistent Gaussian set",
            ));
        }
        let proj = project_scene(scene, width, height);
        let work = gsi_render::render::render_work(&proj);
        Limits::default().check_render_work(work, width, height)?;
        let mut image = self.render_projected(&proj, scene.blend, width, height)?;
        if let Some(t) = &scene.tone {
            t.apply(&mut image.data);
        }
        Ok(image)
    }

    /// [`Gpu::render`] of Gaussians already projected for this size (the fitter projects
    /// once per step for both passes).
    pub fn render_projected(
        &self,
        proj: &[Projected],
        blend: Blend,
        width: u32,
        height: u32,
    ) -> Result<RgbImage> {
        self.checked(|| {
            Limits::default().check_output(width, height)?;
            let mut data = vec![0.0f32; width as usize * height as usize * 3];
            if proj.is_empty() {
                return Ok(RgbImage {
                    width,
                    height,
                    data,
                });
            }
            let tiles_x = width.div_ceil(TILE);
            let tiles_y = height.div_ceil(TILE);
            // Entries per tile row, to cut bands that fit the adapter's limits.
            let mut per_row = vec![0u64; tiles_y as usize];
            for g in proj {
                let span = u64::from(g.bbox.x1 / TILE - g.bbox.x0 / TILE + 1);
                for ty in g.bbox.y0 / TILE..=g.bbox.y1 / TILE {
                    per_row[ty as usize] += span;
                }
            }
            let row_bytes = u64::from(width) * u64::from(TILE) * 12;
            let gaussian_bytes = proj.len() as u64 * 48;
            if gaussian_bytes > self.max_binding
                || row_bytes > self.max_binding
                || tiles_x > self.max_groups
            {
                return Err(too_big(&self.info, "one tile row"));
            }
            let (gaussians, boxes) = upload_layout(proj);
            let g_buf = self.storage(bytemuck::cast_slice(&gaussians));
            let b_buf = self.storage(bytemuck::cast_slice(&boxes));
            let mut ty = 0u32;
            while ty < tiles_y {
                // Grow the band while its index list and output fit in one binding.
                let (mut end, mut entries) = (ty, 0u64);
                while end < tiles_y
                    && end - ty < self.max_groups
                    && (entries + per_row[end as usize]) * 4 <= self.max_binding
                    && u64::from(end - ty + 1) * row_bytes <= self.max_binding
                {
                    entries += per_row[end as usize];
                    end += 1;
                }
                if end == ty {
                    return Err(too_big(&self.info, "the tile lists of one tile row"));
                }
                let rows = ((end * TILE).min(height) - ty * TILE) as usize;
                let band = &mut data[(ty * TILE) as usize * width as usize * 3..]
                    [..rows * width as usize * 3];
                self.render_band(
                    proj,
                    (&g_buf, &b_buf),
                    blend,
                    (width, height, tiles_x),
                    ty..end,
                    band,
                )?;
                ty = end;
            }
            Ok(RgbImage {
                width,
                height,
                data,
            })
        })
    }

    /// A storage buffer holding `bytes` (16 zero bytes when empty: a binding may not be),
    /// which kernels may read and write and the host may copy to and from.
    pub fn storage(&self, bytes: &[u8]) -> wgpu::Buffer {
        let bytes = if bytes.is_empty() {
            &[0u8; 16][..]
        } else {
            bytes
        };
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE
                    | wgpu::BufferUsages::COPY_SRC
                    | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// Render tile rows `rows` into `out` (those pixel rows, RGB).
    fn render_band(
        &self,
        proj: &[Projected],
        (g_buf, b_buf): (&wgpu::Buffer, &wgpu::Buffer),
        blend: Blend,
        (width, height, tiles_x): (u32, u32, u32),
        rows: std::ops::Range<u32>,
        out: &mut [f32],
    ) -> Result<()> {
        let (offsets, lists) = tile_lists(proj, tiles_x, rows.clone())?;
        let indices = lists.parts().1;
        let params = Params {
            width,
            height,
            tiles_x,
            blend: match blend {
                Blend::Sum => 0,
                Blend::Alpha => 1,
            },
            tile_row0: rows.start,
            rows: (out.len() / (width as usize * 3)) as u32,
            _pad: [0; 2],
        };
        let inputs = [
            self.uniform_buffer(bytemuck::bytes_of(&params)),
            g_buf.clone(),
            b_buf.clone(),
            self.storage(bytemuck::cast_slice(&offsets)),
            self.storage(bytemuck::cast_slice(indices)),
        ];
        self.run(&self.render, &inputs, (tiles_x, rows.end - rows.start), out)
    }

    /// Bind `inputs` then an output buffer the size of `out`, dispatch `groups`
    /// workgroups of `kernel`, and read the output back into `out`.
    pub fn run(
        &self,
        kernel: &Kernel,
        inputs: &[wgpu::Buffer],
        groups: (u32, u32),
        out: &mut [f32],
    ) -> Result<()> {
        let out_buf = self.zeroed(out.len() as u64 * 4);
        let buffers: Vec<&wgpu::Buffer> = inputs.iter().chain(std::iter::once(&out_buf)).collect();
        let bind = kernel.bind(&self.device, &buffers);
        let mut enc = self.encoder();
        self.pass(&mut enc, &[(kernel, &bind, groups)]);
        let [bytes] = self.read_back(enc, [&out_buf])?;
        out.copy_from_slice(&bytemuck::cast_slice::<u8, f32>(&bytes)[..out.len()]);
        Ok(())
    }

    /// A storage buffer of `bytes` zeros (at least 16: a binding may not be empty) that
    /// kernels may read and write and the host may copy to and from.
    pub fn zeroed(&self, bytes: u64) -> wgpu::Buffer {
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: bytes.next_multiple_of(4).max(16),
            usage: wgpu::BufferUsages::STORAGE
                | wgpu::BufferUsages::COPY_SRC
                | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// A mappable buffer of at least `size` bytes: the smallest such one of the ring, or a
    /// new one (of the next power of two, so that the ring serves the sizes around it).
    /// Each fits the adapter, since the source it copies does.
    fn staging_buffer(&self, size: u64) -> wgpu::Buffer {
        let mut ring = self.staging.lock().unwrap_or_else(|e| e.into_inner());
        let best = (0..ring.len())
            .filter(|&k| ring[k].size() >= size)
            .min_by_key(|&k| ring[k].size());
        if let Some(k) = best {
            return ring.remove(k);
        }
        drop(ring);
        self.traffic
            .staging_buffers
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        // Small ones (progress reports, gradients of small fits) are rounded up for the
        // ring to serve nearby sizes; large ones (rendered images) are made to measure and
        // not kept, so that the ring never holds much memory.
        let size = if size <= STAGING_KEEP_MAX {
            size.max(8).next_power_of_two()
        } else {
            size
        };
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("gsi staging"),
            size,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    }

    /// Submit `enc` with copies of `buffers` appended, wait, and return their bytes.
    pub fn read_back<const N: usize>(
        &self,
        enc: wgpu::CommandEncoder,
        buffers: [&wgpu::Buffer; N],
    ) -> Result<[Vec<u8>; N]> {
        self.read_back_later(enc, buffers).collect(self)
    }

    /// Submit `enc` with copies of `buffers` appended and start mapping the copies,
    /// without waiting: the host may record and submit more work before it collects the
    /// result ([`PendingRead::collect`]), so that the device is never left idle while the
    /// host waits for a report it could read a step later.
    pub fn read_back_later<const N: usize>(
        &self,
        mut enc: wgpu::CommandEncoder,
        buffers: [&wgpu::Buffer; N],
    ) -> PendingRead<N> {
        // One staging buffer per source, from the ring when one there is large enough.
        let staging = buffers.map(|b| {
            let s = self.staging_buffer(b.size());
            enc.copy_buffer_to_buffer(b, 0, &s, 0, b.size());
            (s, b.size())
        });
        let index = self.submit([enc.finish()]);
        self.traffic
            .read_backs
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let (tx, rx) = std::sync::mpsc::channel();
        for (s, _) in &staging {
            let tx = tx.clone();
            s.slice(..).map_async(wgpu::MapMode::Read, move |r| {
                let _ = tx.send(r.is_ok());
            });
        }
        PendingRead {
            staging,
            index,
            number: self
                .traffic
                .submissions
                .load(std::sync::atomic::Ordering::Relaxed),
            mapped: rx,
        }
    }

    /// Workgroups of [`forward::GROUP`] invocations for `n` items, laid out in two
    /// dimensions when one is not enough (kernels recover the linear index).
    pub fn groups(&self, n: u64) -> Result<(u32, u32)> {
        let g = n.div_ceil(u64::from(forward::GROUP)).max(1);
        let max = u64::from(self.max_groups.max(1));
        let y = g.div_ceil(max);
        if y > max {
            return Err(too_big(&self.info, "this dispatch"));
        }
        Ok((g.min(max) as u32, y as u32))
    }

    /// Run `f`, turning a wgpu validation or out-of-memory error it raises into an
    /// [`Error`], where wgpu's default is to panic. Every public entry point that
    /// creates GPU resources or records work goes through here.
    pub fn checked<T>(&self, f: impl FnOnce() -> Result<T>) -> Result<T> {
        let out = scoped(&self.device, f);
        let escaped = self
            .uncaptured
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take();
        match escaped {
            Some(e) if out.is_ok() => Err(Error::new(ErrorKind::Device, format!("GPU: {e}"))),
            _ => out,
        }
    }

    /// Record into `enc` one compute pass running `dispatches` in order (wgpu orders
    /// each dispatch's reads after the writes of the ones before it).
    pub fn pass(&self, enc: &mut wgpu::CommandEncoder, dispatches: &[Dispatch<'_>]) {
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
        for (kernel, bind, groups) in dispatches {
            kernel.dispatch(&mut pass, bind, *groups);
        }
    }

    /// A command encoder for one submission.
    pub fn encoder(&self) -> wgpu::CommandEncoder {
        self.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None })
    }

    /// A uniform block the host may rewrite between submissions.
    pub fn uniform_buffer(&self, bytes: &[u8]) -> wgpu::Buffer {
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytes,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            })
    }

    /// The kernel set of type `T`, built by `make` the first time it is asked for on this
    /// device. Each stage keeps its kernels beside its code and asks for them here, so
    /// that this device layer knows no stage.
    #[cfg_attr(not(feature = "encode"), allow(dead_code))]
    pub fn kernels<T: std::any::Any + Send + Sync>(
        &self,
        make: impl FnOnce(&wgpu::Device) -> T,
    ) -> Result<std::sync::Arc<T>> {
        let mut cache = self.kernels.lock().unwrap_or_else(|e| e.into_inner());
        if let Some(k) = cache.iter().find_map(|k| k.clone().downcast::<T>().ok()) {
            return Ok(k);
        }
        // Built in an error scope, and cached only when it built: a refused shader is an
        // error now and a fresh try next time, never a broken pipeline kept for good.
        let k = std::sync::Arc::new(scoped(&self.device, || Ok(make(&self.device)))?);
        cache.push(k.clone());
        Ok(k)
    }
}

/// A kernel, what it is bound to, and its workgroups.
pub type Dispatch<'a> = (&'a Kernel, &'a wgpu::BindGroup, (u32, u32));

/// A read-back submitted by [`Gpu::read_back_later`] and not yet collected. Dropping it
/// unread is harmless: its staging buffers are then not returned to the ring.
pub struct PendingRead<const N: usize> {
    /// Each staging buffer, and how many of its bytes are the result.
    staging: [(wgpu::Buffer, u64); N],
    index: wgpu::SubmissionIndex,
    /// The device's submission count just after this one ([`Gpu::traffic`]).
    number: u64,
    /// One message per staging buffer: whether it mapped.
    mapped: std::sync::mpsc::Receiver<bool>,
}

impl<const N: usize> PendingRead<N> {
    /// Wait for the copies (at most the device's wait timeout) and return their bytes.
    pub fn collect(self, gpu: &Gpu) -> Result<[Vec<u8>; N]> {
        let relaxed = std::sync::atomic::Ordering::Relaxed;
        if gpu.traffic.submissions.load(relaxed) == self.number {
            gpu.traffic.stalls.fetch_add(1, relaxed);
        }
        gpu.wait(Some(self.index))?;
        // The map callbacks run on whichever thread polls the device next: another one
        // may be running them still, so each message is waited for (the senders are gone
        // once the callbacks have run, so this cannot hang past the timeout).
        let timeout = *gpu.wait_timeout.lock().unwrap_or_else(|e| e.into_inner());
        let mapped = (0..N).all(|_| self.mapped.recv_timeout(timeout) == Ok(true));
        if !mapped {
            return Err(Error::new(
                ErrorKind::Device,
                "GPU: reading the result back failed",
            ));
        }
        let mut out = Vec::with_capacity(N);
        for (s, len) in &self.staging {
            let view = s
                .slice(..)
                .get_mapped_range()
                .map_err(|e| Error::new(ErrorKind::Device, format!("GPU: {e}")))?;
            out.push(view[..*len as usize].to_vec());
            drop(view);
            s.unmap();
        }
        // Returned to the ring, which forgets its least recently returned buffer when full:
        // the working set of the current loop stays, that of an earlier one ages out.
        let mut ring = gpu.staging.lock().unwrap_or_else(|e| e.into_inner());
        for (s, _) in self.staging {
            if s.size() <= STAGING_KEEP_MAX {
                if ring.len() == STAGING_RING {
                    ring.remove(0);
                }
                ring.push(s);
            }
        }
        Ok(out.try_into().expect("N parts"))
    }
}

/// A compute pipeline and the layout of its one bind group.
pub struct Kernel {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

impl Kernel {
    /// Entry point `main` of `source`. Binding 0 is a uniform block, then come `reads`
    /// read-only storage buffers, then `writes` read-write ones: every shader of this
    /// crate declares its bindings in that order.
    pub fn new(
        device: &wgpu::Device,
        label: &str,
        source: &str,
        reads: u32,
        writes: u32,
    ) -> Kernel {
        let [k] = Kernel::entries(device, label, source, ["main"], reads, writes);
        k
    }

    /// The entry points `names` of `source`, as [`Kernel::new`] builds one, sharing one
    /// bind group layout: a bind group made for one serves them all.
    pub fn entries<const N: usize>(
        device: &wgpu::Device,
        label: &str,
        source: &str,
        names: [&str; N],
        reads: u32,
        writes: u32,
    ) -> [Kernel; N] {
        let bindings = 1 + reads + writes;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(label),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        let entries: Vec<wgpu::BindGroupLayoutEntry> = (0..bindings)
            .map(|binding| wgpu::BindGroupLayoutEntry {
                binding,
                visibility: wgpu::ShaderStages::COMPUTE,
                ty: wgpu::BindingType::Buffer {
                    ty: if binding == 0 {
                        wgpu::BufferBindingType::Uniform
                    } else {
                        wgpu::BufferBindingType::Storage {
                            read_only: binding <= reads,
                        }
                    },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect();
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some(label),
            entries: &entries,
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(label),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        names.map(|name| Kernel {
            pipeline: device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some(label),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some(name),
                compilation_options: Default::default(),
                cache: None,
            }),
            layout: layout.clone(),
        })
    }

    /// A bind group of `buffers`, in binding order.
    pub fn bind(&self, device: &wgpu::Device, buffers: &[&wgpu::Buffer]) -> wgpu::BindGroup {
        let entries: Vec<wgpu::BindGroupEntry> = buffers
            .iter()
            .enumerate()
            .map(|(binding, b)| wgpu::BindGroupEntry {
                binding: binding as u32,
                resource: b.as_entire_binding(),
            })
            .collect();
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &entries,
        })
    }

    /// Record a dispatch of `groups` workgroups bound to `bind` into `pass`.
    pub fn dispatch(
        &self,
        pass: &mut wgpu::ComputePass<'_>,
        bind: &wgpu::BindGroup,
        groups: (u32, u32),
    ) {
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, bind, &[]);
        pass.dispatch_workgroups(groups.0, groups.1, 1);
    }
}

/// Per-tile lists of projected-Gaussian indices (stored order) for tile rows `rows`, from
/// the crate's one binner ([`TileLists`]), with the offsets in the `u32` the shaders read.
pub fn tile_lists(
    proj: &[Projected],
    tiles_x: u32,
    rows: std::ops::Range<u32>,
) -> Result<(Vec<u32>, TileLists)> {
    let lists = TileLists::bin_rows(proj, tiles_x, rows);
    let offsets = lists
        .parts()
        .0
        .iter()
        .map(|&o| u32::try_from(o))
        .collect::<std::result::Result<Vec<u32>, _>>()
        .map_err(|_| Error::new(ErrorKind::LimitExceeded, "more than 2^32 tile-list entries"))?;
    Ok((offsets, lists))
}

pub fn too_big(info: &wgpu::AdapterInfo, what: &str) -> Error {
    Error::new(
        ErrorKind::LimitExceeded,
        format!(
            "{what} exceeds the largest buffer {} can bind; render on the CPU",
            info.name
        ),
    )
}

/// Gaussians as the shader reads them: three `vec4<f32>` and one `vec4<u32>` box each.
pub fn upload_layout(proj: &[Projected]) -> (Vec<[f32; 4]>, Vec<[u32; 4]>) {
    let mut g = Vec::with_capacity(proj.len() * 3);
    let mut b = Vec::with_capacity(proj.len());
    for p in proj {
        let [ca, cb, cc] = p.conic;
        let [r, gr, bl] = p.color;
        g.push([p.mean[0], p.mean[1], ca, cb]);
        g.push([cc, p.opacity, r, gr]);
        g.push([bl, 0.0, 0.0, 0.0]);
        b.push([p.bbox.x0, p.bbox.y0, p.bbox.x1, p.bbox.y1]);
    }
    (g, b)
}

/// Run `f` inside out-of-memory and validation error scopes of `device`: what wgpu raises
/// there becomes an [`Error`] (its default for an unscoped error is to panic).
fn scoped<T>(device: &wgpu::Device, f: impl FnOnce() -> Result<T>) -> Result<T> {
    let memory = device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
    let validation = device.push_error_scope(wgpu::ErrorFilter::Validation);
    let out = f();
    let invalid = pollster::block_on(validation.pop());
    if let Some(e) = pollster::block_on(memory.pop()).or(invalid) {
        let kind = match e {
            wgpu::Error::OutOfMemory { .. } => ErrorKind::LimitExceeded,
            _ => ErrorKind::Device,
        };
        // The description, not `Display`, which for validation says only that; on one line.
        let what = match &e {
            wgpu::Error::Validation { description, .. } => description.clone(),
            other => other.to_string(),
        };
        let what = what
            .lines()
            .map(str::trim)
            .filter(|l| !l.is_empty() && *l != "Caused by:")
            .collect::<Vec<_>>()
            .join(": ");
        return Err(Error::new(kind, format!("GPU: {what}")));
    }
    out
}

/// The largest storage binding to plan buffers against. Metal reports the whole buffer
/// limit here (over 16 GiB on large Macs), while every offset and length this crate binds
/// and every shader index is a `u32`: capped there, an oversized job is refused as
/// [`ErrorKind::LimitExceeded`] rather than overflowing the sort's arithmetic.
fn max_binding(limits: &wgpu::Limits) -> u64 {
    limits
        .max_storage_buffer_binding_size
        .min(limits.max_buffer_size)
        .min(u64::from(u32::MAX))
}

/// The backends to try, in order. `WGPU_BACKEND` when set. Otherwise all of them, except
/// on Windows, where Vulkan is tried first: wgpu compiles WGSL for DX12 with FXC unless
/// built with `static-dxc` (which this crate does not ship, to keep its build lean), and
/// FXC is slow on the loops of these kernels and has its own barrier rules
/// (`backward_alpha.wgsl` has barriers in a loop whose bound is read from a buffer).
fn backend_order(from_env: Option<wgpu::Backends>) -> Vec<wgpu::Backends> {
    match from_env {
        Some(b) => vec![b],
        None if cfg!(windows) => vec![wgpu::Backends::VULKAN, wgpu::Backends::all()],
        None => vec![wgpu::Backends::all()],
    }
}

/// `WGPU_ADAPTER_NAME` when set (a case-insensitive substring of the name), else the
/// adapter wgpu prefers (`WGPU_POWER_PREF`, high performance by default), on `backends`.
async fn pick_adapter(
    instance: &wgpu::Instance,
    backends: wgpu::Backends,
) -> Result<wgpu::Adapter> {
    if let Ok(want) = std::env::var("WGPU_ADAPTER_NAME") {
        let want = want.to_lowercase();
        let adapters = instance.enumerate_adapters(backends).await;
        let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        return adapters
            .into_iter()
            .find(|a| a.get_info().name.to_lowercase().contains(&want))
            .ok_or_else(|| {
                Error::new(
                    ErrorKind::Unavailable,
                    format!(
                        "no adapter named like {want:?} (found: {})",
                        names.join(", ")
                    ),
                )
            });
    }
    instance
        .request_adapter(&wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::from_env()
                .unwrap_or(wgpu::PowerPreference::HighPerformance),
            force_fallback_adapter: false,
            compatible_surface: None,
            ..Default::default()
        })
        .await
        .map_err(|e| Error::new(ErrorKind::Unavailable, format!("no GPU adapter: {e}")))
}

/// Byte size and member offsets (by name) of the one uniform block of a WGSL module, as
/// naga lays it out: what the host's `#[repr(C)]` twin must match. For the tests of this
/// crate and of the stages' GPU twins.
#[doc(hidden)]
pub fn uniform_layout(source: &str) -> (u32, Vec<(String, u32)>) {
    use wgpu::naga;
    let module = naga::front::wgsl::parse_str(source).expect("the WGSL parses");
    let mut uniforms = module
        .global_variables
        .iter()
        .filter(|(_, v)| v.space == naga::AddressSpace::Uniform);
    let (_, var) = uniforms.next().expect("a uniform block");
    assert!(uniforms.next().is_none(), "one uniform block");
    match &module.types[var.ty].inner {
        naga::TypeInner::Struct { members, span } => (
            *span,
            members
                .iter()
                .map(|m| (m.name.clone().unwrap_or_default(), m.offset))
                .collect(),
        ),
        other => panic!("the uniform is not a struct: {other:?}"),
    }
}

/// Check a `#[repr(C)]` host struct against the uniform block of a WGSL module: the same
/// size, and each listed field at the offset of the WGSL member of that name (or of the
/// name given after `=`, where an array on the host is split into members in WGSL). For the
/// tests of this crate and of the stages' GPU twins.
#[doc(hidden)]
#[macro_export]
macro_rules! assert_uniform_matches {
    ($ty:ty, $source:expr, [$($field:ident $(= $wgsl:literal)?),* $(,)?]) => {{
        let (span, members) = $crate::gpu::uniform_layout(&$source);
        assert_eq!(span as usize, std::mem::size_of::<$ty>(), "size of {}", stringify!($ty));
        $(
            let name = [stringify!($field) $(, $wgsl)?];
            let name = name[name.len() - 1];
            let wgsl = members
                .iter()
                .find(|(n, _)| n == name)
                .unwrap_or_else(|| panic!("no WGSL member {name}"));
            assert_eq!(
                wgsl.1 as usize,
                std::mem::offset_of!($ty, $field),
                "offset of {}.{}", stringify!($ty), stringify!($field)
            );
        )*
    }};
}
pub use crate::assert_uniform_matches;

#[cfg(any(test, feature = "test-support"))]
#[doc(hidden)]
pub mod tests {
    /// The host's uniform structs have their WGSL blocks' layouts (no device needed).
    #[test]
    fn uniform_structs_match_their_wgsl_layouts() {
        use super::forward::FitUniform;
        use super::Params;
        assert_uniform_matches!(
            Params,
            shader!("device/render"),
            [width, height, tiles_x, blend, tile_row0, rows]
        );
        assert_uniform_matches!(
            FitUniform,
            shader!("device/fit_common", "fit/fit_adam"),
            [
                width,
                height,
                tiles_x,
                tiles_y,
                count,
                capacity,
                blend,
                has_opacity,
                qat,
                bits = "bits_position",
                lr = "lr_position",
                c1,
                c2,
                beta1,
                beta2,
                eps,
                cholesky,
                pad = "pad0"
            ]
        );
        // The sort takes eight `u32` as an array, and `SortPlan::write_ranges` writes
        // `ranges` at `RANGES_AT`.
        let source = shader!("device/sort_common", "device/sort_scan");
        let (size, fields) = super::uniform_layout(&source);
        assert_eq!(size, 32);
        let at = super::sort::RANGES_AT as u32;
        assert!(fields.contains(&("ranges".to_string(), at)), "{fields:?}");
    }

    /// A kernel set that fails to build is an error and is not cached: the next request
    /// builds it afresh.
    #[test]
    fn a_failed_kernel_build_is_not_cached() {
        let Some(gpu) = gpu() else { return };
        struct Probe(#[allow(dead_code)] super::Kernel);
        let make = |d: &wgpu::Device| {
            Probe(super::Kernel::new(
                d,
                "probe",
                &shader!("device/render"),
                4,
                1,
            ))
        };
        super::break_shaders_on_this_thread(true);
        let broken = gpu.kernels(make);
        super::break_shaders_on_this_thread(false);
        let e = broken
            .err()
            .expect("a shader that does not compile was accepted");
        assert_eq!(e.kind(), super::ErrorKind::Device, "{e}");
        assert!(gpu.kernels(make).is_ok());
        // The device is still good for everything else.
        assert!(gpu.checked(|| Ok(gpu.zeroed(64))).is_ok());
    }

    /// Metal reports the whole buffer limit as the storage-binding limit; the crate plans
    /// with at most `u32::MAX`, so what does not fit is a limit, not an overflow.
    #[test]
    fn the_binding_limit_is_capped_at_u32() {
        let huge = wgpu::Limits {
            max_storage_buffer_binding_size: 1 << 36,
            max_buffer_size: 1 << 37,
            ..wgpu::Limits::default()
        };
        assert_eq!(super::max_binding(&huge), u64::from(u32::MAX));
        let small = wgpu::Limits {
            max_storage_buffer_binding_size: 1 << 27,
            max_buffer_size: 1 << 26,
            ..wgpu::Limits::default()
        };
        assert_eq!(super::max_binding(&small), 1 << 26);
    }

    /// `WGPU_BACKEND` decides when set; otherwise every backend, Vulkan first on Windows
    /// (DX12 would compile the kernels with FXC).
    #[test]
    fn backends_are_tried_in_order() {
        use wgpu::Backends;
        assert_eq!(super::backend_order(Some(Backends::GL)), vec![Backends::GL]);
        let default = super::backend_order(None);
        if cfg!(windows) {
            assert_eq!(default, vec![Backends::VULKAN, Backends::all()]);
        } else {
            assert_eq!(default, vec![Backends::all()]);
        }
    }

    /// A resource the adapter cannot make is an error, not a panic.
    #[test]
    fn wgpu_errors_become_errors() {
        let Some(gpu) = gpu() else { return };
        let e = gpu
            .checked(|| {
                gpu.zeroed(gpu.max_binding.saturating_mul(64).max(1 << 62));
                Ok(())
            })
            .unwrap_err();
        assert!(
            matches!(
                e.kind(),
                super::ErrorKind::LimitExceeded | super::ErrorKind::Device
            ),
            "{e}"
        );
        assert!(gpu.checked(|| Ok(gpu.zeroed(64))).is_ok());
    }

    /// A device for a test, or `None` where there is none (the test then passes without
    /// checking anything), unless `GSI_REQUIRE_GPU` is set, which makes that a failure:
    /// CI sets it wherever lavapipe is installed, so a skip never goes unseen there.
    pub fn gpu() -> Option<super::Gpu> {
        match super::Gpu::new() {
            Ok(g) => Some(g),
            Err(e) if std::env::var_os("GSI_REQUIRE_GPU").is_some() => {
                panic!("GSI_REQUIRE_GPU is set but {e}")
            }
            Err(_) => None,
        }
    }
}
