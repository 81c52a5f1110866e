//! A tone curve after the mixture set per Gaussian (spec §7.2.2): `a·x^g` per channel, on
//! the values the render shows at the Gaussians' centres.
//!
//! Files written before `GTRC` (spec §6.6) carry their curve this way, and applying
//! their `gENH` runs it. Stage 2 no longer writes it: a curve of the blended value set
//! per Gaussian can only be approached, and on the LOL validation pairs it scored 0.687
//! SSIM against the 0.793 of the same curve on the blended values, drawing the
//! Gaussians of stage 1 as streaks (see `enhance::curve`).
//!
//! As with the denoising, a `sum` record is a coefficient, and the curve belongs to what
//! the render shows. Each Gaussian gets the value its centre should show, and the
//! difference is carried back to the coefficients through the footprint density
//! in a few damped passes (a Jacobi solve). In `alpha` blending the records are the
//! displayed colours, and one pass sets them exactly.

use super::denoise::Neighbours;
use gsi_format::contract::COLOR_MAX;
use gsi_format::format::{Limits, Result, Tone};
use gsi_format::model::Scene;

/// Least value the curve is taken at (spec §7.2.2): below it `x^g` with `g < 1` would be
/// steeper than any 8-bit step can show, and 0 would stay 0 while its neighbours rise.
pub const FLOOR: f32 = 1.0 / 255.0;

/// `colors` after the tone curve `t`, with the footprints of `nb` (spec §7.2.2).
pub fn apply(nb: &Neighbours, colors: &[[f32; 3]], t: &Tone) -> Vec<[f32; 3]> {
    let (mut v, dens) = nb.values(colors);
    let target: Vec<[f32; 3]> = v
        .iter()
        .map(|vi| vi.map(|x| t.scale * x.max(FLOOR).powf(t.exponent)))
        .collect();
    let mut c = colors.to_vec();
    for pass in 0..t.passes {
        if pass > 0 {
            v = nb.values(&c).0;
        }
        for ((ci, ti), (vi, di)) in c.iter_mut().zip(&target).zip(v.iter().zip(&dens)) {
            for k in 0..3 {
                ci[k] += (ti[k] - vi[k]) / di;
            }
        }
    }
    for ci in &mut c {
        *ci = ci.map(|x| x.clamp(-COLOR_MAX, COLOR_MAX));
    }
    c
}

/// `colors` of `scene` after the tone curve `t` (spec §7.2.2). Fails where the search
/// for footprints would pass `limits`, as [`super::denoise::denoise`] does.
pub fn tone(
    scene: &Scene,
    colors: &[[f32; 3]],
    t: &Tone,
    limits: &Limits,
) -> Result<Vec<[f32; 3]>> {
    let nb = super::denoise::neighbours_for(scene, colors, limits, "tone")?;
    Ok(apply(&nb, colors, t))
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::model::{Blend, CovParam, GaussianSet};

    fn two(blend: Blend, colors: [[f32; 3]; 2]) -> Scene {
        Scene {
            weights: gsi_format::model::WeightRule::PerPixel,
            tone: None,
            width: 16,
            height: 16,
            blend,
            cov_param: CovParam::Cholesky,
            gaussians: GaussianSet {
                positions: vec![[0.25, 0.5], [0.375, 0.5]],
                cov: vec![[0.125, 0.0, 0.125]; 2],
                colors: colors.to_vec(),
                opacity: None,
            },
        }
    }

    #[test]
    fn tone_worked_example() {
        // format-spec.md §7.2.2.
        let s = two(Blend::Sum, [[0.5; 3], [0.3; 3]]);
        let t = Tone {
            exponent: 0.5,
            scale: 0.8,
            passes: 1,
        };
        let out = tone(&s, &s.gaussians.colors, &t, &Limits::default()).unwrap();
        for (got, want) in out.iter().zip([0.4867338f32, 0.311264]) {
            for k in 0..3 {
                assert!((got[k] - want).abs() < 2e-7, "{got:?} against {want}");
            }
        }
    }

    #[test]
    fn alpha_records_take_the_curve_exactly() {
        let s = two(Blend::Alpha, [[0.25, 0.5, 0.0], [1.0, 0.04, 0.81]]);
        let t = Tone {
            exponent: 0.5,
            scale: 0.9,
            passes: 3,
        };
        let out = tone(&s, &s.gaussians.colors, &t, &Limits::default()).unwrap();
        for (got, c) in out.iter().zip(&s.gaussians.colors) {
            for k in 0..3 {
                let want = 0.9 * c[k].max(FLOOR).sqrt();
                assert!((got[k] - want).abs() < 1e-6, "{got:?} from {c:?}");
            }
        }
    }

    #[test]
    fn sum_passes_bring_the_centres_to_their_targets() {
        // A row of overlapping Gaussians, 2σ apart as a fit spaces them: one pass leaves
        // a difference, more passes shrink it.
        let mut s = two(Blend::Sum, [[0.2; 3], [0.05; 3]]);
        s.gaussians.positions = vec![[0.25, 0.5], [0.5, 0.5], [0.75, 0.5]];
        s.gaussians.cov = vec![
            [0.125, 0.0, 0.125],
            [0.1875, 0.0, 0.125],
            [0.125, 0.0, 0.125],
        ];
        s.gaussians.colors.push([0.1; 3]);
        let nb = Neighbours::new(&s, &Limits::default()).unwrap();
        let (v0, _) = nb.values(&s.gaussians.colors);
        let miss = |passes: u8| {
            let t = Tone {
                exponent: 0.6,
                scale: 0.7,
                passes,
            };
            let (v, _) = nb.values(&apply(&nb, &s.gaussians.colors, &t));
            v.iter()
                .zip(&v0)
                .map(|(v, v0)| (v[0] - 0.7 * v0[0].max(FLOOR).powf(0.6)).abs())
                .fold(0.0f32, f32::max)
        };
        let (one, eight) = (miss(1), miss(8));
        assert!(eight < 0.1 * one && eight < 1e-3, "{one} then {eight}");
    }

    #[cfg(feature = "encode")]
    #[test]
    fn degenerate_input_stays_finite() {
        let mut s = two(Blend::Sum, [[0.0; 3], [f32::MAX; 3]]);
        s.gaussians.cov[1] = [0.0, 0.0, 0.0];
        let t = Tone {
            exponent: 0.01,
            scale: 64.0,
            passes: 8,
        };
        let out = tone(&s, &s.gaussians.colors, &t, &Limits::default()).unwrap();
        assert!(out
            .iter()
            .flatten()
            .all(|x| x.is_finite() && x.abs() <= COLOR_MAX));
    }
}
