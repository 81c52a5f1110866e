//! Image-quality metrics (`gsi::metrics`): the conventions reproduced against the
//! reference table of `shared/data/README.md`, golden values from scikit-image
//! (`tools/golden_metrics.py`), every loss gradient against central finite differences,
//! and `gsi compare` end to end.

use gsi::metrics::{self, MetricError, Rgb8};

#[path = "../../tests/common/mod.rs"]
mod common;

use common::Lcg;

/// An interleaved RGB reference in `[0, 1]` with some structure, and an image that is
/// the reference plus noise (correlated with it, as a fit is).
fn pair(w: usize, h: usize, seed: u64) -> (Vec<f64>, Vec<f64>) {
    let mut rng = Lcg(seed);
    let mut reference = Vec::with_capacity(w * h * 3);
    for y in 0..h {
        for x in 0..w {
            for c in 0..3 {
                let v = 0.5
                    + 0.3 * ((x as f64 / 7.0 + c as f64).sin() * (y as f64 / 5.0).cos())
                    + 0.15 * (rng.next() - 0.5);
                reference.push(v);
            }
        }
    }
    let img = reference
        .iter()
        .map(|&v| (v + 0.25 * (rng.next() - 0.5)).clamp(0.0, 1.0))
        .collect();
    (img, reference)
}

type LossFn = fn(&[f64], &[f64], u32, u32) -> Result<(f64, Vec<f64>), MetricError>;

/// Central differences at a sample of indices (corners and edges included); every
/// sampled component must agree within 1e-3, relative to the larger of the two
/// derivatives or, for derivatives near zero, to a thousandth of the largest one.
fn check_gradient(loss: LossFn, w: usize, h: usize, seed: u64) {
    let (img, reference) = pair(w, h, seed);
    let (_, grad) = loss(&img, &reference, w as u32, h as u32).unwrap();
    let gmax = grad.iter().fold(0.0f64, |m, g| m.max(g.abs()));
    assert!(gmax > 0.0);
    let n = img.len();
    let mut rng = Lcg(seed ^ 0x5eed);
    let mut idx: Vec<usize> = vec![0, 1, 2, n - 1, 3 * (w - 1), 3 * w * (h / 2) + 4];
    idx.extend((0..60).map(|_| (rng.next() * n as f64) as usize));
    // Large enough that rounding in the loss (a mean of ~10⁵ terms) stays far below the
    // smallest derivatives checked; the truncation error is O(step²).
    let step = 1e-4;
    let mut worst = 0.0f64;
    for &i in &idx {
        let mut p = img.clone();
        p[i] += step;
        let (up, _) = loss(&p, &reference, w as u32, h as u32).unwrap();
        p[i] -= 2.0 * step;
        let (down, _) = loss(&p, &reference, w as u32, h as u32).unwrap();
        let fd = (up - down) / (2.0 * step);
        let scale = fd.abs().max(grad[i].abs()).max(1e-3 * gmax);
        let rel = (fd - grad[i]).abs() / scale;
        worst = worst.max(rel);
        assert!(
            rel <= 1e-3,
            "{w}x{h} index {i}: finite difference {fd:e}, analytic {:e} (relative {rel:e})",
            grad[i]
        );
    }
    eprintln!(
        "{w}x{h}: worst relative gradient error {worst:.1e} over {} components",
        idx.len()
    );
}

#[test]
fn ssim_gradient_matches_finite_differences() {
    check_gradient(metrics::ssim_loss_grad::<f64>, 24, 20, 1);
    check_gradient(metrics::ssim_loss_grad::<f64>, 11, 13, 2);
}

#[test]
fn ms_ssim_gradient_matches_finite_differences() {
    // Five scales (180 ≥ 176), three (50: 50 → 25 → 12), and one (24: plain SSIM).
    check_gradient(metrics::ms_ssim_loss_grad::<f64>, 180, 180, 3);
    check_gradient(metrics::ms_ssim_loss_grad::<f64>, 50, 61, 4);
    check_gradient(metrics::ms_ssim_loss_grad::<f64>, 24, 20, 5);
}

#[test]
fn ms_ssim_of_a_small_image_is_ssim() {
    let (img, reference) = pair(24, 20, 6);
    let a = metrics::ssim_loss_grad(&img, &reference, 24, 20).unwrap();
    let b = metrics::ms_ssim_loss_grad(&img, &reference, 24, 20).unwrap();
    assert!((a.0 - b.0).abs() < 1e-12);
    assert!(a.1.iter().zip(&b.1).all(|(x, y)| (x - y).abs() < 1e-15));
}

/// The `f32` loss the encoder uses agrees with the `f64` one that was checked above.
#[test]
fn f32_loss_agrees_with_f64() {
    let (w, h) = (200, 180);
    let (img, reference) = pair(w, h, 7);
    let img32: Vec<f32> = img.iter().map(|&v| v as f32).collect();
    let ref32: Vec<f32> = reference.iter().map(|&v| v as f32).collect();
    for (l64, l32) in [
        (
            metrics::ssim_loss_grad::<f64> as LossFn,
            metrics::ssim_loss_grad::<f32> as fn(&[f32], &[f32], u32, u32) -> _,
        ),
        (
            metrics::ms_ssim_loss_grad::<f64>,
            metrics::ms_ssim_loss_grad::<f32>,
        ),
    ] {
        let (v64, g64) = l64(&img, &reference, w as u32, h as u32).unwrap();
        let (v32, g32) = l32(&img32, &ref32, w as u32, h as u32).unwrap();
        assert!((v64 - v32 as f64).abs() < 1e-5, "{v64} {v32}");
        let gmax = g64.iter().fold(0.0f64, |m, g| m.max(g.abs()));
        let err = g64
            .iter()
            .zip(&g32)
            .fold(0.0f64, |m, (a, &b)| m.max((a - b as f64).abs()));
        assert!(
            err <= 1e-3 * gmax,
            "gradient error {err:e}, largest {gmax:e}"
        );
    }
}

/// `1 − loss` on an 8-bit image scaled to `[0, 1]` is the metric on the bytes: the loss
/// optimises what `gsi compare` reports.
#[test]
fn loss_is_one_minus_metric() {
    for (w, h) in [(40, 30), (190, 177)] {
        let (img, reference) = pair(w, h, 8);
        let q = |v: &[f64]| -> Vec<u8> { v.iter().map(|&x| (x * 255.0).round() as u8).collect() };
        let (qi, qr) = (q(&img), q(&reference));
        let f = |v: &[u8]| -> Vec<f64> { v.iter().map(|&x| x as f64 / 255.0).collect() };
        let (fi, fr) = (f(&qi), f(&qr));
        let (a, b) = (
            Rgb8::new(w as u32, h as u32, &qr).unwrap(),
            Rgb8::new(w as u32, h as u32, &qi).unwrap(),
        );
        let s = metrics::ssim(a, b).unwrap();
        let (l, _) = metrics::ssim_loss_grad(&fi, &fr, w as u32, h as u32).unwrap();
        assert!((1.0 - l - s).abs() < 1e-12, "{s} {l}");
        let m = metrics::ms_ssim(a, b).unwrap();
        let (l, _) = metrics::ms_ssim_loss_grad(&fi, &fr, w as u32, h as u32).unwrap();
        assert!((1.0 - l - m).abs() < 1e-12, "{m} {l}");
    }
}

#[test]
fn refusals_are_errors_not_panics() {
    let px = [0u8; 12 * 12 * 3];
    assert_eq!(Rgb8::new(0, 5, &[]).unwrap_err(), MetricError::Empty);
    assert!(matches!(
        Rgb8::new(12, 12, &px[1..]),
        Err(MetricError::BufferLength { .. })
    ));
    let a = Rgb8::new(12, 12, &px).unwrap();
    let b = Rgb8::new(6, 24, &px).unwrap();
    for r in [
        metrics::psnr(a, b),
        metrics::ssim(a, b),
        metrics::ms_ssim(a, b),
        metrics::loe(a, b),
    ] {
        assert!(matches!(r, Err(MetricError::SizeMismatch { .. })));
    }
    assert!(metrics::full_reference(a, b).is_err());
    let tiny = Rgb8::new(10, 10, &px[..300]).unwrap();
    assert!(matches!(
        metrics::ssim(tiny, tiny),
        Err(MetricError::TooSmall { min: 11, .. })
    ));
    // DE, EME, PSNR and LOE need no window.
    assert_eq!(metrics::psnr(tiny, tiny).unwrap(), f64::INFINITY);
    assert_eq!(metrics::loe(tiny, tiny).unwrap(), 0.0);
    let _ = metrics::no_reference(tiny);
    let f = [0.5f32; 12 * 12 * 3];
    assert!(metrics::ssim_loss_grad(&f[..300], &f[..300], 10, 10).is_err());
    assert!(metrics::ms_ssim_loss_grad(&f, &f[1..], 12, 12).is_err());
    // Identical images: SSIM 1 is the maximum, the gradient vanishes.
    let (l, g) = metrics::ssim_loss_grad(&f, &f, 12, 12).unwrap();
    assert!(
        l.abs() < 1e-6 && g.iter().all(|v| v.abs() < 1e-4),
        "{l} {g:?}"
    );
    let d: Vec<f64> = (0..12 * 12 * 3).map(|i| (i % 7) as f64 / 7.0).collect();
    let (l, g) = metrics::ms_ssim_loss_grad(&d, &d, 12, 12).unwrap();
    assert!(
        l.abs() < 1e-12 && g.iter().all(|v| v.abs() < 1e-12),
        "{l} {g:?}"
    );
    // An all-black image cannot be brightened to the reference's mean: left as it is.
    let black = [0u8; 12 * 12 * 3];
    let white = [255u8; 12 * 12 * 3];
    let (black, white) = (
        Rgb8::new(12, 12, &black).unwrap(),
        Rgb8::new(12, 12, &white).unwrap(),
    );
    assert_eq!(
        metrics::gt_mean(white, black).unwrap(),
        vec![0u8; 12 * 12 * 3]
    );
    let r = metrics::full_reference(white, black).unwrap();
    assert!(r.psnr == 0.0 && r.psnr_gm == 0.0);
}

#[test]
fn psnr_of_a_known_error() {
    // Every byte off by 5: MSE 25.
    let a = vec![100u8; 20 * 20 * 3];
    let b = vec![105u8; 20 * 20 * 3];
    let (a, b) = (
        Rgb8::new(20, 20, &a).unwrap(),
        Rgb8::new(20, 20, &b).unwrap(),
    );
    let want = 10.0 * (255.0f64 * 255.0 / 25.0).log10();
    assert!((metrics::psnr(a, b).unwrap() - want).abs() < 1e-12);
    let r = metrics::full_reference(a, a).unwrap();
    assert_eq!(
        (r.psnr, r.ssim, r.ms_ssim, r.loe),
        (f64::INFINITY, 1.0, 1.0, 0.0)
    );
}

mod on_shared_data {
    use super::*;
    use std::path::{Path, PathBuf};

    /// `../shared/data` beside the repository, or `None` (with a note) where it is absent.
    fn data_dir() -> Option<PathBuf> {
        let d = common::repo_root().join("../shared/data");
        if d.join("LOL/eval15/low").is_dir() && d.join("kodak").is_dir() {
            Some(d)
        } else {
            eprintln!("note: {} absent; skipping", d.display());
            None
        }
    }

    pub(super) struct Img {
        pub w: u32,
        pub h: u32,
        pub data: Vec<u8>,
    }
    impl Img {
        pub fn view(&self) -> Rgb8<'_> {
            Rgb8::new(self.w, self.h, &self.data).unwrap()
        }
        fn map(&self, f: impl Fn(u8) -> u8) -> Img {
            Img {
                w: self.w,
                h: self.h,
                data: self.data.iter().map(|&v| f(v)).collect(),
            }
        }
        fn crop(&self, cw: u32, ch: u32) -> Img {
            let mut data = Vec::new();
            for y in 0..ch as usize {
                let start = y * self.w as usize * 3;
                data.extend_from_slice(&self.data[start..start + cw as usize * 3]);
            }
            Img { w: cw, h: ch, data }
        }
        /// `clip(v + ((7x + 13y + 5c) mod 21) − 10)`, as in `tools/golden_metrics.py`.
        fn perturbed(&self) -> Img {
            let mut data = self.data.clone();
            for (i, v) in data.iter_mut().enumerate() {
                let (c, p) = (i % 3, i / 3);
                let (x, y) = (p % self.w as usize, p / self.w as usize);
                let d = ((7 * x + 13 * y + 5 * c) % 21) as i32 - 10;
                *v = (*v as i32 + d).clamp(0, 255) as u8;
            }
            Img {
                w: self.w,
                h: self.h,
                data,
            }
        }
    }

    fn load(path: &Path) -> Img {
        let img = image::open(path).unwrap().to_rgb8();
        Img {
            w: img.width(),
            h: img.height(),
            data: img.into_raw(),
        }
    }

    /// `round(255 · (v/255)^γ)`, half to even as numpy.
    fn gamma(img: &Img, g: f64) -> Img {
        img.map(|v| (255.0 * (v as f64 / 255.0).powf(g)).round_ties_even() as u8)
    }

    /// Rows of the README's LOL table that need no external code: the inputs
    /// themselves, gamma 0.4, and gamma chosen per image to bring the mean gray
    /// (BT.601 luma) to 0.5. Each of our means over the 15 pairs must round to the
    /// README's figure (within one unit of its last digit).
    #[test]
    fn readme_table_is_reproduced() {
        let Some(dir) = data_dir() else { return };
        let lol = dir.join("LOL/eval15");
        let mut names: Vec<_> = std::fs::read_dir(lol.join("low"))
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        names.sort();
        assert_eq!(names.len(), 15);
        #[rustfmt::skip]
        let readme: [(&str, [f64; 7]); 3] = [
            ("input", [7.77, 0.195, 18.78, 0.492, 0.0, 4.76, 43.1]),
            ("gamma 0.4", [14.59, 0.621, 22.25, 0.634, 50.2, 6.20, 39.3]),
            ("auto-gamma", [16.33, 0.631, 19.60, 0.650, 68.7, 6.26, 38.7]),
        ];
        let mut sums = [[0.0f64; 7]; 3];
        for n in &names {
            let low = load(&lol.join("low").join(n));
            let high = load(&lol.join("high").join(n));
            let mean_gray = metrics::luma(low.view()).iter().sum::<f64>() / (low.w * low.h) as f64;
            let auto = (0.5f64).ln() / (mean_gray / 255.0).ln();
            let outputs = [low.map(|v| v), gamma(&low, 0.4), gamma(&low, auto)];
            for (row, out) in outputs.iter().enumerate() {
                let r = metrics::full_reference(high.view(), out.view()).unwrap();
                // LOE is input → output, not reference → output.
                let loe = metrics::loe(low.view(), out.view()).unwrap();
                let v = [r.psnr, r.ssim, r.psnr_gm, r.ssim_gm, loe, r.de, r.eme];
                for (s, x) in sums[row].iter_mut().zip(v) {
                    *s += x / names.len() as f64;
                }
            }
        }
        let cols = ["PSNR", "SSIM", "PSNR-gm", "SSIM-gm", "LOE", "DE", "EME"];
        let tol = [0.01, 0.001, 0.01, 0.001, 0.1, 0.01, 0.1];
        eprintln!("LOL eval15, mean over 15 pairs: ours (README)");
        for ((name, want), got) in readme.iter().zip(&sums) {
            let cells: Vec<String> = (0..7)
                .map(|i| format!("{} {:.4} ({})", cols[i], got[i], want[i]))
                .collect();
            eprintln!("  {name:<11} {}", cells.join(", "));
        }
        for ((name, want), got) in readme.iter().zip(&sums) {
            for i in 0..7 {
                assert!(
                    (got[i] - want[i]).abs() <= tol[i] + 1e-9,
                    "{name} {}: ours {:.4}, README {}",
                    cols[i],
                    got[i],
                    want[i]
                );
            }
        }
    }

    /// (image, reference or "" for the perturbed image itself, top-left crop width and
    /// height or 0 for none, PSNR, SSIM, MS-SSIM),
    /// from tools/golden_metrics.py (scikit-image 0.26.0).
    #[rustfmt::skip]
    const GOLDEN: [(&str, &str, u32, u32, f64, f64, f64); 10] = [
        ("LOL/eval15/low/1.png", "LOL/eval15/high/1.png", 0, 0, 7.2193280711, 0.2339772549, 0.5331287519),
        ("LOL/eval15/low/22.png", "LOL/eval15/high/22.png", 0, 0, 6.1071199120, 0.1885850862, 0.4971708371),
        ("LOL/eval15/low/111.png", "LOL/eval15/high/111.png", 0, 0, 5.6122312183, 0.1913990841, 0.5227122942),
        ("kodak/kodim01.png", "", 0, 0, 32.4976173507, 0.8993025570, 0.9905708127),
        ("kodak/kodim04.png", "", 0, 0, 32.4977049975, 0.7828699378, 0.9778825662),
        ("kodak/kodim23.png", "", 0, 0, 32.5396073434, 0.7302033447, 0.9727810300),
        ("kodak/kodim01.png", "", 150, 90, 32.4898063498, 0.8831821887, 0.9889340782),
        ("kodak/kodim01.png", "", 60, 47, 32.4914507169, 0.9227965521, 0.9894895404),
        ("kodak/kodim01.png", "", 40, 30, 32.4873984362, 0.8894944707, 0.9805881057),
        ("kodak/kodim01.png", "", 21, 25, 32.4959927547, 0.9236069095, 0.9236069095),
    ];

    /// The acceptance criterion: |ΔPSNR| ≤ 0.01 dB and |ΔSSIM| ≤ 0.002 against
    /// scikit-image (MS-SSIM held to the same 0.002 against the script's numpy version).
    #[test]
    fn golden_values_from_scikit_image() {
        let Some(dir) = data_dir() else { return };
        for (img, reference, cw, ch, psnr, ssim, ms_ssim) in GOLDEN {
            let mut a = load(&dir.join(img));
            if cw > 0 {
                a = a.crop(cw, ch);
            }
            let (r, o) = if reference.is_empty() {
                let p = a.perturbed();
                (a, p)
            } else {
                (load(&dir.join(reference)), a)
            };
            let got = [
                metrics::psnr(r.view(), o.view()).unwrap(),
                metrics::ssim(r.view(), o.view()).unwrap(),
                metrics::ms_ssim(r.view(), o.view()).unwrap(),
            ];
            let d = [got[0] - psnr, got[1] - ssim, got[2] - ms_ssim];
            eprintln!(
                "{img} {cw}x{ch}: ΔPSNR {:+.2e} dB, ΔSSIM {:+.2e}, ΔMS-SSIM {:+.2e}",
                d[0], d[1], d[2]
            );
            assert!(d[0].abs() <= 0.01 && d[1].abs() <= 0.002 && d[2].abs() <= 0.002);
            // The implementations agree far closer than the criterion: same arithmetic.
            assert!(d.iter().all(|x| x.abs() < 1e-8), "{d:?}");
        }
    }

    #[test]
    fn compare_command() {
        use std::process::Command;
        let dir = std::env::temp_dir().join(format!("gsi-compare-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (w, h) = (48u32, 40u32);
        let (img, reference) = super::pair(w as usize, h as usize, 9);
        let save = |name: &str, v: &[f64], w: u32, h: u32| {
            let bytes: Vec<u8> = v.iter().map(|&x| (x * 255.0).round() as u8).collect();
            let p = dir.join(name);
            image::RgbImage::from_raw(w, h, bytes)
                .unwrap()
                .save(&p)
                .unwrap();
            p
        };
        let a = save("ref.png", &reference, w, h);
        let b = save("img.png", &img, w, h);
        let c = save("other.png", &img[..(w * 30 * 3) as usize], w, 30);
        let gsi = |args: &[&std::ffi::OsStr]| {
            Command::new(env!("CARGO_BIN_EXE_gsi"))
                .arg("compare")
                .args(args)
                .output()
                .unwrap()
        };

        let out = gsi(&[a.as_os_str(), b.as_os_str(), "--json".as_ref()]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        let keys: Vec<&str> = v.as_object().unwrap().keys().map(|k| k.as_str()).collect();
        let mut want = [
            "psnr", "ssim", "ms_ssim", "psnr_gm", "ssim_gm", "loe", "de", "eme",
        ];
        want.sort();
        let mut keys_sorted = keys.clone();
        keys_sorted.sort();
        assert_eq!(keys_sorted, want);
        assert!(v["psnr"].as_f64().unwrap() > 10.0);

        // Identical images: PSNR is infinite, printed as null.
        let out = gsi(&[a.as_os_str(), a.as_os_str(), "--json".as_ref()]);
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert!(v["psnr"].is_null() && v["ssim"].as_f64() == Some(1.0));

        let out = gsi(&[b.as_os_str(), "--no-reference".as_ref(), "--json".as_ref()]);
        assert!(out.status.success());
        let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(v.as_object().unwrap().len(), 2);
        assert!(v["de"].as_f64().is_some() && v["eme"].as_f64().is_some());

        // Text: one aligned line per metric.
        let out = gsi(&[a.as_os_str(), b.as_os_str()]);
        let text = String::from_utf8(out.stdout).unwrap();
        assert_eq!(text.lines().count(), 8, "{text}");
        assert!(text.lines().all(|l| l.len() >= 19));

        // Different sizes: exit 1, one line naming the problem.
        let out = gsi(&[a.as_os_str(), c.as_os_str()]);
        assert_eq!(out.status.code(), Some(1));
        let err = String::from_utf8(out.stderr).unwrap();
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            err.contains("size mismatch") && err.contains("48x40"),
            "{err}"
        );

        // A missing image is a usage error.
        assert_eq!(gsi(&[a.as_os_str()]).status.code(), Some(2));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

/// A workspace reused across calls and sizes gives exactly the free functions' results.
#[test]
fn workspace_reuse_is_exact() {
    let mut ws = metrics::LossWorkspace::<f32>::new();
    for (w, h, seed) in [(190, 180, 11), (24, 20, 12), (61, 50, 13), (190, 180, 14)] {
        let (img, reference) = pair(w, h, seed);
        let img: Vec<f32> = img.iter().map(|&v| v as f32).collect();
        let reference: Vec<f32> = reference.iter().map(|&v| v as f32).collect();
        let (w, h) = (w as u32, h as u32);
        let mut grad = vec![f32::NAN; img.len()];
        let l = ws
            .ssim_loss_grad(&img, &reference, w, h, &mut grad)
            .unwrap();
        assert_eq!(
            (l, grad.clone()),
            metrics::ssim_loss_grad(&img, &reference, w, h).unwrap()
        );
        let l = ws
            .ms_ssim_loss_grad(&img, &reference, w, h, &mut grad)
            .unwrap();
        assert_eq!(
            (l, grad.clone()),
            metrics::ms_ssim_loss_grad(&img, &reference, w, h).unwrap()
        );
        assert!(ws
            .ssim_loss_grad(&img, &reference, w, h, &mut grad[1..])
            .is_err());
    }
}

/// Timing of the losses at 768×512 on one core (run with `--ignored --nocapture`).
#[test]
#[ignore]
fn loss_timing() {
    let (w, h) = (768, 512);
    let (img, reference) = pair(w, h, 10);
    let img: Vec<f32> = img.iter().map(|&v| v as f32).collect();
    let reference: Vec<f32> = reference.iter().map(|&v| v as f32).collect();
    let (w, h) = (w as u32, h as u32);
    let runs = 20;
    // On-CPU time of this thread (Linux), which a busy shared machine inflates less
    // than wall time.
    let cpu_ns = || -> Option<u64> {
        let s = std::fs::read_to_string("/proc/thread-self/schedstat").ok()?;
        s.split_whitespace().next()?.parse().ok()
    };
    let time = |name: &str, f: &mut dyn FnMut()| {
        f();
        let (t, c) = (std::time::Instant::now(), cpu_ns());
        for _ in 0..runs {
            f();
        }
        let ms = t.elapsed().as_secs_f64() * 1e3 / runs as f64;
        let cpu = cpu_ns()
            .zip(c)
            .map(|(b, a)| format!(", {:.1} ms on CPU", (b - a) as f64 / 1e6 / runs as f64));
        eprintln!("{name} {w}x{h}: {ms:.1} ms wall{}", cpu.unwrap_or_default());
    };
    time("ssim_loss_grad", &mut || {
        std::hint::black_box(metrics::ssim_loss_grad(&img, &reference, w, h).unwrap());
    });
    time("ms_ssim_loss_grad", &mut || {
        std::hint::black_box(metrics::ms_ssim_loss_grad(&img, &reference, w, h).unwrap());
    });
    let mut ws = metrics::LossWorkspace::new();
    let mut grad = vec![0f32; img.len()];
    time("LossWorkspace::ssim_loss_grad", &mut || {
        std::hint::black_box(
            ws.ssim_loss_grad(&img, &reference, w, h, &mut grad)
                .unwrap(),
        );
    });
    time("LossWorkspace::ms_ssim_loss_grad", &mut || {
        std::hint::black_box(
            ws.ms_ssim_loss_grad(&img, &reference, w, h, &mut grad)
                .unwrap(),
        );
    });
}
