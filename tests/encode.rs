//! Stage-1 encoder: degenerate images, determinism, budgets, and the stored quality.
#![cfg(feature = "encode")]

use gsi::fit::{encode, Budget, EncodeOptions, Init, Target};
use gsi::format::{read_file, Limits};
use gsi::model::Blend;

mod common;
use common::image;

/// A smooth gradient with a disc and a bar: something with edges and flat parts.
fn scene_like(w: u32, h: u32) -> Target {
    image(w, h, |x, y| {
        let (u, v) = (x as f32 / w as f32, y as f32 / h as f32);
        let disc = ((u - 0.35).powi(2) + (v - 0.5).powi(2)).sqrt() < 0.2;
        let bar = (0.65..0.75).contains(&u);
        [
            if disc { 0.9 } else { 0.2 + 0.5 * u },
            if bar { 0.1 } else { 0.4 + 0.3 * v },
            0.3 + 0.2 * (u + v),
        ]
    })
}

fn opts(budget: Budget, iterations: u32, blend: Blend) -> EncodeOptions {
    EncodeOptions {
        budget,
        iterations,
        blend,
        ..EncodeOptions::default()
    }
}

/// Decode the bytes and check every pixel is finite and the header matches the target.
fn decodes(bytes: &[u8], t: &Target) -> gsi::render::RgbImage {
    let f = read_file(bytes, Limits::default()).expect("the encoder writes valid files");
    assert_eq!(
        (f.records.header.width, f.records.header.height),
        (t.width, t.height)
    );
    let scene = f.records.to_scene();
    assert!(scene.gaussians.all_finite());
    let img = gsi::render::render(&scene, t.width, t.height).unwrap();
    assert!(img.data.iter().all(|v| v.is_finite()));
    img
}

#[test]
fn degenerate_images_encode_to_finite_files() {
    let cases = [
        ("black", image(24, 16, |_, _| [0.0; 3])),
        ("white", image(24, 16, |_, _| [1.0; 3])),
        ("1x1", image(1, 1, |_, _| [0.2, 0.5, 0.9])),
        ("1x40", image(1, 40, |_, y| [y as f32 / 40.0, 0.5, 0.1])),
        ("40x1", image(40, 1, |x, _| [0.3, x as f32 / 40.0, 1.0])),
        (
            "noise",
            image(16, 16, |x, y| {
                [
                    ((x * 7 + y * 13) % 17) as f32 / 16.0,
                    ((x * 3 + y) % 5) as f32 / 4.0,
                    0.5,
                ]
            }),
        ),
    ];
    for (name, t) in &cases {
        for blend in [Blend::Sum, Blend::Alpha] {
            for init in [Init::Adaptive, Init::Random] {
                let o = EncodeOptions {
                    init,
                    ..opts(Budget::Gaussians(20), 30, blend)
                };
                let e = encode(t, &o, gsi::Device::Cpu, &mut |p| {
                    assert!(p.loss.is_finite(), "{name}: loss {}", p.loss)
                })
                .unwrap_or_else(|e| panic!("{name} {blend:?}: {e}"));
                assert!(e.psnr > 0.0, "{name}: PSNR {}", e.psnr); // +∞ for an exact fit, never NaN
                decodes(&e.bytes, t);
            }
        }
    }
}

#[test]
fn fitting_improves_and_the_stored_psnr_is_the_decoded_one() {
    let t = scene_like(64, 48);
    let paper = gsi::fit::Loss::L1MsSsim { lambda: 0.2 };
    for (blend, loss) in [
        (Blend::Sum, gsi::fit::Loss::L2),
        (Blend::Alpha, gsi::fit::Loss::L2),
        (Blend::Sum, paper),
    ] {
        let mut first = None;
        let o = EncodeOptions {
            loss,
            ..opts(Budget::Gaussians(120), 150, blend)
        };
        let e = encode(&t, &o, gsi::Device::Cpu, &mut |p| {
            first.get_or_insert(p.psnr);
        })
        .unwrap();
        let start = first.unwrap();
        assert!(
            e.psnr > start + 1.0,
            "{blend:?}: {start:.2} -> {:.2} dB",
            e.psnr
        );
        assert!(e.psnr > 30.0, "{blend:?}: {:.2} dB", e.psnr);
        // gCRM holds the PSNR of what a decoder shows.
        let img = decodes(&e.bytes, &t);
        let stored = read_file(&e.bytes[..], Limits::default())
            .unwrap()
            .metadata
            .unwrap()
            .psnr
            .unwrap();
        let measured = gsi::fit::loss::psnr8(&img.data, &t.data, t.width, t.height);
        assert!(
            (f64::from(stored) - measured).abs() < 1e-3,
            "stored {stored}, measured {measured}"
        );
        assert!((e.psnr - measured).abs() < 1e-9);
    }
}

/// The last colour solve, on the geometry as stored, gains what the quantization-aware
/// steps left to the colours, in both blend modes, and moves nothing else.
#[cfg(feature = "lab")]
#[test]
fn the_stored_colours_are_solved_for_the_stored_geometry() {
    let t = scene_like(64, 48);
    for blend in [Blend::Sum, Blend::Alpha] {
        let with = opts(Budget::Gaussians(60), 60, blend);
        let without = EncodeOptions {
            lab: gsi::fit::Lab {
                solve_stored_colors: false,
                ..Default::default()
            },
            ..with.clone()
        };
        let solved = encode(&t, &with, gsi::Device::Cpu, &mut |_| {}).unwrap();
        let as_fitted = encode(&t, &without, gsi::Device::Cpu, &mut |_| {}).unwrap();
        assert!(
            solved.psnr > as_fitted.psnr + 0.05,
            "{blend:?}: {:.3} dB solved, {:.3} dB as fitted",
            solved.psnr,
            as_fitted.psnr
        );
        // Only the colours differ: the same Gaussians in the same places.
        let (a, b) = (solved.records.to_scene(), as_fitted.records.to_scene());
        assert_eq!(a.gaussians.positions, b.gaussians.positions);
        assert_eq!(a.gaussians.cov, b.gaussians.cov);
        assert_ne!(a.gaussians.colors, b.gaussians.colors);
        decodes(&solved.bytes, &t);
    }
}

#[test]
fn the_same_seed_gives_the_same_file() {
    let t = scene_like(40, 30);
    let o = opts(Budget::Gaussians(60), 40, Blend::Alpha);
    let a = encode(&t, &o, gsi::Device::Cpu, &mut |_| {}).unwrap().bytes;
    let b = encode(&t, &o, gsi::Device::Cpu, &mut |_| {}).unwrap().bytes;
    assert_eq!(a, b);
    let c = encode(
        &t,
        &EncodeOptions { seed: 1, ..o },
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap()
    .bytes;
    assert_ne!(a, c);
}

#[test]
fn budgets_choose_the_number_of_gaussians() {
    let t = scene_like(96, 64);
    let px = 96.0 * 64.0;
    for bpp in [2.0f32, 4.0] {
        let e = encode(
            &t,
            &opts(Budget::Bpp(bpp), 60, Blend::Sum),
            gsi::Device::Cpu,
            &mut |_| {},
        )
        .unwrap();
        let got = e.bytes.len() as f32 * 8.0 / px;
        assert!(got <= bpp, "asked {bpp} bpp, got {got}");
        assert!(got > 0.5 * bpp, "asked {bpp} bpp, got only {got}");
    }
    // A flat image meets a quality target with few Gaussians; a busy one needs more.
    let flat = image(96, 64, |_, _| [0.4, 0.5, 0.6]);
    let e_flat = encode(
        &flat,
        &opts(Budget::TargetPsnr(35.0), 60, Blend::Sum),
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap();
    let e_busy = encode(
        &t,
        &opts(Budget::TargetPsnr(35.0), 60, Blend::Sum),
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap();
    assert!(e_flat.psnr >= 35.0, "flat: {}", e_flat.psnr);
    assert!(
        e_flat.records.header.count <= 64,
        "flat: {} Gaussians",
        e_flat.records.header.count
    );
    assert!(
        e_flat.records.header.count < e_busy.records.header.count,
        "{} vs {}",
        e_flat.records.header.count,
        e_busy.records.header.count
    );
}

#[test]
fn opacity_is_not_stored_when_not_needed() {
    let t = scene_like(32, 24);
    let e = encode(
        &t,
        &opts(Budget::Gaussians(30), 20, Blend::Sum),
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap();
    assert!(e.records.opacity.is_none());
    let e = encode(
        &t,
        &opts(Budget::Gaussians(30), 20, Blend::Alpha),
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap();
    assert!(e.records.opacity.is_some());
}

#[test]
fn sum_files_are_written_along_the_curve_with_shaped_angles_and_colours_by_footprint() {
    let t = scene_like(128, 96);
    let e = encode(
        &t,
        &opts(Budget::Bpp(2.0), 40, Blend::Sum),
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap();
    let f = read_file(&e.bytes[..], Limits::default()).unwrap();
    // Method 4 (§5.4.5): the angles at the precision of their shape; method 5 (§5.4.6):
    // the colours at the precision of their footprint, version 1.8.
    assert_eq!(
        f.records.header.version_minor,
        gsi::format::VERSION_MINOR_FOOTPRINT
    );
    assert!(f.records.covariance.shape.is_some());
    assert_eq!(f.records.covariance, e.records.covariance);
    assert!(f.records.colors.footprint.is_some());
    assert_eq!(f.records.colors, e.records.colors);
    assert_eq!(f.records.to_scene(), e.records.to_scene());
    let n = f.records.header.count as usize;
    let (u, v) = f.records.positions.codes.split_at(n);
    let keys: Vec<u64> = (0..n)
        .map(|i| gsi::format::context::morton(u[i], v[i]))
        .collect();
    assert!(keys.windows(2).all(|k| k[0] <= k[1]), "not in Morton order");
    // The same codes in the 1.0 codings take more bytes (the colours' codes packed as
    // they are, whatever they mean).
    let plain = |a: &gsi::format::Attribute| gsi::format::Attribute {
        footprint: None,
        ..a.clone()
    };
    let packed: usize = [
        &f.records.positions,
        &f.records.covariance,
        &f.records.colors,
    ]
    .iter()
    .map(|a| plain(a).to_payload(19).unwrap().len())
    .sum();
    let coded: usize = [
        &f.records.positions,
        &f.records.covariance,
        &f.records.colors,
    ]
    .iter()
    .map(|a| f.records.attribute_payload(a, 19, true).unwrap().len())
    .sum();
    assert!(
        coded < packed,
        "methods 3 and 4: {coded} bytes, 1.0 codings {packed}"
    );
    assert!(e.float_psnr.is_finite() && e.psnr.is_finite());
    // Angles are stored within a quarter turn, at most 10 bits each (the noise of 8 for
    // all); the log-scales take 6.
    let angle = f.records.covariance.quantizers[2];
    let eighth = std::f32::consts::FRAC_PI_4;
    assert!(
        angle.min >= -eighth && angle.max <= eighth,
        "angles over [{}, {}]",
        angle.min,
        angle.max
    );
    assert_eq!(
        [angle.bits, f.records.covariance.quantizers[0].bits],
        [10, 6],
        "angle and scale bits"
    );
}

#[test]
fn an_unreachable_byte_budget_is_refused_not_exceeded() {
    let t = scene_like(64, 48);
    match encode(
        &t,
        &opts(Budget::Bpp(0.001), 5, Blend::Sum),
        gsi::Device::Cpu,
        &mut |_| {},
    ) {
        Err(gsi::fit::Error::BudgetUnreachable {
            asked_bpp,
            smallest_bpp,
        }) => assert!(asked_bpp == 0.001 && smallest_bpp > 0.001),
        Err(e) => panic!("wrong error: {e}"),
        Ok(e) => panic!("wrote {} bytes for 0.001 bpp", e.bytes.len()),
    }
}

/// Coarse-to-fine: the coarse steps fit a half-size copy, the full-resolution ones refine it
/// into a valid file; the progress counts every step once, in order, and its share of the
/// work grows to 1 with the coarse steps counted at a quarter; and the coarse start is
/// skipped where the reduced image would be too small.
#[test]
fn a_coarse_start_is_refined_at_full_resolution() {
    use gsi::fit::Coarse;
    let t = scene_like(96, 64);
    let coarse = EncodeOptions {
        coarse: Some(Coarse {
            factor: 2,
            fraction: 0.5,
        }),
        ..opts(Budget::Gaussians(120), 60, Blend::Sum)
    };
    let mut seen = Vec::new();
    let e = encode(&t, &coarse, gsi::Device::Cpu, &mut |p| seen.push(*p)).unwrap();
    let img = decodes(&e.bytes, &t);
    let psnr = gsi::fit::loss::psnr8(&img.data, &t.data, t.width, t.height);
    assert!((psnr - e.psnr).abs() < 1e-9 && psnr > 24.0, "{psnr}");
    let first_pass: Vec<_> = seen.iter().take_while(|p| p.total == 60).collect();
    assert!(first_pass
        .windows(2)
        .all(|w| w[0].iteration < w[1].iteration && w[0].work <= w[1].work));
    // A report counts the steps done: the last says all 60.
    let last = first_pass.last().unwrap();
    assert_eq!(last.iteration, 60);
    // 30 coarse steps at 1/4 and 30 full ones: the coarse ones are a fifth of the work.
    let at_switch = first_pass.iter().find(|p| p.iteration == 30).unwrap();
    assert!((at_switch.work - 0.2).abs() < 1e-6, "{}", at_switch.work);
    assert!((last.work - 1.0).abs() < 1e-9, "{}", last.work);
    let settings = read_file(&e.bytes[..], Limits::default())
        .unwrap()
        .metadata
        .unwrap()
        .settings;
    assert!(settings.contains("coarse=2/0.5"), "{settings}");
    // The same seed, the same file.
    let again = encode(&t, &coarse, gsi::Device::Cpu, &mut |_| {}).unwrap();
    assert_eq!(again.bytes, e.bytes);
    // A 20×20 image has no 16-pixel half: every step at full resolution, the same file as
    // without a coarse start (but for the settings line).
    let small = scene_like(20, 20);
    let mut plain_seen = Vec::new();
    let mut coarse_seen = Vec::new();
    let plain = opts(Budget::Gaussians(20), 20, Blend::Sum);
    let a = encode(&small, &plain, gsi::Device::Cpu, &mut |p| {
        plain_seen.push(p.psnr)
    })
    .unwrap();
    let b = encode(
        &small,
        &EncodeOptions {
            budget: Budget::Gaussians(20),
            iterations: 20,
            ..coarse
        },
        gsi::Device::Cpu,
        &mut |p| coarse_seen.push(p.psnr),
    )
    .unwrap();
    assert_eq!(
        a.records.to_scene().gaussians,
        b.records.to_scene().gaussians
    );
    assert_eq!(plain_seen, coarse_seen);
}

/// A dark image is fitted at full scale and stored at its own level: the file renders
/// the dark image (not the brightened copy the fit saw), says so in `gCRM`, and keeps
/// more of it than a fit at its own level, most of all where brightening will show it.
#[cfg(feature = "lab")]
#[test]
fn a_dark_image_is_fitted_at_full_scale_and_stored_as_it_is() {
    let bright = scene_like(64, 48);
    let dim = 0.08;
    let mut t = bright.clone();
    t.data.iter_mut().for_each(|v| *v *= dim);
    for blend in [Blend::Sum, Blend::Alpha] {
        let lifted = opts(Budget::Gaussians(60), 120, blend);
        let as_is = EncodeOptions {
            lab: gsi::fit::Lab {
                lift_dark: false,
                ..Default::default()
            },
            ..lifted.clone()
        };
        let a = encode(&t, &lifted, gsi::Device::Cpu, &mut |_| {}).unwrap();
        let b = encode(&t, &as_is, gsi::Device::Cpu, &mut |_| {}).unwrap();
        let (img_a, img_b) = (decodes(&a.bytes, &t), decodes(&b.bytes, &t));
        let psnr = |img: &gsi::render::RgbImage, gain: f32| {
            let up = |d: &[f32]| d.iter().map(|v| v * gain).collect::<Vec<_>>();
            gsi::fit::loss::psnr8(&up(&img.data), &up(&t.data), t.width, t.height)
        };
        // Stored as it is: the file's PSNR is against the dark image, and it is that of
        // what a decoder shows.
        assert!((a.psnr - psnr(&img_a, 1.0)).abs() < 1e-9);
        assert!(
            a.psnr > b.psnr - 0.1,
            "{blend:?}: {:.2} dB lifted, {:.2} dB as is",
            a.psnr,
            b.psnr
        );
        let (up_a, up_b) = (psnr(&img_a, 1.0 / dim), psnr(&img_b, 1.0 / dim));
        assert!(
            up_a > up_b + 1.0,
            "{blend:?}, brightened: {up_a:.2} dB lifted, {up_b:.2} dB as is"
        );
        let settings = |bytes: &[u8]| {
            let meta = read_file(bytes, Limits::default()).unwrap().metadata;
            meta.map(|m| m.settings).unwrap_or_default()
        };
        let gain = gsi::fit::dark::gain(&t);
        let want = format!("dark_gain={gain}");
        assert!(gain > 1.0 && settings(&a.bytes).contains(&want), "{want}");
        assert!(!settings(&b.bytes).contains("dark_gain"));
    }
    // A normally exposed image is fitted as it is: the same bytes either way.
    let o = opts(Budget::Gaussians(40), 30, Blend::Sum);
    let off = EncodeOptions {
        lab: gsi::fit::Lab {
            lift_dark: false,
            ..Default::default()
        },
        ..o.clone()
    };
    assert_eq!(
        encode(&bright, &o, gsi::Device::Cpu, &mut |_| {})
            .unwrap()
            .bytes,
        encode(&bright, &off, gsi::Device::Cpu, &mut |_| {})
            .unwrap()
            .bytes
    );
}
