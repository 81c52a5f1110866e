//! The CPU renderer against the pixel contract of `format-spec.md` §6.
//!
//! `naive` below is the contract transcribed as directly as possible: every pixel visits
//! every Gaussian, in stored order, in `f32`. The tiled renderer must match it bit for bit.

use gsi::format::{ErrorKind, Limits};
use gsi::model::{Blend, CovParam, GaussianSet, Scene};
use gsi::render::{render, render_into, RgbImage};
use gsi::synth::{random_scene, SceneSpec};

/// Reference renderer: a per-pixel loop over all Gaussians, written from the spec alone.
/// `E` of spec §6.3.1, written from the spec's text alone (constants from their bit
/// patterns, `round_ties_even` for the rounding the crate does with `1.5·2^23`).
fn spec_exp(x: f32) -> f32 {
    let c = f32::from_bits;
    let x = x.clamp(-87.0, 88.0);
    let n = (x * c(0x3FB8_AA3B)).round_ties_even();
    let r = (x - n * c(0x3F31_8000)) - n * c(0xB95E_8083);
    let mut p = c(0x3950_6967);
    for k in [0x3AB7_43CE, 0x3C08_8908, 0x3D2A_A9C1, 0x3E2A_AAAA] {
        p = p * r + c(k);
    }
    p = p * r + 0.5;
    let e = ((p * r) * r + r) + 1.0;
    e * c(((n as i32 + 127) as u32) << 23)
}

fn naive(scene: &Scene, w: u32, h: u32) -> Vec<f32> {
    const VAR_MIN: f32 = 1e-4;
    const VAR_MAX: f32 = 1e12;
    let (fw, fh) = (w as f32, h as f32);
    let g = &scene.gaussians;
    // Steps 1-7 once per Gaussian; `None` where the Gaussian is skipped outright.
    let prep: Vec<_> = (0..g.len())
        .map(|n| {
            let s = scene.cov_param.covariance(g.cov[n]);
            let a = (s[0] * fw * fw).clamp(VAR_MIN, VAR_MAX);
            let mut b = s[1] * fw * fh;
            let c = (s[2] * fh * fh).clamp(VAR_MIN, VAR_MAX);
            let lim = 0.999 * (a * c).sqrt();
            b = b.clamp(-lim, lim);
            let det = a * c - b * b;
            let conic = (c / det, -b / det, a / det);
            let [u, v] = g.positions[n];
            let (mx, my) = (u * fw, v * fh);
            if !u.is_finite() || !v.is_finite() {
                return None;
            }
            let (rx, ry) = (3.0 * a.sqrt(), 3.0 * c.sqrt());
            // Inclusive ranges in i64 (test sizes are small; f32 -> i64 saturates).
            let i0 = ((mx - rx - 0.5).ceil() as i64).max(0);
            let i1 = ((mx + rx - 0.5).floor() as i64).min(w as i64 - 1);
            let j0 = ((my - ry - 0.5).ceil() as i64).max(0);
            let j1 = ((my + ry - 0.5).floor() as i64).min(h as i64 - 1);
            let o = g.opacity.as_ref().map_or(1.0, |o| o[n]);
            let o = if o.is_finite() {
                o.clamp(0.0, 1.0)
            } else {
                0.0
            };
            // Spec §6.2 step 5: colours are clamped to ±64, non-finite ones are 0.
            let col = g.colors[n].map(|x| {
                if x.is_finite() {
                    x.clamp(-64.0, 64.0)
                } else {
                    0.0
                }
            });
            Some((conic, mx, my, (i0, i1, j0, j1), o, col))
        })
        .collect();
    let mut out = vec![0.0f32; (w * h * 3) as usize];
    for j in 0..h {
        for i in 0..w {
            let mut acc = [0.0f32; 3];
            let mut t = 1.0f32;
            for &(conic, mx, my, (i0, i1, j0, j1), o, col) in prep.iter().flatten() {
                let (ii, jj) = (i as i64, j as i64);
                if ii < i0 || ii > i1 || jj < j0 || jj > j1 {
                    continue;
                }
                let (ca, cb, cc) = conic;
                let dx = (i as f32 + 0.5) - mx;
                let dy = (j as f32 + 0.5) - my;
                let power = -0.5 * (ca * dx * dx + cc * dy * dy) - cb * dx * dy;
                if power > 0.0 {
                    continue;
                }
                let mut alpha = o * spec_exp(power);
                if scene.blend == Blend::Alpha {
                    alpha = alpha.min(0.99);
                }
                if alpha < 1.0 / 255.0 {
                    continue;
                }
                match scene.blend {
                    Blend::Sum => {
                        for k in 0..3 {
                            acc[k] += col[k] * alpha;
                        }
                    }
                    Blend::Alpha => {
                        for k in 0..3 {
                            acc[k] += col[k] * alpha * t;
                        }
                        t *= 1.0 - alpha;
                        if t < 1e-4 {
                            break;
                        }
                    }
                }
            }
            let p = ((j * w + i) * 3) as usize;
            out[p..p + 3].copy_from_slice(&acc);
        }
    }
    out
}

fn assert_bits_eq(got: &[f32], want: &[f32], what: &str) {
    assert_eq!(got.len(), want.len(), "{what}: length");
    for (k, (a, b)) in got.iter().zip(want).enumerate() {
        assert!(
            a.to_bits() == b.to_bits(),
            "{what}: float {k}: tiled {a} vs naive {b}"
        );
    }
}

fn check_against_naive(scene: &Scene, w: u32, h: u32, what: &str) -> RgbImage {
    let img = render(scene, w, h).unwrap();
    assert_eq!((img.width, img.height), (w, h));
    assert!(
        img.data.iter().all(|x| x.is_finite()),
        "{what}: non-finite output"
    );
    assert_bits_eq(&img.data, &naive(scene, w, h), what);
    img
}

#[test]
fn tiled_matches_naive_on_random_scenes() {
    let (rw, rh) = (48u32, 40u32);
    let sizes = [
        (1, 1),
        (1, 37),
        (37, 1),
        (17, 33),
        (rw, rh),
        (2 * rw, 2 * rh),
        (rw / 2, rh / 2),
        (100, 3),
    ];
    let mut seed = 0;
    let mut lit = 0;
    for blend in [Blend::Sum, Blend::Alpha] {
        for cov_param in [CovParam::Cholesky, CovParam::LogScaleRotation] {
            for with_opacity in [false, true] {
                for sigma_px in [(0.5, 8.0), (0.2, 40.0), (0.05, 100.0)] {
                    seed += 1;
                    let mut spec = SceneSpec::new(rw, rh, 150, blend);
                    spec.cov_param = cov_param;
                    spec.with_opacity = with_opacity;
                    spec.sigma_px = sigma_px;
                    let scene = random_scene(seed, spec);
                    for (w, h) in sizes {
                        let what = format!(
                            "{blend:?} {cov_param:?} op={with_opacity} σ={sigma_px:?} {w}x{h}"
                        );
                        let img = check_against_naive(&scene, w, h, &what);
                        lit += img.data.iter().filter(|&&x| x != 0.0).count();
                    }
                }
            }
        }
    }
    // The comparison is only meaningful if the images are not black.
    assert!(lit > 100_000, "{lit}");
}

#[test]
fn alpha_mode_saturates_and_still_matches() {
    // Many large opaque Gaussians: transmittance runs out and pixels stop early.
    let mut spec = SceneSpec::new(40, 30, 400, Blend::Alpha);
    spec.sigma_px = (5.0, 30.0);
    spec.with_opacity = false;
    let scene = random_scene(77, spec);
    check_against_naive(&scene, 40, 30, "saturated");
    check_against_naive(&scene, 81, 19, "saturated 81x19");
}

#[test]
fn faint_gaussians_match() {
    // Opacities around the 1/255 threshold: only the cores of some Gaussians show.
    for blend in [Blend::Sum, Blend::Alpha] {
        let mut spec = SceneSpec::new(40, 30, 300, blend);
        spec.with_opacity = true;
        spec.sigma_px = (0.5, 20.0);
        let mut scene = random_scene(21, spec);
        for o in scene.gaussians.opacity.as_mut().unwrap() {
            *o *= 0.02;
        }
        let img = check_against_naive(&scene, 40, 30, "faint");
        check_against_naive(&scene, 97, 61, "faint 97x61");
        assert!(img.data.iter().any(|&x| x != 0.0));
    }
}

/// Position, covariance parameters, colour and opacity of one hand-made Gaussian.
type Hand = ([f32; 2], [f32; 3], [f32; 3], f32);

fn hand_built(blend: Blend, cov_param: CovParam, gaussians: &[Hand]) -> Scene {
    let mut g = GaussianSet::default();
    for &(pos, cov, col, _) in gaussians {
        g.positions.push(pos);
        g.cov.push(cov);
        g.colors.push(col);
    }
    g.opacity = Some(gaussians.iter().map(|x| x.3).collect());
    Scene {
        weights: gsi::model::WeightRule::PerPixel,
        tone: None,
        width: 20,
        height: 16,
        blend,
        cov_param,
        gaussians: g,
    }
}

#[test]
fn degenerate_gaussians_stay_finite() {
    let (nan, inf) = (f32::NAN, f32::INFINITY);
    let covs = [
        [0.0, 0.0, 0.0],
        [1e30, 1e30, 1e30],
        [-1e30, 1e30, -1e30],
        [f32::MAX, f32::MIN, f32::MAX],
        [nan, nan, nan],
        [inf, -inf, inf],
        [nan, 0.1, inf],
        [0.1, 0.0999, 0.0],
        [-100.0, -100.0, 7.0],
        [1e-30, -1e-30, 1e-30],
        [0.05, 0.02, 0.05],
    ];
    let positions = [
        [0.5, 0.5],
        [0.0, 0.0],
        [1.0, 1.0],
        [-3.0, 0.5],
        [0.5, 40.0],
        [1e30, -1e30],
        [nan, 0.5],
        [0.5, inf],
        [-0.01, 1.01],
    ];
    let colors = [
        [1.0, 0.5, 0.0],
        [-3.0, 50.0, 1e30],
        [nan, inf, -inf],
        [2.0, -1.0, 0.25],
    ];
    let opacities = [1.0, 0.0, 0.5, nan, inf, -1.0, 3.0, 1.0 / 255.0, 0.003];
    let mut list = Vec::new();
    let mut k = 0usize;
    for &cov in &covs {
        for &pos in &positions {
            k += 1;
            list.push((
                pos,
                cov,
                colors[k % colors.len()],
                opacities[k % opacities.len()],
            ));
        }
    }
    for blend in [Blend::Sum, Blend::Alpha] {
        for cov_param in [CovParam::Cholesky, CovParam::LogScaleRotation] {
            let scene = hand_built(blend, cov_param, &list);
            for (w, h) in [(20, 16), (1, 1), (33, 7), (3, 70)] {
                check_against_naive(
                    &scene,
                    w,
                    h,
                    &format!("degenerate {blend:?} {cov_param:?} {w}x{h}"),
                );
            }
        }
    }
}

#[test]
fn far_away_gaussians_touch_nothing() {
    let list: Vec<_> = [
        [-2.0, 0.5],
        [3.0, 0.5],
        [0.5, -2.0],
        [0.5, 3.0],
        [1e20, 1e20],
        [-1e20, 0.5],
    ]
    .iter()
    .map(|&p| (p, [0.01, 0.0, 0.01], [1.0, 1.0, 1.0], 1.0))
    .collect();
    for blend in [Blend::Sum, Blend::Alpha] {
        let scene = hand_built(blend, CovParam::Cholesky, &list);
        let img = check_against_naive(&scene, 20, 16, "far away");
        assert!(img.data.iter().all(|&x| x == 0.0));
    }
}

#[test]
fn no_gaussians_or_no_opacity_is_black() {
    for blend in [Blend::Sum, Blend::Alpha] {
        let empty = hand_built(blend, CovParam::Cholesky, &[]);
        let img = render(&empty, 19, 23).unwrap();
        assert_eq!(img.data.len(), 19 * 23 * 3);
        assert!(img.data.iter().all(|&x| x == 0.0));
        assert!(img.to_rgb8().iter().all(|&x| x == 0));

        let mut spec = SceneSpec::new(30, 20, 50, blend);
        spec.with_opacity = true;
        let mut scene = random_scene(3, spec);
        scene.gaussians.opacity = Some(vec![0.0; 50]);
        let img = check_against_naive(&scene, 30, 20, "opacity 0");
        assert!(img.data.iter().all(|&x| x == 0.0));
    }
}

#[test]
fn centred_isotropic_gaussian() {
    // 33×33 output, centre of pixel 16 at u = v = 16.5 / 33 = 0.5; σ = 1/8 of the
    // image, 4.125 px, so that the variance 17.015625 px² and 3σ = 12.375 px are exact.
    let (color, opacity) = ([0.8, 0.4, 0.2], 0.75);
    let sigma = 0.125;
    for blend in [Blend::Sum, Blend::Alpha] {
        let scene = hand_built(
            blend,
            CovParam::Cholesky,
            &[([0.5, 0.5], [sigma, 0.0, sigma], color, opacity)],
        );
        let img = check_against_naive(&scene, 33, 33, "isotropic");
        let px = |i: i32, j: i32| -> [f32; 3] {
            let p = ((j * 33 + i) * 3) as usize;
            [img.data[p], img.data[p + 1], img.data[p + 2]]
        };
        // power = 0 at the centre, so alpha = opacity exactly (T = 1 in alpha mode).
        assert_eq!(px(16, 16), color.map(|c| c * opacity));
        // Mirror and transpose symmetry around the centre.
        for dj in 0..=16 {
            for di in 0..=16 {
                let v = px(16 + di, 16 + dj);
                for (i, j) in [
                    (16 - di, 16 + dj),
                    (16 + di, 16 - dj),
                    (16 - di, 16 - dj),
                    (16 + dj, 16 + di),
                ] {
                    assert_eq!(px(i, j), v, "({di},{dj}) vs ({i},{j})");
                }
            }
        }
        // Falls off away from the centre, and is cut by the box beyond 3σ = 12.375 px
        // (at 13 px, alpha would still be 0.0054 > 1/255).
        assert!(px(17, 16)[0] < px(16, 16)[0] && px(17, 16)[0] > 0.0);
        assert!(px(16 + 12, 16)[0] > 0.0);
        assert_eq!(px(16 + 13, 16), [0.0; 3]);
    }
}

#[test]
fn output_is_overwritten_and_buffer_length_checked() {
    let scene = random_scene(9, SceneSpec::new(24, 24, 40, Blend::Sum));
    let want = render(&scene, 24, 24).unwrap().data;
    let mut buf = vec![f32::NAN; 24 * 24 * 3];
    render_into(&scene, 24, 24, &mut buf).unwrap();
    assert_bits_eq(&buf, &want, "render_into");
    let mut short = vec![0.0; 24 * 24 * 3 - 1];
    let err = render_into(&scene, 24, 24, &mut short).unwrap_err();
    assert_eq!(err.kind(), ErrorKind::InvalidValue);
    assert_eq!(
        render(&scene, 0, 24).unwrap_err().kind(),
        ErrorKind::InvalidValue
    );
    assert_eq!(
        render(&scene, 24, 0).unwrap_err().kind(),
        ErrorKind::InvalidValue
    );
}

#[test]
fn inconsistent_scene_is_refused() {
    let mut scene = random_scene(9, SceneSpec::new(24, 24, 4, Blend::Sum));
    scene.gaussians.colors.pop();
    assert_eq!(
        render(&scene, 8, 8).unwrap_err().kind(),
        ErrorKind::InvalidValue
    );
}

#[test]
fn to_rgb8_clamps_then_rounds_half_up() {
    // The rule is floor(clamp(c)·255 + 0.5) in f32, which is neither truncation nor
    // `round` (half away from zero) nor round-half-even:
    // - 0.25·255 = 63.75 -> 64 and 0.5·255 = 127.5 -> 128 (truncation: 63, 127);
    // - c·255 = 0.49999997 (the float below 0.5): + 0.5 rounds to 1.0 in f32, so 1
    //   (`round` gives 0);
    // - c·255 = 0.5 exactly: 1 (round-half-even gives 0).
    let below_half = f32::from_bits(989_888_640);
    let half = f32::from_bits(989_888_641);
    assert_eq!(below_half * 255.0, 0.499_999_97);
    assert_eq!(half * 255.0, 0.5);
    let data = vec![
        -1.0,
        0.0,
        0.25,
        0.5,
        1.0,
        7.0,
        127.0 / 255.0,
        below_half,
        half,
        f32::from_bits(989_888_637),
        f32::NAN,
        f32::INFINITY,
    ];
    let img = RgbImage {
        width: 4,
        height: 1,
        data,
    };
    assert_eq!(
        img.to_rgb8(),
        vec![0, 0, 64, 128, 255, 255, 127, 1, 1, 0, 0, 255]
    );
    assert_eq!(
        img.to_rgba8(),
        vec![0, 0, 64, 255, 128, 255, 255, 255, 127, 1, 1, 255, 0, 0, 255, 255]
    );
}

/// `r` refused for asking too much rendering work (its `Ok` value is never printed: an
/// image of 300×300 would flood the report).
fn refused<T>(r: Result<T, gsi::Error>) {
    match r {
        Ok(_) => panic!("rendered past the work limit"),
        Err(e) => {
            assert_eq!(e.kind(), gsi::ErrorKind::LimitExceeded, "{e}");
            assert!(e.to_string().contains("Gaussian-pixel pairs"), "{e}");
        }
    }
}

/// A valid 176-byte file (GHDR 8×8, 59,136 Gaussians at 0-bit depths: every Gaussian the
/// same, covering the image) asks for 59,136 Gaussian–pixel pairs per output pixel. At
/// its own size it renders; at 300×300 and 1000×1000 it is refused by the render-work
/// limit, before any pixel, through every decoding entry point.
#[test]
fn a_tiny_file_cannot_ask_for_hours_of_rendering() {
    let bytes = std::fs::read(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/corpus/valid/fuzz-decode-render-work.gsi"
    ))
    .unwrap();
    assert_eq!(bytes.len(), 176);
    let scene = gsi::format::read_file(&bytes[..], Limits::default())
        .unwrap()
        .records
        .to_scene();
    assert_eq!(scene.gaussians.len(), 59_136);
    gsi::decode(&bytes[..], 8, 8).unwrap();
    for side in [300, 1000] {
        let t = std::time::Instant::now();
        refused(gsi::decode(&bytes[..], side, side));
        refused(gsi::render::render(&scene, side, side));
        let mut buf = vec![0u8; (side * side * 3) as usize];
        refused(gsi::render::render_rgb8_into(&scene, side, side, &mut buf));
        let mut reader = gsi::Reader::new(&bytes[..]).unwrap();
        reader.set_output_size(side, side).unwrap();
        let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
        refused(reader.read_image(&mut buf));
        assert!(t.elapsed().as_secs_f64() < 2.0, "{:?}", t.elapsed());
    }
    // A caller who trusts the file can raise the bound.
    let mut reader = gsi::Reader::with_limits(
        &bytes[..],
        Limits {
            max_render_work: u64::MAX,
            ..Limits::default()
        },
    )
    .unwrap();
    reader.set_output_size(20, 20).unwrap();
    let mut buf = vec![0u8; reader.output_buffer_size().unwrap()];
    reader.read_image(&mut buf).unwrap();
}
