//! The working image stage 2 fits and measures on: the scene rendered small (long side
//! `EnhanceOptions::work_side`), where the losses' statistics of brightness, colour and
//! edges are as good as at full size, and its mean luma. Shared by the fit, the tone
//! curve and the low-light decision, below all three.

use super::operator::ColorOperator;
use gsi_format::model::Scene;

/// The working size for an image of `width × height`: scaled so the long side is at
/// most `side`, never up.
pub fn work_size(width: u32, height: u32, side: u32) -> (u32, u32) {
    let long = width.max(height).max(1);
    if long <= side {
        return (width.max(1), height.max(1));
    }
    let s = f64::from(side) / f64::from(long);
    let scale = |x: u32| ((f64::from(x) * s).round() as u32).max(1);
    (scale(width), scale(height))
}

/// Mean Rec. 601 luma of an image of `width·height·3` floats, clamped to `[0, 1]`.
pub fn mean_luma(img: &[f32]) -> f32 {
    let n = (img.len() / 3).max(1) as f64;
    let s: f64 = img
        .chunks_exact(3)
        .map(|p| f64::from(super::loss::display_luma(p)))
        .sum();
    (s / n) as f32
}

/// `scene` rendered at the working size (long side `work_side`), as blended values.
pub fn working_image(scene: &Scene, work_side: u32) -> Vec<f32> {
    let (w, h) = work_size(scene.width, scene.height, work_side);
    let a = ColorOperator::new(scene, w, h);
    let mut img = vec![0.0; (w * h * 3) as usize];
    a.render(&scene.gaussians.colors, &mut img);
    img
}
