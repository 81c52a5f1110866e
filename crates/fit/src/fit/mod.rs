//! Stage 1: fit Gaussians to an image and write the quantized file (`gsi encode`).
//!
//! The pipeline, each step in its own module:
//! 1. [`init`]: place N Gaussians from the image content (or the paper's random start);
//! 2. [`lsq`]: solve their colours exactly for the fixed geometry;
//! 3. Adam on all parameters ([`params`]) through the differentiable rasterizer
//!    ([`raster`]), with pruning of Gaussians that do not change the render and
//!    error-guided re-placement;
//! 4. quantization-aware fine-tuning: the last iterations render the *quantized*
//!    parameters (straight-through gradients), so the stored file, not the float model,
//!    reaches the quality;
//! 5. quantize with bit depths fitted to each component's range (in `sum` mode the
//!    colour's depth chosen halfway through the fit from its error, [`depth`]), solve the colours
//!    once more for the quantized geometry ([`lsq`] again) and round them a batch at a
//!    time, so that the colours not yet rounded make up the error of those rounded
//!    ([`lsq::quantize_colors`]), write, decode the bytes and record the PSNR of what was
//!    stored.
//!
//! `--bpp` and `--target-psnr` choose N: a file over its byte budget loses its least
//! useful Gaussians and is fine-tuned again; a file under its quality target grows.
//!
//! With [`Coarse`], step 3 starts on a copy of the image reduced in each direction,
//! where a step costs a fraction of a full one, and the full-resolution steps refine what
//! it found ([`effort`] chooses how much of each).

pub mod dark;
pub mod depth;
pub mod effort;
mod error;
pub mod init;
pub mod loss;
// The pieces of a step: public for the benches that time them, not part of the API.
/// The backward pass on the GPU (`shaders/fit/backward_*.wgsl`).
#[cfg(feature = "gpu")]
pub mod backward_gpu;
mod lanes;
#[doc(hidden)]
pub mod lsq;
#[doc(hidden)]
pub mod params;
#[doc(hidden)]
pub mod raster;
#[cfg(feature = "gpu")]
pub(crate) mod resident;
// The seam: one build with the GPU twin, one without (same methods).
#[cfg(feature = "gpu")]
mod twin;
#[cfg(not(feature = "gpu"))]
#[path = "twin_cpu.rs"]
mod twin;

pub use effort::Effort;
pub use error::Error;
pub use gsi_optim::optim::LearningRates;
pub use init::Init;
pub use loss::Loss;

use gsi_format::format::{self, Attribute, BitDepths, Records, WriteOptions};
use gsi_format::model::{Blend, CovParam, GaussianSet, Scene, WeightRule};
use gsi_optim::optim::{self, Adam};
use gsi_render::render::{project_scene, Projected, RgbImage};
use raster::Need;

/// The image being fitted: interleaved RGB in `[0, 1]` (sRGB-encoded values).
pub type Target = RgbImage;

/// How many Gaussians to spend.
#[non_exhaustive]
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Budget {
    Gaussians(usize),
    /// Bits per pixel of the whole file, headers included.
    Bpp(f32),
    /// PSNR (dB) of the stored file: N grows by 1.6× per pass until it is met, for at most
    /// four passes after the first fit (from one Gaussian per 400 pixels, so at most about
    /// one per 60) and never past one Gaussian per 2 pixels. That keeps the work bounded; a
    /// target beyond it is missed, so compare [`Encoded::psnr`] with it.
    TargetPsnr(f32),
}

#[derive(Clone, Debug)]
pub struct EncodeOptions {
    pub budget: Budget,
    /// Optimizer steps of the first pass, the coarse ones included.
    pub iterations: u32,
    /// Fit a reduced copy of the image first (`None`: every step at full resolution).
    pub coarse: Option<Coarse>,
    pub init: Init,
    pub blend: Blend,
    pub seed: u64,
    pub loss: Loss,
    /// Learning rates; the position rate is in normalized units of an image
    /// [`RATE_SIDE`] pixels on its longer side, and scaled to the image being fitted.
    pub lr: LearningRates,
    /// Bit depths; `None` picks them from the image size.
    pub bits: Option<BitDepths>,
    /// Conjugate-gradient iterations of each least-squares colour solve (after pruning
    /// and re-placement); the first solve and the last take twice as many.
    pub color_solve: u32,
    /// Parts of the encoder turned off to measure what they buy (feature `lab`; without
    /// it every part is on, as [`Lab::default`]).
    #[cfg(feature = "lab")]
    pub lab: Lab,
}

/// Switches that turn parts of the encoder off, for the reports and tests that measure
/// what each part buys (feature `lab`). Every default is on: a file is always made with
/// all of them unless an experiment says otherwise.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lab {
    /// Fraction of the iterations spent on quantization-aware fine-tuning (0.2: 0.1 and
    /// 0.35 scored 0.03–0.05 dB lower on photos12 and eval15's normal-light images at 1
    /// bpp).
    pub qat_fraction: f32,
    /// Prune and re-place Gaussians during fitting.
    pub densify: bool,
    /// Whether the stored colours are solved again for the quantized geometry, after the
    /// last step (off: the stored colours as the last step left them, the effort report's
    /// reference; on, +0.35 dB at the default level on the validation images).
    pub solve_stored_colors: bool,
    /// Fit a dark image brightened to full scale and store its colours divided by the
    /// gain ([`dark`]), so that its shadows get Gaussians too. Images whose bright end
    /// reaches half of full scale are fitted as they are either way.
    pub lift_dark: bool,
    /// Round the stored colours a batch at a time, the colours still free solved again
    /// after each so that they make up the rounding error ([`lsq::quantize_colors`]);
    /// off, each colour is rounded to its nearest code alone.
    pub compensate_rounding: bool,
}

impl Default for Lab {
    fn default() -> Self {
        Lab {
            qat_fraction: 0.2,
            densify: true,
            solve_stored_colors: true,
            lift_dark: true,
            compensate_rounding: true,
        }
    }
}

impl EncodeOptions {
    /// The switches in force: the caller's with feature `lab`, all on without it.
    fn lab(&self) -> Lab {
        #[cfg(feature = "lab")]
        return self.lab;
        #[cfg(not(feature = "lab"))]
        Lab::default()
    }
}

/// Coarse-to-fine fitting: the first `fraction` of the iterations fit the image reduced
/// `factor` times in each direction (each output pixel the mean of a `factor`² block).
/// Positions and covariances are stored relative to the image, so the coarse fit is a
/// start for the full one as it is, optimizer state included; a coarse step costs about
/// `1/factor²` of a full one.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Coarse {
    pub factor: u32,
    pub fraction: f32,
}

/// The learning rates of every level: six times GaussianImage's (2e-4, 0.01, 0.01,
/// 0.005, 0.01), which are set for tens of thousands of steps; a level takes 160 to 1600.
/// One factor for all, checked on 8 of LOL eval15's normal-light images at 1 bpp (not
/// Kodak, which the report scores): ×2 to ×8 all beat ×1 at 60, 200, 400 and 800 steps,
/// ×6 by +0.47, +0.93, +0.37 and +0.14 dB; ×12 falls back (BENCHMARKS.md, learning rates
/// for short fits).
pub const LEARNING_RATES: LearningRates = LearningRates {
    position: 1.2e-3,
    log_scale: 0.06,
    rotation: 0.06,
    color: 0.03,
    opacity: 0.06,
};

/// The longer side, in pixels, at which [`EncodeOptions::lr`]'s position rate is meant:
/// on a longer side it shrinks in proportion (`rates_for`), so that a step moves a
/// Gaussian about as many pixels (0.9 at the start of a fit) on a 12 MP photograph as on
/// a Kodak image, where in normalized units as such it moved 4.8 pixels a step on a
/// 4000-pixel side. Kept on that principle: on the scale table's smooth renders, where
/// quantization decides the stored PSNR, it moved effort 1 by +0.6 to +1.4 dB and
/// effort 5 by −1.2 to +0.05 dB (BENCHMARKS.md, learning rates for short fits). 768 is
/// Kodak's side, so the
/// Kodak figures stand; the rates were checked on 600-pixel images, which keep theirs.
pub const RATE_SIDE: u32 = 768;

/// `lr` for a `width × height` image: the position rate scaled by [`RATE_SIDE`] over the
/// longer side (smaller images keep it as it is).
fn rates_for(lr: &LearningRates, width: u32, height: u32) -> LearningRates {
    let side = width.max(height).max(RATE_SIDE);
    LearningRates {
        position: lr.position * RATE_SIDE as f32 / side as f32,
        ..*lr
    }
}

impl Default for EncodeOptions {
    /// The options of [`Effort::DEFAULT`] (test `default_options_are_the_default_effort`).
    fn default() -> Self {
        EncodeOptions {
            budget: Budget::Bpp(1.0),
            iterations: 800,
            coarse: Some(Coarse {
                factor: 2,
                fraction: 0.5,
            }),
            init: Init::Adaptive,
            blend: Blend::Sum,
            seed: 0,
            // PSNR is what the budgets and benchmarks measure: L2 reaches 0.2-0.4 dB more
            // than the paper's L1 + MS-SSIM on Kodak at 1 bpp, and skips MS-SSIM's cost.
            loss: Loss::L2,
            lr: LEARNING_RATES,
            bits: None,
            color_solve: 10,
            #[cfg(feature = "lab")]
            lab: Lab::default(),
        }
    }
}

/// A progress report, every few iterations.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Progress {
    pub iteration: u32,
    pub total: u32,
    pub gaussians: usize,
    pub loss: f32,
    /// PSNR (dB, 8-bit) of the current render; of the quantized one during fine-tuning.
    pub psnr: f64,
    pub seconds: f64,
    /// Share of this pass's work done, in `[0, 1]`: a coarse step counts for the share of
    /// the pixels it renders, so that the pass's time left is about its time so far
    /// `· (1 − work) / work` (a bar that counted steps would run ahead during coarse ones).
    pub work: f64,
}

/// The result of an encode.
pub struct Encoded {
    pub records: Records,
    pub bytes: Vec<u8>,
    /// PSNR (dB, 8-bit RGB) of the decoded file against the target.
    pub psnr: f64,
    /// PSNR of the float fit before quantization: `float_psnr − psnr` is what the stored
    /// precision costs.
    pub float_psnr: f64,
    pub curve: Vec<Progress>,
    /// Why the fit left the GPU it was given for the CPU, if it did.
    pub fallback: Option<String>,
}

/// Bit depths for an image: positions to 1/4 pixel of the longer side, colour 8 bits,
/// and in `sum` mode covariance log-scales 6 bits. In `sum` mode the colour's 8 bits are
/// where a fit starts: [`encode`] then chooses the colour depth from the fit's own error
/// ([`depth`]) unless the caller gave the depths. Chosen on LOL eval15's normal-light
/// images (not Kodak, which the report scores) at 0.5 and 1 bpp, where coarser codes buy
/// more Gaussians within the budget:
/// * Positions 12 or 13 bits and covariance and colour 6 to 9 bits (BENCHMARKS.md, bit
///   depths chosen on a validation set): 1/4 pixel was as good as 1/8, and, on those
///   smooth images, colour below 8 bits lost more than the extra Gaussians bought back
///   (7 bits tied with 8 within ±0.04 dB, 6 bits lost 0.8 dB). On textured photographs
///   (photos12) 6 or 7 bits won by 0.2–0.8 dB: hence the choice per image.
/// * The scales take 6 bits rather than 8 (+0.23 dB at 1 bpp, +0.17 at 0.5, and +0.24
///   at effort 1): the stored colours are solved for the stored geometry, which absorbs most of what coarser scales cost. 5 bits lose again
///   (−0.27 dB at 1 bpp against 6). `alpha` mode was not measured again and keeps 8.
/// * The angle, kept within a quarter turn, took 7 bits: twice the
///   precision the 8 bits over a free angle's range had, in as many bits. Of 6, 7 and 8
///   bits on the same images at 1 bpp, 7 and 8 were within 0.03 dB of each other and 6
///   lost 0.1 dB; with 6-bit scales, a 6-bit angle loses 0.12 dB.
/// * In `sum` mode each angle now keeps the bits its Gaussian's shape needs (format 1.7,
///   [`gsi_format::format::angle`]), at the noise of a uniform 8-bit angle, which takes
///   about the bits that 7 uniform bits took. Of the noise of 6, 7, 8 and 9 uniform bits,
///   on photos12 and eval15's normal-light images at 1 bpp against 7 uniform bits:
///   −0.29, +0.12, +0.18 and +0.02 dB (the last on 15 of the 27 images; the buildings
///   −0.96, −0.03, +0.27, +0.12); at 0.5 bpp 7 and 8 tie (+0.05, +0.07). `alpha` mode
///   keeps 7 uniform bits.
/// * In `sum` mode each colour is stored at the precision of its footprint (format 1.8,
///   [`gsi_format::format::footprint`]): a step falling as `(s1·s2)^−3/8`, on one grid
///   whose depth the colour rule chooses. Of the exponents ½, ¼ and ⅜ on the same images
///   at 1 bpp, against one grid: +0.05, +0.03 and +0.09 dB; ⅜ at 0.5 bpp +0.15 dB.
///   [`encode`] keeps one grid for a dark image fitted brightened.
pub fn default_bits(width: u32, height: u32, blend: Blend) -> BitDepths {
    let side = width.max(height).max(2);
    let position = (32 - (side - 1).leading_zeros() + 2).clamp(6, 20) as u8;
    BitDepths {
        position,
        covariance: if blend == Blend::Sum { 6 } else { 8 },
        angle: if blend == Blend::Sum { 8 } else { 7 },
        angle_by_shape: blend == Blend::Sum,
        color_by_footprint: blend == Blend::Sum,
        color: if blend == Blend::Sum { 8 } else { 7 },
        opacity: 6,
    }
}

/// Bytes per Gaussian of the codes bit-packed (§5.3): the first guess of N under a byte
/// budget, before [`coded_bytes_per_gaussian`] measures what method 3 makes of them.
fn bytes_per_gaussian(bits: BitDepths, blend: Blend) -> f32 {
    let b =
        2 * u32::from(bits.position) + 3 * u32::from(bits.covariance) + 3 * u32::from(bits.color);
    let b = b + if blend == Blend::Alpha {
        u32::from(bits.opacity)
    } else {
        0
    };
    b as f32 / 8.0
}

/// How many of `n` Gaussians to keep so that a file of `bpp` fits in `budget` bpp: bytes
/// beyond the fixed overhead scale with the count; 2 % to spare.
fn shrunk(n: usize, bpp: f32, budget: f32, px: f32) -> usize {
    let fixed = FILE_OVERHEAD * 8.0 / px;
    let ratio = ((budget - fixed) / (bpp - fixed)).clamp(0.0, 1.0);
    (n as f32 * ratio * 0.98) as usize
}

/// Bytes per Gaussian of `scene`'s attribute payloads as [`finish`] writes them
/// (quantized with `bits`, in curve order, method 3 or 4 where it is smaller, colours by
/// footprint in method 5).
fn coded_bytes_per_gaussian(scene: &Scene, bits: BitDepths) -> f32 {
    let mut r = Records::from_scene(scene, bits);
    r.sort_spatially();
    let n = r.header.count.max(1) as f32;
    let bytes: usize = [&r.positions, &r.covariance, &r.colors]
        .into_iter()
        .chain(r.opacity.as_ref())
        .map(|a| {
            r.attribute_payload(a, WriteOptions::default().zstd_level, true)
                .expect("records quantized from a scene have a payload for every attribute")
                .len()
        })
        .sum();
    bytes as f32 / n
}

/// Fixed bytes of a file: signature, header, gCRM, chunk frames and quantizer preambles.
const FILE_OVERHEAD: f32 = 300.0;

/// Most Gaussians a fit of `px` pixels takes: one per two pixels, and at most 2^22.
fn max_gaussians(px: f32) -> usize {
    ((px / 2.0) as usize).clamp(1, 1 << 22)
}

/// How many Gaussians of `per_g` bytes each fit a budget of `bpp` over `px` pixels.
fn fitting_count(bpp: f32, px: f32, per_g: f32) -> usize {
    (((bpp * px / 8.0 - FILE_OVERHEAD) / per_g) as usize).clamp(1, max_gaussians(px))
}

/// What a fitting step measured ([`Fitter::step`] with `measure`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured {
    /// Which step (1 for the fitter's first).
    pub step: u64,
    /// Loss of the step's render.
    pub loss: f32,
    /// PSNR (dB, 8-bit) of the step's render.
    pub psnr: f64,
}

/// What each Gaussian does to a render ([`Fitter::contributions`]).
struct Contributions {
    /// Total colour each Gaussian puts into the image, `Σ_p alpha_i T_i · max|c_i|` (0
    /// for Gaussians that touch no pixel).
    score: Vec<f32>,
    /// `sum` mode: the squared error that dropping the Gaussian alone would add,
    /// `|c|²·Σ_p w²` (colour channels summed); its neighbours then take over part of it,
    /// so this is an upper bound. Infinite in `alpha` mode, where it is not estimated.
    loss: Vec<f64>,
    /// The render.
    image: Vec<f32>,
}

/// The fitting state: parameters, optimizer, target.
pub struct Fitter<'a> {
    target: &'a Target,
    blend: Blend,
    /// The parameters. While a GPU fit is resident they are those of its last
    /// [`Fitter::sync`], and what is written here is lost at the next one.
    pub params: GaussianSet,
    adam: Adam,
    loss: loss::LossFn,
    seed: u64,
    /// Steps taken.
    steps: u64,
    /// A measurement collected early (by [`Fitter::sync`]), for the next step or flush.
    ready: Option<Measured>,
    /// Where [`Fitter::step`] runs (the CPU, or its GPU twin), and why it left the GPU if
    /// it did. While a fit is resident there, `params` and `adam` are those of the last
    /// [`Fitter::sync`].
    twin: twin::Twin<'a>,
}

impl<'a> Fitter<'a> {
    /// `n` Gaussians placed on `target` by `init` (with the adaptive start, their colours
    /// solved), and a fresh optimizer.
    pub fn new(
        target: &'a Target,
        n: usize,
        init: Init,
        blend: Blend,
        loss: Loss,
        seed: u64,
    ) -> Fitter<'a> {
        let params = init::initialize(target, n, init, blend, seed);
        Fitter::started(target, params, init, blend, loss, seed, 20)
    }

    /// A fitter from `params` as `init` placed them: with the adaptive start, their
    /// colours solved first (`solve` iterations).
    fn started(
        target: &'a Target,
        params: GaussianSet,
        init: Init,
        blend: Blend,
        loss: Loss,
        seed: u64,
        solve: usize,
    ) -> Fitter<'a> {
        let mut f = Fitter::with_params(target, params, blend, loss, seed);
        if init == Init::Adaptive {
            f.solve_colors(solve);
        }
        f
    }

    /// A fitter that starts from `params` (relative to the image, so those of another
    /// resolution of the same image serve), with a fresh optimizer.
    pub fn with_params(
        target: &'a Target,
        params: GaussianSet,
        blend: Blend,
        loss: Loss,
        seed: u64,
    ) -> Fitter<'a> {
        Fitter {
            target,
            blend,
            adam: Adam::new(&params),
            params,
            loss: loss::LossFn::new(loss),
            seed,
            steps: 0,
            ready: None,
            twin: twin::Twin::cpu(),
        }
    }

    fn scene_of(&self, g: GaussianSet) -> Scene {
        Scene {
            tone: None,
            width: self.target.width,
            height: self.target.height,
            blend: self.blend,
            cov_param: CovParam::LogScaleRotation,
            gaussians: g,
            weights: WeightRule::Columns32,
        }
    }

    /// The current parameters as a scene; after [`Fitter::sync`] when fitting on a GPU.
    pub fn scene(&self) -> Scene {
        self.scene_of(self.params.clone())
    }

    /// Parameters as they will be after quantization with `bits`. Opacities that are
    /// all 1 are not stored (the file has no opacity attribute); they stay here, at 1,
    /// so that the straight-through gradient still reaches them.
    fn quantized(&self, bits: BitDepths) -> GaussianSet {
        let mut q = Records::from_scene(&self.scene(), bits)
            .to_scene()
            .gaussians;
        if self.params.opacity.is_some() && q.opacity.is_none() {
            q.opacity = Some(vec![1.0; q.len()]);
        }
        q
    }

    /// Put every Gaussian's angle in `[−π/4, π/4]` ([`params::canonical_rotation`]),
    /// swapping its scales (and their optimizer moments) where that takes a quarter turn.
    /// The covariances stay the same, so the render moves only by rounding; the stored
    /// angles then span a quarter turn.
    pub fn canonicalize_rotations(&mut self) {
        self.sync();
        for i in 0..self.params.len() {
            let (p, swapped) = params::canonical_rotation(self.params.cov[i]);
            self.params.cov[i] = p;
            if swapped {
                for s in [&mut self.adam.m, &mut self.adam.v] {
                    if let Some(c) = s.cov.get_mut(i) {
                        c.swap(0, 1);
                    }
                }
            }
        }
    }

    /// Replace the colours by their least-squares optimum for the current geometry.
    pub fn solve_colors(&mut self, iterations: usize) {
        self.sync();
        let mut scene = self.scene();
        solve_scene_colors(&mut scene, &self.target.data, iterations);
        self.params.colors = scene.gaussians.colors;
    }

    /// One optimizer step. With `qat`, the forward pass renders the quantized parameters
    /// and their gradient is applied to the float ones (straight-through). When `measure`
    /// is set, the loss and PSNR of the image the step rendered are measured (a GPU fit
    /// reads nothing back otherwise).
    ///
    /// Returns the measurement that became ready: on the CPU this step's; on the GPU
    /// that of the last measured step before this one, read back after this step was
    /// submitted so that the device does not wait for the host. [`Fitter::flush`]
    /// collects what is still to come.
    pub fn step(
        &mut self,
        lr: &LearningRates,
        qat: Option<BitDepths>,
        measure: bool,
    ) -> Option<Measured> {
        self.steps += 1;
        let now = self.step_now(lr, qat, measure);
        match (self.ready.take(), now) {
            (Some(early), Some(now)) => {
                self.ready = Some(now);
                Some(early)
            }
            (early, now) => early.or(now),
        }
    }

    /// The measurements still to come from earlier steps, one per call (`None` when all
    /// have been returned). Waits for the GPU.
    pub fn flush(&mut self) -> Option<Measured> {
        if let Some(m) = self.ready.take() {
            return Some(m);
        }
        self.twin.flush(&mut self.params, &mut self.adam)
    }

    fn step_now(
        &mut self,
        lr: &LearningRates,
        qat: Option<BitDepths>,
        measure: bool,
    ) -> Option<Measured> {
        let l2 = self.loss.kind() == Loss::L2;
        let (p, a) = (&mut self.params, &mut self.adam);
        let target = self.target;
        if let Some(done) = self
            .twin
            .step(target, self.blend, l2, p, a, self.steps, lr, qat, measure)
        {
            return done;
        }
        let (w, h) = (self.target.width, self.target.height);
        let used = match qat {
            Some(bits) => self.quantized(bits),
            None => self.params.clone(),
        };
        let scene = self.scene_of(used);
        let projected = project_scene(&scene, w, h);
        let (value, psnr, pg) = self.passes(&projected, measure);
        let mut grads = optim::zeros_like(&self.params);
        params::chain(&scene.gaussians, &projected, &pg, w, h, &mut grads);
        self.adam.step(&mut self.params, &grads, lr);
        psnr.map(|psnr| Measured {
            step: self.steps,
            loss: value,
            psnr,
        })
    }

    /// Take this fitter's steps on `gpu`. With the L2 loss the whole step runs there
    /// (`fit::resident`) and the state comes back only at [`Fitter::sync`]; with the
    /// MS-SSIM loss the render and backward passes run there and the rest on the CPU.
    /// If the GPU fails, the fitter continues on the CPU and [`Fitter::fallback`] says why.
    #[cfg(feature = "gpu")]
    pub fn use_gpu(&mut self, gpu: &'a gsi_gpu::gpu::Gpu) {
        self.twin.use_gpu(gpu);
    }

    /// Why the fitter left its GPU for the CPU, if it did.
    pub fn fallback(&self) -> Option<&str> {
        self.twin.fallback()
    }

    /// Bring the parameters and Adam's state back from the GPU, if they live there, so
    /// that `params` and [`Fitter::scene`] are current. Pruning, colour solves and
    /// the final measurement call it themselves. A measurement still to come is kept for
    /// the next [`Fitter::step`] or [`Fitter::flush`].
    pub fn sync(&mut self) {
        self.twin
            .sync(&mut self.params, &mut self.adam, &mut self.ready);
    }

    /// The step's render, loss (with the PSNR when `measure`) and gradients: on the GPU
    /// when the fitter has one, else, or once the GPU has failed, on the CPU.
    fn passes(
        &mut self,
        projected: &[Projected],
        measure: bool,
    ) -> (f32, Option<f64>, Vec<raster::ProjGrad>) {
        let (w, h) = (self.target.width, self.target.height);
        let (target, blend) = (self.target, self.blend);
        let fused = blend == Blend::Sum && self.loss.kind() == Loss::L2;
        let loss = &mut self.loss;
        // The loss of an image and its gradient, and its PSNR when `measure`.
        let mut score = |image: &[f32]| {
            let (value, dl) = loss.eval(image, &target.data, w, h);
            let psnr = measure.then(|| loss::psnr8(image, &target.data, w, h));
            (value, dl, psnr)
        };
        if let Some(done) = self.twin.passes(projected, blend, (w, h), &mut score) {
            return done;
        }
        if fused {
            let step = raster::step_l2_sum(projected, &target.data, w, h, measure);
            let psnr = measure.then(|| loss::psnr8(&step.image, &target.data, w, h));
            return (step.loss, psnr, step.grads);
        }
        let fwd = raster::forward(projected, blend, w, h);
        let (value, dl, psnr) = score(&fwd.image);
        (
            value,
            psnr,
            raster::backward(&fwd, projected, &dl, Need::All),
        )
    }

    /// What each Gaussian does to the current render, and the render.
    fn contributions(&self) -> Contributions {
        let (w, h) = (self.target.width, self.target.height);
        let scene = self.scene();
        let projected = project_scene(&scene, w, h);
        // Σ_p alpha_i T_i: the colour gradient of a render under a gradient of ones.
        let (weights, image) = if self.blend == Blend::Sum {
            let tiles = gsi_render::render::TileLists::bin(&projected, w, h);
            let mut image = vec![0f32; (w * h * 3) as usize];
            let ones = |_: &lanes::Planes, _| lanes::Planes::ones();
            let c = raster::sum_adjoint(&projected, &tiles, w, h, Some(&mut image), ones);
            (c, image)
        } else {
            let fwd = raster::forward(&projected, self.blend, w, h);
            let ones = vec![1f32; fwd.image.len()];
            let pg = raster::backward(&fwd, &projected, &ones, Need::ColorOnly);
            (pg.iter().map(|g| g.color).collect(), fwd.image)
        };
        let sum = self.blend == Blend::Sum;
        let mut score = vec![0f32; self.params.len()];
        let mut loss = vec![if sum { 0.0 } else { f64::INFINITY }; self.params.len()];
        for (g, d) in projected.iter().zip(&weights) {
            let cmax = g.color.iter().fold(0f32, |m, c| m.max(c.abs()));
            score[g.index] = d[0] * cmax.max(1.0 / 255.0);
            if sum {
                // Σ_p w² is half of Σ_p w for a Gaussian wholly inside the image (∫w² = πσ1σ2,
                // ∫w = 2πσ1σ2), and shrinks with Σ_p w where the border cuts it off.
                let c2: f64 = g.color.iter().map(|&c| f64::from(c).powi(2)).sum();
                loss[g.index] = c2 * f64::from(d[0]) / 2.0;
            }
        }
        Contributions { score, loss, image }
    }

    /// Drop Gaussians whose total contribution is below `min_score`, and in `sum` mode
    /// those whose [`Contributions::loss`] is under `min_worth` times what one more
    /// Gaussian placed at the error removes on average; keep at most `keep_at_most` (the
    /// most useful), then add Gaussians where the error is largest until there are `n`.
    /// Returns how many were removed.
    ///
    /// With the fit's squared error `D` falling as `N^−γ` ([`depth::GAMMA`]), one more
    /// Gaussian removes about `γ·D/N`: a Gaussian that holds back less than that is worth
    /// more re-placed at the error. The bar rises with the error, so a textured photograph
    /// that the Gaussians cannot follow sheds the faint ones that a smooth image keeps.
    pub fn prune_and_grow(
        &mut self,
        min_score: f32,
        min_worth: f64,
        keep_at_most: usize,
        n: usize,
    ) -> usize {
        self.sync();
        let Contributions { score, loss, image } = self.contributions();
        let err = self.pixel_errors(&image);
        let bar = if min_worth > 0.0 {
            let sse: f64 = err.iter().copied().map(f64::from).sum();
            min_worth * depth::GAMMA * sse / score.len().max(1) as f64
        } else {
            0.0
        };
        let mut order: Vec<usize> = (0..score.len()).collect();
        order.sort_by(|&a, &b| score[b].total_cmp(&score[a]).then(a.cmp(&b)));
        let mut keep = vec![false; score.len()];
        for &i in order.iter().take(keep_at_most) {
            keep[i] = score[i] >= min_score && loss[i] >= bar;
        }
        let removed = keep.iter().filter(|k| !**k).count();
        optim::retain(&mut self.params, &keep);
        let grow = n.saturating_sub(self.params.len());
        self.adam.resize(&keep, 0);
        if grow > 0 {
            let added = self.add_at_error(&image, &err, grow);
            self.adam
                .resize(&vec![true; self.params.len() - added], added);
        }
        removed
    }

    /// Squared error of `image` against the target at each pixel, channels summed.
    fn pixel_errors(&self, image: &[f32]) -> Vec<f32> {
        image
            .chunks_exact(3)
            .zip(self.target.data.chunks_exact(3))
            .map(|(a, b)| (0..3).map(|c| (a[c] - b[c]).powi(2)).sum())
            .collect()
    }

    /// Append up to `k` small Gaussians at pixels sampled in proportion to the squared
    /// error `err` of `image` ([`Fitter::pixel_errors`]); none where the render is already
    /// exact. Returns how many were added.
    fn add_at_error(&mut self, image: &[f32], err: &[f32], k: usize) -> usize {
        let t = self.target;
        let (w, h) = (t.width as usize, t.height as usize);
        let mut rng = gsi_optim::rng::SplitMix64::new(self.seed ^ self.params.len() as u64);
        let picks = init::stratified(err, w, h, k, &mut rng);
        let n_all = (self.params.len() + k) as f32;
        let sigma = (0.35 * ((w * h) as f32 / n_all).sqrt()).max(0.5);
        let (fw, fh) = (w as f32, h as f32);
        for &p in &picks {
            let (x, y) = ((p % w) as f32 + rng.unit(), (p / w) as f32 + rng.unit());
            self.params.positions.push([x / fw, y / fh]);
            self.params
                .cov
                .push(init::pixel_lsr(sigma, sigma, 0.0, fw, fh));
            let c: [f32; 3] = std::array::from_fn(|ch| {
                t.data[p * 3 + ch]
                    - if self.blend == Blend::Sum {
                        image[p * 3 + ch]
                    } else {
                        0.0
                    }
            });
            self.params.colors.push(c);
            if let Some(o) = self.params.opacity.as_mut() {
                o.push(0.5);
            }
        }
        picks.len()
    }
}

/// Replace `scene`'s colours by their least-squares optimum for its geometry against
/// `target` (`iterations` conjugate-gradient steps from the colours it has), each
/// component kept within ±4.
fn solve_scene_colors(scene: &mut Scene, target: &[f32], iterations: usize) {
    let (w, h) = (scene.width, scene.height);
    let mut projected = project_scene(scene, w, h);
    let colors = lsq::solve_colors(&mut projected, scene.blend, w, h, target, iterations);
    for (g, c) in projected.iter().zip(colors) {
        scene.gaussians.colors[g.index] = c.map(|v| v.clamp(-4.0, 4.0));
    }
}

/// Batches in which the stored colours are rounded, and the CG steps that solve the
/// colours still free after each ([`lsq::quantize_colors`]): 28 products of the normal
/// equations, where the solve before them takes 21. The number of batches matters more
/// than the steps: on five of photos12's Set14 images at 1 bpp, against each colour
/// rounded alone, 2 batches of 5 steps (6 products) gained +0.04 dB on average, 4 of 3
/// (12) +0.07, 4 of 5 (18) +0.07, 8 of 3 +0.09, 8 of 5 (42) +0.08 (one file went over
/// its budget and kept the plain rounding) and 16 of 3 (60) +0.10.
const ROUNDING: (usize, usize) = (8, 3);

/// The codes `nearest` (each colour of `scene`, solved for its geometry, rounded to its
/// nearest code) rounded instead a batch at a time ([`lsq::quantize_colors`]), over the
/// same quantizers.
fn compensated_colors(
    scene: &Scene,
    target: &[f32],
    nearest: &Attribute,
    steps: Option<&[f32]>,
) -> Attribute {
    let qs = std::array::from_fn(|c| nearest.quantizers[c]);
    let (w, h) = (scene.width, scene.height);
    let mut projected = project_scene(scene, w, h);
    let codes = lsq::quantize_colors(
        &mut projected,
        scene.blend,
        (w, h),
        target,
        &qs,
        steps,
        ROUNDING,
    );
    // A Gaussian that touches no pixel keeps its nearest code.
    let mut out = nearest.clone();
    let n = scene.gaussians.len();
    for (g, c) in projected.iter().zip(codes) {
        for (ch, code) in c.into_iter().enumerate() {
            out.codes[ch * n + g.index] = code;
        }
    }
    out
}

/// Learning-rate factor at `it` of `total`: cosine decay to 5 %.
fn schedule(it: u32, total: u32) -> f32 {
    gsi_optim::optim::cosine_decay(it as f32 / total.max(1) as f32, 0.05)
}

/// One run of optimizer steps with its own learning-rate schedule, and where it sits in
/// the pass that the progress reports count.
#[derive(Clone, Copy)]
struct Phase {
    steps: u32,
    /// Steps of the pass before this run.
    first: u32,
    /// Steps of the whole pass.
    all: u32,
    /// The work of one step, and the pass's work before this run and in all.
    step_work: f64,
    work_before: f64,
    work_all: f64,
    /// Whether the last `Lab::qat_fraction` of the steps render the quantized parameters.
    qat: bool,
}

impl Phase {
    /// A pass of `steps` full-resolution steps in one run.
    fn whole(steps: u32, qat: bool) -> Phase {
        Phase {
            steps,
            first: 0,
            all: steps,
            step_work: 1.0,
            work_before: 0.0,
            work_all: f64::from(steps),
            qat,
        }
    }
}

/// How much a Gaussian must hold back at a densification to stay, in units of what one
/// more Gaussian removes ([`Fitter::prune_and_grow`]). Its loss is an upper bound (its
/// neighbours and the colour solve that follows take over part of it), so the bar that
/// balances the two lies above 1. On the validation sets at equal bytes (photos12 and
/// eval15's normal-light images, 0.5 and 1 bpp), against the contribution test alone:
/// 1 gained +0.10 to +0.35 dB, 2 +0.19 to +0.39, 4 +0.26 to +0.36, 8 +0.13 to +0.24 (on
/// three of the four); 2 and 4 tie within 0.03 dB on average, and 2, nearer the bound,
/// moves dark images fitted brightened least (LOL val30 through stage 2: SSIM 0.793
/// against 0.795; 4 gave 0.789).
const PRUNE_WORTH: f64 = 2.0;

/// Runs the optimizer for [`encode`]: pruning and re-placement at fixed points of each run,
/// quantization-aware steps at its end, progress reports, and the early stop of a PSNR
/// target.
struct Runner<'o, 'p> {
    opts: &'o EncodeOptions,
    /// `opts.lr` for the image's size ([`rates_for`]).
    lr: LearningRates,
    bits: BitDepths,
    /// Whether the colour depth is still to be chosen from the fit ([`depth`]): at the
    /// second densification of the first full-resolution run, so that the budget is then
    /// filled at the chosen depth and the quantization-aware steps use it (a fit without
    /// densification keeps the depth it started with).
    choose_color: bool,
    /// PSNR of the last measured step against the image being fitted (brightened, for a
    /// dark image).
    last_psnr: f64,
    /// The byte budget (bits per pixel) that the densification steps fill, once the
    /// Gaussians' own cost can be measured; `None` where there is none to fill.
    fill: Option<f32>,
    /// The full-resolution image's size.
    size: (u32, u32),
    stop_at: Option<f64>,
    /// What the fit's PSNR gains from fitting a brightened copy of the image
    /// ([`dark`]): `20·log10(gain)`, taken off the PSNR reported and compared with a
    /// target, so that both speak of the image as it is.
    psnr_offset: f64,
    start: std::time::Instant,
    on_progress: &'p mut dyn FnMut(&Progress),
    curve: Vec<Progress>,
}

impl Runner<'_, '_> {
    fn run(&mut self, fitter: &mut Fitter<'_>, phase: Phase) {
        let opts = self.opts;
        let total = phase.steps;
        let qat_from = if phase.qat {
            ((1.0 - opts.lab().qat_fraction) * total as f32) as u32
        } else {
            u32::MAX
        };
        let densify_at = [total / 4, total / 2];
        // Measurements may come a step late (a GPU fit's): each says which step it is.
        let base = fitter.steps;
        for it in 0..total {
            if opts.lab().densify && densify_at.contains(&it) && it > 0 {
                if it == densify_at[1] {
                    self.choose_color_bits(fitter);
                }
                let n_now = fitter.params.len();
                let n = self.filling(fitter).unwrap_or(n_now);
                fitter.prune_and_grow(0.5, PRUNE_WORTH, n, n);
                if opts.blend == Blend::Sum || opts.init == Init::Adaptive {
                    fitter.solve_colors(opts.color_solve as usize);
                }
            }
            if it == qat_from {
                fitter.canonicalize_rotations();
            }
            let qat = (it >= qat_from).then_some(self.bits);
            let measure = it % 10 == 0 || it + 1 == total;
            let done = fitter.step(&self.lr.scaled(schedule(it, total)), qat, measure);
            if done.is_some_and(|m| self.measured(m, base, fitter, phase, qat_from)) {
                break;
            }
        }
        while let Some(m) = fitter.flush() {
            self.measured(m, base, fitter, phase, qat_from);
        }
    }

    /// Choose the colour depth from the fit so far ([`depth::color_bits`]), once, at full
    /// resolution.
    fn choose_color_bits(&mut self, fitter: &mut Fitter) {
        let t = fitter.target;
        if !self.choose_color || (t.width, t.height) != self.size {
            return;
        }
        self.choose_color = false;
        fitter.sync();
        let mut scene = fitter.scene();
        for c in &mut scene.gaussians.cov {
            *c = params::canonical_rotation(*c).0;
        }
        let per_g = 8.0 * f64::from(coded_bytes_per_gaussian(&scene, self.bits));
        let mse = 10f64.powf(-self.last_psnr / 10.0);
        let g = &scene.gaussians;
        let by_footprint = self.bits.color_by_footprint;
        if let Some(b) = depth::color_bits(&g.colors, &g.cov, mse, per_g, by_footprint) {
            self.bits.color = b;
        }
    }

    /// How many Gaussians fill the byte budget at what the current ones cost coded, in
    /// the form they will be stored in; `None` without a budget to fill or at a reduced
    /// resolution.
    ///
    /// The count chosen before the fit prices the initial Gaussians, which code a few per
    /// cent dearer than fitted ones, so files came out 6 % under a 1 bpp budget (Kodak).
    /// Measured again at each densification, the count follows the cost.
    fn filling(&self, fitter: &Fitter) -> Option<usize> {
        let b = self.fill?;
        let t = fitter.target;
        let (w, h) = self.size;
        if (t.width, t.height) != (w, h) {
            return None;
        }
        let mut scene = fitter.scene();
        for c in &mut scene.gaussians.cov {
            *c = params::canonical_rotation(*c).0;
        }
        let per_g = coded_bytes_per_gaussian(&scene, self.bits) * 1.01;
        Some(fitting_count(b, w as f32 * h as f32, per_g))
    }

    /// Report a measurement; whether the PSNR target is reached (by a quantization-aware
    /// step).
    fn measured(
        &mut self,
        m: Measured,
        base: u64,
        fitter: &Fitter,
        phase: Phase,
        qat_from: u32,
    ) -> bool {
        let it = (m.step - base) as u32;
        self.last_psnr = m.psnr;
        let work = phase.work_before + f64::from(it) * phase.step_work;
        let p = Progress {
            iteration: phase.first + it,
            total: phase.all,
            gaussians: fitter.params.len(),
            loss: m.loss,
            psnr: m.psnr - self.psnr_offset,
            seconds: self.start.elapsed().as_secs_f64(),
            work: (work / phase.work_all.max(1e-9)).clamp(0.0, 1.0),
        };
        (self.on_progress)(&p);
        self.curve.push(p);
        self.stop_at
            .is_some_and(|target| it > qat_from && p.psnr >= target)
    }
}

/// `target` reduced `factor` times in each direction: each pixel the mean of its block
/// (blocks cut by the right and bottom edges average what they hold).
fn reduced(target: &Target, factor: u32) -> Target {
    let (w, h) = (target.width as usize, target.height as usize);
    let f = factor.max(1) as usize;
    let (rw, rh) = (w.div_ceil(f), h.div_ceil(f));
    let mut data = vec![0f32; rw * rh * 3];
    let mut count = vec![0u32; rw * rh];
    for y in 0..h {
        for x in 0..w {
            let o = (y / f) * rw + x / f;
            count[o] += 1;
            for c in 0..3 {
                data[o * 3 + c] += target.data[(y * w + x) * 3 + c];
            }
        }
    }
    for (px, &k) in data.chunks_exact_mut(3).zip(&count) {
        px.iter_mut().for_each(|v| *v /= k as f32);
    }
    Target {
        width: rw as u32,
        height: rh as u32,
        data,
    }
}

/// The reduced target of `coarse` and its steps for a fit of `n` Gaussians in `iterations`
/// steps, or `None` where there is none: no coarse steps, or a reduced image under 16
/// pixels a side or with fewer than two pixels a Gaussian (then it cannot say where they
/// go). At least one step is left for the full resolution.
fn coarse_start(
    target: &Target,
    coarse: Option<Coarse>,
    n: usize,
    iterations: u32,
) -> Option<(Target, u32)> {
    let c = coarse?;
    let steps = (iterations as f32 * c.fraction.clamp(0.0, 1.0)) as u32;
    let steps = steps.min(iterations.saturating_sub(1));
    let (rw, rh) = (
        target.width.div_ceil(c.factor.max(1)),
        target.height.div_ceil(c.factor.max(1)),
    );
    let fits = rw >= 16 && rh >= 16 && n.saturating_mul(2) <= rw as usize * rh as usize;
    (c.factor >= 2 && steps > 0 && fits).then(|| (reduced(target, c.factor), steps))
}

/// Take `fitter`'s steps on `device`.
fn on_device<'a>(fitter: &mut Fitter<'a>, device: gsi_gpu::Device<'a>) {
    fitter.twin = twin::Twin::on(device);
}

/// What `gCRM` records of an encode (spec §7.1.1): the options that shaped the file, the
/// last four only where they differ from the defaults, so that files made with the
/// settings before them stay the same.
fn settings_of(opts: &EncodeOptions, bits: &BitDepths, gain: f32) -> format::EncoderSettings {
    use format::settings::{BudgetKind, InitKind, LossKind};
    format::EncoderSettings {
        encoder: Some(format!("gsi {}", env!("CARGO_PKG_VERSION"))),
        init: Some(match opts.init {
            Init::Adaptive => InitKind::Adaptive,
            Init::Random => InitKind::Random,
        }),
        iterations: Some(opts.iterations),
        seed: Some(opts.seed),
        budget: Some(match opts.budget {
            Budget::Gaussians(n) => BudgetKind::Gaussians(n as u64),
            Budget::Bpp(b) => BudgetKind::Bpp(b),
            Budget::TargetPsnr(p) => BudgetKind::TargetPsnr(p),
        }),
        loss: Some(match opts.loss {
            Loss::L2 => LossKind::L2,
            Loss::L1MsSsim { lambda } => LossKind::L1MsSsim { lambda },
        }),
        bits: Some([
            bits.position,
            bits.covariance,
            bits.color,
            bits.opacity,
            bits.angle,
        ]),
        coarse: opts.coarse.map(|c| (c.factor, c.fraction)),
        color_solve: (opts.color_solve != 10).then_some(opts.color_solve),
        solve_stored_colors: (!opts.lab().solve_stored_colors).then_some(false),
        dark_gain: (gain > 1.0).then_some(gain),
        other: Vec::new(),
    }
}

/// Fit `target` and write the file, with the optimizer steps on `device`.
///
/// On a GPU (`Fitter::use_gpu`) the whole step runs there with the L2 loss, the render
/// and backward passes with MS-SSIM; initialization, colour solves, pruning and the final
/// measurement stay on the CPU. A GPU that fails is left for the CPU, and
/// [`Encoded::fallback`] says why.
pub fn encode(
    target: &Target,
    opts: &EncodeOptions,
    device: gsi_gpu::Device<'_>,
    on_progress: &mut dyn FnMut(&Progress),
) -> Result<Encoded, Error> {
    check_target(target)?;
    let truth = target;
    let gain = if opts.lab().lift_dark {
        dark::gain(truth)
    } else {
        1.0
    };
    let brightened;
    let target = if gain > 1.0 {
        brightened = dark::brightened(truth, gain);
        &brightened
    } else {
        truth
    };
    let (w, h) = (target.width, target.height);
    let px = (w as f32) * (h as f32);
    let mut bits = opts.bits.unwrap_or_else(|| default_bits(w, h, opts.blend));
    // A dark image fitted brightened keeps its colours on one grid, as it keeps their
    // depth (below): by footprint, the small Gaussians' colours take coarser steps,
    // and stage 2 lifts whatever noise they add.
    if opts.bits.is_none() && gain > 1.0 {
        bits.color_by_footprint = false;
    }
    let per_g = bytes_per_gaussian(bits, opts.blend);
    let max_n = max_gaussians(px);
    let mut n = match opts.budget {
        Budget::Gaussians(n) => n.clamp(1, 1 << 22),
        Budget::Bpp(b) => fitting_count(b, px, per_g),
        Budget::TargetPsnr(_) => ((px / 400.0) as usize).clamp(4.min(max_n), max_n),
    };
    let mut runner = Runner {
        opts,
        lr: rates_for(&opts.lr, w, h),
        bits,
        // A dark image fitted brightened keeps its colour depth: most of its error is
        // sensor noise that the Gaussians should not follow, not texture, and stage 2
        // lifts whatever noise coarser codes add (LOL val30 through stage 2: SSIM 0.795
        // with 8 bits, 0.784 with the rule's 6 and 7, whether stage 2 stores 8 or not).
        choose_color: opts.bits.is_none() && opts.blend == Blend::Sum && gain <= 1.0,
        last_psnr: f64::NAN,
        fill: match opts.budget {
            Budget::Bpp(b) => Some(b),
            _ => None,
        },
        size: (w, h),
        stop_at: match opts.budget {
            Budget::TargetPsnr(p) => Some(f64::from(p)),
            _ => None,
        },
        psnr_offset: 20.0 * f64::from(gain).log10(),
        start: std::time::Instant::now(),
        on_progress,
        curve: Vec::new(),
    };
    let coarse = coarse_start(target, opts.coarse, n, opts.iterations);
    let first = coarse.as_ref().map_or(target, |(t, _)| t);
    let placed = |n| init::initialize(first, n, opts.init, opts.blend, opts.seed);
    let mut params = placed(n);
    if let Budget::Bpp(b) = opts.budget {
        // Method 3's cost depends on the image: measure it on the initial Gaussians, which
        // code within about 2 % of the fitted ones (1.5 % more on kodim05, 1.1 % on
        // kodim23), and place again the count that this cost fits in the budget. Measured
        // before the colour solve, which then runs once.
        let scene = Scene {
            tone: None,
            width: w,
            height: h,
            blend: opts.blend,
            cov_param: CovParam::LogScaleRotation,
            gaussians: params.clone(),
            weights: WeightRule::Columns32,
        };
        let per_g = coded_bytes_per_gaussian(&scene, bits) * 1.02;
        let fits = fitting_count(b, px, per_g);
        if fits.abs_diff(n) * 50 > n {
            n = fits;
            params = placed(n);
        }
    }
    let solve = 2 * opts.color_solve as usize;
    let mut fitter = Fitter::started(
        first, params, opts.init, opts.blend, opts.loss, opts.seed, solve,
    );
    on_device(&mut fitter, device);
    let mut fitter = match &coarse {
        None => {
            runner.run(&mut fitter, Phase::whole(opts.iterations, true));
            fitter
        }
        Some((reduced, steps)) => {
            // Coarse steps count for the share of the pixels they render.
            let step_work = f64::from(reduced.width * reduced.height) / f64::from(w * h);
            let fine = opts.iterations - steps;
            let work_all = f64::from(*steps) * step_work + f64::from(fine);
            let mut phase = Phase {
                steps: *steps,
                first: 0,
                all: opts.iterations,
                step_work,
                work_before: 0.0,
                work_all,
                qat: false,
            };
            runner.run(&mut fitter, phase);
            fitter.sync();
            let fallback = fitter.twin.take_fallback();
            let params = std::mem::take(&mut fitter.params);
            let adam = fitter.adam;
            let mut full = Fitter::with_params(target, params, opts.blend, opts.loss, opts.seed);
            // The optimizer goes on where it was, moments and all. A fresh one's first
            // steps move every parameter by its whole learning rate at once (Adam's bias
            // correction), which undid much of the coarse fit (the scale table's 12 MP
            // image: 50.0 dB at the first full-resolution step, 29.1 dB ten steps later);
            // with the state kept, 160 steps half coarse gained 0.6 dB on the validation
            // images, and a colour solve here gained nothing more (BENCHMARKS.md, the
            // coarse fit handed on whole).
            full.adam = adam;
            // A GPU the coarse steps left stays left, and the reason is kept.
            full.twin = twin::Twin::after(fallback, device);
            phase.work_before = f64::from(*steps) * step_work;
            phase.first = *steps;
            phase.steps = fine;
            phase.step_work = 1.0;
            phase.qat = true;
            runner.run(&mut full, phase);
            full
        }
    };
    let fine_steps = opts.iterations - coarse.as_ref().map_or(0, |c| c.1);
    // The passes below shrink to the budget; refilling it there would undo them.
    runner.fill = None;
    runner.choose_color = false;
    let bits = runner.bits;
    let mut result = finish(&mut fitter, bits, opts, truth, gain)?;
    // Budgets: shrink to the byte budget, or grow to the quality target.
    for _ in 0..4 {
        match opts.budget {
            Budget::Bpp(b) => {
                let bpp = result.bytes.len() as f32 * 8.0 / px;
                if bpp <= b {
                    break;
                }
                n = shrunk(fitter.params.len(), bpp, b, px).max(1);
                fitter.prune_and_grow(0.0, 0.0, n, 0);
            }
            Budget::TargetPsnr(p) => {
                if result.psnr >= f64::from(p) || fitter.params.len() >= max_n {
                    break;
                }
                n = (fitter.params.len() * 8 / 5).min(max_n);
                fitter.prune_and_grow(0.0, 0.0, usize::MAX, n);
                fitter.solve_colors(opts.color_solve as usize);
            }
            Budget::Gaussians(_) => break,
        }
        runner.run(&mut fitter, Phase::whole((fine_steps / 3).max(1), true));
        result = finish(&mut fitter, bits, opts, truth, gain)?;
    }
    // A budget the passes above missed is met by pruning alone; one that even a single
    // Gaussian exceeds is refused, not written over budget.
    while let Budget::Bpp(b) = opts.budget {
        let bpp = result.bytes.len() as f32 * 8.0 / px;
        if bpp <= b {
            break;
        }
        let n_now = fitter.params.len();
        if result.records.header.count <= 1 || n_now <= 1 {
            return Err(Error::BudgetUnreachable {
                asked_bpp: b,
                smallest_bpp: bpp,
            });
        }
        let n = shrunk(n_now, bpp, b, px).clamp(1, n_now - 1);
        fitter.prune_and_grow(0.0, 0.0, n, 0);
        result = finish(&mut fitter, bits, opts, truth, gain)?;
    }
    result.curve = runner.curve;
    result.fallback = fitter.twin.take_fallback();
    Ok(result)
}

/// Quantize, drop what the 8-bit render cannot show, write, and measure the stored PSNR.
fn finish(
    fitter: &mut Fitter,
    bits: BitDepths,
    opts: &EncodeOptions,
    t: &Target,
    gain: f32,
) -> Result<Encoded, Error> {
    fitter.canonicalize_rotations();
    let mut scene = fitter.scene();
    // A Gaussian whose whole contribution is under one 8-bit step changes nothing visible.
    let score = fitter.contributions().score;
    let keep: Vec<bool> = score.iter().map(|&s| s >= 1.0 / 255.0).collect();
    optim::retain(&mut scene.gaussians, &keep);
    if gain > 1.0 {
        for c in &mut scene.gaussians.colors {
            *c = c.map(|v| v / gain);
        }
    }
    let float = gsi_render::render::render(&scene, t.width, t.height)?;
    let float_psnr = loss::psnr8(&float.data, &t.data, t.width, t.height);
    let mut records = Records::from_scene(&scene, bits);
    // The colours each rounded alone, for a byte budget that the compensated ones miss.
    let mut plain = None;
    if opts.lab().solve_stored_colors && opts.color_solve > 0 {
        // The quantization-aware steps move colours by small steps against a geometry whose
        // codes keep changing; once the geometry is fixed, the colours that best render it
        // are one linear solve away: +0.35 dB at the default level on the validation
        // images (+0.32 dB with half the iterations), +0.13 dB at effort 1, for 2-8 % more
        // time (BENCHMARKS.md, the stored colours solved for the stored geometry).
        // Only the colours are quantized again; the geometry's codes stay as they are.
        let mut stored = records.to_scene();
        stored.gaussians.colors = std::mem::take(&mut scene.gaussians.colors);
        solve_scene_colors(&mut stored, &t.data, 2 * opts.color_solve as usize);
        let nearest = records.quantize_colors(&stored.gaussians.colors, bits.color);
        records.colors = if opts.lab().compensate_rounding {
            let steps = records.color_steps();
            let compensated = compensated_colors(&stored, &t.data, &nearest, steps.as_deref());
            if matches!(opts.budget, Budget::Bpp(_)) {
                plain = Some(Records {
                    colors: nearest,
                    ..records.clone()
                });
            }
            compensated
        } else {
            nearest
        };
    }
    let written = stored_file(records, bits, opts, t, gain, float_psnr)?;
    // Compensated codes take a few more bytes (0.07–0.2 % on average over the validation
    // sets, 0.55 % at most): where that takes a file over its budget and the colours
    // rounded alone fit it, the file keeps those, rather than losing Gaussians to the
    // budget.
    if let (Some(plain), Budget::Bpp(b)) = (plain, opts.budget) {
        let bpp = |e: &Encoded| e.bytes.len() as f32 * 8.0 / (t.width as f32 * t.height as f32);
        if bpp(&written) > b {
            let alone = stored_file(plain, bits, opts, t, gain, float_psnr)?;
            if bpp(&alone) <= b {
                return Ok(alone);
            }
        }
    }
    Ok(written)
}

/// `records` in curve order, written, with the PSNR of what they render.
fn stored_file(
    mut records: Records,
    bits: BitDepths,
    opts: &EncodeOptions,
    t: &Target,
    gain: f32,
    float_psnr: f64,
) -> Result<Encoded, Error> {
    records.sort_spatially();
    let decoded = gsi_render::render::render(&records.to_scene(), t.width, t.height)?;
    if !decoded.data.iter().all(|v| v.is_finite()) {
        return Err(Error::NonFinite(
            "the fitted Gaussians render to non-finite values",
        ));
    }
    let psnr = loss::psnr8(&decoded.data, &t.data, t.width, t.height);
    let settings = settings_of(opts, &bits, gain).to_text();
    let bytes = format::to_bytes(
        &records,
        &WriteOptions {
            psnr: Some(psnr as f32),
            settings: Some(settings),
            context_coding: true,
            ..WriteOptions::default()
        },
    )?;
    Ok(Encoded {
        records,
        bytes,
        psnr,
        float_psnr,
        curve: Vec::new(),
        fallback: None,
    })
}

/// Refuse targets that cannot be fitted: empty, mis-sized, or holding non-finite values.
fn check_target(t: &Target) -> Result<(), Error> {
    if t.width == 0 || t.height == 0 || t.data.len() != t.width as usize * t.height as usize * 3 {
        return Err(Error::InvalidTarget(format!(
            "target of {}x{} with {} values",
            t.width,
            t.height,
            t.data.len()
        )));
    }
    if !t.data.iter().all(|v| v.is_finite()) {
        return Err(Error::InvalidTarget(
            "target holds non-finite values".into(),
        ));
    }
    Ok(())
}
#[cfg(test)]
mod tests;
