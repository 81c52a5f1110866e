//! The fitting loop resident on the GPU: every step of stage 1's optimizer without the
//! CPU.
//!
//! The parameters, Adam's moments, the target and every intermediate stay in GPU
//! buffers. A step is one submission of these kernels, in order:
//! 1. `fit_range` (quantization-aware steps only): each component's range, as
//!    `Quantizer::fit` takes it. The quantization itself runs in `f32` where the CPU's
//!    uses `f64`: a value on the midpoint of two codes may take the other one.
//! 2. `fit_project`: the rendered parameters (quantized when asked) projected as
//!    `render::project` does, and the tiles each covers.
//! 3. `fit_scan`, `fit_emit`, the radix sort ([`super::sort`]) and `fit_tiles`: tile lists
//!    holding each tile's Gaussians in stored order, deterministically.
//! 4. `render` and `fit_loss`: the image, the L2 loss and its gradient.
//! 5. `backward_sum` or `backward_alpha`: per-entry gradient slots.
//! 6. `fit_adam`: gather, chain rule and Adam.
//!
//! The host writes one uniform block per step (learning rates, bias corrections) and reads
//! back only when asked for progress: the partial sums of the loss and of the 8-bit
//! squared error, and the number of tile-list entries, which is how the buffers learn
//! that they must grow. That report is read one step late: the measured step's copies are
//! submitted with it, and the host collects them after it has submitted the next step,
//! so the device never waits for the host (on a fast GPU a step takes about as long as a
//! round trip). A step whose lists overflowed is skipped on the GPU (`fit_adam.wgsl`).
//! The lists hold twice the entries of the last report and are doubled again whenever a
//! report finds them three-quarters full, so a skip takes a set whose tile coverage grows
//! by a third within the ten steps between two reports.
//!
//! Pruning, re-placement and colour solves stay on the CPU ([`crate::fit::Fitter`]): the
//! fitter downloads the state before them and uploads it after, a few times per fit.

use super::backward_gpu::BackwardKernels;
use gsi_format::format::{BitDepths, Limits, MAX_BITS};
use gsi_format::model::{Blend, CovParam, GaussianSet};
use gsi_gpu::gpu::forward::{capacity_for, flatten, FitUniform, Forward, ForwardLists, STRIDE};
use gsi_gpu::gpu::{shader, too_big, Gpu, Kernel, PendingRead, SLOT};
use gsi_gpu::gpu::{Error, ErrorKind, Result};
use gsi_optim::optim::{Adam, AdamRule, LearningRates};
use gsi_render::render::RgbImage;

/// The kernels only the optimizer step needs (the forward half is
/// [`gsi_gpu::gpu::forward`]'s), built the first time a fit runs on a device.
pub(crate) struct StepKernels {
    loss: Kernel,
    adam: Kernel,
}

impl StepKernels {
    fn new(device: &wgpu::Device) -> StepKernels {
        let k = |label, source: String, reads, writes| {
            Kernel::new(device, label, &source, reads, writes)
        };
        StepKernels {
            loss: k(
                "fit_loss",
                shader!("device/fit_common", "fit/fit_loss"),
                2,
                3,
            ),
            adam: k(
                "fit_adam",
                shader!("device/fit_common", "fit/fit_adam"),
                6,
                2,
            ),
        }
    }

    fn of(gpu: &Gpu) -> Result<std::sync::Arc<StepKernels>> {
        gpu.kernels(StepKernels::new)
    }
}

/// What a step measured, when asked.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepReport {
    /// Which step (1 for this fit's first [`ResidentFit::step`]).
    pub step: u64,
    /// L2 loss of the rendered image.
    pub loss: f32,
    /// PSNR (dB, 8-bit) of the rendered image, as `fit::loss::psnr8` computes it.
    pub psnr: f64,
}

/// The fit's buffers beyond the forward half's.
struct Backward {
    moments: wgpu::Buffer,
    loss_part: wgpu::Buffer,
    sse8_part: wgpu::Buffer,
    /// The loss gradient, per pixel.
    dl: wgpu::Buffer,
    backward_params: wgpu::Buffer,
    loss: wgpu::BindGroup,
    pixel_groups: (u32, u32),
}

/// A measured step's report in flight, and what the step was run with.
struct Pending {
    read: PendingRead<3>,
    step: u64,
    /// The lists' capacity and the quantization the step rendered with.
    capacity: u32,
    qat: Option<BitDepths>,
}

/// The tile lists, and the fit's buffers sized by them.
struct Lists {
    forward: ForwardLists,
    backward: wgpu::BindGroup,
    adam: wgpu::BindGroup,
}

/// A fit living on the GPU: see the module documentation.
pub struct ResidentFit<'g> {
    gpu: &'g Gpu,
    uniform: FitUniform,
    blend: Blend,
    count: usize,
    has_opacity: bool,
    adam_step: i32,
    forward: Forward,
    back: Backward,
    lists: Lists,
    /// Capacity the lists must grow to before the next step.
    grow_to: Option<u32>,
    /// Steps taken.
    steps: u64,
    /// The last measured step's report (partial loss sums, partial squared errors,
    /// entries), submitted and not yet collected.
    pending: Option<Pending>,
}

impl<'g> ResidentFit<'g> {
    /// Upload `params` (stored parameterization, `log-scale-rotation`), Adam's state and
    /// `target`, and size every buffer. Fails when a buffer would exceed what the adapter
    /// can bind, so that the caller can fit on the CPU instead.
    pub fn new(
        gpu: &'g Gpu,
        target: &RgbImage,
        blend: Blend,
        params: &GaussianSet,
        adam: &Adam,
    ) -> Result<ResidentFit<'g>> {
        gpu.checked(|| {
            let (w, h) = (target.width, target.height);
            Limits::default().check_output(w, h)?;
            let count = params.len();
            if count == 0
                || count > u32::MAX as usize / 64
                || !params.is_consistent()
                || adam.m.len() != count
                || adam.v.len() != count
                || target.data.len() != w as usize * h as usize * 3
            {
                return Err(Error::new(
                    ErrorKind::InvalidValue,
                    "a GPU fit needs a consistent, non-empty Gaussian set and target",
                ));
            }
            let has_opacity = params.opacity.is_some();
            let mut uniform = FitUniform::new(w, h, count, blend, has_opacity);
            uniform.beta1 = adam.beta1;
            uniform.beta2 = adam.beta2;
            uniform.eps = adam.eps;
            // Every step clamps opacity to [0, 1]; the upload does the same, so the chain rule
            // on the GPU never meets an opacity outside it.
            let mut flat = flatten(params, 1.0);
            for g in flat.chunks_exact_mut(STRIDE) {
                g[8] = if g[8].is_finite() {
                    g[8].clamp(0.0, 1.0)
                } else {
                    0.0
                };
            }
            let forward = Forward::new(gpu, &uniform, &flat)?;
            let back = Backward::new(gpu, &forward, &uniform, target, adam)?;
            let capacity = capacity_for(forward.count_entries(gpu)?);
            let lists = Lists::new(gpu, &forward, &back, blend, capacity)?;
            Ok(ResidentFit {
                gpu,
                uniform,
                blend,
                count,
                has_opacity,
                adam_step: adam.step,
                forward,
                back,
                lists,
                grow_to: None,
                steps: 0,
                pending: None,
            })
        })
    }

    /// One optimizer step with learning rates `lr`; with `qat`, the render uses the
    /// parameters quantized to those bit depths and the gradient moves the float ones
    /// (straight-through). When `measure` is set, the step's loss and PSNR are read back
    /// one step late: returned by the next call (after it has submitted its own step) or
    /// by [`ResidentFit::collect`]. Returns the report that became ready, if any; a
    /// measured step whose tile lists overflowed gives none (it was skipped, and the
    /// lists grow before the next step).
    pub fn step(
        &mut self,
        lr: &LearningRates,
        qat: Option<BitDepths>,
        measure: bool,
    ) -> Result<Option<StepReport>> {
        let gpu = self.gpu;
        gpu.checked(|| {
            let gpu = self.gpu;
            if let Some(capacity) = self.grow_to.take() {
                self.lists = Lists::new(gpu, &self.forward, &self.back, self.blend, capacity)?;
            }
            self.adam_step += 1;
            self.steps += 1;
            let u = &mut self.uniform;
            u.capacity = self.lists.forward.capacity;
            (u.c1, u.c2) = AdamRule::at(u.beta1, u.beta2, u.eps, self.adam_step).corrections();
            u.lr = [lr.position, lr.log_scale, lr.rotation, lr.color, lr.opacity];
            u.qat = u32::from(qat.is_some());
            if let Some(b) = qat {
                let cov = if u.cholesky != 0 {
                    CovParam::Cholesky
                } else {
                    CovParam::LogScaleRotation
                };
                // Angles shaped by their Gaussian (`angle_by_shape`) are rendered here at
                // the uniform depth whose noise the shaping matches, not bucket by bucket;
                // colours by footprint (`color_by_footprint`) on one grid of their depth
                // over the colours' own range, not class by class. The file is quantized
                // on the CPU, exactly.
                let [_, _, angle] = b.of_covariance(cov);
                u.bits = [b.position, b.covariance, b.color, b.opacity, angle]
                    .map(|b| u32::from(b.min(MAX_BITS)));
            }
            gpu.queue
                .write_buffer(&self.forward.fit, 0, bytemuck::bytes_of(&self.uniform));
            let k = StepKernels::of(gpu)?;
            let backward = BackwardKernels::get(gpu)?;
            let (f, b, l) = (&self.forward, &self.back, &self.lists);
            let mut enc = gpu.encoder();
            f.record_binning(gpu, &l.forward, &mut enc, qat.is_some());
            let tile_grid = (self.uniform.tiles_x, self.uniform.tiles_y);
            let mut dispatches = f.render(gpu, &l.forward);
            dispatches.extend([
                (&k.loss, &b.loss, b.pixel_groups),
                (backward.of(self.blend), &l.backward, tile_grid),
                (&k.adam, &l.adam, f.gaussian_groups),
            ]);
            gpu.pass(&mut enc, &dispatches);
            let earlier = self.pending.take();
            let capacity = l.forward.capacity;
            if measure {
                let read = gpu.read_back_later(enc, [&b.loss_part, &b.sse8_part, &f.entries]);
                self.pending = Some(Pending {
                    read,
                    step: self.steps,
                    capacity,
                    qat,
                });
            } else {
                gpu.submit([enc.finish()]);
            }
            // This step, if unmeasured, is what `report` may have to account for.
            let unmeasured = (!measure).then_some((capacity, qat));
            match earlier {
                Some(p) => self.report(p, unmeasured),
                None => Ok(None),
            }
        })
    }

    /// Wait for the last measured step's report, if one is still to come.
    pub fn collect(&mut self) -> Result<Option<StepReport>> {
        match self.pending.take() {
            Some(p) => self.gpu.checked(|| self.report(p, None)),
            None => Ok(None),
        }
    }

    /// Read a measured step's report; note when its lists must grow or it was skipped.
    /// `after` is the capacity and quantization of the unmeasured step submitted since, if
    /// any: when the measured step overflowed, that one rendered the same parameters in
    /// the same lists and overflowed too.
    fn report(
        &mut self,
        p: Pending,
        after: Option<(u32, Option<BitDepths>)>,
    ) -> Result<Option<StepReport>> {
        let Pending {
            read,
            step,
            capacity,
            qat,
        } = p;
        let [loss_part, sse8_part, entries] = read.collect(self.gpu)?;
        let entries = bytemuck::cast_slice::<u8, u32>(&entries)[0];
        let loss: f64 = bytemuck::cast_slice::<u8, f32>(&loss_part)
            .iter()
            .map(|&x| f64::from(x))
            .sum();
        let sse: u64 = bytemuck::cast_slice::<u8, u32>(&sse8_part)
            .iter()
            .map(|&x| u64::from(x))
            .sum();
        let values = u64::from(self.uniform.width) * u64::from(self.uniform.height) * 3;
        let lists = capacity;
        let (entries, capacity) = (u64::from(entries), u64::from(capacity));
        let now = u64::from(self.lists.forward.capacity);
        if entries * 4 > now * 3 {
            let grown = capacity_for(entries);
            if u64::from(grown) < entries {
                return Err(too_big(&self.gpu.info, "the tile lists of this fit"));
            }
            self.grow_to = Some(grown.max(self.grow_to.unwrap_or(0)));
        }
        if entries > capacity {
            // Skipped, so not counted in Adam's bias correction from the next step on (the
            // step submitted since was corrected with it counted). A skipped step changes
            // nothing, so an unmeasured step since, with the same lists and quantization,
            // was skipped as well; a measured one reports for itself. (An unmeasured step
            // that overflows on its own stays counted: the host cannot know of it.)
            self.adam_step -= 1;
            if after == Some((lists, qat)) {
                self.adam_step -= 1;
            }
            return Ok(None);
        }
        Ok(Some(StepReport {
            step,
            loss: (loss / values as f64) as f32,
            psnr: gsi_metrics::metrics::psnr_of_sse(sse, values),
        }))
    }

    /// The parameters and Adam's state as they are now, shaped as the CPU fitter keeps
    /// them.
    pub fn download(&self) -> Result<(GaussianSet, Adam)> {
        self.gpu.checked(|| {
            let enc = self.gpu.encoder();
            let [params, moments] = self
                .gpu
                .read_back(enc, [&self.forward.params, &self.back.moments])?;
            let params: &[f32] = bytemuck::cast_slice(&params);
            let moments: &[f32] = bytemuck::cast_slice(&moments);
            let n = self.count * STRIDE;
            let o = self.has_opacity;
            Ok((
                unflatten(&params[..n], o),
                Adam {
                    step: self.adam_step,
                    beta1: self.uniform.beta1,
                    beta2: self.uniform.beta2,
                    eps: self.uniform.eps,
                    m: unflatten(&moments[..n], o),
                    v: unflatten(&moments[n..2 * n], o),
                },
            ))
        })
    }
}

impl Backward {
    fn new(
        gpu: &Gpu,
        f: &Forward,
        uniform: &FitUniform,
        target: &RgbImage,
        adam: &Adam,
    ) -> Result<Backward> {
        let device = &gpu.device;
        let pixels = u64::from(uniform.width) * u64::from(uniform.height);
        let pixel_groups = gpu.groups(pixels)?;
        let loss_groups = u64::from(pixel_groups.0) * u64::from(pixel_groups.1);
        let mut moments = flatten(&adam.m, 0.0);
        moments.extend(flatten(&adam.v, 0.0));
        let moments = gpu.storage(bytemuck::cast_slice(&moments));
        let target = gpu.storage(bytemuck::cast_slice(&target.data));
        let dl = gpu.zeroed(pixels * 12);
        let loss_part = gpu.zeroed(loss_groups * 4);
        let sse8_part = gpu.zeroed(loss_groups * 4);
        let backward_params = gpu.uniform_buffer(bytemuck::cast_slice(&[
            uniform.width,
            uniform.height,
            uniform.tiles_x,
            0u32,
        ]));
        Ok(Backward {
            loss: StepKernels::of(gpu)?.loss.bind(
                device,
                &[&f.fit, &f.image, &target, &dl, &loss_part, &sse8_part],
            ),
            moments,
            loss_part,
            sse8_part,
            dl,
            backward_params,
            pixel_groups,
        })
    }
}

impl Lists {
    fn new(gpu: &Gpu, f: &Forward, b: &Backward, blend: Blend, capacity: u32) -> Result<Lists> {
        let forward = ForwardLists::new(gpu, f, capacity, SLOT as u64 * 4)?;
        let device = &gpu.device;
        let slots = gpu.zeroed(u64::from(capacity) * SLOT as u64 * 4);
        let values = &forward.values;
        Ok(Lists {
            backward: BackwardKernels::get(gpu)?.of(blend).bind(
                device,
                &[
                    &b.backward_params,
                    &f.gaussians,
                    &f.boxes,
                    &f.offsets,
                    values,
                    &b.dl,
                    &slots,
                ],
            ),
            adam: StepKernels::of(gpu)?.adam.bind(
                device,
                &[
                    &f.fit,
                    &f.gaussians,
                    &f.boxes,
                    &f.offsets,
                    values,
                    &slots,
                    &f.entries,
                    &f.params,
                    &b.moments,
                ],
            ),
            forward,
        })
    }
}

fn unflatten(flat: &[f32], has_opacity: bool) -> GaussianSet {
    let g = flat.chunks_exact(STRIDE);
    GaussianSet {
        positions: g.clone().map(|g| [g[0], g[1]]).collect(),
        cov: g.clone().map(|g| [g[2], g[3], g[4]]).collect(),
        colors: g.clone().map(|g| [g[5], g[6], g[7]]).collect(),
        opacity: has_opacity.then(|| g.map(|g| g[8]).collect()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::{Fitter, Init, Loss};
    use gsi_synth::{random_scene, SceneSpec};

    use gsi_gpu::gpu::tests::gpu;

    const LR: LearningRates = LearningRates {
        position: 2e-4,
        log_scale: 0.01,
        rotation: 0.01,
        color: 0.005,
        opacity: 0.01,
    };

    fn target(w: u32, h: u32, blend: Blend) -> RgbImage {
        let mut t =
            gsi_render::render::render(&random_scene(7, SceneSpec::new(w, h, 120, blend)), w, h)
                .unwrap();
        t.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
        t
    }

    /// A fit of `params` to `t` whose tile lists hold 8 entries, far too few for a step,
    /// with Adam at step 0.
    fn in_tiny_lists<'g>(gpu: &'g Gpu, t: &RgbImage, params: &GaussianSet) -> ResidentFit<'g> {
        let mut adam = gsi_optim::optim::Adam::new(params);
        adam.step = 0;
        let mut r = ResidentFit::new(gpu, t, Blend::Alpha, params, &adam).unwrap();
        r.lists = Lists::new(gpu, &r.forward, &r.back, Blend::Alpha, 8).unwrap();
        r
    }

    /// Lists too small for a step: the step changes nothing, the next report asks for
    /// more room, and the step after it, in the grown lists, moves the parameters.
    #[test]
    fn an_overflowing_step_is_skipped_and_the_lists_grow() {
        let Some(gpu) = gpu() else { return };
        let t = target(120, 90, Blend::Alpha);
        let fitter = Fitter::new(&t, 150, Init::Adaptive, Blend::Alpha, Loss::L2, 1);
        let mut r = in_tiny_lists(&gpu, &t, &fitter.params);
        assert_eq!(r.step(&LR, None, true).unwrap(), None);
        assert_eq!(r.collect().unwrap(), None, "an overflowing step reported");
        let (after, _) = r.download().unwrap();
        assert_eq!(
            after, fitter.params,
            "an overflowing step changed the parameters"
        );
        let grown = r.grow_to.expect("the report asked for no more room");
        assert!(grown > 8);
        assert_eq!(
            r.adam_step, 0,
            "a skipped step counted in Adam's bias correction"
        );
        assert_eq!(r.step(&LR, None, true).unwrap(), None);
        let report = r.collect().unwrap().unwrap();
        assert_eq!(report.step, 2);
        assert_eq!(r.lists.forward.capacity, grown);
        assert!(report.psnr.is_finite() && report.psnr > 10.0, "{report:?}");
        let (after, _) = r.download().unwrap();
        assert_ne!(after, fitter.params);
        assert_eq!(r.adam_step, 1);
    }

    /// The report of an overflowing step comes a step late, when the next step is already
    /// queued in the same lists: that one, unmeasured, is skipped too and is not counted
    /// in Adam's bias correction either.
    #[test]
    fn the_step_queued_behind_an_overflow_is_not_counted() {
        let Some(gpu) = gpu() else { return };
        let t = target(120, 90, Blend::Alpha);
        let fitter = Fitter::new(&t, 150, Init::Adaptive, Blend::Alpha, Loss::L2, 1);
        let mut r = in_tiny_lists(&gpu, &t, &fitter.params);
        assert_eq!(r.step(&LR, None, true).unwrap(), None);
        assert_eq!(
            r.step(&LR, None, false).unwrap(),
            None,
            "an overflow reported"
        );
        assert_eq!(r.adam_step, 0);
        let (after, _) = r.download().unwrap();
        assert_eq!(
            after, fitter.params,
            "a skipped step changed the parameters"
        );
        // The lists grew for the third step, which moves the parameters.
        r.step(&LR, None, true).unwrap();
        assert_eq!(r.collect().unwrap().map(|m| m.step), Some(3));
        assert_eq!(r.adam_step, 1);
        assert_ne!(r.download().unwrap().0, fitter.params);
    }

    /// A 1×1 target, and Gaussians none of which is drawn (all off the image): finite
    /// reports and parameters, nothing drawn moves but by Adam's zero gradient.
    #[test]
    fn tiny_targets_and_undrawn_gaussians() {
        let Some(gpu) = gpu() else { return };
        for blend in [Blend::Sum, Blend::Alpha] {
            let t = target(1, 1, blend);
            let fitter = Fitter::new(&t, 3, Init::Adaptive, blend, Loss::L2, 2);
            let adam = gsi_optim::optim::Adam::new(&fitter.params);
            let mut r = ResidentFit::new(&gpu, &t, blend, &fitter.params, &adam).unwrap();
            // Each step returns the one before's report; the last is collected.
            for step in 1..=3 {
                let report = r.step(&LR, None, true).unwrap();
                assert_eq!(report.map(|r| r.step), (step > 1).then_some(step - 1));
                assert!(report.is_none_or(|r| r.loss.is_finite()), "{report:?}");
            }
            let report = r.collect().unwrap().unwrap();
            assert!(report.step == 3 && report.loss.is_finite(), "{report:?}");
            let mut off = fitter.params.clone();
            off.positions.iter_mut().for_each(|p| *p = [5.0, -3.0]);
            let adam = gsi_optim::optim::Adam::new(&off);
            let mut r = ResidentFit::new(&gpu, &t, blend, &off, &adam).unwrap();
            r.step(&LR, Some(crate::fit::default_bits(1, 1, blend)), true)
                .unwrap();
            let report = r.collect().unwrap().unwrap();
            // Nothing drawn: the render is black.
            let black = crate::fit::loss::psnr8(&[0.0; 3], &t.data, 1, 1);
            assert_eq!(report.psnr, black);
            let (after, _) = r.download().unwrap();
            assert_eq!(after, off);
        }
    }

    /// θ is read through sin and cos, whose error the GPU APIs bound only inside
    /// [-π, π]: the same Gaussians with θ moved by whole turns far outside it must fit
    /// as they do inside (the shaders reduce θ first).
    #[test]
    fn angles_far_outside_a_turn_fit_as_inside() {
        let Some(gpu) = gpu() else { return };
        let t = target(96, 64, Blend::Sum);
        let fitter = Fitter::new(&t, 120, Init::Adaptive, Blend::Sum, Loss::L2, 3);
        let inside = fitter.params.clone();
        assert!(inside
            .cov
            .iter()
            .all(|c| c[2].abs() <= std::f32::consts::PI));
        let mut outside = inside.clone();
        for (k, c) in outside.cov.iter_mut().enumerate() {
            // 16 turns up or down: θ near ±100, where an f32 still holds it to 1e-5.
            let turns = if k % 2 == 0 { 16.0 } else { -16.0 };
            c[2] += turns * std::f32::consts::TAU;
        }
        let losses = |params: &GaussianSet| -> Vec<f32> {
            let adam = gsi_optim::optim::Adam::new(params);
            let mut r = ResidentFit::new(&gpu, &t, Blend::Sum, params, &adam).unwrap();
            (0..6)
                .map(|_| {
                    r.step(&LR, None, true).unwrap();
                    r.collect().unwrap().unwrap().loss
                })
                .collect()
        };
        let (a, b) = (losses(&inside), losses(&outside));
        for (x, y) in a.iter().zip(&b) {
            assert!(
                (x - y).abs() <= 1e-4 * x.abs().max(1e-6),
                "{a:?} against {b:?}"
            );
        }
    }

    /// A kernel whose shader does not compile (as a vendor compiler may refuse what
    /// lavapipe takes) is an error, the fit finishes on the CPU with the reason in its
    /// result, and nothing broken is cached: the next fit on the same device runs there.
    #[test]
    fn a_shader_that_does_not_compile_gives_an_error_and_the_cpu() {
        use crate::fit::{encode, Budget, EncodeOptions};
        use gsi_gpu::Device;
        let Some(gpu) = gpu() else { return };
        let t = target(64, 48, Blend::Sum);
        let opts = EncodeOptions {
            budget: Budget::Gaussians(60),
            iterations: 12,
            ..EncodeOptions::default()
        };
        let cpu = encode(&t, &opts, Device::Cpu, &mut |_| {}).unwrap();

        gsi_gpu::gpu::break_shaders_on_this_thread(true);
        // A device whose own kernels do not build is not opened.
        let refused = gsi_gpu::gpu::Gpu::new()
            .err()
            .expect("a broken shader was accepted");
        assert_eq!(
            refused.kind(),
            gsi_gpu::gpu::ErrorKind::Unavailable,
            "{refused}"
        );
        let broken = encode(&t, &opts, Device::Gpu(&gpu), &mut |_| {});
        gsi_gpu::gpu::break_shaders_on_this_thread(false);
        let broken = broken.unwrap();
        let why = broken.fallback.expect("no fallback reported");
        assert!(why.contains("GPU"), "{why}");
        assert_eq!(
            broken.bytes, cpu.bytes,
            "the CPU did not take the whole fit"
        );

        let again = encode(&t, &opts, Device::Gpu(&gpu), &mut |_| {}).unwrap();
        assert_eq!(again.fallback, None, "a failed build was cached");
    }
}
