//! Gradient checks and forward equivalence for the differentiable rasterizer.

use super::params::chain;
use super::raster::{backward, forward, Need};
use super::{Coarse, Effort, EncodeOptions};
use gsi_format::model::{Blend, CovParam, GaussianSet, Scene};
use gsi_optim::optim::zeros_like as zero_grads;
use gsi_render::render::{project_scene, render, Projected};
use gsi_synth::{random_scene, SceneSpec, SplitMix64};

/// Every angle lands within a quarter turn of 0 and the covariance stays what it was
/// (to rounding), with the scales swapped exactly when an odd number of quarter turns
/// was taken off.
#[test]
fn canonical_rotations_keep_the_covariance() {
    let mut rng = SplitMix64::new(5);
    let eighth = std::f32::consts::FRAC_PI_4;
    for i in 0..2000 {
        let p = [
            -6.0 + 4.0 * rng.unit(),
            -6.0 + 4.0 * rng.unit(),
            // Up to ±20 rad, and the quarter turns themselves.
            if i < 16 {
                (i as f32 - 8.0) * 2.0 * eighth
            } else {
                40.0 * (rng.unit() - 0.5)
            },
        ];
        let (q, swapped) = super::params::canonical_rotation(p);
        assert!((-eighth..=eighth).contains(&q[2]), "{p:?} -> {q:?}");
        assert_eq!(swapped, q[0] != p[0] && p[0] != p[1], "{p:?} -> {q:?}");
        let (a, b) = (
            CovParam::LogScaleRotation.covariance(p),
            CovParam::LogScaleRotation.covariance(q),
        );
        let scale = a[0].max(a[2]);
        for k in 0..3 {
            assert!(
                (a[k] - b[k]).abs() <= 2e-5 * scale,
                "{p:?} -> {q:?}: {a:?} vs {b:?}"
            );
        }
    }
    let nan = [0.0, 1.0, f32::NAN];
    assert!(!super::params::canonical_rotation(nan).1);
}

/// `alpha` blending renders with the decoder's own loops; `sum` with the lanes of
/// `super::lanes`, whose forward pass does the decoder's operations in its order: both
/// give the decoder's pixels bit for bit.
#[test]
fn forward_matches_the_decoder() {
    for (seed, blend) in [
        (1, Blend::Sum),
        (2, Blend::Alpha),
        (3, Blend::Alpha),
        (4, Blend::Sum),
    ] {
        let scene = random_scene(
            seed,
            SceneSpec {
                sigma_px: (0.3, 12.0),
                ..SceneSpec::new(70, 45, 400, blend)
            },
        );
        for (w, h) in [(70, 45), (33, 17), (140, 90), (1, 1)] {
            let fwd = forward(&project_scene(&scene, w, h), blend, w, h);
            let want = render(&scene, w, h).unwrap();
            assert!(fwd.image == want.data, "{blend:?} {w}x{h}");
        }
    }
}

/// The fused step (`sum`, L2) gives the image and gradients of the three passes run one
/// after the other, bit for bit, with and without the alphas kept (a tile list longer
/// than `KEPT_LIST_MAX` is evaluated again); and so do the step without its image and
/// the colour solve's adjoint ([`super::raster::sum_adjoint`]).
#[test]
fn fused_step_gives_the_gradients_of_the_passes() {
    use super::lanes::KEPT_LIST_MAX;
    use super::loss::{Loss, LossFn};
    use super::raster::{step_l2_sum, sum_adjoint};
    let cases = [
        (5, 400, vec![(70, 45), (33, 17), (16, 16), (1, 1)]),
        (6, KEPT_LIST_MAX + 10, vec![(5, 3)]),
    ];
    for (seed, n, sizes) in cases {
        let scene = random_scene(
            seed,
            SceneSpec {
                sigma_px: (0.3, 12.0),
                ..SceneSpec::new(70, 45, n, Blend::Sum)
            },
        );
        for (w, h) in sizes {
            let mut rng = SplitMix64::new(seed + u64::from(w));
            let target: Vec<f32> = (0..w * h * 3).map(|_| rng.range(0.0, 1.0)).collect();
            let proj = project_scene(&scene, w, h);
            let fwd = forward(&proj, Blend::Sum, w, h);
            let (value, dl) = LossFn::new(Loss::L2).eval(&fwd.image, &target, w, h);
            let want = backward(&fwd, &proj, &dl, Need::All);
            let got = step_l2_sum(&proj, &target, w, h, true);
            assert!(got.image == fwd.image, "{n} Gaussians, {w}x{h}: image");
            assert!(got.grads == want, "{n} Gaussians, {w}x{h}: gradients");
            let rel = (got.loss - value).abs() / value.max(1e-12);
            assert!(
                rel < 1e-5,
                "{n} Gaussians, {w}x{h}: loss {} vs {value}",
                got.loss
            );
            let unmeasured = step_l2_sum(&proj, &target, w, h, false);
            assert!(unmeasured.image.is_empty() && unmeasured.grads == want);
            assert_eq!(unmeasured.loss, got.loss);
            // The colour solve's operator: Aᵀ(y − A c), as the passes compute it.
            let resid: Vec<f32> = target.iter().zip(&fwd.image).map(|(y, a)| y - a).collect();
            let want: Vec<[f32; 3]> = backward(&fwd, &proj, &resid, Need::ColorOnly)
                .iter()
                .map(|g| g.color)
                .collect();
            let tiles = gsi_render::render::TileLists::bin(&proj, w, h);
            let got = sum_adjoint(&proj, &tiles, w, h, None, |acc, rect| {
                let mut d = super::lanes::Planes::gather(&target, w, rect);
                for (dc, ac) in d.0.iter_mut().zip(&acc.0) {
                    dc.iter_mut().zip(ac).for_each(|(y, a)| *y -= a);
                }
                d
            });
            assert!(got == want, "{n} Gaussians, {w}x{h}: adjoint");
        }
    }
}

/// A scene on which the loss is smooth: every Gaussian covers every pixel with
/// `alpha` well above the cut-off and below the `alpha` cap, so finite differences do
/// not cross a threshold.
fn smooth_scene(blend: Blend, seed: u64) -> Scene {
    let mut rng = SplitMix64::new(seed);
    let (w, h) = (12u32, 10u32);
    let mut g = GaussianSet::default();
    for _ in 0..5 {
        g.positions.push([rng.range(0.3, 0.7), rng.range(0.3, 0.7)]);
        let (s1, s2) = (rng.range(7.0, 10.0), rng.range(6.0, 9.0));
        g.cov.push([
            (s1 / w as f32).ln(),
            (s2 / h as f32).ln(),
            rng.range(-1.0, 1.0),
        ]);
        g.colors.push([
            rng.range(-1.0, 1.0),
            rng.range(0.0, 1.0),
            rng.range(0.0, 2.0),
        ]);
    }
    if blend == Blend::Alpha {
        g.opacity = Some((0..5).map(|_| rng.range(0.2, 0.55)).collect());
    }
    Scene {
        weights: gsi_format::model::WeightRule::PerPixel,
        tone: None,
        width: w,
        height: h,
        blend,
        cov_param: CovParam::LogScaleRotation,
        gaussians: g,
    }
}

/// A named scalar of the parameters, its analytic gradient, and where to find it.
type Probe = (String, f32, Box<dyn Fn(&mut GaussianSet) -> &mut f32>);

/// `L = Σ_p weight_p · image_p`, accumulated in f64, rendered by the decoder.
fn loss(scene: &Scene, weights: &[f32]) -> f64 {
    let img = render(scene, scene.width, scene.height).unwrap();
    img.data
        .iter()
        .zip(weights)
        .map(|(a, b)| f64::from(*a) * f64::from(*b))
        .sum()
}

fn analytic(scene: &Scene, weights: &[f32]) -> GaussianSet {
    let (w, h) = (scene.width, scene.height);
    let projected = project_scene(scene, w, h);
    assert_eq!(projected.len(), scene.gaussians.len());
    let fwd = forward(&projected, scene.blend, w, h);
    let pg = backward(&fwd, &projected, weights, Need::All);
    let mut grads = zero_grads(&scene.gaussians);
    chain(&scene.gaussians, &projected, &pg, w, h, &mut grads);
    grads
}

#[test]
fn every_gradient_matches_finite_differences() {
    for (blend, seed) in [
        (Blend::Sum, 1),
        (Blend::Sum, 2),
        (Blend::Alpha, 3),
        (Blend::Alpha, 4),
    ] {
        let scene = smooth_scene(blend, seed);
        let mut rng = SplitMix64::new(seed + 100);
        let weights: Vec<f32> = (0..scene.width * scene.height * 3)
            .map(|_| rng.range(-1.0, 1.0))
            .collect();
        let grads = analytic(&scene, &weights);
        let n = scene.gaussians.len();
        let mut checked = 0;
        // (name, getter of a mutable parameter, step)
        for i in 0..n {
            let mut probes: Vec<Probe> = Vec::new();
            for k in 0..2 {
                probes.push((
                    format!("pos[{i}][{k}]"),
                    grads.positions[i][k],
                    Box::new(move |g| &mut g.positions[i][k]),
                ));
            }
            for k in 0..3 {
                probes.push((
                    format!("cov[{i}][{k}]"),
                    grads.cov[i][k],
                    Box::new(move |g| &mut g.cov[i][k]),
                ));
                probes.push((
                    format!("color[{i}][{k}]"),
                    grads.colors[i][k],
                    Box::new(move |g| &mut g.colors[i][k]),
                ));
            }
            if blend == Blend::Alpha {
                probes.push((
                    format!("opacity[{i}]"),
                    grads.opacity.as_ref().unwrap()[i],
                    Box::new(move |g| &mut g.opacity.as_mut().unwrap()[i]),
                ));
            }
            for (name, an, get) in probes {
                let step = if name.starts_with("pos") { 2e-3 } else { 1e-2 };
                let mut plus = scene.clone();
                *get(&mut plus.gaussians) += step;
                let mut minus = scene.clone();
                *get(&mut minus.gaussians) -= step;
                let fd = (loss(&plus, &weights) - loss(&minus, &weights)) / (2.0 * f64::from(step));
                let an = f64::from(an);
                // The render is f32: a loss of ~10 carries ~1e-6 relative noise, i.e. ~5e-4 in
                // a difference quotient, so tiny gradients are compared on an absolute floor.
                let err = (fd - an).abs() / fd.abs().max(an.abs()).max(0.1);
                assert!(
                    err < 5e-3,
                    "{blend:?} {name}: analytic {an}, finite difference {fd}"
                );
                checked += 1;
            }
        }
        assert!(checked >= 40);
    }
}

#[test]
fn colour_least_squares_reproduces_a_reachable_image() {
    // Render a scene, scramble its colours, solve: the colours come back.
    for blend in [Blend::Sum, Blend::Alpha] {
        let scene = random_scene(
            9,
            SceneSpec {
                sigma_px: (2.0, 6.0),
                ..SceneSpec::new(40, 30, 30, blend)
            },
        );
        let target = render(&scene, 40, 30).unwrap();
        let mut projected = project_scene(&scene, 40, 30);
        for g in projected.iter_mut() {
            g.color = [0.5; 3];
        }
        super::lsq::solve_colors(&mut projected, blend, 40, 30, &target.data, 200);
        let fwd = forward(&projected, blend, 40, 30);
        let err = fwd
            .image
            .iter()
            .zip(&target.data)
            .map(|(a, b)| (a - b).abs())
            .fold(0f32, f32::max);
        assert!(err < 2e-3, "{blend:?}: max error {err}");
    }
}

/// Colours rounded a batch at a time, the rest solved again after each, render the
/// target better than each colour rounded alone, and every code stays in its quantizer's
/// range; a single batch is the plain rounding.
#[test]
fn compensated_rounding_beats_rounding_alone() {
    use gsi_format::format::Quantizer;
    for blend in [Blend::Sum, Blend::Alpha] {
        let scene = random_scene(
            5,
            SceneSpec {
                sigma_px: (1.0, 8.0),
                ..SceneSpec::new(48, 40, 120, blend)
            },
        );
        // A target the Gaussians cannot reach exactly, so that the solve leaves a residual.
        let mut target = render(&scene, 48, 40).unwrap();
        for (k, v) in target.data.iter_mut().enumerate() {
            *v += 0.05 * ((k * 7919 % 13) as f32 / 13.0 - 0.5);
        }
        let mut projected = project_scene(&scene, 48, 40);
        let solved = super::lsq::solve_colors(&mut projected, blend, 48, 40, &target.data, 100);
        let qs: [Quantizer; 3] =
            std::array::from_fn(|c| Quantizer::fit(5, solved.iter().map(|x| x[c])));
        let sse = |p: &[Projected]| -> f64 {
            let img = forward(p, blend, 48, 40).image;
            img.iter()
                .zip(&target.data)
                .map(|(a, b)| f64::from(a - b).powi(2))
                .sum()
        };
        let error = |codes: &[[u32; 3]]| -> f64 {
            let mut p = projected.clone();
            for (g, c) in p.iter_mut().zip(codes) {
                g.color = std::array::from_fn(|ch| qs[ch].dequantize(c[ch]));
            }
            sse(&p)
        };
        let plain: Vec<[u32; 3]> = solved
            .iter()
            .map(|c| std::array::from_fn(|ch| qs[ch].quantize(c[ch])))
            .collect();
        let single = super::lsq::quantize_colors(
            &mut projected.clone(),
            blend,
            (48, 40),
            &target.data,
            &qs,
            None,
            (1, 5),
        );
        assert_eq!(single, plain, "{blend:?}");
        let compensated = super::lsq::quantize_colors(
            &mut projected.clone(),
            blend,
            (48, 40),
            &target.data,
            &qs,
            None,
            (8, 5),
        );
        assert!(compensated
            .iter()
            .all(|c| (0..3).all(|ch| c[ch] <= qs[ch].max_code())));
        // What rounding adds to the solved colours' error, each way.
        let e_solved = sse(&projected);
        let (e_plain, e_comp) = (error(&plain) - e_solved, error(&compensated) - e_solved);
        assert!(
            e_plain > 0.0 && e_comp < 0.6 * e_plain,
            "{blend:?}: added by rounding: compensated {e_comp}, plain {e_plain}"
        );
    }
}

/// Opacities all at 1 are not stored (no opacity attribute), but a quantization-aware step
/// still renders them at 1 and passes their gradient straight through, as the GPU loop
/// does: the opacities move.
#[test]
fn quantization_aware_steps_keep_unstored_opacities() {
    use super::{default_bits, Fitter, Init, LearningRates, Loss};
    let scene = random_scene(4, SceneSpec::new(40, 30, 80, Blend::Alpha));
    let mut target = render(&scene, 40, 30).unwrap();
    target.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    let mut f = Fitter::new(&target, 60, Init::Adaptive, Blend::Alpha, Loss::L2, 1);
    let n = f.params.len();
    f.params.opacity = Some(vec![1.0; n]);
    let bits = default_bits(40, 30, Blend::Alpha);
    assert_eq!(f.quantized(bits).opacity, Some(vec![1.0; n]));
    let lr = LearningRates {
        position: 0.0,
        log_scale: 0.0,
        rotation: 0.0,
        color: 0.0,
        opacity: 0.01,
    };
    f.step(&lr, Some(bits), false);
    let moved = f
        .params
        .opacity
        .as_ref()
        .unwrap()
        .iter()
        .filter(|&&o| o < 1.0)
        .count();
    assert!(moved > 0, "no opacity moved");
}

#[test]
fn default_options_are_the_default_effort() {
    let mut leveled = EncodeOptions {
        iterations: 1,
        coarse: Some(Coarse {
            factor: 3,
            fraction: 0.9,
        }),
        color_solve: 1,
        ..EncodeOptions::default()
    };
    Effort::DEFAULT.apply(&mut leveled);
    assert_eq!(
        format!("{leveled:?}"),
        format!("{:?}", EncodeOptions::default())
    );
    // Levels order time: steps never fall and the coarse share never grows.
    let steps: Vec<(u32, f32)> = (1..=9)
        .map(|l| {
            let mut o = EncodeOptions::default();
            Effort::new(l).unwrap().apply(&mut o);
            (o.iterations, o.coarse.map_or(0.0, |c| c.fraction))
        })
        .collect();
    assert!(steps
        .windows(2)
        .all(|w| w[0].0 <= w[1].0 && w[0].1 >= w[1].1));
    assert_eq!((Effort::new(0), Effort::new(10)), (None, None));
}

/// Position rates mean pixels a step: scaled down on images longer than `RATE_SIDE`, kept
/// on smaller ones; the other rates are the same at every size.
#[test]
fn position_rates_follow_the_image_size() {
    use super::{rates_for, LEARNING_RATES, RATE_SIDE};
    let lr = LEARNING_RATES;
    assert_eq!(rates_for(&lr, 768, 512), lr);
    assert_eq!(rates_for(&lr, 16, 600), lr);
    let big = rates_for(&lr, 3000, 4000);
    let pixels = |r: &super::LearningRates, side: u32| r.position * side as f32;
    assert!((pixels(&big, 4000) - pixels(&lr, RATE_SIDE)).abs() < 1e-6);
    assert_eq!(
        (big.log_scale, big.rotation, big.color),
        (lr.log_scale, lr.rotation, lr.color)
    );
}

/// The full-resolution steps of a coarse-to-fine fit go on from the coarse ones, moments
/// and step count included: with a fresh optimizer, whose first steps move every
/// parameter by its whole learning rate, the PSNR fell by 2 dB after the switch
/// (this image: 26.9 dB at the first full-resolution step, 24.8 dB ten steps later; with
/// the state kept, 27.8 dB).
#[cfg(feature = "lab")]
#[test]
fn the_fine_steps_go_on_from_the_coarse_ones() {
    let scene = random_scene(
        11,
        SceneSpec {
            sigma_px: (1.0, 10.0),
            ..SceneSpec::new(128, 96, 600, Blend::Sum)
        },
    );
    let mut target = render(&scene, 128, 96).unwrap();
    target.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    let opts = EncodeOptions {
        budget: super::Budget::Gaussians(400),
        iterations: 80,
        coarse: Some(Coarse {
            factor: 2,
            fraction: 0.5,
        }),
        lab: super::Lab {
            densify: false,
            qat_fraction: 0.0,
            ..Default::default()
        },
        ..EncodeOptions::default()
    };
    let e = super::encode(&target, &opts, gsi_gpu::Device::Cpu, &mut |_| {}).unwrap();
    let at = |it: u32| e.curve.iter().find(|p| p.iteration == it).unwrap().psnr;
    let (switch, later) = (at(41), at(51));
    assert!(
        later > switch - 0.5,
        "{switch:.2} dB, ten steps later {later:.2} dB"
    );
}

/// In `sum` mode the colour depth follows the fit's error: a texture the Gaussians
/// cannot follow is stored with coarser colour codes than a smooth image (whose error is
/// small), and depths the caller gave are kept.
#[test]
fn the_colour_depth_follows_the_fit_error() {
    let (w, h) = (64u32, 48u32);
    let smooth = super::Target {
        width: w,
        height: h,
        data: (0..w * h)
            .flat_map(|i| {
                let (x, y) = ((i % w) as f32 / w as f32, (i / w) as f32 / h as f32);
                [0.2 + 0.6 * x, 0.3 + 0.4 * y, 0.5]
            })
            .collect(),
    };
    let mut rng = SplitMix64::new(3);
    let noise = super::Target {
        data: (0..w * h * 3).map(|_| rng.unit()).collect(),
        ..smooth.clone()
    };
    let opts = EncodeOptions {
        budget: super::Budget::Bpp(2.0),
        iterations: 60,
        coarse: None,
        ..EncodeOptions::default()
    };
    let depth = |t: &super::Target, o: &EncodeOptions| {
        let e = super::encode(t, o, gsi_gpu::Device::Cpu, &mut |_| {}).unwrap();
        e.records.colors.quantizers[0].bits
    };
    let (rough, fine) = (depth(&noise, &opts), depth(&smooth, &opts));
    assert!(rough < fine, "noise {rough} bits, smooth {fine} bits");
    assert!(super::depth::COLOR_BITS.contains(&rough) && super::depth::COLOR_BITS.contains(&fine));
    let given = EncodeOptions {
        bits: Some(super::default_bits(w, h, Blend::Sum)),
        ..opts
    };
    assert_eq!(depth(&noise, &given), 8);
}

/// At a densification a Gaussian that holds back less error than one more Gaussian would
/// remove is dropped, and only where the fit's error is large: the same faint Gaussian
/// stays on a target the scene renders exactly, and a bar of 0 keeps it anywhere.
#[test]
fn pruning_weighs_a_gaussian_against_the_fit_error() {
    use super::{init::pixel_lsr, Fitter, Loss};
    let (w, h) = (64u32, 48u32);
    let (fw, fh) = (w as f32, h as f32);
    let scene = Scene {
        weights: gsi_format::model::WeightRule::PerPixel,
        tone: None,
        width: w,
        height: h,
        blend: Blend::Sum,
        cov_param: CovParam::LogScaleRotation,
        gaussians: GaussianSet {
            positions: vec![[0.5, 0.5], [0.25, 0.25]],
            cov: vec![
                pixel_lsr(10.0, 8.0, 0.3, fw, fh),
                pixel_lsr(1.0, 1.0, 0.0, fw, fh),
            ],
            colors: vec![[0.5; 3], [0.05; 3]],
            opacity: None,
        },
    };
    let exact = render(&scene, w, h).unwrap();
    // ±0.1 on every value: a mean squared error of 0.01 that no two Gaussians follow (a
    // bar of 0.9·0.01·9216/2 ≈ 41, against 0.024 for the faint one and 190 for the other).
    let mut noisy = exact.clone();
    for (i, v) in noisy.data.iter_mut().enumerate() {
        *v += if (i / 3 + i / 3 / w as usize) % 2 == 0 {
            0.1
        } else {
            -0.1
        };
    }
    let kept = |target: &_, worth: f64| {
        let mut f = Fitter::with_params(target, scene.gaussians.clone(), Blend::Sum, Loss::L2, 1);
        f.prune_and_grow(0.0, worth, usize::MAX, 0);
        f.params.colors.iter().map(|c| c[0]).collect::<Vec<_>>()
    };
    assert_eq!(kept(&noisy, 1.0), vec![0.5], "the faint Gaussian stayed");
    assert_eq!(kept(&exact, 1.0), vec![0.5, 0.05]);
    assert_eq!(kept(&noisy, 0.0), vec![0.5, 0.05]);
    // The estimate: |c|²·Σ_p w², here 3·0.05²·π·1² (the Gaussian lies inside the image).
    let f = Fitter::with_params(&noisy, scene.gaussians.clone(), Blend::Sum, Loss::L2, 1);
    let loss = f.contributions().loss[1];
    let expected = 3.0 * 0.05f64.powi(2) * std::f64::consts::PI;
    assert!(
        (loss / expected - 1.0).abs() < 0.05,
        "{loss} against {expected}"
    );
}
