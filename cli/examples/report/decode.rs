//! The decoder section of BENCHMARKS.md (`report:decode`): parse and CPU render of random
//! scenes at 768×512, timed here.

use super::median;
use std::time::Instant;

/// Median wall time of `f` over `runs` runs, after one warm-up, in milliseconds.
fn median_ms(runs: usize, mut f: impl FnMut()) -> f64 {
    f();
    median(
        (0..runs)
            .map(|_| {
                let t = Instant::now();
                f();
                t.elapsed().as_secs_f64() * 1e3
            })
            .collect(),
    )
}

/// Parse and CPU render of random scenes at 768×512, timed here so that this command
/// regenerates the figures (criterion's `cargo bench --bench decode` measures the same).
pub fn section(stamp: &(String, String)) -> String {
    use gsi::format::{BitDepths, Limits, Records, WriteOptions};
    use gsi::model::{Blend, WeightRule};
    use gsi::synth::{random_scene, SceneSpec};
    use std::fmt::Write;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "## Decoder: parse and CPU render\n\nMachine: {}. Commit: `{}`. Release build, `parallel` feature (rayon on all cores). \
         Random scenes (`gsi::synth::random_scene`) at 768×512, σ log-uniform in 0.5–8 px (about the footprint of fitted sets), \
         default bit depths; renders into a kept `f32` buffer (`render_into`), the rules of a blend mode in turn; median of 21 rounds after a warm-up. \
         Regenerate with `cargo run --release --example report -- --quick`; \
         `cargo bench --bench decode` measures the same with criterion.\n",
        stamp.0, stamp.1
    );
    let _ = writeln!(
        s,
        "| benchmark | 10k Gaussians | 100k Gaussians |\n|---|---|---|"
    );
    let scenes = |blend, weights| {
        [10_000usize, 100_000].map(|n| {
            random_scene(
                1,
                SceneSpec {
                    weights,
                    ..SceneSpec::new(768, 512, n, blend)
                },
            )
        })
    };
    let parse: Vec<f64> = scenes(Blend::Sum, WeightRule::Columns32)
        .iter()
        .map(|scene| {
            let bytes = gsi::format::to_bytes(
                &Records::from_scene(scene, BitDepths::default()),
                &WriteOptions::default(),
            )
            .unwrap();
            median_ms(21, || {
                std::hint::black_box(
                    gsi::format::read_file(&bytes[..], Limits::default())
                        .unwrap()
                        .records
                        .to_scene(),
                );
            })
        })
        .collect();
    let _ = writeln!(
        s,
        "| parse + dequantize | {:.2} ms | {:.2} ms |",
        parse[0], parse[1]
    );
    let rules = [
        (
            WeightRule::Columns32,
            "by columns in bands of 32 rows (§6.3.2, files written now)",
        ),
        (
            WeightRule::Columns,
            "by columns in bands of 16 rows (§6.3.2, files of 1.4)",
        ),
        (WeightRule::PerPixel, "per pixel (§6.3, files before 1.4)"),
    ];
    // Into a kept buffer, as `cargo bench` does: a fresh 4.7 MB image a render would time
    // the allocator's page faults (0.8 ms a render here) beside the renderer.
    let mut out = vec![0f32; 768 * 512 * 3];
    for blend in [Blend::Sum, Blend::Alpha] {
        // The rules of a blend mode take turns, a render of each per round, so that the
        // machine's load over the minutes this takes falls on each alike (timed one row
        // after another, two rows came out in the opposite order to their difference
        // timed in turns).
        let all: Vec<[gsi::Scene; 2]> =
            rules.iter().map(|&(rule, _)| scenes(blend, rule)).collect();
        let mut times = vec![[Vec::new(), Vec::new()]; rules.len()];
        for round in 0..22 {
            for (scenes, times) in all.iter().zip(&mut times) {
                for (scene, times) in scenes.iter().zip(times.iter_mut()) {
                    let t = Instant::now();
                    gsi::render::render_into(std::hint::black_box(scene), 768, 512, &mut out)
                        .unwrap();
                    // The first round warms up.
                    if round > 0 {
                        times.push(t.elapsed().as_secs_f64() * 1e3);
                    }
                }
            }
        }
        for ((_, rule_name), [t10k, t100k]) in rules.iter().zip(times) {
            let _ = writeln!(
                s,
                "| render CPU, `{}`, weights {rule_name}, 768×512 | {:.2} ms | {:.1} ms |",
                blend.name(),
                median(t10k),
                median(t100k)
            );
        }
    }
    let _ = writeln!(
        s,
        "\nTarget of issue 2: 10k Gaussians at 768×512, `sum`, ≤ 25 ms on the 2-core machine.\n"
    );
    s
}
