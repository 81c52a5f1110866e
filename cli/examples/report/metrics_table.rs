//! The metrics section of BENCHMARKS.md (`report:metrics`): gsi's metrics on LOL eval15
//! beside the reference table of `../shared/data/README.md`.

use super::{images, load};
use gsi::metrics::{self, Rgb8};
use std::path::{Path, PathBuf};

/// The LOL eval15 rows of `../shared/data/README.md`: method, then PSNR | SSIM | PSNR-gm |
/// SSIM-gm | LOE | DE | EME as that file gives them.
pub(crate) const README_ROWS: [(&str, &str); 5] = [
    (
        "input (no enhancement)",
        "7.77 | 0.195 | 18.78 | 0.492 | 0 | 4.76 | 43.1",
    ),
    (
        "gamma 0.4",
        "14.59 | 0.621 | 22.25 | 0.634 | 50.2 | 6.20 | 39.3",
    ),
    (
        "auto-gamma",
        "16.33 | 0.631 | 19.60 | 0.650 | 68.7 | 6.26 | 38.7",
    ),
    (
        "CLAHE",
        "10.17 | 0.435 | 17.67 | 0.487 | 444.5 | 6.05 | 19.7",
    ),
    (
        "Zero-DCE++",
        "15.16 | 0.566 | 19.49 | 0.531 | 232.9 | 6.79 | 45.4",
    ),
];

/// `low` through the curve `255 (v / 255)^g`, rounded as the README's baselines are.
pub(crate) fn gamma_curve(low: &[u8], g: f64) -> Vec<u8> {
    low.iter()
        .map(|&v| (255.0 * (f64::from(v) / 255.0).powf(g)).round_ties_even() as u8)
        .collect()
}

/// The exponent that brings the mean BT.601 luma of `low` to 0.5 (auto-gamma).
pub(crate) fn auto_gamma_exponent(low: &[u8], w: u32, h: u32) -> f64 {
    let luma = metrics::luma(Rgb8::new(w, h, low).unwrap());
    gamma_for_mean(luma.iter().sum::<f64>() / luma.len() as f64 / 255.0)
}

/// The power that takes a mean luma of `mean` (0–1) to 0.5.
pub(crate) fn gamma_for_mean(mean: f64) -> f64 {
    0.5f64.ln() / mean.ln()
}

/// Our metrics on LOL eval15 beside the reference table of `../shared/data/README.md`,
/// for the rows that need no outside code: the input, gamma 0.4, and the gamma that
/// brings the mean gray level (BT.601 luma) to 0.5.
pub fn section(lol: &Path, stamp: &(String, String)) -> String {
    use std::fmt::Write;
    let names: Vec<PathBuf> = images(&lol.join("low"), usize::MAX);
    let mut sums = [[0f64; 7]; 3];
    for low_path in &names {
        let (t, low) = load(low_path);
        let (_, high) = load(&lol.join("high").join(low_path.file_name().unwrap()));
        let (w, h) = (t.width, t.height);
        let auto = auto_gamma_exponent(&low, w, h);
        for (k, out) in [low.clone(), gamma_curve(&low, 0.4), gamma_curve(&low, auto)]
            .iter()
            .enumerate()
        {
            let r = metrics::full_reference(
                Rgb8::new(w, h, &high).unwrap(),
                Rgb8::new(w, h, out).unwrap(),
            )
            .unwrap();
            let loe = metrics::loe(
                Rgb8::new(w, h, &low).unwrap(),
                Rgb8::new(w, h, out).unwrap(),
            )
            .unwrap();
            for (acc, v) in sums[k]
                .iter_mut()
                .zip([r.psnr, r.ssim, r.psnr_gm, r.ssim_gm, loe, r.de, r.eme])
            {
                *acc += v;
            }
        }
    }
    let n = names.len().max(1) as f64;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Metrics: agreement with the reference figures\n\nMachine: {}. Commit: `{}`. `gsi::metrics` on LOL eval15 (mean of {} pairs \
         against `high`; LOE against the input), beside the table of `../shared/data/README.md`. `cargo test --test metrics` \
         also checks them against scikit-image 0.26 (`tools/golden_metrics.py`): every |ΔPSNR|, |ΔSSIM|, |ΔMS-SSIM| < 5e-11.\n",
        stamp.0,
        stamp.1,
        names.len()
    );
    let _ = writeln!(s, "| method | PSNR | SSIM | PSNR-gm | SSIM-gm | LOE | DE | EME |\n|---|---|---|---|---|---|---|---|");
    for (k, name) in ["input", "gamma 0.4", "auto-gamma"].iter().enumerate() {
        let m = sums[k].map(|v| v / n);
        let _ = writeln!(
            s,
            "| {name}, gsi | {:.2} | {:.3} | {:.2} | {:.3} | {:.1} | {:.2} | {:.1} |",
            m[0], m[1], m[2], m[3], m[4], m[5], m[6]
        );
        let _ = writeln!(s, "| {name}, README | {} |", README_ROWS[k].1);
    }
    let _ = writeln!(s);
    s
}
