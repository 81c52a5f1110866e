//! The chroma map after the mixture and any gain map (spec §7.2.4): where the low image
//! was within its noise of black, the colour of the lifted result is mostly the noise's
//! and the sensor's black level, and a tone curve that lifts those regions ×10–×16 shows
//! it as a cast (a black backpack turned green, a grey wall pink). Each Gaussian's
//! colour is moved towards its own grey by a scale that is 1 where the input was lit and
//! falls towards 0 as its level falls into the noise.
//!
//! The scale of a region lit at `L` (8-bit steps of the input's luma, averaged over a
//! cell of the map) is `L² / (L² + σ²)`: the Wiener gain of a signal of amplitude `L`
//! against noise `σ`, half at `L = σ`. `σ` is [`NOISE`], the noise of dark photographs
//! measured on LOL's low images. A scale is exact in the Gaussian domain as the gain map
//! is: moving a colour towards its grey is linear, so in `sum` blending the blended colour
//! moves by the scale wherever it is nearly constant across a footprint.

use super::gain::at_centres;
use gsi_format::contract::COLOR_MAX;
use gsi_format::format::ChromaMap;

/// Rec. 601 luma weights, in binary32 as spec §7.2.4 writes them: a colour's own grey.
/// The same numbers as `gsi_metrics`' `BT601_F32`, kept here because applying a stored
/// map is a decoder's work, which builds without the metrics.
pub const LUMA: [f32; 3] = [0.299, 0.587, 0.114];

/// `colors` (of Gaussians centred at `positions`) moved towards their own grey by the
/// map's scale at each centre, exactly as spec §7.2.4: `y = (0.299·c0 + 0.587·c1) +
/// 0.114·c2`, then `y + s·(c − y)` per channel, clamped to `±COLOR_MAX`.
pub fn apply(map: &ChromaMap, positions: &[[f32; 2]], colors: &[[f32; 3]]) -> Vec<[f32; 3]> {
    at_centres(&map.scales, map.width, map.height, positions)
        .into_iter()
        .zip(colors)
        .map(|(s, c)| {
            let y = (LUMA[0] * c[0] + LUMA[1] * c[1]) + LUMA[2] * c[2];
            c.map(|x| (y + s * (x - y)).clamp(-COLOR_MAX, COLOR_MAX))
        })
        .collect()
}

#[cfg(feature = "encode")]
pub use plan::{plan, scale_at, CELL, KEEP, NOISE, SCALE_BITS};

#[cfg(feature = "encode")]
mod plan {
    use super::super::loss::display_luma;
    use gsi_format::format::{Attribute, ChromaMap};

    /// Noise of a dark photograph's luma, in 8-bit steps: the median over LOL `val30`'s
    /// 30 low images and eval15's 15 (1.31 and 1.32 by Immerkær's estimator), which the
    /// synthetic dark Kodak set was built to match (1.31). The colour of a region lit
    /// at this level keeps half its distance from grey.
    pub const NOISE: f32 = 1.3;
    /// Side of a map cell, in working pixels, and bits of each stored scale: the scale
    /// varies slowly and needs no precision. On LOL `val30` and the synthetic set, cells
    /// of 16 pixels and 4 bits score as cells of 8 and 8 bits (20.51 / 21.95 dB against
    /// 20.48 / 21.94) and add a median 62 bytes to a file instead of 444: enough, at
    /// 444, to take the median 600×400 file below a compression ratio of 20×.
    pub const CELL: u32 = 16;
    /// See [`CELL`].
    pub const SCALE_BITS: u8 = 4;
    /// A scene whose every cell keeps at least this share of its chroma gets no map: a
    /// lit scene's file stays as it was.
    pub const KEEP: f32 = 0.95;

    /// The share of its chroma a region lit at `level` (8-bit steps of luma) keeps:
    /// `L² / (L² + σ²)` with `σ` = [`NOISE`].
    pub fn scale_at(level: f64) -> f32 {
        let (l, sigma) = (level.max(0.0), f64::from(NOISE));
        (l * l / (l * l + sigma * sigma)) as f32
    }

    /// The chroma map of `img`, the low image's working image (`width × height`
    /// blended values, [`super::super::working::working_image`], before any
    /// enhancement), in cells of [`CELL`] pixels; `None` where no cell was lit within a
    /// few noise levels of black.
    pub fn plan(img: &[f32], width: u32, height: u32) -> Option<ChromaMap> {
        let (w, h) = (width as usize, height as usize);
        let cell = CELL as usize;
        let (mw, mh) = (w.div_ceil(cell), h.div_ceil(cell));
        let mut sum = vec![0.0f64; mw * mh];
        let mut count = vec![0u32; mw * mh];
        for (i, px) in img.chunks_exact(3).enumerate() {
            let (x, y) = (i % w, i / w);
            let c = (y / cell) * mw + x / cell;
            sum[c] += f64::from(display_luma(px)) * 255.0;
            count[c] += 1;
        }
        let scales: Vec<[f32; 1]> = sum
            .iter()
            .zip(&count)
            .map(|(&s, &n)| [scale_at(s / f64::from(n.max(1)))])
            .collect();
        if scales.iter().all(|&[s]| s >= KEEP) {
            return None;
        }
        Some(ChromaMap {
            width: mw as u16,
            height: mh as u16,
            scales: Attribute::fit(&scales, [SCALE_BITS]),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::format::Attribute;

    /// Spec §7.2.4's worked example.
    #[test]
    fn chroma_worked_example() {
        let map = ChromaMap {
            width: 2,
            height: 1,
            scales: Attribute::fit(&[[0.0f32], [1.0]], [8]),
        };
        let out = apply(&map, &[[0.5, 0.5]], &[[0.4, 0.2, 0.1]]);
        // The bit patterns the spec prints (computed there with numpy's float32).
        assert_eq!(
            out[0].map(f32::to_bits),
            [0x3ea5_fd8b, 0x3e65_94b0, 0x3e32_617c],
            "{:?}",
            out[0]
        );
        assert_eq!(
            LUMA.map(f32::to_bits),
            [0x3e99_1687, 0x3f16_45a2, 0x3de9_78d5]
        );
        #[cfg(feature = "encode")]
        assert_eq!(LUMA, gsi_metrics::metrics::BT601_F32);
    }

    #[test]
    fn a_scale_of_one_keeps_a_colour_and_zero_makes_it_grey() {
        let keep = ChromaMap {
            width: 1,
            height: 1,
            scales: Attribute::fit(&[[1.0f32]], [8]),
        };
        let grey = ChromaMap {
            width: 1,
            height: 1,
            scales: Attribute::fit(&[[0.0f32]], [8]),
        };
        let c = [[0.7f32, -0.2, 0.3]];
        assert_eq!(apply(&keep, &[[0.3, 0.6]], &c), c.to_vec());
        let g = apply(&grey, &[[0.3, 0.6]], &c)[0];
        assert!(g[0] == g[1] && g[1] == g[2], "{g:?}");
    }

    #[test]
    fn colours_stay_finite_and_within_range() {
        let map = ChromaMap {
            width: 3,
            height: 2,
            scales: Attribute::fit(&[[0.0f32], [0.5], [1.0], [0.25], [0.9], [0.1]], [8]),
        };
        let pos = [[0.0, 0.0], [1.0, 1.0], [f32::NAN, 0.3], [-5.0, 9.0]];
        let col = [[64.0, -64.0, 64.0], [-64.0; 3], [0.2, 0.0, 1.0], [0.0; 3]];
        for o in apply(&map, &pos, &col) {
            assert!(
                o.iter().all(|x| x.is_finite() && x.abs() <= COLOR_MAX),
                "{o:?}"
            );
        }
    }

    #[cfg(feature = "encode")]
    mod planning {
        use super::super::*;
        use gsi_format::format::ChromaMap;
        use gsi_format::model::{Blend, CovParam, GaussianSet, Scene};

        /// [`plan`] on `scene`'s working image of long side `side`.
        fn plan_of(scene: &Scene, side: u32) -> Option<ChromaMap> {
            let (w, h) = crate::enhance::working::work_size(scene.width, scene.height, side);
            plan(&crate::enhance::working::working_image(scene, side), w, h)
        }

        /// A grid of round Gaussians of one colour over a `w × h` image.
        fn flat(c: [f32; 3]) -> Scene {
            let (nx, ny) = (16, 12);
            let mut g = GaussianSet::default();
            for j in 0..ny {
                for i in 0..nx {
                    g.positions
                        .push([(i as f32 + 0.5) / nx as f32, (j as f32 + 0.5) / ny as f32]);
                    g.cov.push([0.6 / nx as f32, 0.0, 0.6 / ny as f32]);
                    g.colors.push(c);
                }
            }
            Scene {
                weights: gsi_format::model::WeightRule::PerPixel,
                width: 160,
                height: 120,
                blend: Blend::Sum,
                cov_param: CovParam::Cholesky,
                gaussians: g,
                tone: None,
            }
        }

        #[test]
        fn a_lit_scene_gets_no_map() {
            assert!(plan_of(&flat([0.3, 0.25, 0.2]), 256).is_none());
        }

        #[test]
        fn the_scale_is_half_at_the_noise_and_rises_with_the_level() {
            assert_eq!(scale_at(0.0), 0.0);
            assert_eq!(scale_at(-3.0), 0.0);
            assert_eq!(scale_at(f64::from(NOISE)), 0.5);
            assert!(scale_at(10.0 * f64::from(NOISE)) > 0.99);
            let mut last = 0.0;
            for i in 1..100 {
                let s = scale_at(f64::from(i) * 0.1);
                assert!(s > last && s < 1.0);
                last = s;
            }
        }

        #[test]
        fn a_scene_near_black_gets_a_map_and_a_darker_one_a_lower_scale() {
            let mid = |c: [f32; 3]| {
                let map = plan_of(&flat(c), 256).expect("a map");
                let s = map.scales.values::<1>();
                s[s.len() / 2 + usize::from(map.width) / 2][0]
            };
            let (dim, dimmer) = (mid([0.004, 0.012, 0.004]), mid([0.001, 0.003, 0.001]));
            assert!(dimmer < dim && dim < KEEP, "{dimmer} {dim}");
        }

        #[test]
        fn black_and_empty_scenes_give_finite_scales() {
            let black = plan_of(&flat([0.0; 3]), 256).expect("a map");
            assert!(black.scales.values::<1>().iter().all(|[s]| *s == 0.0));
            let mut empty = flat([0.0; 3]);
            empty.gaussians = GaussianSet::default();
            let m = plan_of(&empty, 256).expect("a map of a black image");
            assert!(m.scales.values::<1>().iter().all(|[s]| s.is_finite()));
        }
    }
}
