//! Probe (not a decoder path): what a column recurrence for `exp` would buy the CPU
//! decoder, and what it costs in accuracy, before any spec change is written for it.
//! `sum` blending only.
//!
//! ```sh
//! cargo run --release -p gsi-render --features encode --example recurrence_probe -- FILE.gsi [W H]
//! ```
//!
//! Along a pixel column the power is a parabola in the row offset, so with `w = E(p)`:
//! `w(j+1) = w(j)·r(j)`, `r(j+1) = r(j)·k`, `r(j) = E(p(j+1) − p(j))`, `k = E(−C)`, and
//! the power itself by differences (`p += d`, `d −= C`): two products and two sums a row
//! in place of `E` and the quadratic. Each chunk column starts from `E` at its first row;
//! a lane restarts from `E` on any row after one whose `w` fell below `E(RESTART)` (where
//! it may be denormal or clamped), and a Gaussian whose `k` would leave `E`'s range
//! (`C > −RESTART`) takes every row from `E`. What it had to learn: near a centre the
//! differenced power rounds to either side of 0, so the spec's `power ≤ 0` test (a guard
//! against rounding in the direct form) must not be kept, or a Gaussian loses its peak.
//! The probe times the spec's loop (`Kernel::tile`), this one and, on x86-64 with FMA,
//! the spec's rule with its multiply-adds fused (the other cheap spec change: `E` in
//! FMA steps), on the same tile lists, alternating, one thread, and compares their sums
//! with the spec's.

use gsi_format::contract::{exp_in_range, ALPHA_MIN, EXP_MIN};
use gsi_format::format::{read_file, Limits};
use gsi_format::model::Blend;
use gsi_render::render::lanes::{Acc, Footprint, Kernel, LANES};
use gsi_render::render::{project_scene, Projected, Rect, TileLists, TILE};
use std::time::Instant;

const RESTART: f32 = -60.0;
const ACC_W: usize = TILE as usize + LANES;

fn offset(i: u32, m: f32) -> f32 {
    (i as f32 + 0.5) - m
}

#[inline(always)]
fn e(x: f32) -> f32 {
    exp_in_range::<false>(x.clamp(EXP_MIN, 80.0))
}

#[inline(always)]
fn tile_sum_rec(list: &[u32], proj: &[Projected], rect: Rect, acc: &mut Acc, stats: &mut [u64; 4]) {
    for &k in list {
        let g = &proj[k as usize];
        let Some(f) = Footprint::of(g, rect) else {
            continue;
        };
        let [ca, cb, cc] = g.conic;
        let cut = g.cutoff();
        let kk = e(-cc);
        // Too steep a column for k (or a NaN conic): every row from E.
        let steep = cc.is_nan() || cc > -RESTART;
        for start in f.starts() {
            let first = f.x0 + start as u32;
            let at0 = start as i32;
            let (lx0, lx1) = (f.lx0 as i32 - at0, f.lx1 as i32 - at0);
            let mut dx = [0f32; LANES];
            let mut inside = [false; LANES];
            for l in 0..LANES {
                dx[l] = offset(first.wrapping_add(l as u32), g.mean[0]);
                inside[l] = (l as i32 >= lx0) & ((l as i32) < lx1);
            }
            let power = |dy: f32, l: usize| -> f32 {
                -0.5 * (ca * dx[l] * dx[l] + cc * dy * dy) - cb * dx[l] * dy
            };
            let j0 = f.ys.start;
            let dy0 = offset(j0, g.mean[1]);
            let mut p = [0f32; LANES];
            let mut w = [0f32; LANES];
            let mut r = [0f32; LANES];
            for l in 0..LANES {
                p[l] = power(dy0, l);
                w[l] = e(p[l]);
                r[l] = e(power(dy0 + 1.0, l) - p[l]);
            }
            let tiny = e(RESTART);
            let mut d = [0f32; LANES];
            for l in 0..LANES {
                d[l] = power(dy0 + 1.0, l) - p[l];
            }
            let mut dy = dy0;
            for j in f.ys.clone() {
                let at = (j - rect.y0) as usize * ACC_W + start;
                let mut alpha = [0f32; LANES];
                for l in 0..LANES {
                    let a = g.opacity * w[l];
                    let keep = inside[l] & (p[l] >= cut) & (a >= ALPHA_MIN);
                    alpha[l] = if keep { a } else { 0.0 };
                }
                stats[0] += 1;
                let lit = alpha.iter().filter(|&&a| a != 0.0).count() as u64;
                stats[1] += lit;
                stats[3] += u64::from(lit == 0);
                for (ch, plane) in acc.0.iter_mut().enumerate() {
                    let px = &mut plane[at..at + LANES];
                    for l in 0..LANES {
                        px[l] += g.color[ch] * alpha[l];
                    }
                }
                // Next row.
                let any = w.iter().fold(steep, |any, &x| any | (x < tiny));
                if any {
                    stats[2] += 1;
                    for l in 0..LANES {
                        let direct = steep || w[l] < tiny;
                        let pn = power(dy + 1.0, l);
                        let wn = if direct { e(pn) } else { w[l] * r[l] };
                        let rn = if direct {
                            e(power(dy + 2.0, l) - pn)
                        } else {
                            r[l] * kk
                        };
                        w[l] = wn;
                        r[l] = rn;
                    }
                } else {
                    for l in 0..LANES {
                        w[l] *= r[l];
                        r[l] *= kk;
                    }
                }
                for l in 0..LANES {
                    p[l] += d[l];
                    d[l] -= cc;
                }
                dy += 1.0;
            }
        }
    }
}

/// The spec's rule with its multiply-adds fused (`exp`'s polynomial in FMA steps): what a
/// spec that defined `E` with fused multiply-adds would cost, on x86-64 with AVX2 and FMA.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,fma")]
fn fused_tile(list: &[u32], proj: &[Projected], rect: Rect, acc: &mut Acc) {
    for &k in list {
        let g = &proj[k as usize];
        let Some(f) = Footprint::of(g, rect) else {
            continue;
        };
        for start in f.starts() {
            for j in f.ys.clone() {
                let dy = offset(j, g.mean[1]);
                let (alpha, _) = f.alphas_with::<true, false, false>(start, dy);
                let at = (j - rect.y0) as usize * ACC_W + start;
                for (ch, plane) in acc.0.iter_mut().enumerate() {
                    let px = &mut plane[at..at + LANES];
                    for l in 0..LANES {
                        px[l] += g.color[ch] * alpha[l];
                    }
                }
            }
        }
    }
}

/// The probe's loop, built for AVX2 where the CPU has it (as `Kernel::detect` picks the
/// spec's), else portable.
fn rec_tile(list: &[u32], proj: &[Projected], rect: Rect, acc: &mut Acc, stats: &mut [u64; 4]) {
    #[cfg(target_arch = "x86_64")]
    if std::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (detected just above).
        return unsafe { rec_tile_avx2(list, proj, rect, acc, stats) };
    }
    tile_sum_rec(list, proj, rect, acc, stats)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn rec_tile_avx2(
    list: &[u32],
    proj: &[Projected],
    rect: Rect,
    acc: &mut Acc,
    stats: &mut [u64; 4],
) {
    tile_sum_rec(list, proj, rect, acc, stats)
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let file = read_file(std::fs::File::open(&args[0]).unwrap(), Limits::default()).unwrap();
    let scene = file.records.to_scene();
    assert_eq!(scene.blend, Blend::Sum, "the probe covers sum blending");
    let (w, h) = if args.len() >= 3 {
        (args[1].parse().unwrap(), args[2].parse().unwrap())
    } else {
        (scene.width, scene.height)
    };
    let proj = project_scene(&scene, w, h);
    let lists = TileLists::bin(&proj, w, h);
    let tiles_x = w.div_ceil(TILE);
    let rects: Vec<Rect> = (0..lists.len())
        .map(|t| {
            let (tx, ty) = (t as u32 % tiles_x, t as u32 / tiles_x);
            Rect {
                x0: tx * TILE,
                y0: ty * TILE,
                x1: ((tx + 1) * TILE).min(w),
                y1: ((ty + 1) * TILE).min(h),
            }
        })
        .collect();
    let kernel = Kernel::detect();
    #[cfg(target_arch = "x86_64")]
    let fused = std::is_x86_feature_detected!("avx2") && std::is_x86_feature_detected!("fma");
    #[cfg(not(target_arch = "x86_64"))]
    let fused = false;
    // 0: the spec's loop; 1: the recurrence; 2: the spec's rule with fused multiply-adds.
    let run = |path: usize, out: &mut Vec<Acc>| -> (f64, [u64; 4]) {
        out.clear();
        let mut stats = [0u64; 4];
        let t = Instant::now();
        for (i, rect) in rects.iter().enumerate() {
            let mut acc = Acc::zero();
            match path {
                0 => kernel.tile(Blend::Sum, lists.list(i), &proj, *rect, &mut acc),
                1 => rec_tile(lists.list(i), &proj, *rect, &mut acc, &mut stats),
                // SAFETY: path 2 runs only where the CPU has AVX2 and FMA (`fused`).
                #[cfg(target_arch = "x86_64")]
                _ => unsafe { fused_tile(lists.list(i), &proj, *rect, &mut acc) },
                #[cfg(not(target_arch = "x86_64"))]
                _ => unreachable!(),
            }
            out.push(acc);
        }
        (t.elapsed().as_secs_f64() * 1e3, stats)
    };
    let paths = if fused { 3 } else { 2 };
    let mut outs: Vec<Vec<Acc>> = (0..paths).map(|_| Vec::new()).collect();
    let mut times: Vec<Vec<f64>> = vec![Vec::new(); paths];
    let mut stats = [0u64; 4];
    for _ in 0..15 {
        for (path, out) in outs.iter_mut().enumerate() {
            let (t, s) = run(path, out);
            times[path].push(t);
            if path == 1 {
                stats = s;
            }
        }
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    println!(
        "{w}x{h} {} Gaussians ({kernel:?}), medians of 15, one thread: spec loop {:.2} ms, recurrence {:.2} ms{}",
        proj.len(),
        median(&mut times[0]),
        median(&mut times[1]),
        if fused {
            format!(", spec rule with fused multiply-adds {:.2} ms", median(&mut times[2]))
        } else {
            String::new()
        }
    );
    println!(
        "recurrence: {} chunk-rows, {:.1} % of their lanes taking light, {:.1} % with none, {} restarted",
        stats[0],
        100.0 * stats[1] as f64 / (8.0 * stats[0] as f64),
        100.0 * stats[3] as f64 / stats[0] as f64,
        stats[2]
    );
    for (path, name) in [(1, "recurrence"), (2, "fused")]
        .into_iter()
        .take(paths - 1)
    {
        // Max |difference| of the f32 sums, and 8-bit values that differ, against the spec.
        let (mut worst, mut differ, mut n) = (0f32, 0usize, 0usize);
        for (t, rect) in rects.iter().enumerate() {
            for j in 0..(rect.y1 - rect.y0) as usize {
                for i in 0..(rect.x1 - rect.x0) as usize {
                    for ch in 0..3 {
                        let a = outs[0][t].0[ch][j * ACC_W + i];
                        let b = outs[path][t].0[ch][j * ACC_W + i];
                        worst = worst.max((a - b).abs());
                        let q = |x: f32| (x.clamp(0.0, 1.0) * 255.0).round() as u8;
                        differ += usize::from(q(a) != q(b));
                        n += 1;
                    }
                }
            }
        }
        println!("{name} against the spec: max |sum difference| {worst:.2e}; 8-bit values differing {differ} of {n}");
    }
}
