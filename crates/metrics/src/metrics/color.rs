//! Colour: the sRGB transfer curve and a cast measured in CIELAB.
//!
//! A colour cast is a shift of the whole image's chromaticity. Stage 2 must not add one,
//! and [`color_cast`] measures it as the difference between the mean CIELAB `a*` and `b*`
//! (D65 white, sRGB primaries) of an image and of its reference: 1 unit is about a just
//! noticeable difference, and a cast of a few units shows on a white wall.

use super::{check_pair, MetricError, Rgb8};

/// ITU-R BT.601 luma weights of R, G and B: what every stage, metric and report of gsi
/// calls brightness, in one place.
pub const BT601: [f64; 3] = [0.299, 0.587, 0.114];
/// [`BT601`] in `f32` (each weight the `f32` nearest it), for per-pixel loops in `f32`.
pub const BT601_F32: [f32; 3] = [0.299, 0.587, 0.114];

/// The sRGB decoding curve (IEC 61966-2-1) of a value in `[0, 1]`.
pub fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

/// The sRGB encoding curve, the inverse of [`srgb_to_linear`], clamped to `[0, 1]`.
pub fn linear_to_srgb(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// The mean CIELAB `a*` and `b*` of an 8-bit sRGB image (D65).
pub fn mean_ab(image: Rgb8<'_>) -> [f64; 2] {
    // sRGB primaries to XYZ, each row divided by the D65 white's X, Y, Z.
    const M: [[f64; 3]; 3] = [
        [0.4124 / 0.950_47, 0.3576 / 0.950_47, 0.1805 / 0.950_47],
        [0.2126, 0.7152, 0.0722],
        [0.0193 / 1.088_83, 0.1192 / 1.088_83, 0.9505 / 1.088_83],
    ];
    let lut: Vec<f64> = (0..256)
        .map(|v| srgb_to_linear(f64::from(v) / 255.0))
        .collect();
    let f = |t: f64| {
        if t > 0.008_856 {
            t.cbrt()
        } else {
            7.787 * t + 16.0 / 116.0
        }
    };
    let (mut a, mut b) = (0.0, 0.0);
    for p in image.data.chunks_exact(3) {
        let l = [
            lut[usize::from(p[0])],
            lut[usize::from(p[1])],
            lut[usize::from(p[2])],
        ];
        let [x, y, z] = M.map(|r| f(r[0] * l[0] + r[1] * l[1] + r[2] * l[2]));
        a += 500.0 * (x - y);
        b += 200.0 * (y - z);
    }
    let n = (image.data.len() / 3).max(1) as f64;
    [a / n, b / n]
}

/// `image`'s colour cast against `reference`: the difference of their mean `a*` and
/// `b*` (image minus reference). Positive `a*` is towards magenta, negative towards
/// green; positive `b*` towards yellow, negative towards blue.
pub fn color_cast(reference: Rgb8<'_>, image: Rgb8<'_>) -> Result<[f64; 2], MetricError> {
    check_pair(reference, image)?;
    let (r, i) = (mean_ab(reference), mean_ab(image));
    Ok([i[0] - r[0], i[1] - r[1]])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The `f32` weights are the `f32`s nearest the `f64` ones.
    #[test]
    fn bt601_in_f32_is_bt601_rounded() {
        for k in 0..3 {
            assert_eq!(super::BT601_F32[k], super::BT601[k] as f32);
        }
    }

    #[test]
    fn grey_has_no_chroma_and_a_warm_tint_is_yellow() {
        let grey = vec![128u8; 4 * 3];
        let [a, b] = mean_ab(Rgb8::new(2, 2, &grey).unwrap());
        assert!(a.abs() < 0.01 && b.abs() < 0.01, "{a} {b}");
        let warm: Vec<u8> = [150u8, 128, 100].repeat(4);
        let cast = color_cast(
            Rgb8::new(2, 2, &grey).unwrap(),
            Rgb8::new(2, 2, &warm).unwrap(),
        )
        .unwrap();
        assert!(cast[1] > 10.0, "{cast:?}");
    }

    #[test]
    fn the_transfer_curves_invert_each_other() {
        for i in 0..=100 {
            let v = f64::from(i) / 100.0;
            assert!((linear_to_srgb(srgb_to_linear(v)) - v).abs() < 1e-12);
        }
    }
}
