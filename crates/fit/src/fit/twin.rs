//! Stage 1's one seam between the CPU and its GPU twin: where the [`super::Fitter`]'s
//! steps run. With feature `gpu` this is the real twin (the resident L2 step of
//! [`super::resident`], the render and backward passes of [`super::backward_gpu`]); without
//! it, `twin_cpu.rs` has the same methods and always answers "on the CPU", so that the
//! fitter's code holds no `cfg` of its own.
//!
//! A struct with two builds rather than a trait object: the choice is made once, at
//! compile time, the calls inline away in a CPU-only build, and the fitter keeps one field.

use super::{raster, resident, Measured};
use gsi_format::format::BitDepths;
use gsi_format::model::{Blend, GaussianSet};
use gsi_gpu::gpu::{Error, Gpu};
use gsi_optim::optim::{Adam, LearningRates};
use gsi_render::render::Projected;

/// Where a fitter's steps run, and why they left the GPU if they did.
pub(crate) struct Twin<'a> {
    gpu: Option<&'a Gpu>,
    /// The L2 fit living on the GPU between syncs, and the steps taken before it started;
    /// while it exists, the fitter's parameters and Adam are those of the last sync.
    resident: Option<(resident::ResidentFit<'a>, u64)>,
    fallback: Option<String>,
}

/// A resident fit's report as the fitter counts steps (`base` taken before it started).
fn measured(r: resident::StepReport, base: u64) -> Measured {
    Measured {
        step: base + r.step,
        loss: r.loss,
        psnr: r.psnr,
    }
}

impl<'a> Twin<'a> {
    /// Every step on the CPU.
    pub fn cpu() -> Twin<'a> {
        Twin {
            gpu: None,
            resident: None,
            fallback: None,
        }
    }

    /// The steps on `device`: a GPU's, or the CPU for a device this build has no twin for.
    pub fn on(device: gsi_gpu::Device<'a>) -> Twin<'a> {
        let mut t = Twin::cpu();
        if let gsi_gpu::Device::Gpu(gpu) = device {
            t.gpu = Some(gpu);
        }
        t
    }

    /// The steps on `device`, unless an earlier fitter of the same encode left the GPU
    /// (`fallback`): then on the CPU, with the reason kept.
    pub fn after(fallback: Option<String>, device: gsi_gpu::Device<'a>) -> Twin<'a> {
        match fallback {
            Some(why) => Twin {
                fallback: Some(why),
                ..Twin::cpu()
            },
            None => Twin::on(device),
        }
    }

    /// Take the steps on `gpu` from now on.
    pub fn use_gpu(&mut self, gpu: &'a Gpu) {
        self.gpu = Some(gpu);
    }

    /// Why the steps left the GPU for the CPU, if they did.
    pub fn fallback(&self) -> Option<&str> {
        self.fallback.as_deref()
    }

    pub fn take_fallback(&mut self) -> Option<String> {
        self.fallback.take()
    }

    /// A measurement still to come from the resident fit (waiting for the GPU).
    pub fn flush(&mut self, params: &mut GaussianSet, adam: &mut Adam) -> Option<Measured> {
        let (resident, base) = self.resident.as_mut()?;
        let base = *base;
        match resident.collect() {
            Ok(report) => report.map(|r| measured(r, base)),
            Err(e) => {
                self.resident_failed(&e, params, adam);
                None
            }
        }
    }

    /// Bring the parameters and Adam's state back from the GPU, if they live there; a
    /// measurement collected on the way goes to `ready` unless one is there.
    pub fn sync(
        &mut self,
        params: &mut GaussianSet,
        adam: &mut Adam,
        ready: &mut Option<Measured>,
    ) {
        if let Some((resident, base)) = self.resident.as_mut() {
            let base = *base;
            match resident.collect() {
                Ok(Some(r)) => *ready = ready.or(Some(measured(r, base))),
                Ok(None) => {}
                // The parameters may still come back: `resident_failed` tries.
                Err(e) => return self.resident_failed(&e, params, adam),
            }
        }
        if let Some((resident, _)) = self.resident.take() {
            match resident.download() {
                Ok((p, a)) => {
                    *params = p;
                    *adam = a;
                }
                Err(e) => self.gpu_failed(&e),
            }
        }
    }

    /// A step of the resident fit (`l2`: the fitter's loss is L2; `steps`: this one's
    /// number), or `None` where it takes none: no GPU, another loss, or the GPU failed
    /// and the step falls to the CPU.
    #[allow(clippy::too_many_arguments)]
    pub fn step(
        &mut self,
        target: &'a super::Target,
        blend: Blend,
        l2: bool,
        params: &mut GaussianSet,
        adam: &mut Adam,
        steps: u64,
        lr: &LearningRates,
        qat: Option<BitDepths>,
        measure: bool,
    ) -> Option<Option<Measured>> {
        let gpu = self.gpu?;
        if !l2 {
            return None;
        }
        if self.resident.is_none() {
            match resident::ResidentFit::new(gpu, target, blend, params, adam) {
                Ok(r) => self.resident = Some((r, steps - 1)),
                Err(e) => {
                    self.gpu_failed(&e);
                    return None;
                }
            }
        }
        let (resident, base) = self.resident.as_mut()?;
        let base = *base;
        match resident.step(lr, qat, measure) {
            Ok(report) => Some(report.map(|r| measured(r, base))),
            Err(e) => {
                self.resident_failed(&e, params, adam);
                None
            }
        }
    }

    /// The render and backward passes on the GPU, with the loss `score` computes on the
    /// CPU, or `None` where there is no GPU or it failed.
    #[allow(clippy::type_complexity)]
    pub fn passes(
        &mut self,
        projected: &[Projected],
        blend: Blend,
        (w, h): (u32, u32),
        score: &mut dyn FnMut(&[f32]) -> (f32, Vec<f32>, Option<f64>),
    ) -> Option<(f32, Option<f64>, Vec<raster::ProjGrad>)> {
        let gpu = self.gpu?;
        let mut on_gpu = || -> gsi_gpu::gpu::Result<_> {
            let image = gpu.render_projected(projected, blend, w, h)?;
            let (value, dl, psnr) = score(&image.data);
            let pg = super::backward_gpu::backward(gpu, projected, blend, w, h, &dl)?;
            Ok((
                value,
                psnr,
                pg.iter().map(raster::ProjGrad::from_slot).collect(),
            ))
        };
        match on_gpu() {
            Ok(done) => Some(done),
            Err(e) => {
                self.gpu_failed(&e);
                None
            }
        }
    }

    /// Leave a failed resident fit for the CPU, continuing from what the GPU holds if it
    /// can still say, else from the last sync.
    fn resident_failed(&mut self, e: &Error, params: &mut GaussianSet, adam: &mut Adam) {
        if let Some(Ok((p, a))) = self.resident.take().map(|(r, _)| r.download()) {
            *params = p;
            *adam = a;
        }
        self.gpu_failed(e);
    }

    fn gpu_failed(&mut self, e: &Error) {
        self.fallback
            .get_or_insert_with(|| format!("fitting continues on the CPU: {e}"));
        self.gpu = None;
        self.resident = None;
    }
}
