//! One fitting iteration (forward, loss, backward, Adam) at 768×512, and the pieces of it;
//! with a hardware GPU (or `GSI_BENCH_ANY_GPU=1`, which takes a software one too), the
//! same iteration resident on the GPU (`gpu_fit_iteration`).

use criterion::{criterion_group, criterion_main, Criterion};
use gsi::fit::{lsq, raster, Fitter, Init, Loss, Target};
use gsi::model::Blend;
use gsi::render::project_scene;
use gsi::synth::{random_scene, SceneSpec};
use std::hint::black_box;

/// A target with detail at every scale: the render of 20k random Gaussians.
fn target() -> Target {
    let scene = random_scene(
        7,
        SceneSpec {
            sigma_px: (0.5, 24.0),
            ..SceneSpec::new(768, 512, 20_000, Blend::Sum)
        },
    );
    let mut t = gsi::render::render(&scene, 768, 512).unwrap();
    for v in &mut t.data {
        *v = v.clamp(0.0, 1.0);
    }
    t
}

fn fit_iteration(c: &mut Criterion) {
    let t = target();
    let mut group = c.benchmark_group("fit_iteration");
    group.sample_size(20);
    for blend in [Blend::Sum, Blend::Alpha] {
        for (loss, name) in [
            (Loss::L2, "l2"),
            (Loss::L1MsSsim { lambda: 0.2 }, "l1-ms-ssim"),
        ] {
            let mut f = Fitter::new(&t, 5000, Init::Adaptive, blend, loss, 0);
            let lr = gsi::fit::EncodeOptions::default().lr;
            group.bench_function(format!("{}/{name}/5k", blend.name()), |b| {
                b.iter(|| black_box(f.step(&lr, None, false)))
            });
        }
        let f = Fitter::new(&t, 5000, Init::Adaptive, blend, Loss::L2, 0);
        let scene = f.scene();
        let proj = project_scene(&scene, 768, 512);
        let fwd = raster::forward(&proj, blend, 768, 512);
        let d = vec![1e-3f32; fwd.image.len()];
        group.bench_function(format!("{}/forward/5k", blend.name()), |b| {
            b.iter(|| black_box(raster::forward(&proj, blend, 768, 512)))
        });
        group.bench_function(format!("{}/backward/5k", blend.name()), |b| {
            b.iter(|| black_box(raster::backward(&fwd, &proj, &d, raster::Need::All)))
        });
        // The colour solve after pruning and re-placement (effort 1's 8 iterations).
        group.bench_function(format!("{}/color_solve_8/5k", blend.name()), |b| {
            b.iter(|| {
                let mut p = proj.clone();
                black_box(lsq::solve_colors(&mut p, blend, 768, 512, &t.data, 8))
            })
        });
        // What a step of the default fit runs: both passes and the loss, tile by tile.
        if blend == Blend::Sum {
            group.bench_function("sum/step_l2/5k", |b| {
                b.iter(|| black_box(raster::step_l2_sum(&proj, &t.data, 768, 512, true)))
            });
        }
    }
    group.finish();
}

/// Ten resident steps, the last one measured (so the time includes waiting for all ten
/// and one progress read-back): a tenth of it is the cost of a step in a real fit, which
/// reads progress every ten steps.
#[cfg(feature = "gpu")]
fn gpu_fit_iteration(c: &mut Criterion) {
    let gpu = if std::env::var_os("GSI_BENCH_ANY_GPU").is_some() {
        gsi::gpu::Gpu::new()
    } else {
        gsi::gpu::Gpu::new_hardware()
    };
    let gpu = match gpu {
        Ok(g) => g,
        Err(e) => {
            eprintln!("gpu_fit_iteration skipped: {e}");
            return;
        }
    };
    eprintln!("adapter: {}", gpu.adapter());
    let t = target();
    let lr = gsi::fit::EncodeOptions::default().lr;
    let mut group = c.benchmark_group("gpu_fit_iteration");
    group.sample_size(10);
    for blend in [Blend::Sum, Blend::Alpha] {
        for n in [5000, 9000, 70_000] {
            let mut f = Fitter::new(&t, n, Init::Adaptive, blend, Loss::L2, 0);
            f.use_gpu(&gpu);
            group.bench_function(format!("{}/l2/{}k/10-steps", blend.name(), n / 1000), |b| {
                b.iter(|| {
                    for k in 0..10 {
                        black_box(f.step(&lr, None, k == 9));
                    }
                })
            });
        }
    }
    group.finish();
}

#[cfg(not(feature = "gpu"))]
fn gpu_fit_iteration(_: &mut Criterion) {}

criterion_group!(benches, fit_iteration, gpu_fit_iteration);
criterion_main!(benches);
