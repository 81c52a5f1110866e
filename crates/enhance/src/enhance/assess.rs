//! Whether an image needs stage 2: the low-light decision of its front door.
//!
//! A global meter reads a lamp, a window or a lit sky as "well exposed" and leaves the
//! dark rest of the photograph alone. The decision is local instead: an image is
//! enhanced when a meaningful part of it is under-exposed, judged from the illumination
//! of [`super::light`] (the brightest channel, smoothed over 1/32 of the image).
//!
//! A region is under-exposed where its illumination is below [`DARK_LEVEL`]: 0.2 on
//! the display scale is a linear 0.033, about 2.4 stops below middle grey, where a
//! well-exposed photograph keeps its deep shadows only. An image is low-light when
//! [`DARK_SHARE`], a quarter of it, is. On the validation sets this enhances every LOL
//! pair and every dark photograph of `mef13` (34–78 % under-exposed) and leaves its
//! daylight scenes, lit interiors and sunsets (0–15 %) as they are.
//!
//! An image with no value above half an 8-bit step ([`BLACK_PEAK`]) is black, not dark:
//! every value decodes to 0 in 8 bits, and a lift to middle grey would multiply what is
//! left below that step by hundreds. It is left as it is, with that reason; `force`
//! enhances it anyway (content finer than 8 bits, from a 16-bit or float source, may
//! want that).

use super::light::illumination;
use super::operator::ColorOperator;
use super::working::work_size;
use gsi_format::model::Scene;
use gsi_render::render::project;
use std::fmt;

/// Illumination below which a region counts as under-exposed.
pub const DARK_LEVEL: f32 = 0.2;
/// Share of the image that must be under-exposed for it to be enhanced.
pub const DARK_SHARE: f32 = 0.25;
/// Brightest value below which an image is black: half an 8-bit step, where the decoder
/// rounds every value to 0.
pub const BLACK_PEAK: f32 = 0.5 / 255.0;

/// What [`assess`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
#[non_exhaustive]
pub struct Assessment {
    /// Share of the image whose illumination is below [`DARK_LEVEL`], in `[0, 1]`.
    pub dark_share: f32,
    /// Mean display luma of the image as it is.
    pub mean_luma: f32,
    /// Its brightest value, any channel (0 where there is none). Where that is under
    /// [`BLACK_PEAK`], [`assess`] also counts the light each Gaussian gives its nearest
    /// pixel at full size, which a working size too coarse for it can miss.
    pub peak: f32,
}

impl Assessment {
    /// Whether stage 2 should enhance the image: [`DARK_SHARE`] of it or more is
    /// under-exposed, and it is not black.
    pub fn is_low_light(&self) -> bool {
        self.dark_share >= DARK_SHARE && !self.is_black()
    }

    /// Whether no value of the image reaches [`BLACK_PEAK`]: every value would decode to
    /// 0 in 8 bits. (A NaN peak, which [`assess`] never gives, counts as black.)
    pub fn is_black(&self) -> bool {
        self.peak.is_nan() || self.peak < BLACK_PEAK
    }

    /// The reason [`super::Outcome::NotLowLight`] gives, where [`Self::is_low_light`] is
    /// false: "nothing to lift" for a black image, else "not a low-light image".
    pub fn verdict(&self) -> &'static str {
        if self.is_black() {
            "nothing to lift"
        } else {
            "not a low-light image"
        }
    }
}

impl fmt::Display for Assessment {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.is_black() {
            return write!(
                f,
                "the image is black (no value reaches half an 8-bit step), mean luma {:.3}",
                self.mean_luma
            );
        }
        write!(
            f,
            "{:.0}% of the image is under-exposed (lit below {DARK_LEVEL} on a 0-1 scale; \
             {:.0}% makes it low-light), mean luma {:.3}",
            100.0 * self.dark_share,
            100.0 * DARK_SHARE,
            self.mean_luma
        )
    }
}

/// Assess `scene` as shown, rendered at the working size of stage 2 (long side
/// `work_side`).
pub fn assess(scene: &Scene, work_side: u32) -> Assessment {
    let (w, h) = work_size(scene.width, scene.height, work_side);
    let op = ColorOperator::new(scene, w, h);
    let mut img = vec![0.0f32; (w * h * 3) as usize];
    op.render(&scene.gaussians.colors, &mut img);
    if let Some(t) = &scene.tone {
        t.apply(&mut img);
    }
    let mut a = assess_image(&img, w as usize, h as usize);
    // Only an image that looks black at the working size needs each Gaussian projected.
    if a.is_black() {
        a.peak = a.peak.max(own_light(scene));
    }
    a
}

/// The most light any one Gaussian gives a pixel of the full-size image: its weight at
/// the pixel centre nearest its own (spec §6.3) times its colour, through the tone curve
/// where the scene has one. A Gaussian much smaller than a working pixel (a star, a
/// distant lamp) can fall between the working size's pixel centres; this keeps an image
/// that shows it from reading as black, and one whose Gaussians reach no pixel centre
/// still reads as black.
fn own_light(scene: &Scene) -> f32 {
    let (w, h) = (scene.width, scene.height);
    // The nearest pixel centre, kept within the box; `project` gives finite means.
    let near = |m: f32, lo: u32, hi: u32| ((m - 0.5).round().max(0.0) as u32).clamp(lo, hi);
    let mut most = 0.0f32;
    for g in (0..scene.gaussians.len()).filter_map(|k| project(scene, k, w, h)) {
        let i = near(g.mean[0], g.bbox.x0, g.bbox.x1);
        let j = near(g.mean[1], g.bbox.y0, g.bbox.y1);
        let Some(alpha) = g.alpha_at(i, j, scene.blend) else {
            continue;
        };
        for (k, c) in g.color.iter().enumerate() {
            let v = alpha * c;
            let shown = scene.tone.as_ref().map_or(v, |t| t.eval(k, v));
            most = most.max(shown);
        }
    }
    most
}

/// [`assess`] of an image of `width × height` interleaved RGB display values.
pub fn assess_image(rgb: &[f32], width: usize, height: usize) -> Assessment {
    let light = illumination(rgb, width, height);
    let n = light.len().max(1) as f32;
    let dark = light.iter().filter(|&&l| l < DARK_LEVEL).count() as f32;
    // (`max` passes over NaN.)
    let peak = rgb.iter().fold(0.0f32, |m, &v| m.max(v));
    Assessment {
        dark_share: dark / n,
        mean_luma: super::fit::mean_luma(rgb),
        peak,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(v: f32, w: usize, h: usize) -> Vec<f32> {
        vec![v; w * h * 3]
    }

    #[test]
    fn a_dark_image_is_low_light_and_a_bright_one_is_not() {
        assert!(assess_image(&flat(0.05, 64, 48), 64, 48).is_low_light());
        let a = assess_image(&flat(0.6, 64, 48), 64, 48);
        assert!(!a.is_low_light() && a.dark_share == 0.0, "{a:?}");
    }

    #[test]
    fn a_lamp_does_not_hide_a_dark_room() {
        // A dark room (0.03) with a lamp filling a tenth of the frame at full brightness:
        // its mean is that of a well-exposed photograph's shadows, but most of it is dark.
        let (w, h) = (80, 60);
        let mut img = flat(0.03, w, h);
        for y in 0..h {
            for x in 0..8 {
                img[(y * w + x) * 3..][..3].copy_from_slice(&[1.0, 0.95, 0.8]);
            }
        }
        let a = assess_image(&img, w, h);
        assert!(a.is_low_light() && a.dark_share > 0.7, "{a:?}");
    }

    #[test]
    fn a_bright_scene_with_a_dark_corner_is_left_alone() {
        let (w, h) = (80, 60);
        let mut img = flat(0.5, w, h);
        for y in 0..20 {
            for x in 0..20 {
                img[(y * w + x) * 3..][..3].copy_from_slice(&[0.02; 3]);
            }
        }
        let a = assess_image(&img, w, h);
        assert!(!a.is_low_light() && a.dark_share < 0.1, "{a:?}");
        assert!(a.to_string().contains("under-exposed"), "{a}");
    }

    #[test]
    fn black_white_and_tiny_images_are_assessed() {
        for (img, w, h, low) in [
            (flat(0.01, 1, 1), 1, 1, true),
            (flat(1.0, 3, 2), 3, 2, false),
            (flat(0.0, 1, 1), 1, 1, false),
            (vec![f32::NAN; 12], 2, 2, false),
        ] {
            let a = assess_image(&img, w, h);
            assert_eq!(a.is_low_light(), low, "{a:?}");
            assert!(a.dark_share.is_finite() && a.mean_luma.is_finite() && a.peak.is_finite());
        }
    }

    #[test]
    fn a_black_image_has_nothing_to_lift_and_one_step_is_dark() {
        let black = assess_image(&flat(0.0, 64, 48), 64, 48);
        assert!(black.is_black() && !black.is_low_light(), "{black:?}");
        assert_eq!(black.verdict(), "nothing to lift");
        assert!(black.to_string().contains("black"), "{black}");
        // Just under half a step everywhere is black; one pixel at half a step is not.
        let mut img = flat(BLACK_PEAK * 0.99, 64, 48);
        assert!(assess_image(&img, 64, 48).is_black());
        img[3 * 100 + 1] = BLACK_PEAK;
        let a = assess_image(&img, 64, 48);
        assert!(!a.is_black() && a.is_low_light(), "{a:?}");
        assert_eq!(a.verdict(), "not a low-light image");
        // The darkest LOL images average two 8-bit steps: dark, not black.
        assert!(assess_image(&flat(2.0 / 255.0, 64, 48), 64, 48).is_low_light());
    }

    #[test]
    fn a_star_between_the_working_pixels_is_not_black() {
        use gsi_format::model::{Blend, CovParam, GaussianSet, WeightRule};
        // One Gaussian of σ 0.04 px (a Cholesky factor of 1e-5) in a 4000 × 3000 image;
        // the 256-pixel working size clamps it to σ 0.01 working px, half a working pixel
        // from the nearest centre.
        let star = |(u, v): (f32, f32), colour: f32| Scene {
            weights: WeightRule::PerPixel,
            width: 4000,
            height: 3000,
            blend: Blend::Sum,
            cov_param: CovParam::Cholesky,
            gaussians: GaussianSet {
                positions: vec![[u, v]],
                cov: vec![[1e-5, 0.0, 1e-5]],
                colors: vec![[colour; 3]],
                ..GaussianSet::default()
            },
            tone: None,
        };
        // On the centre of pixel (2000, 1500): that pixel shows it at full strength.
        let on_centre = (2000.5 / 4000.0, 1500.5 / 3000.0);
        let lit = star(on_centre, 1.0);
        let (w, h) = work_size(4000, 3000, 256);
        let mut img = vec![0.0f32; (w * h * 3) as usize];
        ColorOperator::new(&lit, w, h).render(&lit.gaussians.colors, &mut img);
        assert!(
            img.iter().all(|&v| v < BLACK_PEAK),
            "the working size sees it"
        );
        let a = assess(&lit, 256);
        assert!(!a.is_black() && a.is_low_light() && a.peak == 1.0, "{a:?}");
        // Too faint, or between pixel centres where its 3σ box holds none: black.
        assert!(assess(&star(on_centre, BLACK_PEAK * 0.5), 256).is_black());
        let between = star((0.5, 0.5), 1.0);
        assert!(assess(&between, 256).is_black());
        // (It touches no pixel at full size: its projection has no pixel box.)
        assert!(
            project(&between, 0, 4000, 3000).is_none(),
            "it decodes to black"
        );
    }
}
