//! The gain map after the mixture (spec §7.2.3): stage 2's local exposure, a slowly
//! varying gain multiplied into every Gaussian's colour.
//!
//! A gain that varies slowly across a footprint is exact in the Gaussian domain
//! (`Σ γ(mᵢ)·cᵢ·αᵢ(p) ≈ γ(p)·C(p)`), unlike a curve of the blended value (spec §6.6), so
//! the lift of a scene's shadows lives in the colour records and the tone curve in
//! `GTRC`. Applying a stored map needs each Gaussian's centre and colour only.

use super::mixture::tap;
use gsi_format::contract::COLOR_MAX;
use gsi_format::format::{Attribute, GainMap};

/// `colors` (of Gaussians centred at `positions`) times the map's gain at each centre,
/// clamped to `±COLOR_MAX`, exactly as spec §7.2.3.
pub fn apply(map: &GainMap, positions: &[[f32; 2]], colors: &[[f32; 3]]) -> Vec<[f32; 3]> {
    at_centres(&map.gains, map.width, map.height, positions)
        .into_iter()
        .zip(colors)
        .map(|(g, c)| c.map(|x| (x * g).clamp(-COLOR_MAX, COLOR_MAX)))
        .collect()
}

/// The value of a one-component map of `width × height` cells (row by row) at each
/// centre of `positions`, bilinearly: what the gain map and the chroma map (spec
/// §7.2.3, §7.2.4) read per Gaussian.
pub fn at_centres(map: &Attribute, width: u16, height: u16, positions: &[[f32; 2]]) -> Vec<f32> {
    let values: Vec<f32> = map.values::<1>().into_iter().map(|[v]| v).collect();
    let (w, h) = (usize::from(width), usize::from(height));
    positions.iter().map(|&p| at(&values, w, h, p)).collect()
}

/// The bilinear value of a `w × h` map at normalized position `p` (the tap of spec §7.2
/// step 1, summed from 0 in its order).
fn at(gains: &[f32], w: usize, h: usize, p: [f32; 2]) -> f32 {
    let t = tap(w, h, p);
    let mut g = 0.0f32;
    for (&cell, &b) in t.cells.iter().zip(&t.weights) {
        g += b * gains[cell as usize];
    }
    g
}

#[cfg(test)]
mod tests {
    use super::*;
    use gsi_format::format::Attribute;

    /// Spec §7.2.3's worked example.
    #[test]
    fn gain_worked_example() {
        let map = GainMap {
            width: 2,
            height: 1,
            gains: Attribute::fit(&[[1.0f32], [4.0]], [8]),
        };
        let out = apply(&map, &[[0.5, 0.5]], &[[0.1, 0.2, -0.05]]);
        assert_eq!(out, vec![[0.25, 0.5, -0.125]]);
    }

    #[test]
    fn colours_stay_finite_and_keep_their_sign() {
        let map = GainMap {
            width: 3,
            height: 2,
            gains: Attribute::fit(&[[64.0f32], [0.5], [1.0], [2.0], [64.0], [3.0]], [8]),
        };
        let pos = [
            [0.0, 0.0],
            [1.0, 1.0],
            [f32::NAN, 0.3],
            [-5.0, 9.0],
            [0.4, 0.6],
        ];
        let col = [
            [1.0, -1.0, 0.0],
            [60.0, -60.0, 0.5],
            [0.2; 3],
            [0.1; 3],
            [-0.3; 3],
        ];
        for (o, c) in apply(&map, &pos, &col).iter().zip(&col) {
            for k in 0..3 {
                assert!(o[k].is_finite() && o[k].abs() <= COLOR_MAX, "{o:?}");
                assert!(o[k] * c[k] >= 0.0, "{o:?} from {c:?}");
            }
        }
    }
}
