//! One stage-2 enhancement iteration (mixture forward, `A·c`, zero-shot loss, backward,
//! Adam) on a 600×400 scene of 4000 Gaussians, the size of a LOL image at about 1 bpp,
//! applying a stored enhancer to every colour (`--apply-from`), the denoising that
//! comes before the mixture (neighbour search and two passes), the per-Gaussian tone
//! curve of older files (applied as stored), stage 2's low-light decision (`assess`) and
//! its choice of tone curve and gain map (`curve-plan`) and of chroma map
//! (`chroma-plan`, `chroma-apply`); and the zero-shot loss alone at
//! the working size (`loss/256x171`).

use criterion::{criterion_group, criterion_main, Criterion};
use gsi::enhance::features::FeatureBank;
use gsi::enhance::fit::{EnhanceOptions, Session};
use gsi::enhance::loss::{ImageLoss, LossParams, LossWeights};
use gsi::model::Blend;
use gsi::synth::{random_scene, SceneSpec};
use std::hint::black_box;

fn enhance_iteration(c: &mut Criterion) {
    let mut group = c.benchmark_group("enhance");
    group.sample_size(20);
    for blend in [Blend::Sum, Blend::Alpha] {
        let mut scene = random_scene(3, SceneSpec::new(600, 400, 4000, blend));
        for col in &mut scene.gaussians.colors {
            *col = col.map(|x| x * 0.15);
        }
        let opts = EnhanceOptions::default();
        let mut session = Session::new(&scene, &opts, &FeatureBank);
        group.bench_function(format!("{}/iteration/4k", blend.name()), |b| {
            b.iter(|| black_box(session.step()))
        });
        let fitted = Session::new(
            &scene,
            &EnhanceOptions {
                iterations: 5,
                ..opts.clone()
            },
            &FeatureBank,
        )
        .finish();
        let g = &scene.gaussians;
        group.bench_function(format!("{}/apply/4k", blend.name()), |b| {
            b.iter(|| black_box(fitted.enhancer.apply(&g.positions, &g.colors)))
        });
        let denoise = gsi::format::Denoise {
            range: 0.02,
            strength: 1.0,
            passes: 2,
        };
        let limits = gsi::format::Limits::default();
        group.bench_function(format!("{}/denoise/4k", blend.name()), |b| {
            b.iter(|| {
                black_box(gsi::enhance::denoise::denoise(
                    &scene, &g.colors, &denoise, &limits,
                ))
            })
        });
        let tone = gsi::format::Tone {
            exponent: 0.7,
            scale: 1.5,
            passes: 4,
        };
        group.bench_function(format!("{}/tone/4k", blend.name()), |b| {
            b.iter(|| black_box(gsi::enhance::tone::tone(&scene, &g.colors, &tone, &limits)))
        });
        group.bench_function(format!("{}/assess/4k", blend.name()), |b| {
            b.iter(|| black_box(gsi::enhance::assess::assess(&scene, opts.work_side)))
        });
        let curve = gsi::enhance::curve::CurveOptions::default();
        let target = gsi::enhance::curve::MID_GREY;
        group.bench_function(format!("{}/curve-plan/4k", blend.name()), |b| {
            b.iter(|| {
                black_box(gsi::enhance::curve::plan(
                    &scene,
                    &g.colors,
                    target,
                    &curve,
                    opts.work_side,
                ))
            })
        });
        let low = gsi::enhance::working::working_image(&scene, opts.work_side);
        let (lw, lh) = gsi::enhance::working::work_size(scene.width, scene.height, opts.work_side);
        group.bench_function(format!("{}/chroma-plan/4k", blend.name()), |b| {
            b.iter(|| black_box(gsi::enhance::chroma::plan(&low, lw, lh)))
        });
        let scales: Vec<[f32; 1]> = (0..16 * 11).map(|i| [(i % 7) as f32 / 6.0]).collect();
        let chroma = gsi::format::ChromaMap {
            width: 16,
            height: 11,
            scales: gsi::format::Attribute::fit(&scales, [4]),
        };
        group.bench_function(format!("{}/chroma-apply/4k", blend.name()), |b| {
            b.iter(|| {
                black_box(gsi::enhance::chroma::apply(
                    &chroma,
                    &g.positions,
                    &g.colors,
                ))
            })
        });
        let speckle = gsi::format::Speckle {
            threshold: 0.015_294_117,
        };
        group.bench_function(format!("{}/speckle/4k", blend.name()), |b| {
            b.iter(|| black_box(gsi::enhance::speckle::apply(&scene, &g.colors, &speckle)))
        });
        group.bench_function(format!("{}/setup/4k", blend.name()), |b| {
            b.iter(|| black_box(Session::new(&scene, &opts, &FeatureBank)))
        });
    }
    // The loss and its gradient at the working size of a 600×400 image, on a random
    // image and a darker, noisier version of it as the low image.
    let (w, h) = (256, 171);
    // A 64-bit LCG's top 24 bits: uniform in [0, 1).
    let mut state = 11u64;
    let mut unit = move || {
        state = state
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let img: Vec<f32> = (0..w * h * 3).map(|_| 0.05 + 0.9 * unit()).collect();
    let low: Vec<f32> = img.iter().map(|&v| 0.2 * v + 0.03 * unit()).collect();
    let loss = ImageLoss::new(&low, w, h, LossWeights::default(), LossParams::default());
    let mut grad = vec![0f32; img.len()];
    group.bench_function("loss/256x171", |b| {
        b.iter(|| black_box(loss.eval(&img, &mut grad)))
    });
    group.finish();
}

criterion_group!(benches, enhance_iteration);
criterion_main!(benches);
