//! Stage 2's one seam between the CPU and its GPU twin: where the session's mixture (every
//! Gaussian's mixing weights and operators, forward and backward) runs. With feature
//! `gpu` this holds [`super::gpu::GpuMixture`]; without it, `twin_cpu.rs` has the same
//! methods and always answers "not on a GPU", so that the session holds no `cfg` of its
//! own. A struct with two builds rather than a trait object, as stage 1's: the choice is
//! made at compile time and the session keeps one field.

use super::gpu::GpuMixture;
use super::mixture::{Enhancer, MapTap};
use gsi_gpu::gpu::Gpu;

/// The mixture's device: a GPU's, or none (the CPU).
pub(crate) struct Twin<'a>(Option<GpuMixture<'a>>);

impl<'a> Twin<'a> {
    pub fn cpu() -> Twin<'a> {
        Twin(None)
    }

    /// The mixture of `enh` on `device` (`chunk` Gaussians per trace chunk, `taps` and the
    /// colours `c0` as the session has them): `Ok(true)` where it runs on a GPU from now
    /// on, `Ok(false)` on the CPU, an error where the adapter cannot hold it.
    pub fn open(
        &mut self,
        device: gsi_gpu::Device<'a>,
        enh: &Enhancer,
        chunk: usize,
        taps: &[MapTap],
        c0: &[[f32; 3]],
    ) -> Result<bool, String> {
        match device {
            gsi_gpu::Device::Gpu(gpu) => self.open_on(gpu, enh, chunk, taps, c0),
            _ => Ok(false),
        }
    }

    /// As [`Twin::open`], on `gpu`.
    pub fn open_on(
        &mut self,
        gpu: &'a Gpu,
        enh: &Enhancer,
        chunk: usize,
        taps: &[MapTap],
        c0: &[[f32; 3]],
    ) -> Result<bool, String> {
        let mix = GpuMixture::new(
            gpu,
            enh.experts,
            enh.hidden,
            enh.clamp,
            enh.map.len(),
            chunk,
            taps,
            c0,
        )
        .map_err(|e| e.to_string())?;
        self.0 = Some(mix);
        Ok(true)
    }

    /// Whether the mixture runs on a GPU.
    #[cfg(test)]
    pub fn is_gpu(&self) -> bool {
        self.0.is_some()
    }

    /// The mixture's forward pass into `out`: `Ok(true)` where it ran on the GPU,
    /// `Ok(false)` where there is none; an error leaves the GPU for good.
    pub fn forward(&mut self, enh: &Enhancer, out: &mut [[f32; 3]]) -> Result<bool, String> {
        let Some(g) = &self.0 else { return Ok(false) };
        g.forward(&enh.map, &enh.params, out)
            .map(|()| true)
            .map_err(|e| {
                self.0 = None;
                e.to_string()
            })
    }

    /// The mixture's backward pass, as [`Twin::forward`].
    pub fn backward(
        &mut self,
        g_col: &[[f32; 3]],
        taps: &[MapTap],
        g_map: &mut [f32],
        g_params: &mut [f32],
    ) -> Result<bool, String> {
        let Some(g) = &self.0 else { return Ok(false) };
        g.backward(g_col, taps, g_map, g_params)
            .map(|()| true)
            .map_err(|e| {
                self.0 = None;
                e.to_string()
            })
    }
}
