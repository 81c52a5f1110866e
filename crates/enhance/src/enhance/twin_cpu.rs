//! Stage 2's seam in a build without feature `gpu`: the methods of `twin.rs`, each
//! answering "not on a GPU" (see there).

use super::mixture::{Enhancer, MapTap};

/// The mixture on the CPU: this build has no GPU twin.
pub(crate) struct Twin<'a>(std::marker::PhantomData<&'a ()>);

impl<'a> Twin<'a> {
    pub fn cpu() -> Twin<'a> {
        Twin(std::marker::PhantomData)
    }

    pub fn open(
        &mut self,
        _device: gsi_gpu::Device<'a>,
        _enh: &Enhancer,
        _chunk: usize,
        _taps: &[MapTap],
        _c0: &[[f32; 3]],
    ) -> Result<bool, String> {
        Ok(false)
    }

    pub fn forward(&mut self, _enh: &Enhancer, _out: &mut [[f32; 3]]) -> Result<bool, String> {
        Ok(false)
    }

    pub fn backward(
        &mut self,
        _g_col: &[[f32; 3]],
        _taps: &[MapTap],
        _g_map: &mut [f32],
        _g_params: &mut [f32],
    ) -> Result<bool, String> {
        Ok(false)
    }
}
