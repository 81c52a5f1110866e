//! Stage 1's backward pass on the GPU: the gradients `fit::raster::backward` gives,
//! for both blend modes, from `shaders/fit/backward_*.wgsl`, on the device layer's
//! kernels and buffers ([`gsi_gpu::gpu`]).

use gsi_format::model::Blend;
use gsi_gpu::gpu::{shader, tile_lists, too_big, upload_layout, Gpu, Kernel, Result};
use gsi_render::render::{Projected, TILE};

/// The two backward kernels, built on a device the first time a fit asks for them (this
/// pass and the resident step's share them).
pub(crate) struct BackwardKernels {
    sum: Kernel,
    alpha: Kernel,
}

impl BackwardKernels {
    fn new(device: &wgpu::Device) -> Self {
        let k = |name, source: &str| Kernel::new(device, name, source, 5, 1);
        BackwardKernels {
            sum: k(
                "backward_sum",
                &shader!("fit/backward_bindings", "fit/backward_sum"),
            ),
            alpha: k(
                "backward_alpha",
                &shader!("fit/backward_bindings", "fit/backward_alpha"),
            ),
        }
    }

    /// The kernels of `gpu`, built there on first use.
    pub(crate) fn get(gpu: &Gpu) -> Result<std::sync::Arc<BackwardKernels>> {
        gpu.kernels(BackwardKernels::new)
    }

    /// The backward pass of `blend`.
    pub(crate) fn of(&self, blend: Blend) -> &Kernel {
        match blend {
            Blend::Sum => &self.sum,
            Blend::Alpha => &self.alpha,
        }
    }
}

/// Gradients of a loss with respect to each projected Gaussian on `gpu`, given
/// `dl_dimage` (`width·height·3`): per Gaussian `[d mean (2), d conic (3), d opacity,
/// d colour (3)]`, the quantities `fit::raster::backward` returns. Each tile writes a
/// slot per list entry and the slots are summed in tile order, as on the CPU: no atomics,
/// the same sums on every run.
pub fn backward(
    gpu: &Gpu,
    proj: &[Projected],
    blend: Blend,
    width: u32,
    height: u32,
    dl_dimage: &[f32],
) -> Result<Vec<[f32; 9]>> {
    gpu.checked(|| {
        assert_eq!(dl_dimage.len(), width as usize * height as usize * 3);
        let tiles_x = width.div_ceil(TILE);
        let tiles_y = height.div_ceil(TILE);
        if tiles_x.max(tiles_y) > gpu.max_groups {
            return Err(too_big(&gpu.info, "the backward pass of this image"));
        }
        let (offsets, lists) = tile_lists(proj, tiles_x, 0..tiles_y)?;
        let indices = lists.parts().1;
        let mut slots = vec![0.0f32; indices.len() * 9];
        if proj.is_empty() || indices.is_empty() {
            return Ok(vec![[0.0; 9]; proj.len()]);
        }
        for bytes in [
            slots.len() as u64 * 4,
            dl_dimage.len() as u64 * 4,
            indices.len() as u64 * 4,
        ] {
            if bytes > gpu.max_binding {
                return Err(too_big(&gpu.info, "the backward pass of this image"));
            }
        }
        let (gaussians, boxes) = upload_layout(proj);
        let params = [width, height, tiles_x, 0u32];
        let inputs = [
            gpu.uniform_buffer(bytemuck::cast_slice(&params)),
            gpu.storage(bytemuck::cast_slice(&gaussians)),
            gpu.storage(bytemuck::cast_slice(&boxes)),
            gpu.storage(bytemuck::cast_slice(&offsets)),
            gpu.storage(bytemuck::cast_slice(indices)),
            gpu.storage(bytemuck::cast_slice(dl_dimage)),
        ];
        let kernels = BackwardKernels::get(gpu)?;
        gpu.run(kernels.of(blend), &inputs, (tiles_x, tiles_y), &mut slots)?;
        let mut out = vec![[0.0f32; 9]; proj.len()];
        for (k, slot) in indices.iter().zip(slots.chunks_exact(9)) {
            for (o, s) in out[*k as usize].iter_mut().zip(slot) {
                *o += s;
            }
        }
        Ok(out)
    })
}

#[cfg(test)]
mod tests {
    use gsi_gpu::gpu::{shader, uniform_layout};

    /// The backward passes take four `u32` as an array (no device needed).
    #[test]
    fn the_uniform_block_is_four_words() {
        let source = shader!("fit/backward_bindings", "fit/backward_sum");
        assert_eq!(uniform_layout(&source).0 as usize, 16);
    }
}
