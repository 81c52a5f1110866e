//! Fitting an enhancer to one image, zero-shot (paper §III-B): no reference, no
//! training data, only the no-reference losses of [`super::loss`] on the image the
//! enhanced Gaussians render.
//!
//! Everything is optimized at a reduced working size (long side
//! [`EnhanceOptions::work_side`]): the losses are statistics of brightness, colour and
//! edges, which a 256-pixel rendering estimates as well as a full-size one, and the
//! frozen-geometry render `A·c` ([`ColorOperator`]) makes each iteration cost a sparse
//! product rather than a rasterization.

use super::exposure::{meter, Exposure, Metering};
use super::features::Backbone;
use super::loss::{map_regularizers, ImageLoss, ImageTerms, LossParams, LossWeights, MapTerms};
use super::mixture::{clamp_for, tap, Enhancer, MapTap, GAIN_LOG_MAX};
use super::operator::ColorOperator;
use gsi_format::format::{EnhancerRecord, FitSettings, MAX_EXPERTS};
use gsi_format::model::Scene;
use gsi_optim::optim::FlatAdam;
use gsi_optim::rng::SplitMix64;

/// How an enhancer is fitted. The defaults are the paper's where it gives them (K = 16,
/// the loss weights) and measured choices elsewhere (E = 0.5 for a fit without a tone
/// curve, the learning rate, the sizes, 25 iterations; see BENCHMARKS.md). With the tone
/// curve ([`super::curve`]) the curve sets the exposure and [`super::enhance`] fits the
/// mixture at the image's own level, where it moves the result by little that the curve,
/// the gain map and the chroma map do not undo: 25 iterations score as 100 did on every
/// validation set (LOL `val30` 20.551 against 20.555 dB, the synthetic Kodak set 21.973
/// against 21.980, `mef13`'s median NIQE 4.412 against 4.416; the outputs 40.7 dB apart
/// at the least), and a 600×400 image is enhanced in 0.71 s instead of 2.27 (median wall
/// time of 12 `val30` files, 2-core AMD EPYC).
#[derive(Clone, Debug)]
pub struct EnhanceOptions {
    pub iterations: u32,
    /// K, operators including the identity.
    pub experts: usize,
    /// Width of the operators' two hidden layers.
    pub hidden: usize,
    /// Width of the weight-map head's hidden layer.
    pub head_hidden: usize,
    /// Long side of the working image, in pixels.
    pub work_side: u32,
    /// Side of a weight-map cell, in working pixels.
    pub cell: u32,
    /// Adam's initial step; it decays on a cosine to 1 % of this.
    pub learning_rate: f32,
    pub weights: LossWeights,
    pub params: LossParams,
    /// The mean luma the result is shown at: set by the tone curve's scale.
    pub exposure: Exposure,
    /// Denoising across neighbouring Gaussians before the mixture (`None`, the default:
    /// off; the tone curve keeps the shadows' noise down, and on LOL `val30` and the
    /// synthetic Kodak set the denoising cost 0.17 and 0.38 dB). Applied by
    /// [`super::enhance`], not by [`fit`], which fits the colours it is given.
    pub denoise: Option<super::denoise::DenoiseOptions>,
    /// Remove the Gaussians fitted to noise first ([`super::speckle`], `sum` files only;
    /// default on): on LOL `val30` and the synthetic Kodak set it removed the black dots
    /// and bright needles of flat dark surfaces for +0.05 and +0.03 dB (SSIM +0.019 and
    /// +0.007). Applied by [`super::enhance`].
    pub speckle: bool,
    /// The tone curve on the blended values and the local exposure after the mixture
    /// ([`super::curve`]; `None`: neither, and the mixture's own exposure stands).
    /// Applied by [`super::enhance`] too.
    pub curve: Option<super::curve::CurveOptions>,
    /// Enhance even an image that is not low-light ([`super::assess`]), or one enhanced
    /// before whose original colours were discarded.
    pub force: bool,
    pub seed: u64,
}

impl Default for EnhanceOptions {
    fn default() -> Self {
        EnhanceOptions {
            iterations: 25,
            experts: 16,
            hidden: 8,
            head_hidden: 16,
            work_side: 256,
            cell: 8,
            learning_rate: 1e-3,
            weights: LossWeights::default(),
            params: LossParams::default(),
            exposure: Exposure::default(),
            denoise: None,
            speckle: true,
            curve: Some(super::curve::CurveOptions::default()),
            force: false,
            seed: 0,
        }
    }
}

impl EnhanceOptions {
    /// What [`super::enhance`] refuses before it reads any colour: no iterations, a count
    /// of experts outside `1..=MAX_EXPERTS`, a learning rate that is not positive, loss
    /// weights that are negative or not finite, an exposure outside `(0, 1)`, a tone-curve
    /// exponent outside `(0, MAX_TONE_EXPONENT]`, an empty working size. The message names
    /// the field.
    pub fn check(&self) -> Result<(), String> {
        let max_experts = usize::from(MAX_EXPERTS);
        let max_tone = gsi_format::format::MAX_TONE_EXPONENT;
        if self.iterations == 0 {
            return Err("iterations must be at least 1".into());
        }
        if !(1..=max_experts).contains(&self.experts) {
            return Err(format!(
                "experts {} must be in 1..={max_experts}",
                self.experts
            ));
        }
        if !(self.learning_rate.is_finite() && self.learning_rate > 0.0) {
            return Err(format!(
                "learning rate {} must be positive",
                self.learning_rate
            ));
        }
        let w = self.weights.to_array();
        if !w.iter().all(|x| x.is_finite() && *x >= 0.0) {
            return Err(format!(
                "loss weights {w:?} must be finite and non-negative"
            ));
        }
        if let Exposure::Exactly(e) = self.exposure {
            if !(e > 0.0 && e < 1.0) {
                return Err(format!("exposure {e} must be a mean luma in (0, 1)"));
            }
        }
        if let Some(c) = &self.curve {
            if !(c.exponent > 0.0 && c.exponent <= max_tone) {
                return Err(format!(
                    "tone exponent {} must be in (0, {max_tone}]",
                    c.exponent
                ));
            }
        }
        if self.work_side == 0 || self.cell == 0 || self.hidden == 0 || self.head_hidden == 0 {
            return Err("the working size, cell and hidden widths must be at least 1".into());
        }
        Ok(())
    }
}

/// Reported every iteration.
#[derive(Clone, Copy, Debug)]
pub struct Progress {
    pub iteration: u32,
    pub iterations: u32,
    pub terms: ImageTerms,
    pub map: MapTerms,
}

/// A fitted enhancer and what it did.
#[derive(Clone, Debug)]
pub struct Fitted {
    /// The stored (quantized) enhancer.
    pub record: EnhancerRecord,
    /// [`Enhancer::from_record`] of `record`: the one whose output was kept.
    pub enhancer: Enhancer,
    /// The enhanced colour of every Gaussian (after the tone curve, where
    /// [`super::enhance`] applied one).
    pub colors: Vec<[f32; 3]>,
    /// Loss terms of the mixture's colours, before any tone curve (which keeps their
    /// mean luma).
    pub terms: ImageTerms,
    /// Mean luma of the working image before and after.
    pub mean_luma: (f32, f32),
    /// Why the fit left the GPU it was given for the CPU, if it did.
    pub fallback: Option<String>,
    /// Why the colours were neither denoised nor toned though the options asked for it,
    /// if they were not (set by [`super::enhance`]).
    pub denoise_skipped: Option<String>,
}

pub use super::working::{mean_luma, work_size, working_image};

/// [`meter`] of `scene` rendered at the working size: its own mean luma and the exposure
/// it would have if well exposed.
pub fn scene_metering(scene: &Scene, work_side: u32) -> Metering {
    meter(&working_image(scene, work_side))
}

/// The trainable numbers, as one flat vector so one optimizer serves them all:
/// head `W1 (Hh×D), b1, W2 (K×Hh), b2`, then the operators' parameters.
struct Layout {
    dim: usize,
    head_hidden: usize,
    experts: usize,
    hidden: usize,
}

impl Layout {
    fn head_len(&self) -> usize {
        self.head_hidden * self.dim
            + self.head_hidden
            + self.experts * self.head_hidden
            + self.experts
    }
    fn ops_len(&self) -> usize {
        (self.experts - 1) * Enhancer::params_per_operator(self.hidden)
    }
}

/// Gaussians per parallel work item. Fixed, so that gradients are summed in the same
/// order whatever the thread count and the fit is reproducible from its seed.
const CHUNK: usize = 512;

/// Fit an enhancer to `scene` and return it with the colours it produces, with the
/// mixture (weights and operators, forward and backward) on `device`. Where the GPU
/// cannot hold the mixture, or fails later, the fit goes on on the CPU and
/// [`Fitted::fallback`] says why.
///
/// # Panics
/// If `opts.experts` is 0 or above 64, or `opts.hidden`/`head_hidden` is 0 or above 64.
pub fn fit(
    scene: &Scene,
    opts: &EnhanceOptions,
    backbone: &dyn Backbone,
    device: gsi_gpu::Device<'_>,
    progress: &mut dyn FnMut(&Progress),
) -> Fitted {
    let mut session = Session::new(scene, opts, backbone);
    session.on_device(device);
    for _ in 0..opts.iterations {
        progress(&session.step());
    }
    session.finish()
}

/// One fit in progress: everything that depends only on the frozen scene (the render
/// matrix, the features, the low image's loss statistics) is built once by
/// [`Session::new`], and each [`Session::step`] is one Adam iteration.
pub struct Session<'a> {
    scene: &'a Scene,
    opts: EnhanceOptions,
    a: ColorOperator,
    low: Vec<f32>,
    feats: Vec<f32>,
    loss: ImageLoss,
    taps: Vec<MapTap>,
    lay: Layout,
    theta: Vec<f32>,
    adam: FlatAdam,
    enh: Enhancer,
    iteration: u32,
    // Buffers reused by every step.
    grad: Vec<f32>,
    head_act: Vec<f32>,
    colors: Vec<[f32; 3]>,
    /// The render, and the render as a display shows it (clamped).
    img: Vec<f32>,
    shown: Vec<f32>,
    g_img: Vec<f32>,
    g_col: Vec<[f32; 3]>,
    g_map: Vec<f32>,
    /// The forward pass's activations, per chunk of Gaussians, for the backward pass to
    /// reuse; `None` where they would take more than [`TRACE_BYTES_MAX`].
    traces: Option<Vec<Trace>>,
    /// Why the session left its GPU for the CPU, once it has.
    fallback: Option<String>,
    /// Where the mixture runs: the CPU, or its GPU twin ([`Session::use_gpu`]).
    twin: super::twin::Twin<'a>,
}

impl<'a> Session<'a> {
    /// # Panics
    /// See [`fit`].
    pub fn new(scene: &'a Scene, opts: &EnhanceOptions, backbone: &dyn Backbone) -> Session<'a> {
        assert!(
            (1..=usize::from(MAX_EXPERTS)).contains(&opts.experts),
            "K out of range"
        );
        assert!((1..=64).contains(&opts.hidden) && (1..=64).contains(&opts.head_hidden));
        let (ww, wh) = work_size(scene.width, scene.height, opts.work_side);
        let a = ColorOperator::new(scene, ww, wh);
        let c0 = &scene.gaussians.colors;
        let n = c0.len();
        let mut low = vec![0.0f32; (ww * wh * 3) as usize];
        a.render(c0, &mut low);
        for x in &mut low {
            *x = x.clamp(0.0, 1.0);
        }
        let cell = opts.cell.max(1);
        let (mw, mh) = (ww.div_ceil(cell) as usize, wh.div_ceil(cell) as usize);
        let cells = mw * mh;
        let feats = backbone.extract(&low, ww as usize, wh as usize, mw, mh);
        let loss = ImageLoss::new(&low, ww as usize, wh as usize, opts.weights, opts.params);
        let taps = scene
            .gaussians
            .positions
            .iter()
            .map(|&p| tap(mw, mh, p))
            .collect();
        let lay = Layout {
            dim: backbone.dim(),
            head_hidden: opts.head_hidden,
            experts: opts.experts,
            hidden: opts.hidden,
        };
        let theta = init(&lay, opts.seed);
        Session {
            scene,
            opts: opts.clone(),
            grad: vec![0.0; theta.len()],
            adam: FlatAdam::new(theta.len()),
            enh: Enhancer {
                experts: opts.experts,
                hidden: opts.hidden,
                clamp: clamp_for(scene.blend),
                map_width: mw,
                map_height: mh,
                map: vec![0.0; cells * opts.experts],
                params: Vec::new(),
            },
            head_act: vec![0.0; cells * opts.head_hidden],
            colors: vec![[0.0; 3]; n],
            img: vec![0.0; low.len()],
            shown: vec![0.0; low.len()],
            g_img: vec![0.0; low.len()],
            g_col: vec![[0.0; 3]; n],
            g_map: vec![0.0; cells * opts.experts],
            traces: Trace::for_chunks(n, opts.experts, opts.hidden),
            fallback: None,
            twin: super::twin::Twin::cpu(),
            a,
            low,
            feats,
            loss,
            taps,
            lay,
            theta,
            iteration: 0,
        }
    }

    /// Bring `self.enh` up to date with `theta`: the head's weight map and the operators.
    fn refresh_enhancer(&mut self) {
        let lay = &self.lay;
        head_forward(
            lay,
            &self.theta,
            &self.feats,
            &mut self.head_act,
            &mut self.enh.map,
        );
        self.enh.params.clear();
        self.enh
            .params
            .extend_from_slice(&self.theta[lay.head_len()..]);
    }

    /// The total loss at the current parameters, with its gradient left in `self.grad`.
    fn loss_and_grad(&mut self) -> (ImageTerms, MapTerms) {
        self.refresh_enhancer();
        let c0 = &self.scene.gaussians.colors;
        if !self.mix_forward_on_gpu() {
            mix_forward(
                &self.enh,
                &self.taps,
                c0,
                &mut self.colors,
                self.traces.as_deref_mut(),
            );
        }
        self.a.render(&self.colors, &mut self.img);
        let terms = self
            .loss
            .eval_display(&self.img, &mut self.shown, &mut self.g_img);
        self.a.transpose(&self.g_img, &mut self.g_col);
        self.grad.fill(0.0);
        self.g_map.fill(0.0);
        if !self.mix_backward_on_gpu() {
            mix_backward(
                &self.enh,
                &self.taps,
                c0,
                &self.g_col,
                self.traces.as_deref(),
                &mut self.g_map,
                &mut self.grad[self.lay.head_len()..],
            );
        }
        let lay = &self.lay;
        let (mw, mh) = (self.enh.map_width, self.enh.map_height);
        let map_terms = map_regularizers(
            &self.enh.map,
            mw,
            mh,
            self.opts.experts,
            &self.opts.weights,
            &mut self.g_map,
        );
        head_backward(
            lay,
            &self.theta,
            &self.feats,
            &self.head_act,
            &self.g_map,
            &mut self.grad,
        );
        (terms, map_terms)
    }

    /// Run the mixture on `device` (see [`Session::use_gpu`]); a device this build has
    /// no twin for, or one that cannot hold the mixture, leaves it on the CPU, the latter
    /// with the reason in [`Fitted::fallback`].
    pub fn on_device(&mut self, device: gsi_gpu::Device<'a>) {
        let c0 = &self.scene.gaussians.colors;
        match self.twin.open(device, &self.enh, CHUNK, &self.taps, c0) {
            // The GPU keeps its own trace; the CPU's comes back if the GPU fails.
            Ok(true) => self.traces = None,
            Ok(false) => {}
            Err(e) => self.fallback = Some(format!("enhancement runs on the CPU: {e}")),
        }
    }

    /// Run the mixture (every Gaussian's mixing weights and operators, forward and
    /// backward: most of an iteration) on `gpu`; the render, the loss and the head stay
    /// on the CPU. Fails, leaving the session on the CPU, when the adapter cannot hold
    /// it. Should the GPU fail later, the session says so once and goes on on the CPU.
    #[cfg(feature = "gpu")]
    pub fn use_gpu(&mut self, gpu: &'a gsi_gpu::gpu::Gpu) -> Result<(), String> {
        let c0 = &self.scene.gaussians.colors;
        self.twin.open_on(gpu, &self.enh, CHUNK, &self.taps, c0)?;
        self.traces = None;
        Ok(())
    }

    /// [`mix_forward`] on the GPU; false where there is none, or it failed.
    fn mix_forward_on_gpu(&mut self) -> bool {
        match self.twin.forward(&self.enh, &mut self.colors) {
            Ok(ran) => ran,
            Err(e) => {
                self.gpu_failed(&e);
                false
            }
        }
    }

    /// [`mix_backward`] on the GPU; false where there is none, or it failed (in which
    /// case the CPU's forward pass runs again, for the activations it needs).
    fn mix_backward_on_gpu(&mut self) -> bool {
        let head = self.lay.head_len();
        let ran = self.twin.backward(
            &self.g_col,
            &self.taps,
            &mut self.g_map,
            &mut self.grad[head..],
        );
        match ran {
            Ok(ran) => ran,
            Err(e) => {
                self.gpu_failed(&e);
                self.g_map.fill(0.0);
                self.grad.fill(0.0);
                mix_forward(
                    &self.enh,
                    &self.taps,
                    &self.scene.gaussians.colors,
                    &mut self.colors,
                    self.traces.as_deref_mut(),
                );
                false
            }
        }
    }

    fn gpu_failed(&mut self, e: &str) {
        self.fallback
            .get_or_insert_with(|| format!("enhancement continues on the CPU: {e}"));
        let n = self.scene.gaussians.len();
        self.traces = Trace::for_chunks(n, self.opts.experts, self.opts.hidden);
    }

    /// One Adam iteration, the step size following a cosine from the learning rate to
    /// 1 % of it over `opts.iterations`.
    pub fn step(&mut self) -> Progress {
        let (terms, map) = self.loss_and_grad();
        let iterations = self.opts.iterations.max(1);
        let t = (self.iteration as f32 / iterations as f32).min(1.0);
        let lr = self.opts.learning_rate * gsi_optim::optim::cosine_decay(t, 0.01);
        self.adam.update(&mut self.theta, &self.grad, lr);
        self.iteration += 1;
        Progress {
            iteration: self.iteration,
            iterations: self.opts.iterations,
            terms,
            map,
        }
    }

    /// Quantize the enhancer as it will be stored and apply that one to every colour.
    pub fn finish(mut self) -> Fitted {
        self.refresh_enhancer();
        let (o, w) = (&self.opts, &self.opts.weights);
        let fit = FitSettings {
            weights: w.to_array(),
            exposure: o.params.exposure_target,
            saturation_tau: o.params.saturation_tau,
            contrast_gamma: o.params.contrast_gamma,
            iterations: self.iteration,
            seed: o.seed,
        };
        let record = self.enh.to_record(fit);
        let enhancer = Enhancer::from_record(&record);
        let g = &self.scene.gaussians;
        let colors = enhancer.apply(&g.positions, &g.colors);
        self.a.render(&colors, &mut self.img);
        let terms = self
            .loss
            .eval_display(&self.img, &mut self.shown, &mut self.g_img);
        Fitted {
            record,
            enhancer,
            colors,
            terms,
            mean_luma: (mean_luma(&self.low), mean_luma(&self.shown)),
            fallback: self.fallback.take(),
            denoise_skipped: None,
        }
    }
}

/// Initial parameters: He-style uniform for the hidden layers, small positive hidden
/// biases (dark colours are tiny inputs; the ReLUs must start open for any gradient to
/// reach the first layers), a zero head output (equal mixing weights everywhere), and
/// zero last layers for the operators, so that every operator starts as the
/// identity (paper Eq. 14).
fn init(lay: &Layout, seed: u64) -> Vec<f32> {
    let mut rng = SplitMix64::new(seed ^ 0x6a09_e667_f3bc_c908);
    let mut out = Vec::with_capacity(lay.head_len() + lay.ops_len());
    let mut uniform = |n: usize, fan_in: usize, out: &mut Vec<f32>| {
        let a = (6.0 / fan_in.max(1) as f32).sqrt();
        out.extend((0..n).map(|_| rng.range(-a, a)));
    };
    let (d, hh, k, h) = (lay.dim, lay.head_hidden, lay.experts, lay.hidden);
    uniform(hh * d, d, &mut out);
    out.extend(std::iter::repeat_n(0.1, hh));
    // The head's output starts at 0: equal weights everywhere, so that the map varies
    // only where the fit moves it (a random start left a random map, 14 kB stored).
    out.extend(std::iter::repeat_n(0.0, k * hh));
    out.extend(std::iter::repeat_n(0.0, k));
    let mut rng2 = SplitMix64::new(seed ^ 0xbb67_ae85_84ca_a73b);
    for _ in 1..k {
        let a1 = (6.0f32 / 3.0).sqrt();
        out.extend((0..3 * h).map(|_| rng2.range(-a1, a1)));
        out.extend((0..h).map(|_| rng2.range(0.0, 0.5)));
        let a2 = (6.0 / h as f32).sqrt();
        out.extend((0..h * h).map(|_| rng2.range(-a2, a2)));
        out.extend((0..h).map(|_| rng2.range(0.0, 0.5)));
        out.extend(std::iter::repeat_n(0.0, h + 1));
    }
    out
}

/// `map = W2·relu(W1·f + b1) + b2` per cell; `act` keeps the pre-activations.
fn head_forward(lay: &Layout, theta: &[f32], feats: &[f32], act: &mut [f32], map: &mut [f32]) {
    let (d, hh, k) = (lay.dim, lay.head_hidden, lay.experts);
    let (w1, rest) = theta.split_at(hh * d);
    let (b1, rest) = rest.split_at(hh);
    let (w2, rest) = rest.split_at(k * hh);
    let b2 = &rest[..k];
    for ((f, a), m) in feats
        .chunks_exact(d)
        .zip(act.chunks_exact_mut(hh))
        .zip(map.chunks_exact_mut(k))
    {
        for j in 0..hh {
            a[j] = b1[j]
                + w1[j * d..][..d]
                    .iter()
                    .zip(f)
                    .map(|(w, x)| w * x)
                    .sum::<f32>();
        }
        for (o, m) in m.iter_mut().enumerate() {
            *m = b2[o]
                + w2[o * hh..][..hh]
                    .iter()
                    .zip(&*a)
                    .map(|(w, x)| w * x.max(0.0))
                    .sum::<f32>();
        }
    }
}

/// Gradients of the head parameters (written into `grad[..head_len]`) from `g_map`.
fn head_backward(
    lay: &Layout,
    theta: &[f32],
    feats: &[f32],
    act: &[f32],
    g_map: &[f32],
    grad: &mut [f32],
) {
    let (d, hh, k) = (lay.dim, lay.head_hidden, lay.experts);
    let w2 = &theta[hh * d + hh..][..k * hh];
    let (gw1, rest) = grad.split_at_mut(hh * d);
    let (gb1, rest) = rest.split_at_mut(hh);
    let (gw2, rest) = rest.split_at_mut(k * hh);
    let gb2 = &mut rest[..k];
    let mut g_act = vec![0.0f32; hh];
    for ((f, a), gm) in feats
        .chunks_exact(d)
        .zip(act.chunks_exact(hh))
        .zip(g_map.chunks_exact(k))
    {
        g_act.fill(0.0);
        for (o, &g) in gm.iter().enumerate() {
            if g == 0.0 {
                continue;
            }
            gb2[o] += g;
            for j in 0..hh {
                gw2[o * hh + j] += g * a[j].max(0.0);
                g_act[j] += g * w2[o * hh + j];
            }
        }
        for j in 0..hh {
            if a[j] <= 0.0 || g_act[j] == 0.0 {
                continue;
            }
            gb1[j] += g_act[j];
            for (gw, x) in gw1[j * d..][..d].iter_mut().zip(f) {
                *gw += g_act[j] * x;
            }
        }
    }
}

/// A chunk of Gaussians' colours (or colour gradients).
type Colors<'a> = &'a [[f32; 3]];

/// Most memory the forward activations kept for the backward pass may take: with the
/// defaults (K = 16, hidden width 8) 1204 bytes per Gaussian, so about 890k Gaussians;
/// beyond it the backward pass evaluates the operators again.
const TRACE_BYTES_MAX: usize = 1 << 30;

/// A chunk of Gaussians' forward activations: the mixture weights (K each), and per
/// operator the two hidden pre-activations (hidden width each) and the unclamped output.
/// Profiling showed the operators' evaluation to be the largest cost of an iteration,
/// and without this the backward pass would evaluate them a second time.
struct Trace {
    w: Vec<f32>,
    h1: Vec<f32>,
    h2: Vec<f32>,
    raw: Vec<[f32; 3]>,
}

impl Trace {
    /// One trace per [`CHUNK`] of `n` Gaussians, or `None` over [`TRACE_BYTES_MAX`].
    fn for_chunks(n: usize, experts: usize, hidden: usize) -> Option<Vec<Trace>> {
        let ops = experts.saturating_sub(1);
        let per = experts + ops * (2 * hidden + 3);
        if n.checked_mul(per * 4)? > TRACE_BYTES_MAX {
            return None;
        }
        let chunks = (0..n).step_by(CHUNK).map(|start| (n - start).min(CHUNK));
        Some(
            chunks
                .map(|len| Trace {
                    w: vec![0.0; len * experts],
                    h1: vec![0.0; len * ops * hidden],
                    h2: vec![0.0; len * ops * hidden],
                    raw: vec![[0.0; 3]; len * ops],
                })
                .collect(),
        )
    }
}

/// Every Gaussian's mixed colour (paper Eq. 15) with the current parameters, recording
/// the activations into `traces` when given.
fn mix_forward(
    enh: &Enhancer,
    taps: &[MapTap],
    c0: &[[f32; 3]],
    out: &mut [[f32; 3]],
    traces: Option<&mut [Trace]>,
) {
    let job = |(o, (t, c)): (&mut [[f32; 3]], (&[MapTap], Colors)),
               mut trace: Option<&mut Trace>| {
        let mut s = MixScratch::new(enh);
        for (g, (o, (t, c))) in o.iter_mut().zip(t.iter().zip(c)).enumerate() {
            *o = s.mix(enh, t, *c);
            if let Some(tr) = trace.as_deref_mut() {
                s.record(enh, g, tr);
            }
        }
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        let chunks = out
            .par_chunks_mut(CHUNK)
            .zip(taps.par_chunks(CHUNK).zip(c0.par_chunks(CHUNK)));
        match traces {
            Some(tr) => chunks
                .zip(tr.par_iter_mut())
                .for_each(|(item, trace)| job(item, Some(trace))),
            None => chunks.for_each(|item| job(item, None)),
        }
    }
    #[cfg(not(feature = "parallel"))]
    {
        let mut traces = traces.map(|t| t.iter_mut());
        for item in out
            .chunks_mut(CHUNK)
            .zip(taps.chunks(CHUNK).zip(c0.chunks(CHUNK)))
        {
            job(item, traces.as_mut().and_then(|t| t.next()));
        }
    }
}

/// Gradients of the operators' parameters (added to `g_params`) and of the map logits
/// (added to `g_map`) from the gradients `g_col` of the mixed colours, with the
/// activations [`mix_forward`] recorded in `traces` (or evaluated again without them).
fn mix_backward(
    enh: &Enhancer,
    taps: &[MapTap],
    c0: &[[f32; 3]],
    g_col: &[[f32; 3]],
    traces: Option<&[Trace]>,
    g_map: &mut [f32],
    g_params: &mut [f32],
) {
    let (map_len, params_len) = (g_map.len(), g_params.len());
    let job = |(i, (t, (c, g))): (usize, (&[MapTap], (Colors, Colors)))| {
        let trace = traces.map(|tr| &tr[i]);
        let mut s = MixScratch::new(enh);
        let mut gm = vec![0.0f32; map_len];
        let mut gp = vec![0.0f32; params_len];
        for (k, (t, (c, g))) in t.iter().zip(c.iter().zip(g)).enumerate() {
            s.backward(enh, t, *c, *g, trace.map(|tr| (tr, k)), &mut gm, &mut gp);
        }
        (gm, gp)
    };
    let add = |(gm, gp): (Vec<f32>, Vec<f32>), g_map: &mut [f32], g_params: &mut [f32]| {
        g_map.iter_mut().zip(gm).for_each(|(a, b)| *a += b);
        g_params.iter_mut().zip(gp).for_each(|(a, b)| *a += b);
    };
    #[cfg(feature = "parallel")]
    {
        use rayon::prelude::*;
        let parts: Vec<_> = taps
            .par_chunks(CHUNK)
            .zip(c0.par_chunks(CHUNK).zip(g_col.par_chunks(CHUNK)))
            .enumerate()
            .map(job)
            .collect();
        for p in parts {
            add(p, g_map, g_params);
        }
    }
    #[cfg(not(feature = "parallel"))]
    for p in taps
        .chunks(CHUNK)
        .zip(c0.chunks(CHUNK).zip(g_col.chunks(CHUNK)))
        .enumerate()
    {
        add(job(p), g_map, g_params);
    }
}

/// Buffers for one Gaussian's forward and backward pass through the mixture.
struct MixScratch {
    w: Vec<f32>,
    h1: Vec<f32>,
    h2: Vec<f32>,
    /// Per operator, the pre-activations and unclamped output of the last [`MixScratch::mix`].
    h1s: Vec<f32>,
    h2s: Vec<f32>,
    raws: Vec<[f32; 3]>,
    g_w: Vec<f32>,
    g1: Vec<f32>,
    g2: Vec<f32>,
}

impl MixScratch {
    fn new(e: &Enhancer) -> Self {
        let ops = e.experts - 1;
        MixScratch {
            w: vec![0.0; e.experts],
            h1: vec![0.0; e.hidden],
            h2: vec![0.0; e.hidden],
            h1s: vec![0.0; ops * e.hidden],
            h2s: vec![0.0; ops * e.hidden],
            raws: vec![[0.0; 3]; ops],
            g_w: vec![0.0; e.experts],
            g1: vec![0.0; e.hidden],
            g2: vec![0.0; e.hidden],
        }
    }

    fn mix(&mut self, e: &Enhancer, t: &MapTap, c: [f32; 3]) -> [f32; 3] {
        let h = e.hidden;
        e.weights_at(t, &mut self.w);
        let mut out = c.map(|x| x * self.w[0]);
        for op in 1..e.experts {
            let (h1, h2) = (
                &mut self.h1s[(op - 1) * h..][..h],
                &mut self.h2s[(op - 1) * h..][..h],
            );
            let (y, raw) = e.operator(op, c, h1, h2);
            self.raws[op - 1] = raw;
            for (o, y) in out.iter_mut().zip(y) {
                *o += self.w[op] * y;
            }
        }
        out
    }

    /// Copy the activations of the last [`MixScratch::mix`] into Gaussian `g` of `trace`.
    fn record(&self, e: &Enhancer, g: usize, trace: &mut Trace) {
        let (k, ops) = (e.experts, e.experts - 1);
        let hs = ops * e.hidden;
        trace.w[g * k..][..k].copy_from_slice(&self.w);
        trace.h1[g * hs..][..hs].copy_from_slice(&self.h1s);
        trace.h2[g * hs..][..hs].copy_from_slice(&self.h2s);
        trace.raw[g * ops..][..ops].copy_from_slice(&self.raws);
    }

    /// Add one Gaussian's gradients; `trace`, when given, holds its activations
    /// (Gaussian `.1` of the chunk's trace `.0`).
    #[allow(clippy::too_many_arguments)]
    fn backward(
        &mut self,
        e: &Enhancer,
        t: &MapTap,
        c: [f32; 3],
        g: [f32; 3],
        trace: Option<(&Trace, usize)>,
        g_map: &mut [f32],
        g_params: &mut [f32],
    ) {
        if g == [0.0; 3] {
            return;
        }
        let (k, h) = (e.experts, e.hidden);
        let ops = k - 1;
        let per = Enhancer::params_per_operator(h);
        match trace {
            Some((tr, i)) => self.w.copy_from_slice(&tr.w[i * k..][..k]),
            None => e.weights_at(t, &mut self.w),
        }
        let [lo, hi] = e.clamp;
        self.g_w[0] = dot(g, c);
        for op in 1..k {
            let raw = match trace {
                Some((tr, i)) => {
                    let at = (i * ops + op - 1) * h;
                    self.h1.copy_from_slice(&tr.h1[at..][..h]);
                    self.h2.copy_from_slice(&tr.h2[at..][..h]);
                    tr.raw[i * ops + op - 1]
                }
                None => e.operator(op, c, &mut self.h1, &mut self.h2).1,
            };
            // The operator's output, as `Enhancer::operator` clamps it.
            let y = raw.map(|x| x.max(lo).min(hi));
            self.g_w[op] = dot(g, y);
            // d out / d η = w·c·exp(η) = w·raw where no clamp is active.
            let gy: [f32; 3] = std::array::from_fn(|o| {
                if raw[o] > lo && raw[o] < hi && eta_free(raw[o], c[o]) {
                    self.w[op] * g[o] * raw[o]
                } else {
                    0.0
                }
            });
            if gy == [0.0; 3] {
                continue;
            }
            // All three channels share one log-gain η.
            let g_eta: f32 = gy.iter().sum();
            let p = &e.params[(op - 1) * per..][..per];
            let gp = &mut g_params[(op - 1) * per..][..per];
            let (w2, w3) = (&p[4 * h..4 * h + h * h], &p[5 * h + h * h..6 * h + h * h]);
            let (gw1, gr) = gp.split_at_mut(3 * h);
            let (gb1, gr) = gr.split_at_mut(h);
            let (gw2, gr) = gr.split_at_mut(h * h);
            let (gb2, gr) = gr.split_at_mut(h);
            let (gw3, gb3) = gr.split_at_mut(h);
            // Branch-free, so that the loops over the hidden units vectorize: an
            // inactive unit contributes an exact 0 rather than being skipped, which sums
            // to the same bits while the activations are finite.
            gb3[0] += g_eta;
            for j in 0..h {
                let a = self.h2[j];
                gw3[j] += g_eta * a.max(0.0);
                self.g2[j] = if a > 0.0 { g_eta * w3[j] } else { 0.0 };
            }
            // g1 = W2ᵀ g2, accumulated over j in order for every l at once.
            self.g1.fill(0.0);
            for j in 0..h {
                let gj = self.g2[j];
                for (g1, w) in self.g1.iter_mut().zip(&w2[j * h..][..h]) {
                    *g1 += gj * w;
                }
            }
            for l in 0..h {
                let g1 = if self.h1[l] > 0.0 { self.g1[l] } else { 0.0 };
                gb1[l] += g1;
                for (ci, cv) in c.iter().enumerate() {
                    gw1[l * 3 + ci] += g1 * cv;
                }
            }
            for j in 0..h {
                let gj = self.g2[j];
                gb2[j] += gj;
                for (gw, a) in gw2[j * h..][..h].iter_mut().zip(&self.h1) {
                    *gw += gj * a.max(0.0);
                }
            }
        }
        // Softmax: d/d logit_k = w_k (g_w_k − Σ_j w_j g_w_j); then the bilinear tap.
        let s: f32 = self.w.iter().zip(&self.g_w).map(|(w, g)| w * g).sum();
        for (cell, b) in t.cells.iter().zip(t.weights) {
            if b == 0.0 {
                continue;
            }
            let gm = &mut g_map[*cell as usize * k..][..k];
            for ((gm, w), gw) in gm.iter_mut().zip(&self.w).zip(&self.g_w) {
                *gm += b * w * (gw - s);
            }
        }
    }
}

/// Whether the log-gain clamp at [`GAIN_LOG_MAX`] is inactive for `raw = c·exp(η)`.
fn eta_free(raw: f32, c: f32) -> bool {
    raw.abs() < c.abs() * GAIN_LOG_MAX.exp()
}

fn dot(a: [f32; 3], b: [f32; 3]) -> f32 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::Blend;
    use gsi_synth::{random_scene, SceneSpec};

    /// The backward pass from the recorded activations equals the one that evaluates the
    /// operators again (what sets past [`TRACE_BYTES_MAX`] use), bit for bit.
    #[test]
    fn traced_and_recomputed_gradients_agree() {
        let scene = random_scene(6, SceneSpec::new(60, 40, 1300, Blend::Sum));
        let opts = EnhanceOptions::default();
        let bank = super::super::features::FeatureBank;
        let mut session = Session::new(&scene, &opts, &bank);
        let mut rng = SplitMix64::new(9);
        for t in session.theta.iter_mut() {
            *t += rng.range(-0.2, 0.2);
        }
        assert!(session.traces.as_ref().is_some_and(|t| t.len() == 3));
        session.loss_and_grad();
        let traced = session.grad.clone();
        session.traces = None;
        session.loss_and_grad();
        assert_eq!(traced, session.grad);
        assert!(traced.iter().any(|g| *g != 0.0));
    }

    /// The mixture on the GPU gives the CPU's colours and gradients (to the rounding of
    /// `exp`), and a few iterations later the same loss, both blend modes.
    #[cfg(feature = "gpu")]
    #[test]
    fn the_gpu_mixture_matches_the_cpu() {
        let Some(gpu) = gsi_gpu::gpu::tests::gpu() else {
            return;
        };
        let rel = |a: &[f32], b: &[f32]| {
            let d: f64 = a.iter().zip(b).map(|(x, y)| f64::from(x - y).powi(2)).sum();
            let n: f64 = a.iter().map(|x| f64::from(*x).powi(2)).sum();
            (d / n.max(1e-30)).sqrt()
        };
        // The defaults in both blend modes, then the extremes of K and the hidden width
        // (the shaders' private arrays hold 64).
        let cases = [
            (Blend::Sum, 16, 8, 1300),
            (Blend::Alpha, 16, 8, 1300),
            (Blend::Sum, 1, 8, 300),
            (Blend::Alpha, 2, 1, 300),
            (Blend::Sum, 64, 8, 40),
            (Blend::Sum, 4, 64, 40),
            (Blend::Sum, 64, 64, 40),
        ];
        for (blend, experts, hidden, n) in cases {
            let mut scene = random_scene(8, SceneSpec::new(70, 50, n, blend));
            for c in &mut scene.gaussians.colors {
                *c = c.map(|x| x * 0.3);
            }
            let opts = EnhanceOptions {
                iterations: 15,
                experts,
                hidden,
                ..EnhanceOptions::default()
            };
            let bank = super::super::features::FeatureBank;
            let mut cpu = Session::new(&scene, &opts, &bank);
            let mut rng = SplitMix64::new(3);
            for t in cpu.theta.iter_mut() {
                *t += rng.range(-0.2, 0.2);
            }
            let mut on_gpu = Session::new(&scene, &opts, &bank);
            on_gpu.theta.clone_from(&cpu.theta);
            on_gpu.use_gpu(&gpu).unwrap();
            cpu.loss_and_grad();
            on_gpu.loss_and_grad();
            let flat = |c: &[[f32; 3]]| c.iter().flatten().copied().collect::<Vec<f32>>();
            let head = cpu.lay.head_len();
            let mut errors = vec![
                ("colours", rel(&flat(&cpu.colors), &flat(&on_gpu.colors))),
                ("map", rel(&cpu.g_map, &on_gpu.g_map)),
                ("head", rel(&cpu.grad[..head], &on_gpu.grad[..head])),
            ];
            if experts > 1 {
                errors.push(("operators", rel(&cpu.grad[head..], &on_gpu.grad[head..])));
            }
            // Sums over 1300 Gaussians in the GPU's order and through its `exp`: a few
            // 1e-5 relative, up to about 1.2e-4 for the operators' gradients.
            for (name, e) in errors {
                assert!(
                    e <= 2e-4,
                    "{blend:?} K {experts} h {hidden} {name}: relative error {e}"
                );
            }
            let (mut a, mut b) = (0.0, 0.0);
            for _ in 0..opts.iterations {
                a = cpu.step().terms.total;
                b = on_gpu.step().terms.total;
            }
            assert!(on_gpu.twin.is_gpu(), "the GPU failed");
            assert!(
                ((a - b) / a).abs() < 1e-3,
                "{blend:?} K {experts} after {} iterations: {a} vs {b}",
                opts.iterations
            );
        }
    }

    /// The whole chain (head, softmax, bilinear taps, operators, clamps, `A`, losses)
    /// against central differences of the total loss.
    #[test]
    fn chain_gradient_matches_finite_differences() {
        let only = |k: usize| {
            let mut w = [0.0f32; 7];
            w[k] = 1.0;
            LossWeights::from_array(w)
        };
        let cases = (0..7).map(|k| (Blend::Sum, only(k))).chain([
            (Blend::Sum, LossWeights::default()),
            (Blend::Alpha, LossWeights::default()),
        ]);
        for (blend, weights) in cases {
            let mut scene = random_scene(5, SceneSpec::new(40, 30, 80, blend));
            for c in &mut scene.gaussians.colors {
                *c = c.map(|x| x * 0.3);
            }
            let opts = EnhanceOptions {
                experts: 4,
                hidden: 3,
                head_hidden: 5,
                cell: 10,
                weights,
                // Large enough that the contrast term's hinge is active.
                params: LossParams {
                    contrast_gamma: 3.0,
                    ..LossParams::default()
                },
                ..EnhanceOptions::default()
            };
            let bank = super::super::features::FeatureBank;
            let mut session = Session::new(&scene, &opts, &bank);
            let theta = session.theta.clone();
            // The total loss of `theta`, with its gradient.
            let mut eval = |theta: &[f32]| {
                session.theta.copy_from_slice(theta);
                let (t, m) = session.loss_and_grad();
                let w = &opts.weights;
                let total =
                    f64::from(t.total) + f64::from(w.tv * m.tv) + f64::from(w.entropy * m.entropy);
                (total, session.grad.clone())
            };
            // Move well off the identity start: there every |difference| of the hue
            // and spatial terms sits at its kink, where differences are meaningless.
            let mut rng = SplitMix64::new(4);
            // The head's output starts at 0, so it needs the larger push to pass gradient
            // back to the head's first layer.
            let theta: Vec<f32> = theta.iter().map(|t| t + rng.range(-0.1, 0.1)).collect();
            let (l0, grad) = eval(&theta);
            // Rounding of an f32 render limits the differences to about 1e-4 of the loss.
            let noise = 1e-4 * l0.abs().max(1.0);
            let mut checked = 0;
            for _ in 0..150 {
                let i = (rng.next_u64() % theta.len() as u64) as usize;
                // Kinks (argmax switches of the hue, |·| of the spatial term, clamps)
                // lie near some parameters: a difference straddling one is off, so
                // accept the best of three step sizes.
                let an = f64::from(grad[i]);
                let fds: Vec<f64> = [1e-3f32, 3e-4, 1e-4]
                    .iter()
                    .map(|&h| {
                        let mut tp = theta.clone();
                        tp[i] += h;
                        let lp = eval(&tp).0;
                        tp[i] -= 2.0 * h;
                        let lm = eval(&tp).0;
                        (lp - lm) / (2.0 * f64::from(h))
                    })
                    .collect();
                let fd = *fds
                    .iter()
                    .min_by(|a, b| (*a - an).abs().total_cmp(&(*b - an).abs()))
                    .expect("three");
                if fd.abs().max(an.abs()) < noise {
                    continue;
                }
                checked += 1;
                assert!(
                    (fd - an).abs() <= 0.02 * fd.abs().max(an.abs()) + noise,
                    "{blend:?} {weights:?} param {i}: fd {fds:?} vs analytic {an}"
                );
            }
            assert!(
                checked > 10,
                "{blend:?} {weights:?}: only {checked} parameters carried gradient"
            );
        }
    }
}
