//! The wgpu renderer against the CPU renderer. Runs wherever wgpu finds an adapter (CI:
//! lavapipe from `mesa-vulkan-drivers`); with `GSI_REQUIRE_GPU=1` a missing adapter is a
//! failure rather than a skip, so CI cannot pass without running these.

#[path = "../../tests/common/mod.rs"]
mod common;

use gsi::format::{read_file, Limits};
use gsi::gpu::Gpu;
use gsi::model::Blend;
use gsi::synth::{random_scene, SceneSpec};

fn gpu() -> Option<Gpu> {
    match Gpu::new() {
        Ok(g) => {
            eprintln!("adapter: {}", g.adapter());
            Some(g)
        }
        Err(e) if std::env::var_os("GSI_REQUIRE_GPU").is_some() => {
            panic!("GSI_REQUIRE_GPU is set but {e}")
        }
        Err(e) => {
            eprintln!("skipped: {e}");
            None
        }
    }
}

/// A target with detail at several scales, `w × h`: the render of 300 random Gaussians
/// (returned too), clamped to the displayable range.
fn fit_target(seed: u64, w: u32, h: u32) -> (gsi::Scene, gsi::RgbImage) {
    let source = random_scene(seed, SceneSpec::new(w, h, 300, Blend::Sum));
    let mut target = gsi::render::render(&source, w, h).unwrap();
    target.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    (source, target)
}

/// Largest difference of the 8-bit outputs.
fn max_diff(a: &gsi::render::RgbImage, b: &gsi::render::RgbImage) -> u8 {
    diff(a, b).0
}

/// Largest difference of the 8-bit outputs, how many values differ, and how many there are.
fn diff(a: &gsi::render::RgbImage, b: &gsi::render::RgbImage) -> (u8, usize, usize) {
    let (a, b) = (a.to_rgb8(), b.to_rgb8());
    let d = a.iter().zip(&b).map(|(x, y)| x.abs_diff(*y));
    let max = d.clone().max().unwrap_or(0);
    (max, d.filter(|&x| x != 0).count(), a.len())
}

#[test]
fn gpu_matches_cpu_on_the_corpus_within_one_level() {
    let Some(gpu) = gpu() else { return };
    let mut blends = [0, 0];
    // 8-bit values compared, and how many differ (by one level at most, as asserted).
    let (mut values, mut differ) = (0usize, 0usize);
    for path in common::corpus("valid") {
        let file = read_file(std::fs::File::open(&path).unwrap(), Limits::default()).unwrap();
        let scene = file.records.to_scene();
        blends[(scene.blend == Blend::Alpha) as usize] += 1;
        let (w, h) = (scene.width, scene.height);
        for (ow, oh) in [(w, h), (2 * w, 2 * h), (w.div_ceil(3), h.div_ceil(3))] {
            let cpu = gsi::render::render(&scene, ow, oh).unwrap();
            let gpu_img = gpu.render(&scene, ow, oh).unwrap();
            assert!(gpu_img.data.iter().all(|x| x.is_finite()));
            let (d, off, n) = diff(&cpu, &gpu_img);
            assert!(
                d <= 1,
                "{} at {ow}x{oh}: differs by {d}/255",
                path.display()
            );
            values += n;
            differ += off;
        }
    }
    assert!(
        blends[0] > 3 && blends[1] > 3,
        "both blend modes covered: {blends:?}"
    );
    eprintln!(
        "margin: corpus decodes: {differ} of {values} 8-bit values differ from the CPU's (by 1/255 at most)"
    );
}

/// What a conforming GPU may do differently from the CPU, which these parity tests allow
/// for and no more. Vulkan's SPIR-V precision rules (which wgpu's Metal and DX12 backends
/// do not tighten) promise: `+`, `-`, `*` correctly rounded, but naga marks nothing
/// `NoContraction`, so a driver may fuse `a * b + c` into one rounding (Metal compiles
/// with fast math); `x / y` to 2.5 ulp; `sqrt` as `1 / inversesqrt`, 2 ulp; `exp` to
/// 3 + 2·|x| ulp; `sin`/`cos` to an absolute 2^-11, and only inside [-π, π] (the shaders
/// reduce θ there first). So a pixel where a Gaussian's alpha is within those errors of
/// `ALPHA_MIN`, or on the edge of its 3σ box, may flip; elsewhere values agree to a level.
///
/// A scene resident on the GPU, projected and binned there, draws the CPU's pixels on the
/// corpus (both covariance parameterizations and blend modes): every 8-bit value within 1
/// of the CPU's, except on the one-pixel rim of some Gaussian's box, where the GPU's own
/// arithmetic may move the edge by a pixel (by at most 3 levels there). Lavapipe has
/// no such flip; the margins are printed for hardware runs (`tools/gpu-kit.sh`).
#[test]
fn a_resident_scene_draws_the_cpu_pixels() {
    let Some(gpu) = gpu() else { return };
    let mut params = [0, 0];
    // Values compared, values off by more than 1 (all on box rims), worst difference.
    let mut totals = (0usize, 0usize, 0u8);
    for path in common::corpus("valid") {
        let file = read_file(std::fs::File::open(&path).unwrap(), Limits::default()).unwrap();
        let scene = file.records.to_scene();
        if scene.gaussians.is_empty() {
            continue;
        }
        params[(scene.cov_param == gsi::model::CovParam::Cholesky) as usize] += 1;
        let (w, h) = (scene.width, scene.height);
        for (ow, oh) in [(w, h), (2 * w + 1, 2 * h), (w.div_ceil(3), h.div_ceil(3))] {
            let cpu = gsi::render::render(&scene, ow, oh).unwrap().to_rgb8();
            let resident = gsi::gpu::GpuScene::new(&gpu, &scene, ow, oh).unwrap();
            resident.draw(2).unwrap();
            let img = resident.image().unwrap();
            assert!(img.data.iter().all(|x| x.is_finite()));
            let img = img.to_rgb8();
            let diffs: Vec<u8> = cpu.iter().zip(&img).map(|(a, b)| a.abs_diff(*b)).collect();
            let rim = box_rims(&scene, ow, oh);
            let off: Vec<usize> = (0..diffs.len()).filter(|&i| diffs[i] > 1).collect();
            let worst = diffs.iter().copied().max().unwrap_or(0);
            let stray = off.iter().filter(|&&i| !rim[i / 3]).count();
            totals.0 += diffs.len();
            totals.1 += off.len();
            totals.2 = totals.2.max(worst);
            assert!(
                stray == 0 && worst <= 3,
                "{} at {ow}x{oh}: {} values off by more than 1, {stray} of them off every \
                 box rim, worst {worst}",
                path.display(),
                off.len()
            );
        }
    }
    eprintln!(
        "margin: resident pixels: {} of {} values off by more than 1 (all on box rims), \
         worst {}/255",
        totals.1, totals.0, totals.2
    );
    assert!(
        params[0] > 0 && params[1] > 0,
        "both covariance parameterizations: {params:?}"
    );
}

/// Pixels within one pixel of the edge of some Gaussian's box (as the CPU projects it):
/// where a GPU's rounding may move the edge.
fn box_rims(scene: &gsi::Scene, w: u32, h: u32) -> Vec<bool> {
    let mut rim = vec![false; w as usize * h as usize];
    let mut mark = |x: i64, y: i64| {
        if (0..i64::from(w)).contains(&x) && (0..i64::from(h)).contains(&y) {
            rim[y as usize * w as usize + x as usize] = true;
        }
    };
    for g in gsi::render::project_scene(scene, w, h) {
        let b = g.bbox;
        let (x0, y0, x1, y1) = (
            i64::from(b.x0),
            i64::from(b.y0),
            i64::from(b.x1),
            i64::from(b.y1),
        );
        for x in x0 - 1..=x1 + 1 {
            for y in [y0 - 1, y0, y1, y1 + 1] {
                mark(x, y);
            }
        }
        for y in y0 - 1..=y1 + 1 {
            for x in [x0 - 1, x0, x1, x1 + 1] {
                mark(x, y);
            }
        }
    }
    rim
}

#[test]
fn bands_split_by_the_binding_limit_give_the_same_image() {
    let Some(mut gpu) = gpu() else { return };
    for blend in [Blend::Sum, Blend::Alpha] {
        let scene = random_scene(3, SceneSpec::new(200, 150, 2000, blend));
        let whole = gpu.render(&scene, 200, 150).unwrap();
        let cpu = gsi::render::render(&scene, 200, 150).unwrap();
        assert!(max_diff(&whole, &cpu) <= 1);
        // Room for two tile rows of output: ten bands.
        let mut small = Gpu::new().unwrap();
        small.limit_bindings(200 * 16 * 12 * 2 + 64 * 1024);
        let banded = small.render(&scene, 200, 150).unwrap();
        assert_eq!(banded.data, whole.data, "{blend:?}");
        // A limit below one tile row's output is refused with a clear error.
        small.limit_bindings(1000);
        let e = small.render(&scene, 200, 150).unwrap_err();
        assert_eq!(e.kind(), gsi::gpu::ErrorKind::LimitExceeded);
        gpu.limit_bindings(u64::MAX);
    }
}

#[test]
fn empty_and_tiny_scenes() {
    let Some(gpu) = gpu() else { return };
    let empty = random_scene(1, SceneSpec::new(10, 7, 0, Blend::Sum));
    assert!(gpu
        .render(&empty, 10, 7)
        .unwrap()
        .data
        .iter()
        .all(|&x| x == 0.0));
    let one = random_scene(2, SceneSpec::new(1, 1, 1, Blend::Alpha));
    let (a, b) = (
        gpu.render(&one, 1, 1).unwrap(),
        gsi::render::render(&one, 1, 1).unwrap(),
    );
    assert!(max_diff(&a, &b) <= 1);
    assert!(gpu.render(&one, 0, 5).is_err());
}

#[test]
fn cli_decode_on_the_gpu_and_a_missing_adapter() {
    let Some(_) = gpu() else { return };
    let file = common::corpus("valid")
        .into_iter()
        .find(|p| p.to_string_lossy().contains("alpha-lsr-500"))
        .unwrap();
    let dir = common::scratch_dir(env!("CARGO_TARGET_TMPDIR")).join("gpu-cli");
    std::fs::create_dir_all(&dir).unwrap();
    // Mesa's window-system probe complains on stderr when this is unset.
    let xdg = dir.join("xdg");
    std::fs::create_dir_all(&xdg).unwrap();
    let run = |device: &str, out: &str, env: &[(&str, &str)]| {
        let mut cmd = std::process::Command::new(common::gsi_exe(env!("CARGO_BIN_EXE_gsi")));
        cmd.args([
            "decode",
            file.to_str().unwrap(),
            "--scale",
            "2",
            "--device",
            device,
            "-o",
        ])
        .arg(dir.join(out))
        .env("XDG_RUNTIME_DIR", &xdg);
        for (k, v) in env {
            cmd.env(k, v);
        }
        cmd.output().unwrap()
    };
    assert!(run("gpu", "g.png", &[]).status.success());
    assert!(run("cpu", "c.png", &[]).status.success());
    // The two PNGs agree to at most one level per value: PSNR above 48 dB.
    let cmp = std::process::Command::new(common::gsi_exe(env!("CARGO_BIN_EXE_gsi")))
        .args(["compare", "--json"])
        .arg(dir.join("c.png"))
        .arg(dir.join("g.png"))
        .output()
        .unwrap();
    assert!(cmp.status.success());
    let json: serde_json::Value = serde_json::from_slice(&cmp.stdout).unwrap();
    let psnr = json["psnr"].as_f64().unwrap_or(f64::INFINITY); // null: identical
    assert!(psnr > 48.0, "GPU and CPU PNGs differ: {psnr} dB");
    let out = run(
        "gpu",
        "none.png",
        &[("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")],
    );
    assert_eq!(out.status.code(), Some(1));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("no adapter named like"), "{err}");
    assert!(!dir.join("none.png").exists());
}

/// The backward pass on the GPU against `fit::raster::backward`, both blend modes and an
/// edge-cut size: relative error of each kind of gradient (mean, conic, opacity, colour)
/// at most 1e-3.
#[test]
fn gradients_match_the_cpu() {
    for blend in [Blend::Sum, Blend::Alpha] {
        for (w, h) in [(96, 64), (50, 37)] {
            gradients_match(blend, w, h);
        }
    }
}

fn gradients_match(blend: Blend, w: u32, h: u32) {
    use gsi::fit::raster::{backward, forward, Need};
    let Some(gpu) = gpu() else { return };
    let scene = random_scene(11, SceneSpec::new(w, h, 400, blend));
    let proj = gsi::render::project_scene(&scene, w, h);
    let fwd = forward(&proj, blend, w, h);
    let mut rng = gsi::synth::SplitMix64::new(5);
    let n = fwd.image.len() as f32;
    let dl: Vec<f32> = fwd
        .image
        .iter()
        .map(|&x| 2.0 * (x - rng.unit()) / n)
        .collect();
    let cpu = backward(&fwd, &proj, &dl, Need::All);
    let gpu_grads = gsi::fit::backward_gpu::backward(&gpu, &proj, blend, w, h, &dl).unwrap();
    assert_eq!(cpu.len(), gpu_grads.len());
    let kinds: [(&str, std::ops::Range<usize>); 4] = [
        ("mean", 0..2),
        ("conic", 2..5),
        ("opacity", 5..6),
        ("colour", 6..9),
    ];
    for (name, range) in kinds {
        let (mut diff, mut norm) = (0f64, 0f64);
        for (c, g) in cpu.iter().zip(&gpu_grads) {
            let c = [
                c.mean[0], c.mean[1], c.conic[0], c.conic[1], c.conic[2], c.opacity, c.color[0],
                c.color[1], c.color[2],
            ];
            for k in range.clone() {
                assert!(g[k].is_finite());
                diff += f64::from(g[k] - c[k]).powi(2);
                norm += f64::from(c[k]).powi(2);
            }
        }
        let rel = (diff / norm.max(1e-30)).sqrt();
        eprintln!(
            "margin: gradient {blend:?} {w}x{h} {name}: relative error {rel:.2e} (bound 1e-3)"
        );
        assert!(
            norm > 0.0 && rel <= 1e-3,
            "{blend:?} {w}x{h} {name}: relative error {rel}"
        );
    }
}

/// A fit whose steps run on the GPU decodes (on the CPU) at the quality of the same fit on
/// the CPU: within 0.5 dB, both blend modes, and with a coarse start (whose reduced fit
/// runs on the GPU too, then hands its Gaussians to the full-resolution one).
#[test]
fn a_gpu_fit_matches_a_cpu_fit() {
    use gsi::fit::{encode, Budget, Coarse, EncodeOptions};
    use gsi::Device;
    let Some(gpu) = gpu() else { return };
    // A target with detail at several scales: the render of random Gaussians.
    let source = random_scene(21, SceneSpec::new(96, 64, 600, Blend::Sum));
    let mut target = gsi::render::render(&source, 96, 64).unwrap();
    target.data.iter_mut().for_each(|v| *v = v.clamp(0.0, 1.0));
    let half = Some(Coarse {
        factor: 2,
        fraction: 0.5,
    });
    for (blend, coarse) in [(Blend::Sum, None), (Blend::Alpha, None), (Blend::Sum, half)] {
        let opts = EncodeOptions {
            budget: Budget::Gaussians(250),
            iterations: 150,
            blend,
            coarse,
            ..EncodeOptions::default()
        };
        let cpu = encode(&target, &opts, gsi::Device::Cpu, &mut |_| {}).unwrap();
        let on_gpu = encode(&target, &opts, Device::Gpu(&gpu), &mut |_| {}).unwrap();
        eprintln!(
            "{blend:?} {coarse:?}: CPU fit {:.2} dB, GPU fit {:.2} dB",
            cpu.psnr, on_gpu.psnr
        );
        assert_eq!(on_gpu.fallback, None);
        assert!(
            cpu.psnr > 20.0,
            "{blend:?}: the CPU fit itself failed ({:.2} dB)",
            cpu.psnr
        );
        assert!(
            (cpu.psnr - on_gpu.psnr).abs() <= 0.5,
            "{blend:?}: {:.2} vs {:.2} dB",
            cpu.psnr,
            on_gpu.psnr
        );
    }
}

/// The fitting loop resident on the GPU takes the CPU's steps: from the same start, the
/// same losses and PSNRs, and parameters after several Adam steps (quantization-aware ones
/// included) within what Adam can make of rounding: Adam divides a gradient by its own
/// running scale, so a near-zero gradient whose sign differs by rounding moves a parameter
/// by up to its learning rate the other way. Each parameter is held to 2·lr per step taken,
/// which any conforming GPU meets; lavapipe's actual differences are far smaller (printed).
#[test]
fn resident_steps_follow_the_cpu_steps() {
    use gsi::fit::{default_bits, Fitter, Init, Loss};
    let Some(gpu) = gpu() else { return };
    let (w, h) = (83, 61);
    let (_, target) = fit_target(31, w, h);
    let lr = gsi::fit::EncodeOptions::default().lr;
    for blend in [Blend::Sum, Blend::Alpha] {
        // The GPU's quantization-aware steps render every angle at the uniform depth; the
        // CPU's render them shaped by their Gaussian (spec §5.4.5) where the depths say
        // so, as the file stores them. The steps are compared where both do the same.
        let bits = gsi::format::BitDepths {
            angle_by_shape: false,
            color_by_footprint: false,
            ..default_bits(w, h, blend)
        };
        let mut cpu = Fitter::new(&target, 200, Init::Adaptive, blend, Loss::L2, 3);
        let mut on_gpu = Fitter::new(&target, 200, Init::Adaptive, blend, Loss::L2, 3);
        on_gpu.use_gpu(&gpu);
        for it in 0..12 {
            let qat = (it >= 8).then_some(bits);
            let a = cpu.step(&lr, qat, true).unwrap();
            // The GPU's report comes a step late; `flush` waits for it now.
            assert_eq!(on_gpu.step(&lr, qat, true), None);
            let b = on_gpu.flush().unwrap();
            eprintln!("{blend:?} step {it}: CPU {a:?} GPU {b:?}");
            assert_eq!(a.step, b.step);
            assert!(
                ((a.loss - b.loss) / a.loss).abs() < 1e-3 && (a.psnr - b.psnr).abs() < 0.05,
                "{blend:?} step {it}: {a:?} vs {b:?}"
            );
        }
        on_gpu.sync();
        let (p, q) = (&cpu.params, &on_gpu.params);
        assert_eq!(p.len(), q.len());
        let flat = |s: &gsi::model::GaussianSet| -> Vec<f32> {
            (0..s.len())
                .flat_map(|i| {
                    let mut v = s.positions[i].to_vec();
                    v.extend(s.cov[i]);
                    v.extend(s.colors[i]);
                    v.extend(s.opacity.as_ref().map(|o| o[i]));
                    v
                })
                .collect()
        };
        // Learning rate of each flattened component: u, v, ln σ1, ln σ2, θ, r, g, b, (o).
        let per = if p.opacity.is_some() { 9 } else { 8 };
        let (p, q) = (flat(p), flat(q));
        let rate = |k: usize| match k % per {
            0 | 1 => lr.position,
            2 | 3 => lr.log_scale,
            4 => lr.rotation,
            5..=7 => lr.color,
            _ => lr.opacity,
        };
        let mut worst = 0f32;
        for (k, (a, b)) in p.iter().zip(&q).enumerate() {
            let bound = 2.0 * 12.0 * rate(k);
            worst = worst.max((a - b).abs() / bound);
            assert!(
                (a - b).abs() <= bound,
                "{blend:?}: component {k}: {a} vs {b}"
            );
        }
        eprintln!("margin: trajectory {blend:?}: worst parameter difference {worst:.2e} of its bound 2·lr·steps");
        let diff: f64 = p
            .iter()
            .zip(&q)
            .map(|(a, b)| f64::from(a - b).powi(2))
            .sum();
        let norm: f64 = p.iter().map(|a| f64::from(*a).powi(2)).sum();
        let rel = (diff / norm).sqrt();
        eprintln!("margin: trajectory {blend:?}: parameters after 12 steps differ by {rel:.2e} (relative)");
    }
}

/// Degenerate and non-finite parameters, read as the CPU reads them: a resident scene
/// draws them without a non-finite value, and as the CPU does, both parameterizations and
/// blend modes.
#[test]
fn a_resident_scene_survives_degenerate_gaussians() {
    use gsi::model::{CovParam, GaussianSet, Scene};
    let Some(gpu) = gpu() else { return };
    let odd = [
        0.0,
        -0.0,
        1e-30,
        1e30,
        -1e30,
        f32::INFINITY,
        f32::NAN,
        0.5,
        -3.0,
    ];
    let mut g = GaussianSet::default();
    let mut k = 0usize;
    for &a in &odd {
        for &b in &odd {
            let pick = |i: usize| odd[(k + i) % odd.len()];
            g.positions.push([0.5 + 0.1 * (k % 5) as f32, pick(1)]);
            g.cov.push([a, b, pick(2)]);
            g.colors.push([pick(3), 0.5, pick(4)]);
            k += 1;
        }
    }
    // And well-behaved ones, so the image is not just black.
    for i in 0..20 {
        g.positions.push([0.05 * i as f32, 0.5]);
        g.cov.push([-3.0, -3.5, 0.3]);
        g.colors.push([0.8, 0.3, 0.1]);
    }
    for blend in [Blend::Sum, Blend::Alpha] {
        for cov_param in [CovParam::LogScaleRotation, CovParam::Cholesky] {
            let mut gaussians = g.clone();
            if blend == Blend::Alpha {
                gaussians.opacity = Some(
                    (0..gaussians.len())
                        .map(|i| odd[i % odd.len()].clamp(-1.0, 2.0))
                        .collect(),
                );
                gaussians.opacity.as_mut().unwrap()[3] = f32::NAN;
            }
            let scene = Scene {
                weights: gsi::model::WeightRule::PerPixel,
                tone: None,
                width: 40,
                height: 30,
                blend,
                cov_param,
                gaussians,
            };
            let cpu = gsi::render::render(&scene, 40, 30).unwrap();
            let img = gsi::gpu::GpuScene::new(&gpu, &scene, 40, 30)
                .unwrap()
                .image()
                .unwrap();
            assert!(
                img.data.iter().all(|x| x.is_finite()),
                "{blend:?} {cov_param:?}"
            );
            let d = max_diff(&cpu, &img);
            assert!(d <= 1, "{blend:?} {cov_param:?}: differs by {d}/255");
        }
    }
}

/// `gsi enhance --device gpu` (the mixture on the GPU) writes a file that decodes as the
/// CPU's does; with no such adapter it fails and leaves the file as it was.
#[test]
fn cli_enhance_on_the_gpu() {
    use gsi::format::{to_bytes, BitDepths, Records, WriteOptions};
    let Some(_) = gpu() else { return };
    let dir = common::scratch_dir(env!("CARGO_TARGET_TMPDIR")).join("gpu-enhance");
    let xdg = dir.join("xdg");
    std::fs::create_dir_all(&xdg).unwrap();
    let mut scene = random_scene(12, SceneSpec::new(64, 48, 300, Blend::Sum));
    for c in &mut scene.gaussians.colors {
        *c = c.map(|x| x * 0.15);
    }
    let bits = BitDepths {
        position: 12,
        covariance: 10,
        angle: 10,
        angle_by_shape: false,
        color_by_footprint: false,
        color: 10,
        opacity: 8,
    };
    let dark = to_bytes(&Records::from_scene(&scene, bits), &WriteOptions::default()).unwrap();
    let input = dir.join("dark.gsi");
    std::fs::write(&input, &dark).unwrap();
    let run = |args: &[&str], env: &[(&str, &str)]| {
        let mut cmd = std::process::Command::new(common::gsi_exe(env!("CARGO_BIN_EXE_gsi")));
        cmd.args(args).env("XDG_RUNTIME_DIR", &xdg);
        for (k, v) in env {
            cmd.env(k, v);
        }
        cmd.output().unwrap()
    };
    let p = |name: &str| dir.join(name).to_str().unwrap().to_string();
    for device in ["gpu", "cpu"] {
        let out = run(
            &[
                "enhance",
                &p("dark.gsi"),
                "-o",
                &p(&format!("{device}.gsi")),
                "--iterations",
                "40",
                "--device",
                device,
                "--quiet",
            ],
            &[],
        );
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let out = run(
            &[
                "decode",
                &p(&format!("{device}.gsi")),
                "-o",
                &p(&format!("{device}.png")),
                "--device",
                "cpu",
            ],
            &[],
        );
        assert!(out.status.success());
    }
    // Enhanced, not passed over as bright enough.
    assert_ne!(std::fs::read(dir.join("gpu.gsi")).unwrap(), dark);
    let cmp = run(&["compare", "--json", &p("cpu.png"), &p("gpu.png")], &[]);
    let json: serde_json::Value = serde_json::from_slice(&cmp.stdout).unwrap();
    let psnr = json["psnr"].as_f64().unwrap_or(f64::INFINITY);
    assert!(psnr > 45.0, "GPU and CPU enhancements differ: {psnr} dB");
    let out = run(
        &["enhance", &p("dark.gsi"), "--in-place", "--device", "gpu"],
        &[("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")],
    );
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(std::fs::read(&input).unwrap(), dark);
}

/// A device that does not finish in time gives an error, not a wait without end, and is
/// usable again once the wait is long enough.
#[test]
fn a_wait_past_its_timeout_is_an_error() {
    let Some(gpu) = gpu() else { return };
    let scene = random_scene(5, SceneSpec::new(1024, 1024, 20_000, Blend::Alpha));
    gpu.set_wait_timeout(std::time::Duration::ZERO);
    let e = gpu
        .render(&scene, 2048, 2048)
        .expect_err("a 4-megapixel render finished in no time");
    assert_eq!(e.kind(), gsi::gpu::ErrorKind::TimedOut, "{e}");
    gpu.set_wait_timeout(gsi::gpu::DEFAULT_WAIT_TIMEOUT);
    let img = gpu.render(&scene, 64, 64).unwrap();
    assert!(img.data.iter().all(|v| v.is_finite()));
}

/// Host round trips per fitting step and per enhancement iteration, counted by the device
/// (`Gpu::traffic`): the numbers a fast GPU's step time is bound by. Held to what they are
/// (a regression guard) and printed for the kit's report. A measured fitting step reads
/// its report back one step late, after the next step is queued, so the device never
/// idles for the host (no stall); an enhancement iteration still waits twice, because the
/// render and the loss between its two halves run on the CPU.
#[test]
fn round_trips_per_step_and_per_iteration() {
    use gsi::enhance::{features::FeatureBank, fit::EnhanceOptions, fit::Session};
    use gsi::fit::{Fitter, Init, Loss};
    let Some(gpu) = gpu() else { return };
    let (source, target) = fit_target(41, 80, 60);
    let lr = gsi::fit::EncodeOptions::default().lr;
    let mut fitter = Fitter::new(&target, 150, Init::Adaptive, Blend::Sum, Loss::L2, 1);
    fitter.use_gpu(&gpu);
    fitter.step(&lr, None, false); // uploads and sizes the lists
                                   // Submissions, read-backs, stalls and staging buffers made, per call of `f`.
    let per = |f: &mut dyn FnMut()| {
        let t0 = gpu.traffic();
        for _ in 0..10 {
            f();
        }
        let t1 = gpu.traffic();
        let per = |a: u64, b: u64| (b - a) as f64 / 10.0;
        [
            per(t0.submissions, t1.submissions),
            per(t0.read_backs, t1.read_backs),
            per(t0.stalls, t1.stalls),
            per(t0.staging_buffers, t1.staging_buffers),
        ]
    };
    let quiet = per(&mut || {
        fitter.step(&lr, None, false);
    });
    // As every measured step was before reports came late: the host waits for the step
    // it has just submitted, and the device idles meanwhile. (The first makes the ring's
    // buffers.)
    fitter.step(&lr, None, true);
    fitter.flush().expect("no report");
    let waited = per(&mut || {
        assert_eq!(fitter.step(&lr, None, true), None);
        fitter.flush().expect("no report");
    });
    // Every step measured: each returns its predecessor's report.
    assert_eq!(fitter.step(&lr, None, true), None);
    let mut last = fitter.step(&lr, None, true).unwrap().step;
    let measured = per(&mut || {
        let m = fitter.step(&lr, None, true).expect("no report a step late");
        assert_eq!(m.step, last + 1);
        last = m.step;
    });
    assert_eq!(fitter.flush().map(|m| m.step), Some(last + 1));
    assert_eq!(fitter.flush(), None);
    assert_eq!(fitter.fallback(), None);
    let opts = EnhanceOptions {
        iterations: 10,
        ..EnhanceOptions::default()
    };
    let mut session = Session::new(&source, &opts, &FeatureBank);
    session.use_gpu(&gpu).unwrap();
    session.step();
    session.step();
    let enhance = per(&mut || {
        session.step();
    });
    eprintln!(
        "margin: round trips per fitting step {quiet:?} (submissions, read-backs, stalls, \
         staging buffers made), per measured step {measured:?} (read at once: {waited:?}), \
         per enhancement iteration {enhance:?}"
    );
    assert_eq!(quiet, [1.0, 0.0, 0.0, 0.0]);
    assert_eq!(waited, [1.0, 1.0, 1.0, 0.0]);
    // A measured step reads back its report through the staging ring, collected after
    // the next step is queued: no stall, no new buffer.
    assert_eq!(measured, [1.0, 1.0, 0.0, 0.0]);
    assert!(
        enhance[1] <= 2.0 && enhance[2] <= 2.0 && enhance[3] == 0.0,
        "{enhance:?}"
    );
}

/// More Gaussians than one block of the multi-workgroup scan (`fit_scan.wgsl`, 4096 per
/// block), with some blocks empty of drawn Gaussians: a resident scene still draws the
/// CPU's pixels, so every block's offsets are right.
#[test]
fn a_resident_scene_of_many_blocks_draws_the_cpu_pixels() {
    let Some(gpu) = gpu() else { return };
    let (w, h) = (640, 480);
    for (n, blend) in [(20_000, Blend::Alpha), (9_000, Blend::Sum)] {
        let scene = random_scene(13, SceneSpec::new(w, h, n, blend));
        let cpu = gsi::render::render(&scene, w, h).unwrap().to_rgb8();
        let resident = gsi::gpu::GpuScene::new(&gpu, &scene, w, h).unwrap();
        let img = resident.image().unwrap().to_rgb8();
        let rim = box_rims(&scene, w, h);
        let diffs: Vec<u8> = cpu.iter().zip(&img).map(|(a, b)| a.abs_diff(*b)).collect();
        let off: Vec<usize> = (0..diffs.len()).filter(|&i| diffs[i] > 1).collect();
        let stray = off.iter().filter(|&&i| !rim[i / 3]).count();
        let worst = diffs.iter().copied().max().unwrap_or(0);
        assert!(
            stray == 0 && worst <= 3,
            "{n} Gaussians, {blend:?}: {} values off, {stray} off every box rim, worst {worst}",
            off.len()
        );
    }
}
