//! Rendering on a GPU with wgpu compute shaders (`shaders/render.wgsl`).
//!
//! The GPU renders the same pixels as [`crate::render`]: projection and tile binning are
//! the CPU's own ([`project_scene`]), and the shader evaluates spec §6 per pixel in the
//! same `f32` order, so the only difference is the rounding of `exp` (within 1/255 after
//! 8-bit conversion; `tests/gpu.rs` holds it to that).
//!
//! The adapter is headless (no surface) and honours wgpu's environment variables:
//! `WGPU_BACKEND` (e.g. `vulkan`), `WGPU_ADAPTER_NAME` (a substring of the adapter's
//! name) and `WGPU_POWER_PREF`. Large outputs and long tile lists are split into bands
//! of tile rows so that no buffer exceeds the adapter's limits.

use crate::format::{Error, ErrorKind, Limits, Result};
use crate::model::{Blend, Scene};
use crate::render::{project_scene, Projected, RgbImage, TILE};
use wgpu::util::DeviceExt;

/// Why no GPU can be used.
#[derive(Debug)]
pub struct GpuError(String);

impl std::fmt::Display for GpuError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for GpuError {}

/// A device with the render pipeline built, ready for any number of renders.
pub struct Gpu {
    device: wgpu::Device,
    queue: wgpu::Queue,
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    info: wgpu::AdapterInfo,
    /// Largest storage binding, bytes.
    max_binding: u64,
}

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

impl Gpu {
    /// Open the adapter the environment asks for (or the default one), software
    /// rasterizers such as lavapipe included, and build the pipeline. Fails, without
    /// panicking, when there is no usable adapter.
    pub fn new() -> std::result::Result<Gpu, GpuError> {
        Self::open(true)
    }

    /// [`Gpu::new`], refusing an adapter that is itself a CPU rasterizer: what
    /// `--device auto` wants, since the CPU renderer beats an emulated GPU.
    pub fn new_hardware() -> std::result::Result<Gpu, GpuError> {
        Self::open(false)
    }

    fn open(allow_software: bool) -> std::result::Result<Gpu, GpuError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(pick_adapter(&instance))?;
        let info = adapter.get_info();
        if !allow_software && info.device_type == wgpu::DeviceType::Cpu {
            return Err(GpuError(format!("only a software adapter ({})", info.name)));
        }
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("gsi"),
            required_limits: limits.clone(),
            ..Default::default()
        }))
        .map_err(|e| GpuError(format!("{}: {e}", info.name)))?;
        let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some("render.wgsl"),
            source: wgpu::ShaderSource::Wgsl(include_str!("../../shaders/render.wgsl").into()),
        });
        let storage = |binding, read_only| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        };
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("render"),
            entries: &[
                wgpu::BindGroupLayoutEntry {
                    binding: 0,
                    visibility: wgpu::ShaderStages::COMPUTE,
                    ty: wgpu::BindingType::Buffer {
                        ty: wgpu::BufferBindingType::Uniform,
                        has_dynamic_offset: false,
                        min_binding_size: None,
                    },
                    count: None,
                },
                storage(1, true),
                storage(2, true),
                storage(3, true),
                storage(4, true),
                storage(5, false),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("render"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("render"),
            layout: Some(&pipeline_layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let max_binding = limits
            .max_storage_buffer_binding_size
            .min(limits.max_buffer_size);
        Ok(Gpu {
            device,
            queue,
            pipeline,
            layout,
            info,
            max_binding,
        })
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

    /// Render `scene` at `width × height`: the same pixels as [`crate::render::render`],
    /// within the rounding of `exp`.
    pub fn render(&self, scene: &Scene, width: u32, height: u32) -> Result<RgbImage> {
        Limits::default().check_output(width, height)?;
        if !scene.gaussians.is_consistent() {
            return Err(Error::new(
                ErrorKind::InvalidValue,
                "inconsistent Gaussian set",
            ));
        }
        let proj = project_scene(scene, width, height);
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
        for g in &proj {
            let span = u64::from(g.bbox.x1 / TILE - g.bbox.x0 / TILE + 1);
            for ty in g.bbox.y0 / TILE..=g.bbox.y1 / TILE {
                per_row[ty as usize] += span;
            }
        }
        let row_bytes = u64::from(width) * u64::from(TILE) * 12;
        let gaussian_bytes = proj.len() as u64 * 48;
        if gaussian_bytes > self.max_binding || row_bytes > self.max_binding {
            return Err(too_big(&self.info, "one tile row"));
        }
        let (gaussians, boxes) = upload_layout(&proj);
        let g_buf = self.storage(bytemuck::cast_slice(&gaussians));
        let b_buf = self.storage(bytemuck::cast_slice(&boxes));
        let mut ty = 0u32;
        while ty < tiles_y {
            // Grow the band while its index list and output fit in one binding.
            let (mut end, mut entries) = (ty, 0u64);
            while end < tiles_y
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
            let band =
                &mut data[(ty * TILE) as usize * width as usize * 3..][..rows * width as usize * 3];
            self.render_band(
                &proj,
                (&g_buf, &b_buf),
                scene.blend,
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
    }

    fn storage(&self, bytes: &[u8]) -> wgpu::Buffer {
        // A binding may not be empty.
        let bytes = if bytes.is_empty() {
            &[0u8; 16][..]
        } else {
            bytes
        };
        self.device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytes,
                usage: wgpu::BufferUsages::STORAGE,
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
        let band_tiles = (tiles_x * (rows.end - rows.start)) as usize;
        let mut counts = vec![0u32; band_tiles + 1];
        for g in proj {
            for ty in (g.bbox.y0 / TILE).max(rows.start)..=(g.bbox.y1 / TILE).min(rows.end - 1) {
                for tx in g.bbox.x0 / TILE..=g.bbox.x1 / TILE {
                    counts[((ty - rows.start) * tiles_x + tx) as usize + 1] += 1;
                }
            }
        }
        for t in 1..counts.len() {
            counts[t] += counts[t - 1];
        }
        let mut fill = counts.clone();
        let mut indices = vec![0u32; counts[band_tiles] as usize];
        for (k, g) in proj.iter().enumerate() {
            for ty in (g.bbox.y0 / TILE).max(rows.start)..=(g.bbox.y1 / TILE).min(rows.end - 1) {
                for tx in g.bbox.x0 / TILE..=g.bbox.x1 / TILE {
                    let t = ((ty - rows.start) * tiles_x + tx) as usize;
                    indices[fill[t] as usize] = k as u32;
                    fill[t] += 1;
                }
            }
        }
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
        let p_buf = self
            .device
            .create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: None,
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            });
        let o_buf = self.storage(bytemuck::cast_slice(&counts));
        let i_buf = self.storage(bytemuck::cast_slice(&indices));
        let out_bytes = (out.len() * 4) as u64;
        let out_buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: out_bytes,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read_buf = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: None,
            size: out_bytes,
            usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind = self.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: None,
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: p_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: g_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: b_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: o_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: i_buf.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: out_buf.as_entire_binding(),
                },
            ],
        });
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor { label: None });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor::default());
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind, &[]);
            pass.dispatch_workgroups(tiles_x, rows.end - rows.start, 1);
        }
        enc.copy_buffer_to_buffer(&out_buf, 0, &read_buf, 0, out_bytes);
        self.queue.submit([enc.finish()]);
        let slice = read_buf.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.device
            .poll(wgpu::PollType::wait_indefinitely())
            .map_err(|e| Error::new(ErrorKind::Io, format!("GPU: {e}")))?;
        match rx.recv() {
            Ok(Ok(())) => {}
            _ => {
                return Err(Error::new(
                    ErrorKind::Io,
                    "GPU: reading the result back failed",
                ))
            }
        }
        {
            let view = slice
                .get_mapped_range()
                .map_err(|e| Error::new(ErrorKind::Io, format!("GPU: {e}")))?;
            out.copy_from_slice(bytemuck::cast_slice(&view));
        }
        read_buf.unmap();
        Ok(())
    }
}

fn too_big(info: &wgpu::AdapterInfo, what: &str) -> Error {
    Error::new(
        ErrorKind::LimitExceeded,
        format!(
            "{what} exceeds the largest buffer {} can bind; render on the CPU",
            info.name
        ),
    )
}

/// Gaussians as the shader reads them: three `vec4<f32>` and one `vec4<u32>` box each.
fn upload_layout(proj: &[Projected]) -> (Vec<[f32; 4]>, Vec<[u32; 4]>) {
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

/// `WGPU_ADAPTER_NAME` when set (a case-insensitive substring of the name), else the
/// adapter wgpu prefers (`WGPU_POWER_PREF`, high performance by default).
async fn pick_adapter(instance: &wgpu::Instance) -> std::result::Result<wgpu::Adapter, GpuError> {
    if let Ok(want) = std::env::var("WGPU_ADAPTER_NAME") {
        let want = want.to_lowercase();
        let backends = wgpu::Backends::from_env().unwrap_or(wgpu::Backends::all());
        let adapters = instance.enumerate_adapters(backends).await;
        let names: Vec<String> = adapters.iter().map(|a| a.get_info().name).collect();
        return adapters
            .into_iter()
            .find(|a| a.get_info().name.to_lowercase().contains(&want))
            .ok_or_else(|| {
                GpuError(format!(
                    "no adapter named like {want:?} (found: {})",
                    names.join(", ")
                ))
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
        .map_err(|e| GpuError(format!("no GPU adapter: {e}")))
}
