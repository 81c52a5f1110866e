//! Numerical stress: no NaN or infinity may leave any stage, whatever the input.
//!
//! Property tests feed the model, the quantizers, the renderer and the fitter with
//! degenerate and extreme values; deterministic tests cover the edge images and the
//! optimizer's extremes.

use gsi::contract::COLOR_MAX;
use gsi::format::{self, Attribute, Limits, Quantizer, Records};
use gsi::model::{Blend, CovParam, GaussianSet, Scene};
use gsi::render::render;
use proptest::prelude::*;

mod common;

/// Any `f32`, with the awkward ones (0, ±∞, NaN, extremes, subnormals) made likely.
fn wild() -> impl Strategy<Value = f32> {
    prop_oneof![
        3 => -4.0f32..4.0,
        1 => Just(0.0f32),
        1 => Just(f32::INFINITY),
        1 => Just(f32::NEG_INFINITY),
        1 => Just(f32::NAN),
        1 => Just(f32::MAX),
        1 => Just(f32::MIN),
        1 => Just(f32::MIN_POSITIVE / 4.0),
        1 => Just(1e-30f32),
        1 => Just(-1e30f32),
        2 => any::<f32>(),
    ]
}

/// One Gaussian: position, covariance parameters, colour, opacity.
type Raw = ([f32; 2], [f32; 3], [f32; 3], f32);

fn scene(blend: Blend, cov_param: CovParam, g: Vec<Raw>, opacity: bool) -> Scene {
    Scene {
        weights: gsi::model::WeightRule::PerPixel,
        tone: None,
        width: 17,
        height: 11,
        blend,
        cov_param,
        gaussians: GaussianSet {
            positions: g.iter().map(|x| x.0).collect(),
            cov: g.iter().map(|x| x.1).collect(),
            colors: g.iter().map(|x| x.2).collect(),
            opacity: opacity.then(|| g.iter().map(|x| x.3).collect()),
        },
    }
}

fn gaussian() -> impl Strategy<Value = Raw> {
    (
        [wild(), wild()],
        [wild(), wild(), wild()],
        [wild(), wild(), wild()],
        wild(),
    )
}

fn blend() -> impl Strategy<Value = Blend> {
    prop_oneof![Just(Blend::Sum), Just(Blend::Alpha)]
}

fn cov_param() -> impl Strategy<Value = CovParam> {
    prop_oneof![Just(CovParam::Cholesky), Just(CovParam::LogScaleRotation)]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    /// Covariances of any parameters are finite and positive semi-definite.
    #[test]
    fn covariance_is_always_finite(p in [wild(), wild(), wild()], cp in cov_param()) {
        let s = cp.covariance(p);
        prop_assert!(s.iter().all(|x| x.is_finite()), "{:?}", s);
        prop_assert!(s[0] >= 0.0 && s[2] >= 0.0);
        prop_assert!(s[1] * s[1] <= s[0] * s[2] * (1.0 + 1e-5) + 1e-30, "{:?}", s);
    }

    /// Any Gaussian set, however degenerate, renders to finite pixels bounded by what
    /// the colour clamp allows, at any size.
    #[test]
    fn render_is_finite_and_bounded(
        g in prop::collection::vec(gaussian(), 0..24),
        blend in blend(),
        cp in cov_param(),
        opacity in any::<bool>(),
        w in 1u32..40,
        h in 1u32..40,
    ) {
        let n = g.len() as f32;
        let img = render(&scene(blend, cp, g, opacity), w, h).unwrap();
        let bound = match blend { Blend::Sum => COLOR_MAX * n, Blend::Alpha => COLOR_MAX };
        for v in &img.data {
            prop_assert!(v.is_finite() && v.abs() <= bound + 1e-3, "{} (bound {})", v, bound);
        }
    }

    /// Records at every quantizer edge (codes 0 and 2^bits − 1, extreme ranges)
    /// dequantize to finite values, survive the container, and render finitely.
    #[test]
    fn quantizer_edges_render_finitely(
        bits in 1u8..=24,
        lo in prop_oneof![Just(-3e38f32), Just(-1.0f32), Just(0.0f32)],
        hi in prop_oneof![Just(3e38f32), Just(1.0f32), Just(1e-30f32)],
        blend in blend(),
        cp in cov_param(),
    ) {
        let q = Quantizer { bits, min: lo, max: hi.max(lo) };
        prop_assume!(q.validate().is_ok() && q.min < q.max);
        let top = q.max_code();
        let codes = |c: usize| -> Vec<u32> { (0..4).map(|i| if (i + c) % 2 == 0 { 0 } else { top }).collect() };
        let attr = |k: usize| Attribute { quantizers: vec![q; k], codes: (0..k).flat_map(codes).collect(), shape: None, footprint: None };
        let records = Records { tone: None, weights: gsi::WeightRule::PerPixel,
            header: format::Header::new(9, 7, 4, blend, cp),
            positions: attr(2),
            covariance: attr(3),
            colors: attr(3),
            opacity: Some(attr(1)),
        };
        let bytes = format::to_bytes(&records, &format::WriteOptions::default()).unwrap();
        let file = format::read_file(&bytes[..], Limits::default()).unwrap();
        prop_assert_eq!(&file.records, &records);
        let scene = file.records.to_scene();
        let g = &scene.gaussians;
        prop_assert!(g.all_finite());
        for (w, h) in [(9, 7), (1, 1), (30, 2)] {
            prop_assert!(render(&scene, w, h).unwrap().data.iter().all(|v| v.is_finite()));
        }
    }

    /// Quantizing any values (NaN and infinities included) gives codes in range, and
    /// dequantizing them gives finite values within the quantizer's range.
    #[test]
    fn quantization_is_total(v in prop::collection::vec(wild(), 1..40), bits in 0u8..=24) {
        let q = Quantizer::fit(bits, v.iter().copied());
        prop_assert!(q.validate().is_ok(), "{:?}", q);
        for &x in &v {
            let c = q.quantize(x);
            prop_assert!(c <= q.max_code());
            let y = q.dequantize(c);
            prop_assert!(y.is_finite() && y >= q.min && y <= q.max, "{} -> {} -> {} in {:?}", x, c, y, q);
        }
    }

    /// Angles shaped by their Gaussian (spec §5.4.5) from any values, at any depth: the
    /// shaped codes are coded in method 4 and read back as they were, and render finitely.
    #[test]
    fn shaped_angles_from_any_values_roundtrip(
        g in prop::collection::vec(gaussian(), 0..40),
        scale in 1u8..=24,
        angle in 1u8..=24,
    ) {
        let scene = scene(Blend::Sum, CovParam::LogScaleRotation, g, false);
        let bits = format::BitDepths {
            covariance: scale,
            angle,
            angle_by_shape: true,
            color_by_footprint: false,
            ..format::BitDepths::default()
        };
        let records = Records::from_scene(&scene, bits);
        let opts = format::WriteOptions { context_coding: true, ..Default::default() };
        let bytes = format::to_bytes(&records, &opts).unwrap();
        let file = format::read_file(&bytes[..], Limits::default()).unwrap();
        prop_assert_eq!(&file.records.covariance.codes, &records.covariance.codes);
        let back = file.records.to_scene();
        prop_assert!(back.gaussians.all_finite());
        prop_assert!(render(&back, 17, 11).unwrap().data.iter().all(|v| v.is_finite()));
    }
}

#[cfg(feature = "encode")]
mod fitting {
    use gsi::fit::{encode, Budget, EncodeOptions, Init, LearningRates, Loss, Target};
    use gsi::model::Blend;

    use super::common::image as target;

    fn textured(w: u32, h: u32) -> Target {
        target(w, h, |x, y| {
            let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
            [
                0.5 + 0.4 * (9.0 * u).sin(),
                0.5 + 0.4 * (7.0 * v + 3.0 * u).cos(),
                if (x / 6 + y / 6) % 2 == 0 { 0.8 } else { 0.2 },
            ]
        })
    }

    fn finite_curve(name: &str, opts: &EncodeOptions, t: &Target) -> Vec<f32> {
        let mut losses = Vec::new();
        let e = encode(t, opts, gsi::Device::Cpu, &mut |p| {
            assert!(p.loss.is_finite(), "{name}: loss {}", p.loss);
            assert!(!p.psnr.is_nan(), "{name}: PSNR NaN");
            losses.push(p.loss);
        })
        .unwrap_or_else(|e| panic!("{name}: {e}"));
        let scene = gsi::format::read_file(&e.bytes[..], Default::default())
            .unwrap()
            .records
            .to_scene();
        let img = gsi::render::render(&scene, t.width, t.height).unwrap();
        assert!(
            img.data.iter().all(|v| v.is_finite()),
            "{name}: non-finite pixel"
        );
        losses
    }

    /// With extreme learning rates the fit may be poor, but nothing becomes NaN or ∞.
    #[test]
    fn learning_rate_extremes_stay_finite() {
        let t = textured(48, 32);
        let base = EncodeOptions::default().lr;
        for (name, f) in [("lr x1000", 1000.0f32), ("lr x1e-6", 1e-6), ("lr x0", 0.0)] {
            for blend in [Blend::Sum, Blend::Alpha] {
                let lr: LearningRates = base.scaled(f);
                let opts = EncodeOptions {
                    budget: Budget::Gaussians(60),
                    iterations: 40,
                    blend,
                    lr,
                    ..EncodeOptions::default()
                };
                finite_curve(&format!("{name} {blend:?}"), &opts, &t);
            }
        }
    }

    /// At the default learning rates the loss falls on average: the mean of the last
    /// tenth of the reports is below the mean of the first tenth, for every init,
    /// blend mode and loss.
    #[cfg(feature = "lab")]
    #[test]
    fn loss_decreases_on_average() {
        let t = textured(64, 48);
        for init in [Init::Adaptive, Init::Random] {
            for blend in [Blend::Sum, Blend::Alpha] {
                for loss in [Loss::L2, Loss::L1MsSsim { lambda: 0.2 }] {
                    let opts = EncodeOptions {
                        budget: Budget::Gaussians(80),
                        iterations: 150,
                        init,
                        blend,
                        loss,
                        lab: gsi::fit::Lab {
                            densify: false,
                            ..Default::default()
                        },
                        ..EncodeOptions::default()
                    };
                    let name = format!("{init:?} {blend:?} {loss:?}");
                    let l = finite_curve(&name, &opts, &t);
                    let k = (l.len() / 10).max(1);
                    let head: f32 = l[..k].iter().sum::<f32>() / k as f32;
                    let tail: f32 = l[l.len() - k..].iter().sum::<f32>() / k as f32;
                    assert!(tail < head, "{name}: loss {head} -> {tail}");
                }
            }
        }
    }

    /// Images at the edges of what the encoder accepts.
    #[test]
    fn extreme_images_stay_finite() {
        let cases = [
            ("black", target(20, 20, |_, _| [0.0; 3])),
            ("white", target(20, 20, |_, _| [1.0; 3])),
            ("1x1", target(1, 1, |_, _| [0.7, 0.1, 0.4])),
            ("2x1", target(2, 1, |x, _| [x as f32, 1.0 - x as f32, 0.5])),
            ("1x30", target(1, 30, |_, y| [0.0, (y % 2) as f32, 1.0])),
            ("checker", target(16, 16, |x, y| [((x + y) % 2) as f32; 3])),
        ];
        for (name, t) in &cases {
            for init in [Init::Adaptive, Init::Random] {
                for blend in [Blend::Sum, Blend::Alpha] {
                    let opts = EncodeOptions {
                        budget: Budget::Gaussians(10),
                        iterations: 25,
                        init,
                        blend,
                        ..EncodeOptions::default()
                    };
                    finite_curve(&format!("{name} {init:?} {blend:?}"), &opts, t);
                }
            }
        }
    }
}
