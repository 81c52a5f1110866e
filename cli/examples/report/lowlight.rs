//! The synthetic low-light validation set of stage 2 (issue 14), shared by the report
//! and the `lowlight_set` example: see that example for what it is and how it was matched
//! to LOL.

use gsi::metrics::BT601;
use gsi::metrics::{linear_to_srgb, srgb_to_linear};
use std::path::{Path, PathBuf};

/// eval15's low images: mean Rec. 601 luma (of the 8-bit values, `[0, 1]`) between 0.025
/// and 0.097 (`measure`). The dark images' mean luma is spread log-uniformly over this.
const LUMA_RANGE: (f64, f64) = (0.025, 0.097);

/// Noise standard deviation of eval15's low images per channel (R, G, B), in 8-bit
/// steps: the median over the 15 images of what `measure` prints (R 0.91–2.27, G
/// 0.88–1.41, B 0.83–1.94). It hardly depends on the level over the dark range the
/// images occupy (the pooled fit `σ² = 2.29 + 0.02·v`), so it is taken as constant; red
/// and blue are noisier than green, as a camera's white-balance gains make them.
const SIGMA: [f64; 3] = [1.93, 1.19, 1.55];

fn luma(p: &[u8]) -> f64 {
    (BT601[0] * f64::from(p[0]) + BT601[1] * f64::from(p[1]) + BT601[2] * f64::from(p[2])) / 255.0
}

fn mean_luma(rgb: &[u8]) -> f64 {
    rgb.chunks_exact(3).map(luma).sum::<f64>() / (rgb.len() / 3) as f64
}

/// The PNG files of `dir`, sorted by name.
pub fn pngs(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "png"))
        .collect();
    v.sort();
    v
}

fn load(path: &Path) -> (u32, u32, Vec<u8>) {
    let img = image::open(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .to_rgb8();
    let (w, h) = img.dimensions();
    (w, h, img.into_raw())
}

/// Noise of one channel against level: for every interior pixel, the level is the 3×3
/// mean and the residual Immerkær's Laplacian-difference operator, which cancels any
/// locally planar signal. Returns, per level bin of 4 steps, (mean level, σ, count),
/// σ from the median absolute residual (robust to edges).
fn noise_by_level(w: usize, h: usize, rgb: &[u8], c: usize) -> Vec<(f64, f64, usize)> {
    const BINS: usize = 32;
    let mut res: Vec<Vec<f64>> = vec![Vec::new(); BINS];
    let mut lev: Vec<f64> = vec![0.0; BINS];
    let at = |x: usize, y: usize| f64::from(rgb[(y * w + x) * 3 + c]);
    for y in 1..h - 1 {
        for x in 1..w - 1 {
            let mut mean = 0.0;
            let mut r = 0.0;
            for dy in 0..3 {
                for dx in 0..3 {
                    let v = at(x + dx - 1, y + dy - 1);
                    mean += v;
                    let k = [[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]][dy][dx];
                    r += k * v;
                }
            }
            mean /= 9.0;
            let b = (mean / 4.0) as usize;
            if b < BINS {
                res[b].push(r.abs());
                lev[b] += mean;
            }
        }
    }
    res.into_iter()
        .zip(lev)
        .filter(|(v, _)| v.len() >= 200)
        .map(|(mut v, lev)| {
            let n = v.len();
            v.sort_by(f64::total_cmp);
            // For Gaussian noise of σ, the operator's output has σ·6 (√36 = the norm of
            // its kernel); its absolute value has median 0.6745 of that.
            let sigma = v[n / 2] / 0.6745 / 6.0;
            (lev / n as f64, sigma, n)
        })
        .collect()
}

pub fn measure(dir: &Path) {
    let mut pooled: Vec<(f64, f64, usize)> = Vec::new();
    for p in pngs(dir) {
        let (w, h, rgb) = load(&p);
        let mut line = format!(
            "{} mean luma {:.4}:",
            p.file_name().unwrap().to_string_lossy(),
            mean_luma(&rgb)
        );
        // The same image averaged over 2×2 blocks: white noise halves, noise that is
        // correlated between neighbours (demosaicing, in-camera denoising) does not.
        let (w2, h2) = (w as usize / 2, h as usize / 2);
        let mut half = vec![0u8; w2 * h2 * 3];
        for y in 0..h2 {
            for x in 0..w2 {
                for c in 0..3 {
                    let at = |dx: usize, dy: usize| {
                        u32::from(rgb[((2 * y + dy) * w as usize + 2 * x + dx) * 3 + c])
                    };
                    half[(y * w2 + x) * 3 + c] =
                        ((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1) + 2) / 4) as u8;
                }
            }
        }
        for c in 0..3 {
            let n = noise_by_level(w as usize, h as usize, &rgb, c);
            let n2 = noise_by_level(w2, h2, &half, c);
            let avg = |n: &[(f64, f64, usize)]| {
                let k: usize = n.iter().map(|t| t.2).sum();
                n.iter().map(|t| t.1 * t.2 as f64).sum::<f64>() / k.max(1) as f64
            };
            line += &format!(" c{c} sigma {:.2} binned {:.2};", avg(&n), avg(&n2));
            pooled.extend(n);
        }
        println!("{line}");
    }
    // σ² = A + B·v by least squares, weighted by count.
    let (mut sw, mut sx, mut sy, mut sxx, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(l, s, k) in &pooled {
        let wgt = k as f64;
        sw += wgt;
        sx += wgt * l;
        sy += wgt * s * s;
        sxx += wgt * l * l;
        sxy += wgt * l * s * s;
    }
    let b = (sw * sxy - sx * sy) / (sw * sxx - sx * sx);
    let a = (sy - b * sx) / sw;
    println!("pooled fit: sigma^2 = {a:.3} + {b:.4} * level (8-bit steps)");
}

/// Deterministic normal deviates (Box–Muller over the crate's SplitMix64).
struct Normal(gsi::synth::SplitMix64);

impl Normal {
    fn next(&mut self) -> f64 {
        let u1 = f64::from(self.0.unit()).max(1e-12);
        let u2 = f64::from(self.0.unit());
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }
}

/// `rgb` as a shorter exposure shows it: linear light times `gain`, back through the
/// sRGB curve, in `[0, 255]` before noise and rounding.
fn darken(rgb: &[u8], gain: f64) -> Vec<f64> {
    rgb.iter()
        .map(|&v| 255.0 * linear_to_srgb(gain * srgb_to_linear(f64::from(v) / 255.0)))
        .collect()
}

pub fn make(src: &Path, out: &Path) {
    std::fs::create_dir_all(out.join("low")).unwrap();
    std::fs::create_dir_all(out.join("high")).unwrap();
    let files = pngs(src);
    let mut rng = Normal(gsi::synth::SplitMix64::new(0x6c6f_776c));
    for (i, p) in files.iter().enumerate() {
        let name = p.file_name().unwrap();
        let (w, h, rgb) = load(p);
        // Target mean luma: evenly spaced in log over the measured range, in an order
        // that does not follow the file order.
        let t = ((i * 7) % files.len()) as f64 / (files.len() - 1).max(1) as f64;
        let want = LUMA_RANGE.0 * (LUMA_RANGE.1 / LUMA_RANGE.0).powf(t);
        let (mut lo, mut hi) = (1e-4f64, 1.0f64);
        for _ in 0..50 {
            let g = (lo * hi).sqrt();
            let d = darken(&rgb, g);
            let m = d
                .chunks_exact(3)
                .map(|p| BT601[0] * p[0] + BT601[1] * p[1] + BT601[2] * p[2])
                .sum::<f64>()
                / 255.0
                / (d.len() / 3) as f64;
            if m < want {
                lo = g;
            } else {
                hi = g;
            }
        }
        let dark = darken(&rgb, (lo * hi).sqrt());
        let low: Vec<u8> = dark
            .iter()
            .enumerate()
            .map(|(i, &v)| (v + SIGMA[i % 3] * rng.next()).round().clamp(0.0, 255.0) as u8)
            .collect();
        image::save_buffer(
            out.join("low").join(name),
            &low,
            w,
            h,
            image::ColorType::Rgb8,
        )
        .unwrap();
        std::fs::copy(p, out.join("high").join(name)).unwrap();
        println!(
            "{}: gain {:.4}, mean luma {:.4} (wanted {want:.4}), reference {:.4}",
            name.to_string_lossy(),
            (lo * hi).sqrt(),
            mean_luma(&low),
            mean_luma(&rgb)
        );
    }
}

/// Linear luminance of each pixel of an image averaged over 3×3 blocks.
fn lin_luma_blocks(w: u32, h: u32, rgb: &[u8]) -> Vec<f64> {
    let (w, h) = (w as usize, h as usize);
    let mut out = Vec::new();
    for by in 0..h / 3 {
        for bx in 0..w / 3 {
            let mut acc = [0f64; 3];
            for y in 0..3 {
                for x in 0..3 {
                    for c in 0..3 {
                        acc[c] +=
                            f64::from(rgb[((3 * by + y) * w + 3 * bx + x) * 3 + c]) / 255.0 / 9.0;
                    }
                }
            }
            let l = acc.map(srgb_to_linear);
            out.push(0.2126 * l[0] + 0.7152 * l[1] + 0.0722 * l[2]);
        }
    }
    out
}

fn stats(lin: &[f64]) -> (f64, f64, f64) {
    let n = lin.len() as f64;
    let logavg = (lin.iter().map(|v| (v + 1e-4).ln()).sum::<f64>() / n).exp();
    let mut s = lin.to_vec();
    s.sort_by(f64::total_cmp);
    (logavg, s[s.len() / 2], s[s.len() * 99 / 100])
}

/// Display mean luma of `rgb` after a linear-light gain.
fn gained_luma(rgb: &[u8], g: f64) -> f64 {
    let d = darken(rgb, g);
    d.chunks_exact(3)
        .map(|p| BT601[0] * p[0] + BT601[1] * p[1] + BT601[2] * p[2])
        .sum::<f64>()
        / 255.0
        / (d.len() / 3) as f64
}

pub fn rules(kodak: &Path, set: &Path) {
    let mut k = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for p in pngs(kodak) {
        let (w, h, rgb) = load(&p);
        let (la, med, p99) = stats(&lin_luma_blocks(w, h, &rgb));
        let img: Vec<f32> = rgb.iter().map(|&v| f32::from(v) / 255.0).collect();
        let m = gsi::enhance::exposure::meter(&img);
        let (w_, h_) = (w as usize, h as usize);
        let a = gsi::enhance::assess::assess_image(&img, w_, h_);
        println!(
            "{} own {:.3} metered {:.3} gain {:.2} under-exposed {:.0}% low-light {}",
            p.file_name().unwrap().to_string_lossy(),
            m.own,
            m.target,
            m.gain,
            100.0 * a.dark_share,
            a.is_low_light()
        );
        k.0.push(la);
        k.1.push(med);
        k.2.push(p99);
        k.3.push(mean_luma(&rgb));
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (kla, kmed, kp99, kmean) = (
        median(&mut k.0),
        median(&mut k.1),
        median(&mut k.2),
        median(&mut k.3),
    );
    println!("kodak medians: logavg {kla:.4} median {kmed:.4} p99 {kp99:.4} mean luma {kmean:.4}");
    let mut err = [0f64; 6];
    let mut n = 0.0;
    for p in pngs(&set.join("low")) {
        let (w, h, low) = load(&p);
        let (_, _, high) = load(&set.join("high").join(p.file_name().unwrap()));
        let (la, med, p99) = stats(&lin_luma_blocks(w, h, &low));
        let r = [
            0.5,
            kmean,
            gained_luma(&low, kla / la),
            gained_luma(&low, kmed / med.max(1e-5)),
            gained_luma(&low, kp99 / p99.max(1e-5)),
            gained_luma(&low, (kla / la).min(kp99 / p99.max(1e-5))),
        ];
        let want = mean_luma(&high);
        for (e, v) in err.iter_mut().zip(r) {
            *e += (v - want).abs();
        }
        n += 1.0;
        println!("{} low {:.3} ref {want:.3} | fixed {:.3} kodak {:.3} logavg {:.3} median {:.3} p99 {:.3} blend {:.3}", p.file_name().unwrap().to_string_lossy(), mean_luma(&low), r[0], r[1], r[2], r[3], r[4], r[5]);
    }
    println!(
        "MAE: fixed {:.3} kodak {:.3} logavg {:.3} median {:.3} p99 {:.3} blend {:.3}",
        err[0] / n,
        err[1] / n,
        err[2] / n,
        err[3] / n,
        err[4] / n,
        err[5] / n
    );
}
