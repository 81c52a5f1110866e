//! The forward half of the resident pipeline: Gaussians uploaded once, then projected,
//! binned and rendered on the GPU with nothing crossing the bus. Stage 1's resident fit
//! (`fit::resident`) runs it at every step; [`GpuScene`] runs it to draw a decoded scene
//! again and again (what a viewer, or a frame-rate measurement, does).
//!
//! Kernels: `fit_range` (quantization-aware steps only), `fit_project`, `fit_scan`,
//! `fit_emit`, the radix sort (`gpu::sort`), `fit_tiles` (only where the sort takes more
//! than one pass: a one-pass sort writes the tile ranges itself), then `render`.

// Without the stages (feature `encode`) only `GpuScene` draws with this half; the
// buffers and helpers the resident fit adds to it go unused.
#![cfg_attr(not(feature = "encode"), allow(dead_code))]

use super::sort::{RadixSort, SortPlan};
use super::{too_big, Dispatch, Gpu, Kernel};
use super::{Error, ErrorKind, Result};
use gsi_format::format::Limits;
use gsi_format::model::Blend;
use gsi_format::model::{CovParam, GaussianSet, Scene};
use gsi_render::render::{RgbImage, TILE};

pub use super::sort::SCAN_PER;

/// Floats per Gaussian in the parameter and moment buffers (`STRIDE` of
/// `fit_common.wgsl`): u, v, ln σ1, ln σ2, θ, r, g, b, opacity.
pub const STRIDE: usize = 9;
/// Invocations per workgroup of the one-dimensional kernels (`GROUP`).
pub const GROUP: u32 = 256;

/// The pipelines of the forward half (projection, binning, tile ranges), built the first
/// time a resident pipeline runs on a device.
pub struct ForwardKernels {
    pub range: Kernel,
    pub project: Kernel,
    /// `fit_scan.wgsl`'s `blocks` and `apply`, sharing one bind group.
    pub scan: [Kernel; 2],
    pub emit: Kernel,
    pub tiles: Kernel,
    pub sort: RadixSort,
}

impl ForwardKernels {
    fn new(device: &wgpu::Device) -> ForwardKernels {
        let k = |label, source: String, reads, writes| {
            Kernel::new(device, label, &source, reads, writes)
        };
        ForwardKernels {
            range: k(
                "fit_range",
                shader!("device/fit_common", "device/fit_range"),
                1,
                1,
            ),
            project: k(
                "fit_project",
                shader!("device/fit_common", "device/fit_project"),
                2,
                3,
            ),
            scan: Kernel::entries(
                device,
                "fit_scan",
                &shader!("device/fit_common", "device/fit_scan"),
                ["blocks", "apply"],
                1,
                3,
            ),
            emit: k(
                "fit_emit",
                shader!("device/fit_common", "device/fit_emit"),
                2,
                2,
            ),
            tiles: k(
                "fit_tiles",
                shader!("device/fit_common", "device/fit_tiles"),
                2,
                1,
            ),
            sort: RadixSort::new(device),
        }
    }

    /// The kernels, built the first time in an error scope: a compiler that refuses a
    /// shader gives an error (and the caller the CPU), and nothing is cached, so a later
    /// call tries again rather than finding a broken pipeline.
    pub fn ensure(gpu: &Gpu) -> Result<&ForwardKernels> {
        if let Some(k) = gpu.forward.get() {
            return Ok(k);
        }
        let built = gpu.checked(|| Ok(ForwardKernels::new(&gpu.device)))?;
        Ok(gpu.forward.get_or_init(|| built))
    }

    /// The kernels, once [`ForwardKernels::ensure`] has built them (every user holds a
    /// [`Forward`], whose constructor does).
    pub fn of(gpu: &Gpu) -> &ForwardKernels {
        gpu.forward.get_or_init(|| ForwardKernels::new(&gpu.device))
    }
}

/// The uniform block `Fit` of `fit_common.wgsl`, shared by the forward half and the
/// optimizer step (`fit::resident`).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FitUniform {
    pub width: u32,
    pub height: u32,
    pub tiles_x: u32,
    pub tiles_y: u32,
    pub count: u32,
    pub capacity: u32,
    pub blend: u32,
    pub has_opacity: u32,
    pub qat: u32,
    /// Position, covariance, colour, opacity, angle (as `fit_common.wgsl` orders them).
    pub bits: [u32; 5],
    pub lr: [f32; 5],
    pub c1: f32,
    pub c2: f32,
    pub beta1: f32,
    pub beta2: f32,
    pub eps: f32,
    pub cholesky: u32,
    pub pad: [u32; 3],
}

// The size of `Fit` in `fit_common.wgsl`, checked at compile time here and against the WGSL
// itself by `gpu::tests::uniform_structs_match_their_wgsl_layouts`.
const _: () = assert!(std::mem::size_of::<FitUniform>() == 112);

impl FitUniform {
    /// `count` Gaussians drawn at `width × height`; no step taken yet.
    pub fn new(
        width: u32,
        height: u32,
        count: usize,
        blend: Blend,
        has_opacity: bool,
    ) -> FitUniform {
        FitUniform {
            width,
            height,
            tiles_x: width.div_ceil(TILE),
            tiles_y: height.div_ceil(TILE),
            count: count as u32,
            capacity: 0,
            blend: u32::from(blend == Blend::Alpha),
            has_opacity: u32::from(has_opacity),
            qat: 0,
            bits: [0; 5],
            lr: [0.0; 5],
            c1: 1.0,
            c2: 1.0,
            beta1: 0.0,
            beta2: 0.0,
            eps: 0.0,
            cholesky: 0,
            pad: [0; 3],
        }
    }
}

/// Buffers and bindings of the forward half whose size the image and the number of
/// Gaussians fix.
pub struct Forward {
    pub fit: wgpu::Buffer,
    pub params: wgpu::Buffer,
    pub image: wgpu::Buffer,
    pub gaussians: wgpu::Buffer,
    pub boxes: wgpu::Buffer,
    first_entry: wgpu::Buffer,
    /// `[0]`: tile-list entries of the last frame (saturating).
    pub entries: wgpu::Buffer,
    pub offsets: wgpu::Buffer,
    range: wgpu::BindGroup,
    project: wgpu::BindGroup,
    scan: wgpu::BindGroup,
    /// Workgroups of the scan's `blocks` and `apply`: one per block of Gaussians.
    scan_groups: (u32, u32),
    render_params: wgpu::Buffer,
    pub gaussian_groups: (u32, u32),
    tile_groups: (u32, u32),
    tiles: (u32, u32),
}

/// The buffers sized by the number of tile-list entries, and what binds them.
pub struct ForwardLists {
    pub capacity: u32,
    /// Gaussian of each sorted entry: tile t lists `values[offsets[t]..offsets[t + 1]]`.
    pub values: wgpu::Buffer,
    /// Whether the sort writes the tile ranges (`f.offsets`), so `fit_tiles` need not.
    ranges_by_sort: bool,
    plan: SortPlan,
    emit: wgpu::BindGroup,
    tiles: wgpu::BindGroup,
    render: wgpu::BindGroup,
}

impl Forward {
    /// Upload `params` (`STRIDE` floats per Gaussian) and make room for a frame of the
    /// size `uniform` gives. Fails when a buffer exceeds what the adapter can bind.
    pub fn new(gpu: &Gpu, uniform: &FitUniform, params: &[f32]) -> Result<Forward> {
        let (w, h) = (uniform.width, uniform.height);
        let n = u64::from(uniform.count);
        let pixels = u64::from(w) * u64::from(h);
        let tiles = u64::from(uniform.tiles_x) * u64::from(uniform.tiles_y);
        for bytes in [pixels * 12, n * STRIDE as u64 * 8, n * 48] {
            if bytes > gpu.max_binding {
                return Err(too_big(&gpu.info, "this set of Gaussians at this size"));
            }
        }
        if uniform.tiles_x.max(uniform.tiles_y) > gpu.max_groups {
            return Err(too_big(&gpu.info, "a dispatch over the tiles of this size"));
        }
        let device = &gpu.device;
        let k = ForwardKernels::ensure(gpu)?;
        let fit = gpu.uniform_buffer(bytemuck::bytes_of(uniform));
        let params = gpu.storage(bytemuck::cast_slice(params));
        let ranges = gpu.zeroed(STRIDE as u64 * 8);
        let gaussians = gpu.zeroed(n * 48);
        let boxes = gpu.zeroed(n * 16);
        let touched = gpu.zeroed(n * 4);
        let first_entry = gpu.zeroed(n * 4);
        let entries = gpu.zeroed(4);
        let blocks = n.div_ceil(u64::from(GROUP * SCAN_PER)).max(1);
        let block_sums = gpu.zeroed(blocks * 4);
        // Render's own uniform block: the whole image, one band.
        let render_params = gpu.uniform_buffer(bytemuck::cast_slice(&[
            w,
            h,
            uniform.tiles_x,
            uniform.blend,
            0,
            h,
            0,
            0,
        ]));
        Ok(Forward {
            range: k.range.bind(device, &[&fit, &params, &ranges]),
            project: k.project.bind(
                device,
                &[&fit, &params, &ranges, &gaussians, &boxes, &touched],
            ),
            scan: k.scan[0].bind(
                device,
                &[&fit, &touched, &first_entry, &entries, &block_sums],
            ),
            scan_groups: gpu.groups(blocks * u64::from(GROUP))?,
            image: gpu.zeroed(pixels * 12),
            offsets: gpu.zeroed((tiles + 1) * 4),
            gaussian_groups: gpu.groups(n)?,
            tile_groups: gpu.groups(tiles + 1)?,
            tiles: (uniform.tiles_x, uniform.tiles_y),
            fit,
            params,
            gaussians,
            boxes,
            first_entry,
            entries,
            render_params,
        })
    }

    /// The scan's two dispatches: block sums, then each block's offset and its Gaussians'.
    fn scan<'a>(&'a self, k: &'a ForwardKernels) -> [Dispatch<'a>; 2] {
        [
            (&k.scan[0], &self.scan, self.scan_groups),
            (&k.scan[1], &self.scan, self.scan_groups),
        ]
    }

    /// The tile-list entries the Gaussians need as uploaded (a projection and a scan on
    /// the GPU, and one number read back).
    pub fn count_entries(&self, gpu: &Gpu) -> Result<u64> {
        let k = ForwardKernels::of(gpu);
        let mut enc = gpu.encoder();
        let [a, b] = self.scan(k);
        gpu.pass(
            &mut enc,
            &[(&k.project, &self.project, self.gaussian_groups), a, b],
        );
        let [entries] = gpu.read_back(enc, [&self.entries])?;
        Ok(u64::from(bytemuck::cast_slice::<u8, u32>(&entries)[0]))
    }

    /// Record projection and binning: a compute pass, then the sort's.
    pub fn record_binning(
        &self,
        gpu: &Gpu,
        lists: &ForwardLists,
        enc: &mut wgpu::CommandEncoder,
        quantized: bool,
    ) {
        let k = ForwardKernels::of(gpu);
        let [a, b] = self.scan(k);
        let mut dispatches = Vec::with_capacity(6);
        if quantized {
            dispatches.push((&k.range, &self.range, (1, 1)));
        }
        dispatches.extend([
            (&k.project, &self.project, self.gaussian_groups),
            a,
            b,
            (&k.emit, &lists.emit, self.gaussian_groups),
        ]);
        gpu.pass(enc, &dispatches);
        lists.plan.record(&k.sort, enc);
    }

    /// The tile ranges (unless the sort wrote them) and the render, to run after
    /// [`Forward::record_binning`].
    pub fn render<'a>(&'a self, gpu: &'a Gpu, lists: &'a ForwardLists) -> Vec<Dispatch<'a>> {
        let mut dispatches = Vec::with_capacity(2);
        if !lists.ranges_by_sort {
            dispatches.push((
                &ForwardKernels::of(gpu).tiles,
                &lists.tiles,
                self.tile_groups,
            ));
        }
        dispatches.push((&gpu.render, &lists.render, self.tiles));
        dispatches
    }
}

impl ForwardLists {
    /// Lists for `capacity` entries; `per_entry` more bytes of the caller's per entry
    /// count against the adapter's limit.
    pub fn new(gpu: &Gpu, f: &Forward, capacity: u32, per_entry: u64) -> Result<ForwardLists> {
        if u64::from(capacity) * per_entry.max(4) > gpu.max_binding {
            return Err(too_big(
                &gpu.info,
                "the tile lists of this set of Gaussians",
            ));
        }
        let device = &gpu.device;
        let k = ForwardKernels::of(gpu);
        let keys = gpu.zeroed(u64::from(capacity) * 4);
        let values = gpu.zeroed(u64::from(capacity) * 4);
        let tiles = f.tiles.0 * f.tiles.1;
        let key_bits = (32 - tiles.saturating_sub(1).leading_zeros()).max(1);
        let mut plan = SortPlan::new(gpu, &k.sort, &keys, &values, &f.entries, capacity, key_bits)?;
        // Sorted in one pass (up to 2048 tiles: 768×512 has 1536), the sort's scan holds
        // the tile ranges and writes them: one dispatch fewer a frame.
        let ranges_by_sort = plan.write_ranges(gpu, &k.sort, &f.offsets, tiles);
        let (sorted_keys, sorted_values) = plan.sorted();
        Ok(ForwardLists {
            capacity,
            emit: k
                .emit
                .bind(device, &[&f.fit, &f.boxes, &f.first_entry, &keys, &values]),
            tiles: k
                .tiles
                .bind(device, &[&f.fit, sorted_keys, &f.entries, &f.offsets]),
            render: gpu.render.bind(
                device,
                &[
                    &f.render_params,
                    &f.gaussians,
                    &f.boxes,
                    &f.offsets,
                    sorted_values,
                    &f.image,
                ],
            ),
            values: sorted_values.clone(),
            ranges_by_sort,
            plan,
        })
    }
}

/// Most tile-list entries: keeps `SLOT · entry` and every other index within a `u32`.
pub const MAX_ENTRIES: u32 = u32::MAX / 64;

/// List capacity for a set that covers `entries` tile entries now: room to double.
pub fn capacity_for(entries: u64) -> u32 {
    (entries.saturating_mul(2)).clamp(4096, u64::from(MAX_ENTRIES)) as u32
}

/// `STRIDE` floats per Gaussian; `opacity` stands in where the set has none.
pub fn flatten(set: &GaussianSet, opacity: f32) -> Vec<f32> {
    let mut out = Vec::with_capacity(set.len() * STRIDE);
    for i in 0..set.len() {
        out.extend_from_slice(&set.positions[i]);
        out.extend_from_slice(&set.cov[i]);
        out.extend_from_slice(&set.colors[i]);
        out.push(set.opacity.as_ref().map_or(opacity, |o| o[i]));
    }
    out
}

/// A decoded scene resident on the GPU, drawn at a fixed size as often as wanted: the
/// whole forward pipeline runs per frame (projection, binning, render), only the image
/// comes back, and only when asked.
///
/// Its pixels are those of [`Gpu::render`] but for the projection, which here runs in
/// the GPU's `sin`, `cos` and `exp`: a pixel on the edge of a Gaussian's box may fall on
/// either side of it. Decoding (`gsi decode`) keeps [`Gpu::render`], whose projection is
/// the CPU's own.
pub struct GpuScene<'g> {
    gpu: &'g Gpu,
    width: u32,
    height: u32,
    forward: Forward,
    lists: ForwardLists,
    /// The scene's tone curve (spec §6.6), applied on the CPU to what is read back.
    tone: Option<gsi_format::model::ToneCurve>,
}

impl<'g> GpuScene<'g> {
    /// Upload `scene` for drawing at `width × height`, and draw it once to check that
    /// its tile lists fit.
    pub fn new(gpu: &'g Gpu, scene: &Scene, width: u32, height: u32) -> Result<GpuScene<'g>> {
        gpu.checked(|| {
            Limits::default().check_output(width, height)?;
            let g = &scene.gaussians;
            if !g.is_consistent() || g.is_empty() || g.len() > u32::MAX as usize / 64 {
                return Err(Error::new(
                    ErrorKind::InvalidValue,
                    "a GPU scene needs a consistent, non-empty Gaussian set",
                ));
            }
            let mut uniform =
                FitUniform::new(width, height, g.len(), scene.blend, g.opacity.is_some());
            uniform.cholesky = u32::from(scene.cov_param == CovParam::Cholesky);
            // Parameters read as the CPU reads them (`CovParam::covariance`, `render::project`):
            // non-finite ones as 0, a non-finite centre or opacity as a Gaussian not drawn.
            // An angle is brought into [-π, π] here, with the CPU's own `sin` and `cos`: a
            // GPU's are only accurate near 0, and a file may hold any angle.
            let rotation = scene.cov_param == CovParam::LogScaleRotation;
            let params: Vec<f32> = flatten(g, 1.0)
                .chunks_exact(STRIDE)
                .flat_map(|p| {
                    let mut p: [f32; STRIDE] = p.try_into().expect("STRIDE floats");
                    for x in &mut p[2..8] {
                        *x = if x.is_finite() { *x } else { 0.0 };
                    }
                    if rotation {
                        let (sin, cos) = p[4].sin_cos();
                        p[4] = sin.atan2(cos);
                    }
                    if !p[8].is_finite() {
                        p[8] = 0.0;
                    }
                    if !(p[0].is_finite() && p[1].is_finite()) {
                        p[0] = -1e9;
                    }
                    p
                })
                .collect();
            let forward = Forward::new(gpu, &uniform, &params)?;
            // A scene does not move: its lists need exactly the entries it has now.
            let entries = forward.count_entries(gpu)?;
            if entries > u64::from(MAX_ENTRIES) {
                return Err(too_big(&gpu.info, "the tile lists of this scene"));
            }
            let mut s = GpuScene::with_lists(gpu, forward, uniform, entries.max(1) as u32)?;
            s.tone = scene.tone.clone();
            Ok(s)
        })
    }

    fn with_lists(
        gpu: &'g Gpu,
        forward: Forward,
        mut uniform: FitUniform,
        capacity: u32,
    ) -> Result<GpuScene<'g>> {
        uniform.capacity = capacity;
        gpu.queue
            .write_buffer(&forward.fit, 0, bytemuck::bytes_of(&uniform));
        let lists = ForwardLists::new(gpu, &forward, capacity, 4)?;
        Ok(GpuScene {
            gpu,
            width: uniform.width,
            height: uniform.height,
            forward,
            lists,
            tone: None,
        })
    }

    /// A frame's commands.
    fn frame(&self) -> wgpu::CommandEncoder {
        let mut enc = self.gpu.encoder();
        self.forward
            .record_binning(self.gpu, &self.lists, &mut enc, false);
        self.gpu
            .pass(&mut enc, &self.forward.render(self.gpu, &self.lists));
        enc
    }

    /// Queue `frames` draws without waiting for them.
    pub fn draw(&self, frames: u32) -> Result<()> {
        self.gpu.checked(|| {
            for _ in 0..frames {
                self.gpu.submit([self.frame().finish()]);
            }
            Ok(())
        })
    }

    /// Wait until every queued draw has finished, at most [`Gpu::set_wait_timeout`].
    pub fn wait(&self) -> Result<()> {
        self.gpu.wait(None)
    }

    /// Draw once more and read the image back, through the scene's tone curve where it
    /// has one (applied on the CPU: [`GpuScene::draw`] times the blending alone).
    pub fn image(&self) -> Result<RgbImage> {
        let [bytes] = self
            .gpu
            .checked(|| self.gpu.read_back(self.frame(), [&self.forward.image]))?;
        let n = self.width as usize * self.height as usize * 3;
        let mut data = bytemuck::cast_slice::<u8, f32>(&bytes)[..n].to_vec();
        if let Some(t) = &self.tone {
            t.apply(&mut data);
        }
        Ok(RgbImage {
            width: self.width,
            height: self.height,
            data,
        })
    }
}
