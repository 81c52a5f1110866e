//! Stage 2's per-Gaussian work on the GPU: the mixture's forward pass (mixing weights and
//! the K − 1 operator MLPs for every Gaussian) and its backward pass down to the
//! parameters' gradients.
//!
//! That is where `gsi enhance` spends most of an iteration on the CPU (`perf`: the
//! operators' forward and backward passes, about two thirds). The image side (the render
//! `A·c`, the zero-shot loss and `Aᵀ`) stays on the CPU, so an iteration moves the
//! colours, their gradients, the logit gradients and the parameter gradients across the
//! bus: a few hundred kilobytes for a few thousand Gaussians.
//!
//! Kernels (`shaders/enhance_*.wgsl`): `enhance_forward` (the mixing weights per
//! Gaussian, the operators per (Gaussian, operator), then the mixed colour per Gaussian,
//! keeping a trace of the activations), `enhance_backward` (per (Gaussian, operator) the
//! gradients of η and of the hidden pre-activations; per Gaussian the logit gradients)
//! and `enhance_params` (one invocation per chunk of Gaussians and parameter, summing in
//! the CPU's order; the host adds the chunks in order).
//!
//! Results equal the CPU's to the rounding of `exp` and of one product's association
//! (the logit gradient is `b·(w·(g − s))` here, `(b·w)·(g − s)` there): a relative 2e-7
//! after one iteration (`enhance::fit` tests).

use super::mixture::{MapTap, GAIN_LOG_MAX};
use gsi_gpu::gpu::{shader, too_big, Gpu, Kernel};
use gsi_gpu::gpu::{Error, ErrorKind, Result};

/// u32 words per Gaussian in the `gauss` buffer (`GAUSS` in the shaders).
pub const GAUSS: usize = 12;
/// Largest K and hidden width the shaders' private arrays hold (`WIDTH_MAX`).
pub const WIDTH_MAX: usize = 64;

/// The buffer-layout constants this stage's shaders share with the host, as WGSL, written
/// from the Rust constants ahead of `shaders/enhance/` (the device layer's prelude holds
/// the pixel contract's).
fn layout() -> String {
    format!("const GAUSS: u32 = {GAUSS}u;\nconst WIDTH_MAX: u32 = {WIDTH_MAX}u;\n")
}

/// The pipelines, built the first time an enhancement runs on a device.
pub(crate) struct EnhanceKernels {
    weights: Kernel,
    operators: Kernel,
    mixed: Kernel,
    operators_back: Kernel,
    logits_back: Kernel,
    params: Kernel,
}

impl EnhanceKernels {
    fn new(device: &wgpu::Device) -> EnhanceKernels {
        let [weights, operators, mixed] = Kernel::entries(
            device,
            "enhance_forward",
            &shader!(prelude = &layout(); "enhance/enhance_common", "enhance/enhance_forward"),
            ["weights", "operators", "mixed"],
            3,
            2,
        );
        let [operators_back, logits_back] = Kernel::entries(
            device,
            "enhance_backward",
            &shader!(prelude = &layout(); "enhance/enhance_common", "enhance/enhance_backward"),
            ["operators", "logits"],
            4,
            2,
        );
        let params = Kernel::new(
            device,
            "enhance_params",
            &shader!(prelude = &layout(); "enhance/enhance_common", "enhance/enhance_params"),
            3,
            1,
        );
        EnhanceKernels {
            weights,
            operators,
            mixed,
            operators_back,
            logits_back,
            params,
        }
    }
}

/// The uniform block `Mix` of `enhance_common.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct MixUniform {
    count: u32,
    experts: u32,
    hidden: u32,
    per: u32,
    lo: f32,
    hi: f32,
    gain_log_max: f32,
    chunk: u32,
    _pad: [u32; 4],
}

// The size of `Mix` in `enhance_common.wgsl`, checked at compile time here and against the
// WGSL itself by `mix_uniform_matches_its_wgsl_layout`.
const _: () = assert!(std::mem::size_of::<MixUniform>() == 48);

/// The mixture of one enhancement fit, resident on the GPU: the Gaussians' taps and
/// colours, uploaded once, and the buffers every iteration reuses.
pub struct GpuMixture<'g> {
    gpu: &'g Gpu,
    count: usize,
    experts: usize,
    params_len: usize,
    logits_len: usize,
    chunk: usize,
    chunks: usize,
    params: wgpu::Buffer,
    logits: wgpu::Buffer,
    colors: wgpu::Buffer,
    g_col: wgpu::Buffer,
    g_logits: wgpu::Buffer,
    partials: wgpu::Buffer,
    forward: wgpu::BindGroup,
    backward: wgpu::BindGroup,
    sums: wgpu::BindGroup,
    gaussian_groups: (u32, u32),
    operator_groups: (u32, u32),
    param_groups: (u32, u32),
}

impl<'g> GpuMixture<'g> {
    /// Upload the Gaussians (`taps` into a logit map of `logits_len / experts` cells, and
    /// their original colours `c0`) for a mixture of `experts` operators of `hidden`
    /// units with outputs clamped to `clamp`, whose backward pass sums over `chunk`
    /// Gaussians at a time. Fails when the buffers exceed what the adapter can bind.
    #[allow(clippy::too_many_arguments)]
    pub fn new(
        gpu: &'g Gpu,
        experts: usize,
        hidden: usize,
        clamp: [f32; 2],
        logits_len: usize,
        chunk: usize,
        taps: &[MapTap],
        c0: &[[f32; 3]],
    ) -> Result<GpuMixture<'g>> {
        gpu.checked(|| {
            let count = c0.len();
            if count == 0 {
                return Err(Error::new(
                    ErrorKind::InvalidValue,
                    "no Gaussians to enhance",
                ));
            }
            if !(1..=WIDTH_MAX).contains(&experts)
                || !(1..=WIDTH_MAX).contains(&hidden)
                || taps.len() != count
                || chunk == 0
                || logits_len % experts != 0
                || taps
                    .iter()
                    .any(|t| t.cells.iter().any(|&c| c as usize * experts >= logits_len))
            {
                return Err(Error::new(
                    ErrorKind::InvalidValue,
                    "a GPU mixture needs matching taps and colours, 1..=64 experts and hidden units",
                ));
            }
            let ops = experts - 1;
            let per = super::mixture::Enhancer::params_per_operator(hidden);
            let params_len = ops * per;
            let chunks = count.div_ceil(chunk);
            // Trace: K weights, then 2h pre-activations and 3 outputs per operator.
            let n = count as u64;
            let trace_len = n * (experts + ops * (2 * hidden + 3)) as u64;
            let back_len = n * (ops * (2 * hidden + 1)) as u64;
            let partials_len = (chunks * params_len) as u64;
            for words in [
                trace_len,
                back_len,
                partials_len,
                n * experts as u64,
                n * GAUSS as u64,
                n * 3,
            ] {
                if words * 4 > gpu.max_binding || words > u64::from(u32::MAX) {
                    return Err(too_big(&gpu.info, "this enhancement's mixture"));
                }
            }
            let uniform = MixUniform {
                count: count as u32,
                experts: experts as u32,
                hidden: hidden as u32,
                per: per as u32,
                lo: clamp[0],
                hi: clamp[1],
                gain_log_max: GAIN_LOG_MAX,
                chunk: chunk as u32,
                _pad: [0; 4],
            };
            let mut gauss = vec![0u32; count * GAUSS];
            for ((rec, t), c) in gauss.chunks_exact_mut(GAUSS).zip(taps).zip(c0) {
                rec[..4].copy_from_slice(&t.cells);
                for i in 0..4 {
                    rec[4 + i] = t.weights[i].to_bits();
                }
                for i in 0..3 {
                    rec[8 + i] = c[i].to_bits();
                }
            }
            let device = &gpu.device;
            let k = gpu.kernels(EnhanceKernels::new)?;
            let mix = gpu.uniform_buffer(bytemuck::bytes_of(&uniform));
            let gauss = gpu.storage(bytemuck::cast_slice(&gauss));
            let params = gpu.zeroed(params_len as u64 * 4);
            let logits = gpu.zeroed(logits_len as u64 * 4);
            let colors = gpu.zeroed(count as u64 * 12);
            let trace = gpu.zeroed(trace_len * 4);
            let g_col = gpu.zeroed(count as u64 * 12);
            let g_logits = gpu.zeroed(count as u64 * experts as u64 * 4);
            let back = gpu.zeroed(back_len * 4);
            let partials = gpu.zeroed(partials_len * 4);
            Ok(GpuMixture {
                forward: k
                    .weights
                    .bind(device, &[&mix, &params, &logits, &gauss, &colors, &trace]),
                backward: k.operators_back.bind(
                    device,
                    &[&mix, &params, &gauss, &trace, &g_col, &g_logits, &back],
                ),
                sums: k
                    .params
                    .bind(device, &[&mix, &gauss, &trace, &back, &partials]),
                gaussian_groups: gpu.groups(n)?,
                operator_groups: gpu.groups(n * ops as u64)?,
                param_groups: gpu.groups(partials_len)?,
                gpu,
                count,
                experts,
                params_len,
                logits_len,
                chunk,
                chunks,
                params,
                logits,
                colors,
                g_col,
                g_logits,
                partials,
            })
        })
    }

    /// Every Gaussian's mixed colour for the logit map `logits` and operator parameters
    /// `params` (the layouts of `enhance::mixture::Enhancer`), into `out`. A colour that
    /// comes back non-finite is an error (the CPU's operators map NaN to the clamp; a
    /// GPU's `min` and `max` need not), so that the caller can continue on the CPU.
    ///
    /// # Panics
    /// If the slices' lengths are not those given to [`GpuMixture::new`].
    pub fn forward(&self, logits: &[f32], params: &[f32], out: &mut [[f32; 3]]) -> Result<()> {
        assert_eq!(logits.len(), self.logits_len);
        assert_eq!(params.len(), self.params_len);
        assert_eq!(out.len(), self.count);
        self.gpu.checked(|| {
            let gpu = self.gpu;
            gpu.queue
                .write_buffer(&self.logits, 0, bytemuck::cast_slice(logits));
            if !params.is_empty() {
                gpu.queue
                    .write_buffer(&self.params, 0, bytemuck::cast_slice(params));
            }
            let k = gpu.kernels(EnhanceKernels::new)?;
            let mut enc = gpu.encoder();
            gpu.pass(
                &mut enc,
                &[
                    (&k.weights, &self.forward, self.gaussian_groups),
                    (&k.operators, &self.forward, self.operator_groups),
                    (&k.mixed, &self.forward, self.gaussian_groups),
                ],
            );
            let [colors] = gpu.read_back(enc, [&self.colors])?;
            let colors: &[f32] = bytemuck::cast_slice(&colors);
            if !colors[..self.count * 3].iter().all(|c| c.is_finite()) {
                return Err(Error::new(
                    ErrorKind::InvalidValue,
                    "the GPU's mixture gave a non-finite colour",
                ));
            }
            for (o, c) in out.iter_mut().zip(colors.chunks_exact(3)) {
                *o = [c[0], c[1], c[2]];
            }
            Ok(())
        })
    }

    /// The backward pass of the last [`GpuMixture::forward`] from the colour gradients
    /// `g_col`: adds the logit map's gradient to `g_map` (through `taps`, the ones given
    /// to [`GpuMixture::new`]) and the parameters' to `g_params`, summed in the CPU's
    /// chunks and order.
    ///
    /// # Panics
    /// If the slices' lengths are not those given to [`GpuMixture::new`].
    pub fn backward(
        &self,
        g_col: &[[f32; 3]],
        taps: &[MapTap],
        g_map: &mut [f32],
        g_params: &mut [f32],
    ) -> Result<()> {
        assert_eq!(g_col.len(), self.count);
        assert_eq!(taps.len(), self.count);
        assert_eq!(g_map.len(), self.logits_len);
        assert_eq!(g_params.len(), self.params_len);
        self.gpu.checked(|| {
            let gpu = self.gpu;
            gpu.queue
                .write_buffer(&self.g_col, 0, bytemuck::cast_slice(g_col));
            let k = gpu.kernels(EnhanceKernels::new)?;
            let mut enc = gpu.encoder();
            // `enhance_params` returns at once when there are no operators.
            gpu.pass(
                &mut enc,
                &[
                    (&k.operators_back, &self.backward, self.operator_groups),
                    (&k.logits_back, &self.backward, self.gaussian_groups),
                    (&k.params, &self.sums, self.param_groups),
                ],
            );
            let [g_logits, partials] = gpu.read_back(enc, [&self.g_logits, &self.partials])?;
            let g_logits: &[f32] = bytemuck::cast_slice(&g_logits);
            let partials: &[f32] = bytemuck::cast_slice(&partials);
            if self.params_len > 0 {
                for part in partials.chunks_exact(self.params_len).take(self.chunks) {
                    for (g, p) in g_params.iter_mut().zip(part) {
                        *g += p;
                    }
                }
            }
            // Spread each Gaussian's logit gradient over its tap's cells, chunk by chunk as
            // the CPU pass does.
            let k = self.experts;
            let mut part = vec![0.0f32; g_map.len()];
            for (taps, gl) in taps.chunks(self.chunk).zip(g_logits.chunks(self.chunk * k)) {
                part.fill(0.0);
                for (t, gl) in taps.iter().zip(gl.chunks_exact(k)) {
                    for (&cell, &b) in t.cells.iter().zip(&t.weights) {
                        if b == 0.0 {
                            continue;
                        }
                        for (p, &x) in part[cell as usize * k..][..k].iter_mut().zip(gl) {
                            *p += b * x;
                        }
                    }
                }
                for (g, p) in g_map.iter_mut().zip(&part) {
                    *g += p;
                }
            }
            Ok(())
        })
    }
}

#[cfg(test)]
mod tests {
    use super::MixUniform;
    use gsi_gpu::gpu::{assert_uniform_matches, shader};

    /// The host's `Mix` block has the WGSL one's layout (no device needed).
    #[test]
    fn mix_uniform_matches_its_wgsl_layout() {
        assert_uniform_matches!(
            MixUniform,
            shader!(prelude = &super::layout(); "enhance/enhance_common", "enhance/enhance_forward"),
            [count, experts, hidden, per, lo, hi, gain_log_max, chunk]
        );
    }
}
