//! Which exposure to aim at, chosen from the image alone, the way a camera meters a
//! scene: with no reference and no training data, only statistics of well-exposed
//! photographs.
//!
//! A fixed target (the exposure term's `E`, paper Eq. 17) is wrong for most images: the
//! references of LOL eval15 range from mean luma 0.24 to 0.63, and a fixed 0.5 leaves
//! some images washed out and others dull. [`meter`] instead finds the gain, in linear
//! light, that a shorter exposure would have to be multiplied by to look like a
//! well-exposed photograph, and aims at the mean luma the image would have after that
//! gain. Two statistics of the 24 Kodak photographs set the gain:
//!
//! * the log-average linear luminance (the "key" of a scene, which averaging metering
//!   places at a fixed value), and
//! * the 99th percentile of linear luminance (the highlights, which a well-exposed
//!   photograph keeps below clipping),
//!
//! and the smaller of the two gains wins, so that a scene with a bright lamp or window is
//! not lifted until its highlights burn out. The constants were measured on Kodak
//! (`cargo run --release --example lowlight_set -- rules`), which is also the
//! reference set of the synthetic validation set; LOL's references were not used.
//!
//! The metered exposure is what `--exposure auto` aims at ([`Exposure::Metered`]). The
//! default aims at middle grey ([`Exposure::MidGrey`]): on the validation pairs it lands
//! closer to the references' exposure. Whether to act at all is decided locally, by
//! [`super::assess`]: a global meter reads a lamp or a window as a well-exposed scene.

use super::loss::display_luma;
use gsi_metrics::metrics::{linear_to_srgb, srgb_to_linear};

/// Median over the 24 Kodak photographs of the log-average linear luminance (Rec. 709
/// weights on sRGB-decoded channels, each photograph averaged over 3×3 blocks, `+1e-4`
/// inside the logarithm).
pub const KODAK_KEY: f32 = 0.1423;

/// Median over the same photographs of the 99th percentile of linear luminance.
pub const KODAK_HIGHLIGHT: f32 = 0.8030;

/// How close the output's mean luma must land to the target it aims at.
pub const TOLERANCE: f32 = 0.05;

/// Added to the luminance inside the logarithm of the key, so black pixels count as
/// very dark rather than infinitely so; the same as when the constants were measured.
const KEY_EPS: f64 = 1e-4;

/// The mean luma stage 2 shows its result at (the tone curve's scale, [`super::curve`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum Exposure {
    /// Middle grey, [`super::curve::MID_GREY`]: where a camera's averaging meter puts a
    /// scene's mean.
    #[default]
    MidGrey,
    /// This mean luma, in `(0, 1)`.
    Exactly(f32),
    /// The exposure [`meter`] finds for the image.
    Metered,
}

impl Exposure {
    /// The mean luma to aim at for an image of display values `img` (interleaved RGB,
    /// stage 2's working image).
    pub fn target(self, img: &[f32]) -> f32 {
        match self {
            Exposure::MidGrey => super::curve::MID_GREY,
            Exposure::Exactly(e) => e,
            Exposure::Metered => meter(img).target,
        }
    }
}

/// What [`meter`] found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Metering {
    /// Mean display luma of the image as it is.
    pub own: f32,
    /// The linear-light gain that makes it look well exposed (at least 1).
    pub gain: f32,
    /// Mean display luma of the image after that gain: the exposure to aim at.
    pub target: f32,
}

/// A display value as a screen shows it: clamped to `[0, 1]`, and 0 where not finite.
fn shown(v: f32) -> f32 {
    if v.is_finite() {
        v.clamp(0.0, 1.0)
    } else {
        0.0
    }
}

/// sRGB decoding of one display value as shown.
fn to_linear(v: f32) -> f64 {
    srgb_to_linear(f64::from(shown(v)))
}

/// sRGB encoding of one linear value.
fn to_display(v: f64) -> f32 {
    linear_to_srgb(v) as f32
}

/// Meter an image of `width × height × 3` display values (interleaved RGB, nominally in
/// `[0, 1]`; stage 2 passes the scene rendered at its working size).
pub fn meter(img: &[f32]) -> Metering {
    let n = img.len() / 3;
    if n == 0 {
        return Metering {
            own: 0.0,
            gain: 1.0,
            target: 0.0,
        };
    }
    let lin: Vec<[f64; 3]> = img
        .chunks_exact(3)
        .map(|p| [to_linear(p[0]), to_linear(p[1]), to_linear(p[2])])
        .collect();
    let mut lum: Vec<f64> = lin
        .iter()
        .map(|l| 0.2126 * l[0] + 0.7152 * l[1] + 0.0722 * l[2])
        .collect();
    let key = (lum.iter().map(|v| (v + KEY_EPS).ln()).sum::<f64>() / n as f64).exp();
    lum.sort_by(f64::total_cmp);
    let high = lum[(n * 99 / 100).min(n - 1)];
    // A black image has no key or highlight to meter: its gain is bounded by the
    // smallest luminance the key can see.
    let gain = (f64::from(KODAK_KEY) / key)
        .min(f64::from(KODAK_HIGHLIGHT) / high.max(KEY_EPS))
        .max(1.0);
    let own = img
        .chunks_exact(3)
        .map(|p| f64::from(display_luma(&[shown(p[0]), shown(p[1]), shown(p[2])])))
        .sum::<f64>()
        / n as f64;
    let target = lin
        .iter()
        .map(|l| {
            let p = l.map(|c| to_display(c * gain));
            f64::from(display_luma(&p))
        })
        .sum::<f64>()
        / n as f64;
    Metering {
        own: own as f32,
        gain: gain as f32,
        target: target as f32,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(v: f32, n: usize) -> Vec<f32> {
        vec![v; n * 3]
    }

    #[test]
    fn a_dark_flat_image_is_lifted_to_the_key() {
        let m = meter(&flat(0.02, 64));
        assert!(m.gain > 2.0, "{m:?}");
        // A flat image's key is its luminance (plus the logarithm's epsilon): the gain
        // brings it to KODAK_KEY, the highlight (the same value) asking for more.
        let lum = to_linear(0.02);
        let want = to_display(f64::from(KODAK_KEY) * lum / (lum + KEY_EPS));
        assert!((m.target - want).abs() < 1e-3, "{m:?} want {want}");
    }

    #[test]
    fn a_bright_image_is_left_alone() {
        let m = meter(&flat(0.6, 64));
        assert_eq!(m.gain, 1.0);
        assert!((m.target - m.own).abs() < 1e-6);
    }

    #[test]
    fn highlights_cap_the_gain() {
        // Mostly black with a few bright pixels (a lamp): the key asks for a large
        // gain, the highlights for none.
        let mut img = flat(0.01, 1000);
        for v in &mut img[..3 * 20] {
            *v = 0.9;
        }
        let m = meter(&img);
        assert!(m.gain < 1.2, "{m:?}");
    }

    #[test]
    fn black_white_and_empty_images_give_finite_targets() {
        for img in [flat(0.0, 16), flat(1.0, 16), Vec::new(), vec![f32::NAN; 12]] {
            let m = meter(&img);
            assert!(
                m.target.is_finite() && m.gain.is_finite() && m.own.is_finite(),
                "{m:?}"
            );
            assert!((0.0..=1.0).contains(&m.target));
        }
    }
}
