//! Stage 1's seam in a build without feature `gpu`: the methods of `twin.rs`, each
//! answering "on the CPU" (see there).

use super::{raster, Measured};
use gsi_format::format::BitDepths;
use gsi_format::model::{Blend, GaussianSet};
use gsi_optim::optim::{Adam, LearningRates};
use gsi_render::render::Projected;

/// Every step on the CPU: this build has no GPU twin.
pub(crate) struct Twin<'a>(std::marker::PhantomData<&'a ()>);

impl<'a> Twin<'a> {
    pub fn cpu() -> Twin<'a> {
        Twin(std::marker::PhantomData)
    }

    pub fn on(_device: gsi_gpu::Device<'a>) -> Twin<'a> {
        Twin::cpu()
    }

    pub fn after(_fallback: Option<String>, _device: gsi_gpu::Device<'a>) -> Twin<'a> {
        Twin::cpu()
    }

    pub fn fallback(&self) -> Option<&str> {
        None
    }

    pub fn take_fallback(&mut self) -> Option<String> {
        None
    }

    pub fn flush(&mut self, _params: &mut GaussianSet, _adam: &mut Adam) -> Option<Measured> {
        None
    }

    pub fn sync(
        &mut self,
        _params: &mut GaussianSet,
        _adam: &mut Adam,
        _ready: &mut Option<Measured>,
    ) {
    }

    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        _target: &'a super::Target,
        _blend: Blend,
        _l2: bool,
        _params: &mut GaussianSet,
        _adam: &mut Adam,
        _steps: u64,
        _lr: &LearningRates,
        _qat: Option<BitDepths>,
        _measure: bool,
    ) -> Option<Option<Measured>> {
        None
    }

    #[allow(clippy::type_complexity)]
    pub fn passes(
        &mut self,
        _projected: &[Projected],
        _blend: Blend,
        _size: (u32, u32),
        _score: &mut dyn FnMut(&[f32]) -> (f32, Vec<f32>, Option<f64>),
    ) -> Option<(f32, Option<f64>, Vec<raster::ProjGrad>)> {
        None
    }
}
