//! NIQE (`gsi::metrics::niqe`): golden values from BasicSR's translation of LIVE's MATLAB
//! release (`tools/golden_niqe.py`), degenerate and small images, and a sanity check that
//! noise makes an image less natural.

use gsi::metrics::{self, MetricError, Rgb8, NIQE_PATCH};

#[path = "../../tests/common/mod.rs"]
mod common;

use common::Lcg;

fn niqe_of(w: u32, h: u32, data: &[u8]) -> Result<f64, MetricError> {
    metrics::niqe(Rgb8::new(w, h, data).unwrap())
}

#[test]
fn smaller_than_a_patch_is_an_error() {
    for (w, h) in [(95, 200), (200, 95), (95, 95), (1, 1), (48, 40)] {
        let data = vec![128u8; w * h * 3];
        let r = niqe_of(w as u32, h as u32, &data);
        assert_eq!(
            r,
            Err(MetricError::TooSmall {
                width: w as u32,
                height: h as u32,
                min: NIQE_PATCH
            })
        );
        let msg = r.unwrap_err().to_string();
        assert!(msg.contains("96x96"), "{msg}");
        let rep = metrics::no_reference(Rgb8::new(w as u32, h as u32, &data).unwrap());
        assert_eq!(rep.niqe, None);
    }
}

#[test]
fn degenerate_images_are_finite() {
    let (w, h) = (288usize, 192usize);
    let flat = |v: u8| niqe_of(w as u32, h as u32, &vec![v; w * h * 3]).unwrap();
    let (black, white, grey) = (flat(0), flat(255), flat(128));
    // A flat image has all-zero MSCN coefficients whatever its level.
    assert!(black.is_finite() && black > 0.0, "{black}");
    assert_eq!(black, white);
    assert_eq!(black, grey);

    let mut rng = Lcg(7);
    let noise: Vec<u8> = (0..w * h * 3).map(|_| (rng.next() * 256.0) as u8).collect();
    let n = niqe_of(w as u32, h as u32, &noise).unwrap();
    assert!(n.is_finite() && n > 0.0, "{n}");

    // One patch (no covariance) and one patch with the rest flat.
    let one = niqe_of(96, 96, &noise[..96 * 96 * 3]).unwrap();
    assert!(one.is_finite() && one > 0.0, "{one}");
    let mut half_flat = noise.clone();
    half_flat[..w * 3 * 96].fill(40);
    let hf = niqe_of(w as u32, h as u32, &half_flat).unwrap();
    assert!(hf.is_finite() && hf > 0.0, "{hf}");
    // A single bright pixel on black: MSCN of one sign only in its patches.
    let mut dot = vec![0u8; w * h * 3];
    dot[(100 * w + 150) * 3..(100 * w + 151) * 3].fill(255);
    let d = niqe_of(w as u32, h as u32, &dot).unwrap();
    assert!(d.is_finite() && d > 0.0, "{d}");
}

/// Rows and columns beyond the last whole patch are not used.
#[test]
fn partial_patches_are_cropped() {
    let (w, h) = (250usize, 140usize);
    let mut rng = Lcg(3);
    let img: Vec<u8> = (0..w * h * 3)
        .map(|i| {
            let (x, y) = ((i / 3) % w, (i / 3) / w);
            (128.0
                + 60.0 * ((x as f64 / 9.0).sin() + (y as f64 / 13.0).cos()) * 0.5
                + 20.0 * rng.normal())
            .clamp(0.0, 255.0) as u8
        })
        .collect();
    let (cw, ch) = (192usize, 96usize);
    let mut crop = Vec::new();
    for y in 0..ch {
        crop.extend_from_slice(&img[y * w * 3..(y * w + cw) * 3]);
    }
    assert_eq!(
        niqe_of(w as u32, h as u32, &img).unwrap(),
        niqe_of(cw as u32, ch as u32, &crop).unwrap()
    );
}

mod on_shared_data {
    use super::*;
    use std::path::{Path, PathBuf};

    /// BasicSR 1.4.2's `niqe()` (LIVE's MATLAB release translated; LIVE's pristine
    /// model) in float64 on the BT.601 luma rounded to 8 bits, from
    /// `tools/golden_niqe.py`: (folder, file, stock, exact). "Exact" sets MSCN
    /// coefficients below 1e-9 to 0 first: rounding noise in flat areas (LOL high 1 and
    /// 111, kodim23 have some) that MATLAB's AGGD fit counts as signed samples, and that
    /// gsi computes as exact zeros.
    const GOLDEN: [(&str, &str, f64, f64); 9] = [
        (
            "LOL/eval15/low",
            "1.png",
            6.43490304464265,
            6.43490304464265,
        ),
        (
            "LOL/eval15/low",
            "22.png",
            6.6916690710406055,
            6.6916690710406055,
        ),
        (
            "LOL/eval15/low",
            "111.png",
            8.652034892860435,
            8.652034892860435,
        ),
        (
            "LOL/eval15/high",
            "1.png",
            5.158980366533673,
            5.155668483189789,
        ),
        (
            "LOL/eval15/high",
            "22.png",
            3.528957714771872,
            3.528957714771872,
        ),
        (
            "LOL/eval15/high",
            "111.png",
            4.4725625641224855,
            4.466897150176268,
        ),
        (
            "kodak",
            "kodim01.png",
            3.4489617432928688,
            3.4489617432928688,
        ),
        ("kodak", "kodim04.png", 2.452169881131828, 2.452169881131828),
        ("kodak", "kodim23.png", 4.245069846585851, 4.246903153153686),
    ];
    /// kodim01 with rows 0..192, columns 0..288 black: two patches at each scale have
    /// all-zero MSCN, whose AGGD fits MATLAB leaves NaN (nanmean / nancov then skip them).
    /// Level 0 has no rounding noise: stock and exact agree.
    const GOLDEN_BLACK_BOX: f64 = 8.284095573953367;

    /// Against the stock reference: NIQE is read to two decimals, and the rounding noise
    /// of flat areas moves the reference itself by up to 0.006 (its float32 run moves
    /// by as much).
    const TOLERANCE: f64 = 0.01;
    /// Against the exact reference: both sides compute the same formulas in float64 (the
    /// half-scale image is exact here, rounded in BasicSR), so they agree to rounding
    /// unless an AGGD shape, a 0.001 grid choice, flips on a tie: none does here.
    const SAME_ARITHMETIC: f64 = 1e-9;

    fn data_dir() -> Option<PathBuf> {
        let d = common::repo_root().join("../shared/data");
        if d.join("LOL/eval15/low").is_dir() && d.join("kodak").is_dir() {
            Some(d)
        } else {
            eprintln!("note: {} absent; skipping", d.display());
            None
        }
    }

    fn load(path: &Path) -> (u32, u32, Vec<u8>) {
        let img = image::open(path).unwrap().to_rgb8();
        (img.width(), img.height(), img.into_raw())
    }

    #[test]
    fn golden_basicsr_matlab() {
        let Some(dir) = data_dir() else { return };
        let mut worst = 0.0f64;
        let mut check = |label: &str, got: f64, stock: f64, exact: f64| {
            eprintln!(
                "{label}: {got:.10} vs stock {stock:.10} (Δ {:+.2e}), exact {exact:.10} (Δ {:+.2e})",
                got - stock,
                got - exact
            );
            assert!(
                (got - stock).abs() <= TOLERANCE,
                "{label}: {got} vs {stock}"
            );
            worst = worst.max((got - exact).abs());
        };
        for (folder, name, stock, exact) in GOLDEN {
            let (w, h, data) = load(&dir.join(folder).join(name));
            let got = niqe_of(w, h, &data).unwrap();
            check(&format!("{folder}/{name}"), got, stock, exact);
        }
        let (w, h, mut data) = load(&dir.join("kodak/kodim01.png"));
        for y in 0..192 {
            data[y * w as usize * 3..(y * w as usize + 288) * 3].fill(0);
        }
        let got = niqe_of(w, h, &data).unwrap();
        check(
            "kodim01 + black box",
            got,
            GOLDEN_BLACK_BOX,
            GOLDEN_BLACK_BOX,
        );
        assert!(worst < SAME_ARITHMETIC, "worst {worst:e}");
    }

    /// Strong Gaussian noise makes a photograph less natural.
    #[test]
    fn noise_raises_niqe() {
        let Some(dir) = data_dir() else { return };
        for name in ["kodim01.png", "kodim23.png"] {
            let (w, h, data) = load(&dir.join("kodak").join(name));
            let clean = niqe_of(w, h, &data).unwrap();
            let mut rng = Lcg(11);
            let noisy: Vec<u8> = data
                .iter()
                .map(|&v| (v as f64 + 30.0 * rng.normal()).round().clamp(0.0, 255.0) as u8)
                .collect();
            let n = niqe_of(w, h, &noisy).unwrap();
            eprintln!("{name}: clean {clean:.4}, σ = 30 noise {n:.4}");
            assert!(n > clean + 2.0, "{name}: {clean} -> {n}");
        }
    }

    /// `gsi compare --no-reference` reports the library's NIQE, in JSON and in text.
    #[test]
    fn compare_command_reports_niqe() {
        use std::process::Command;
        let Some(dir) = data_dir() else { return };
        let path = dir.join("kodak/kodim23.png");
        let (w, h, data) = load(&path);
        let want = niqe_of(w, h, &data).unwrap();
        let run = |json: bool| {
            let mut c = Command::new(env!("CARGO_BIN_EXE_gsi"));
            c.arg("compare").arg(&path).arg("--no-reference");
            if json {
                c.arg("--json");
            }
            let out = c.output().unwrap();
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            String::from_utf8(out.stdout).unwrap()
        };
        let v: serde_json::Value = serde_json::from_str(&run(true)).unwrap();
        assert_eq!(v.as_object().unwrap().len(), 3);
        assert_eq!(v["niqe"].as_f64(), Some(want));
        let text = run(false);
        let line = text.lines().find(|l| l.starts_with("niqe")).expect(&text);
        let shown: f64 = line.split_whitespace().nth(1).unwrap().parse().unwrap();
        assert!((shown - want).abs() < 1e-4, "{line}");
    }
}
