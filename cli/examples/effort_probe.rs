//! Time and PSNR of one encoder configuration on a few images: how the effort levels were
//! chosen on a validation set (BENCHMARKS.md, effort levels).
//!
//! ```sh
//! cargo run --release -p gsi-cli --example effort_probe -- STEPS COARSE_SHARE FACTOR SOLVE IMAGE...
//! ```
//!
//! Each image is encoded at 1 bpp on the CPU, one after another; a line per image, then the
//! mean PSNR and median time. `COARSE_SHARE` 0 (or `FACTOR` 1) fits at full resolution only.
//! `GSI_PROBE_LR=F` multiplies every learning rate by `F` (how the rates of the levels
//! were checked, BENCHMARKS.md, learning rates for short fits). `GSI_PROBE_CURVE=1` prints every progress
//! report (step, Gaussians, PSNR, seconds since the start), to see where a fit's time goes.
//! `GSI_PROBE_STORED=0` leaves the stored colours as the last step left them (no final
//! colour solve, as the effort report's reference); `GSI_PROBE_COMPENSATE=0` rounds each
//! stored colour to its nearest code alone; `GSI_PROBE_QAT=F` spends the last `F` of the
//! steps on quantization-aware fine-tuning (default: the encoder's). `GSI_PROBE_BITS=C,A,K`
//! sets the covariance, angle and colour depths (the position's stays the default for the
//! size); `GSI_PROBE_BPP=B` the budget (default 1); `GSI_PROBE_BLEND=alpha` fits in `alpha`
//! mode.

use gsi::fit::{default_bits, encode, Budget, Coarse, EncodeOptions, Lab, Target};
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.len() < 5 {
        eprintln!("usage: effort_probe STEPS COARSE_SHARE FACTOR SOLVE IMAGE...");
        std::process::exit(2);
    }
    let number = |k: usize| -> f32 {
        args[k]
            .parse()
            .unwrap_or_else(|_| panic!("{} is not a number", args[k]))
    };
    let (fraction, factor) = (number(1), number(2) as u32);
    let lr_scale: f32 = std::env::var("GSI_PROBE_LR").map_or(1.0, |v| {
        v.parse()
            .unwrap_or_else(|_| panic!("GSI_PROBE_LR={v} is not a number"))
    });
    let depths: Option<Vec<u8>> = std::env::var("GSI_PROBE_BITS").ok().map(|v| {
        v.split(',')
            .map(|d| d.parse().unwrap_or_else(|_| panic!("GSI_PROBE_BITS={v}")))
            .collect::<Vec<u8>>()
    });
    if let Some(d) = &depths {
        assert_eq!(d.len(), 3, "GSI_PROBE_BITS takes three depths: C,A,K");
    }
    let bpp: f32 = std::env::var("GSI_PROBE_BPP").map_or(1.0, |v| {
        v.parse()
            .unwrap_or_else(|_| panic!("GSI_PROBE_BPP={v} is not a number"))
    });
    let mut opts = EncodeOptions {
        lr: EncodeOptions::default().lr.scaled(lr_scale),
        budget: Budget::Bpp(bpp),
        iterations: number(0) as u32,
        coarse: (fraction > 0.0 && factor > 1).then_some(Coarse { factor, fraction }),
        color_solve: number(3) as u32,
        lab: Lab {
            solve_stored_colors: std::env::var("GSI_PROBE_STORED").map_or(true, |v| v != "0"),
            compensate_rounding: std::env::var("GSI_PROBE_COMPENSATE").map_or(true, |v| v != "0"),
            qat_fraction: std::env::var("GSI_PROBE_QAT").map_or(Lab::default().qat_fraction, |v| {
                v.parse()
                    .unwrap_or_else(|_| panic!("GSI_PROBE_QAT={v} is not a number"))
            }),
            ..Default::default()
        },
        blend: match std::env::var("GSI_PROBE_BLEND").as_deref() {
            Ok("alpha") => gsi::model::Blend::Alpha,
            _ => gsi::model::Blend::Sum,
        },
        ..EncodeOptions::default()
    };
    let curve = std::env::var_os("GSI_PROBE_CURVE").is_some();
    let (mut psnr, mut seconds, mut bits_per) = (Vec::new(), Vec::new(), Vec::new());
    for path in &args[4..] {
        let img = image::open(path)
            .unwrap_or_else(|e| panic!("{path}: {e}"))
            .into_rgb8();
        let target = Target {
            width: img.width(),
            height: img.height(),
            data: img
                .into_raw()
                .iter()
                .map(|&v| f32::from(v) / 255.0)
                .collect(),
        };
        if let Some(d) = &depths {
            let mut bits = default_bits(target.width, target.height, opts.blend);
            (bits.covariance, bits.angle, bits.color) = (d[0], d[1], d[2]);
            opts.bits = Some(bits);
        }
        let t0 = Instant::now();
        let e = encode(&target, &opts, gsi::Device::Cpu, &mut |p| {
            if curve {
                println!(
                    "  step {}/{}  N {}  {:.2} dB  {:.2} s",
                    p.iteration, p.total, p.gaussians, p.psnr, p.seconds
                );
            }
        })
        .expect("encode");
        let s = t0.elapsed().as_secs_f64();
        let n = e.records.header.count;
        println!(
            "{path}: N {n}  {} bytes  {:.1} bits/G  {:.3} dB  {s:.2} s",
            e.bytes.len(),
            e.bytes.len() as f64 * 8.0 / f64::from(n.max(1)),
            e.psnr
        );
        bits_per.push(e.bytes.len() as f64 * 8.0 / f64::from(n.max(1)));
        psnr.push(e.psnr);
        seconds.push(s);
    }
    seconds.sort_by(f64::total_cmp);
    println!(
        "mean PSNR {:.3} dB  mean {:.2} bits/G  median time {:.2} s",
        psnr.iter().sum::<f64>() / psnr.len() as f64,
        bits_per.iter().sum::<f64>() / bits_per.len() as f64,
        seconds[seconds.len() / 2]
    );
}
