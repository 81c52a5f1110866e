//! One fitting iteration (forward, loss, backward, Adam) at 768×512, and the pieces of it.

use criterion::{criterion_group, criterion_main, Criterion};
use gsi::fit::{raster, Fitter, Init, Loss, Target};
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
    }
    group.finish();
}

criterion_group!(benches, fit_iteration);
criterion_main!(benches);
