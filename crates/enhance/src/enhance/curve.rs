//! How stage 2 sets the exposure of what it shows: a tone curve on the blended values
//! (stored in `GTRC`, spec §6.6) and, where the scene's highlights hold the curve back,
//! a gain map that lifts its shadows (stored in `gENH`, spec §7.2.3).
//!
//! **The curve** is `S(a·x^g)`: a power `g` (default [`CurveOptions::default`]'s 0.5)
//! scaled so that the output's mean luma lands on the target, with a soft shoulder `S`
//! that rolls values above [`KNEE`] off towards [`WHITE`] instead of clipping them. A
//! shorter exposure relates to a longer one by a gain in linear light, which through a
//! camera's curve compresses in display values; on the validation pairs (LOL `val30`, the
//! synthetic dark Kodak set) a power of 0.5 on the blended values scored 20.30 dB / 0.793
//! SSIM and 21.95 / 0.794, where a gain alone scored 19.0 / 0.66. Compressing the
//! relative contrast of the shadows also keeps their noise down, which a gain lifts as
//! much as the signal. The curve must act on the blended value: set per Gaussian (spec
//! §7.2.2) the same curve scores 0.687 SSIM on `val30` and draws the stage-1 Gaussians
//! as streaks, since a power of a sum of Gaussians is not a sum of the same Gaussians.
//!
//! **The highlight cap.** The scale `a` is at most what brings the scene's bright
//! regions (the 99th percentile of its illumination, [`super::light`]) to the shoulder's
//! knee ([`HIGHLIGHT_CAP`]): a dark room with a lamp is not lifted until the lamp burns
//! out.
//!
//! **Local exposure.** Where the cap keeps the mean below the target, the shadows are
//! lifted on their own: a gain `(bright / local)^β` on the output's illumination, 1 in
//! the bright regions, at most [`GAIN_MAX`], with `β` in `[0, 1]` the smallest that makes
//! up [`LOCAL_SHARE`] of the shortfall (LIME's `I / L^γ` with `γ` chosen per image). It
//! is stored as a map of gains in the colour records, where a slowly varying gain is
//! exact (spec §7.2.3). A uniformly dark scene reaches its target under the cap and gets
//! no map: local gains score lower against references taken with a longer exposure
//! (−0.5 dB on `val30` at `β` = 0.3 on every image), which is a global change of light.

use super::light::{illumination, quantile};
use super::operator::ColorOperator;
use super::working::work_size;
use gsi_format::format::{Attribute, GainMap, MAX_GAIN};
use gsi_format::model::{Scene, ToneCurve};

/// Middle grey: 18 % reflectance, which sRGB encodes as 0.46. A camera's averaging meter
/// puts a scene's mean there, and so does stage 2 by default; the LOL validation pairs'
/// references average 0.45.
pub const MID_GREY: f32 = 0.46;
/// Where the curve's shoulder starts rolling values off.
pub const KNEE: f64 = 0.8;
/// What the shoulder approaches and never reaches: 249 in 8 bits, below the 250 that
/// counts a pixel as clipped.
pub const WHITE: f64 = 249.0 / 255.0;
/// Where the scene's bright regions may end at most: the shoulder's knee, so that they
/// keep their contrast rather than being rolled off.
pub const HIGHLIGHT_CAP: f32 = KNEE as f32;
/// The percentile of the illumination that stands for the bright regions: the 99th, as
/// the metering of [`super::exposure`] takes for the highlights.
pub const BRIGHT_QUANTILE: f32 = 0.99;
/// The share of the shortfall (the target's mean luma less what the capped curve shows)
/// that the gain map makes up. Half keeps some of the scene's lighting: on the
/// validation sets, making up all of it scored 20.02 dB on LOL `val30` and 21.56 on the
/// synthetic set (pixel-domain probe), half 20.39 and 21.94, none 20.19 and 22.09, but
/// none leaves the darkest `mef13` photograph at mean luma 0.27.
pub const LOCAL_SHARE: f32 = 0.5;
/// Largest lift of the local exposure, on the output's scale.
pub const GAIN_MAX: f32 = 4.0;
/// Knots of the stored curve: with knots even in `sqrt(x)`, a power of 0.5 is exact and
/// the shoulder is within 1/1000 of the function.
pub const KNOTS: usize = 64;
/// Side of a gain-map cell, in working pixels (the mixture's cell).
pub const GAIN_CELL: u32 = 8;
/// Bits of each stored gain.
pub const GAIN_BITS: u8 = 8;
/// How close to the target a mean luma counts as reached.
const REACHED: f32 = 0.005;
/// Halvings of every bisection here.
const STEPS: u32 = 40;

/// How stage 2 shows its result.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CurveOptions {
    /// The power `g` of the curve, in `(0, 4]`; 1 leaves the tones as the mixture made
    /// them and only sets the exposure.
    pub exponent: f32,
    /// Whether the shadows of a scene whose highlights cap the curve are lifted on their
    /// own (a gain map).
    pub local: bool,
    /// Whether the colour of regions lit within the noise of black is moved towards grey
    /// (a chroma map, [`super::chroma`]), so that the curve does not show the noise's and
    /// the black level's colour as a cast.
    pub chroma: bool,
}

impl Default for CurveOptions {
    fn default() -> Self {
        CurveOptions {
            exponent: 0.5,
            local: true,
            chroma: true,
        }
    }
}

/// What [`plan`] chose.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// The mean luma it aimed at.
    pub target: f32,
    /// The curve to store in `GTRC`.
    pub curve: ToneCurve,
    /// Its scale `a`.
    pub scale: f32,
    /// Whether the highlight cap held the scale below what the target asked.
    pub capped: bool,
    /// The gain map, where one was needed.
    pub gain: Option<GainMap>,
    /// The local exposure's `β` (0 without a map).
    pub beta: f32,
    /// The colours with the gain map applied (the colours given, without one).
    pub colors: Vec<[f32; 3]>,
    /// Mean luma of the working image as shown, through the curve.
    pub mean_luma: f32,
}

/// The shoulder: identity below [`KNEE`], then rolling off towards [`WHITE`].
fn shoulder(y: f64) -> f64 {
    if y <= KNEE {
        y.max(0.0)
    } else {
        KNEE + (WHITE - KNEE) * ((y - KNEE) / (WHITE - KNEE)).tanh()
    }
}

/// `S(a·x^g)` of a blended value `x` in `[0, 1]`.
fn shown(x: f64, a: f64, g: f64) -> f64 {
    shoulder(a * x.clamp(0.0, 1.0).powf(g))
}

/// Mean display luma of `x` (blended values, `w·h·3`, already raised to `g`) scaled by
/// `a` and per pixel by `lift` (1 where `None`), through the shoulder.
fn luma_of(xg: &[f32], lift: Option<&[f32]>, a: f64) -> f32 {
    let n = (xg.len() / 3).max(1) as f64;
    let sum: f64 = xg
        .chunks_exact(3)
        .enumerate()
        .map(|(p, px)| {
            let l = lift.map_or(1.0, |l| f64::from(l[p]));
            let c = |k: usize| shoulder(a * l * f64::from(px[k]));
            let [wr, wg, wb] = gsi_metrics::metrics::BT601;
            wr * c(0) + wg * c(1) + wb * c(2)
        })
        .sum();
    (sum / n) as f32
}

/// The smallest `a` in `[e^−12, e^12]` at which [`luma_of`] reaches `target` (the
/// largest where it never does): it rises with `a`.
fn solve_scale(xg: &[f32], lift: Option<&[f32]>, target: f32) -> f64 {
    let (mut lo, mut hi) = (-12.0f64, 12.0f64);
    for _ in 0..STEPS {
        let mid = 0.5 * (lo + hi);
        if luma_of(xg, lift, mid.exp()) < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    (0.5 * (lo + hi)).exp()
}

/// Choose the curve (and the gain map, where needed) that shows `colors` (the
/// mixture's output for `scene`'s geometry) at mean luma `target`, rendered at the
/// working size (long side `work_side`).
pub fn plan(
    scene: &Scene,
    colors: &[[f32; 3]],
    target: f32,
    opts: &CurveOptions,
    work_side: u32,
) -> Plan {
    let g = f64::from(
        opts.exponent
            .clamp(1e-3, gsi_format::format::MAX_TONE_EXPONENT),
    );
    let target = if target.is_finite() {
        target.clamp(0.0, WHITE as f32)
    } else {
        MID_GREY
    };
    let (w, h) = work_size(scene.width, scene.height, work_side);
    let (wu, hu) = (w as usize, h as usize);
    let op = ColorOperator::new(scene, w, h);
    let mut img = vec![0.0f32; wu * hu * 3];
    // The decoder clamps a blended value to [0, 1] before the curve (spec §6.6).
    let raise = |img: &[f32]| -> Vec<f32> {
        img.iter()
            .map(|&v| (f64::from(v).clamp(0.0, 1.0).powf(g)) as f32)
            .collect()
    };
    op.render(colors, &mut img);
    let mut xg = raise(&img);
    let bright = quantile(&illumination(&img, wu, hu), BRIGHT_QUANTILE);
    let cap = f64::from(HIGHLIGHT_CAP) / f64::from(bright.max(1e-4)).powf(g);
    let wanted = solve_scale(&xg, None, target);
    let mut a = wanted.min(cap);
    let mut out = Plan {
        target,
        curve: curve_for(a, g),
        scale: a as f32,
        capped: wanted > cap,
        gain: None,
        beta: 0.0,
        colors: colors.to_vec(),
        mean_luma: luma_of(&xg, None, a),
    };
    if !(opts.local && out.capped && out.mean_luma < target - REACHED) {
        return out;
    }
    let goal = out.mean_luma + LOCAL_SHARE * (target - out.mean_luma);
    // The output's illumination at this scale, and its bright level.
    let shown_img: Vec<f32> = xg
        .iter()
        .map(|&x| shoulder(a * f64::from(x)) as f32)
        .collect();
    let lit = illumination(&shown_img, wu, hu);
    let lit_bright = quantile(&lit, BRIGHT_QUANTILE).max(1e-3);
    let lift_at = |beta: f64| -> Vec<f32> {
        lit.iter()
            .map(|&l| {
                let r = f64::from(lit_bright) / f64::from(l.max(1e-3));
                (r.powf(beta).clamp(1.0, f64::from(GAIN_MAX))) as f32
            })
            .collect()
    };
    let (mut lo, mut hi) = (0.0f64, 1.0f64);
    if luma_of(&xg, Some(&lift_at(1.0)), a) < goal {
        lo = 1.0;
    } else {
        for _ in 0..STEPS / 2 {
            let mid = 0.5 * (lo + hi);
            if luma_of(&xg, Some(&lift_at(mid)), a) < goal {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        lo = 0.5 * (lo + hi);
    }
    let lift = lift_at(lo);
    // The lift is on the output's scale; the colours get its `1/g` power, so that
    // `(γ·x)^g` is the lift times `x^g`. Sampled at the cell centres of the map.
    let (mw, mh) = (w.div_ceil(GAIN_CELL), h.div_ceil(GAIN_CELL));
    let mut gains = Vec::with_capacity((mw * mh) as usize);
    for cy in 0..mh {
        for cx in 0..mw {
            let px = ((cx * GAIN_CELL + GAIN_CELL / 2).min(w - 1)) as usize;
            let py = ((cy * GAIN_CELL + GAIN_CELL / 2).min(h - 1)) as usize;
            let l = f64::from(lift[py * wu + px]).powf(1.0 / g);
            gains.push([(l as f32).clamp(1.0, MAX_GAIN)]);
        }
    }
    let map = GainMap {
        width: mw as u16,
        height: mh as u16,
        gains: Attribute::fit(&gains, [GAIN_BITS]),
    };
    let lifted = super::gain::apply(&map, &scene.gaussians.positions, colors);
    op.render(&lifted, &mut img);
    xg = raise(&img);
    a = solve_scale(&xg, None, target).min(cap);
    out.curve = curve_for(a, g);
    out.scale = a as f32;
    out.gain = Some(map);
    out.beta = lo as f32;
    out.colors = lifted;
    out.mean_luma = luma_of(&xg, None, a);
    out
}

/// The stored curve `S(a·x^g)`.
fn curve_for(a: f64, g: f64) -> ToneCurve {
    ToneCurve::sample(KNOTS, |x| shown(x, a, g)).expect("KNOTS is in range")
}

#[cfg(test)]
mod tests {
    use super::super::working::mean_luma;
    use super::*;
    use gsi_format::model::{Blend, CovParam, GaussianSet};

    /// A grid of round Gaussians over a `w × h` image, coloured by `f(u, v)`.
    fn grid(w: u32, h: u32, f: impl Fn(f32, f32) -> f32) -> Scene {
        let (nx, ny) = (24, 16);
        let mut g = GaussianSet::default();
        for j in 0..ny {
            for i in 0..nx {
                let (u, v) = ((i as f32 + 0.5) / nx as f32, (j as f32 + 0.5) / ny as f32);
                g.positions.push([u, v]);
                g.cov.push([0.6 / nx as f32, 0.0, 0.6 / ny as f32]);
                let c = f(u, v);
                g.colors.push([c, c * 0.9, c * 0.8]);
            }
        }
        Scene {
            weights: gsi_format::model::WeightRule::PerPixel,
            width: w,
            height: h,
            blend: Blend::Sum,
            cov_param: CovParam::Cholesky,
            gaussians: g,
            tone: None,
        }
    }

    fn shown_luma(scene: &Scene, p: &Plan) -> f32 {
        let mut s = scene.clone();
        s.gaussians.colors = p.colors.clone();
        s.tone = Some(p.curve.clone());
        let img = gsi_render::render::render(&s, 96, 64).unwrap();
        mean_luma(&img.data)
    }

    #[test]
    fn a_uniformly_dark_scene_reaches_the_target_without_a_map() {
        let scene = grid(96, 64, |u, _| 0.02 + 0.03 * u);
        let p = plan(
            &scene,
            &scene.gaussians.colors,
            MID_GREY,
            &CurveOptions::default(),
            256,
        );
        assert!(p.gain.is_none() && !p.capped, "{p:?}");
        assert!((p.mean_luma - MID_GREY).abs() < 0.01, "{}", p.mean_luma);
        assert!((shown_luma(&scene, &p) - MID_GREY).abs() < 0.02);
    }

    #[test]
    fn a_lamp_caps_the_curve_and_the_shadows_are_lifted_on_their_own() {
        // A dark room with a bright lamp on the left fifth.
        let scene = grid(96, 64, |u, _| if u < 0.2 { 0.95 } else { 0.02 });
        let global = CurveOptions {
            local: false,
            ..CurveOptions::default()
        };
        let g = plan(&scene, &scene.gaussians.colors, MID_GREY, &global, 256);
        assert!(
            g.capped && g.gain.is_none() && g.mean_luma < MID_GREY - 0.05,
            "{g:?}"
        );
        let l = plan(
            &scene,
            &scene.gaussians.colors,
            MID_GREY,
            &CurveOptions::default(),
            256,
        );
        let map = l.gain.as_ref().expect("a gain map");
        assert!(l.beta > 0.0 && l.mean_luma > g.mean_luma + 0.03, "{l:?}");
        // The lamp keeps its gain of about 1; the room is lifted.
        let gains = map.gains.values::<1>();
        let (first, last) = (gains[0][0], gains[usize::from(map.width) - 1][0]);
        assert!(first < 1.5 && last > 2.0, "{first} {last}");
        // Nothing is shown at or above 250.
        let mut s = scene.clone();
        s.gaussians.colors = l.colors.clone();
        s.tone = Some(l.curve.clone());
        let rgb = gsi_render::render::render(&s, 96, 64).unwrap().to_rgb8();
        assert!(rgb.iter().all(|&v| v < 250));
    }

    #[test]
    fn black_white_and_empty_scenes_give_finite_curves() {
        for scene in [
            grid(8, 8, |_, _| 0.0),
            grid(8, 8, |_, _| 1.0),
            grid(1, 1, |_, _| 0.3),
            Scene {
                gaussians: GaussianSet::default(),
                ..grid(4, 4, |_, _| 0.0)
            },
        ] {
            for target in [MID_GREY, 0.0, f32::NAN, 2.0] {
                let p = plan(
                    &scene,
                    &scene.gaussians.colors,
                    target,
                    &CurveOptions::default(),
                    256,
                );
                assert!(
                    p.scale.is_finite() && p.scale > 0.0 && p.mean_luma.is_finite(),
                    "{p:?}"
                );
                assert!(p.colors.iter().flatten().all(|c| c.is_finite()));
            }
        }
    }

    #[test]
    fn the_stored_curve_follows_the_function() {
        let (a, g) = (2.3, 0.5);
        let c = curve_for(a, g);
        for i in 0..=1000 {
            let x = i as f32 / 1000.0;
            let want = shown(f64::from(x), a, g);
            assert!((f64::from(c.eval(0, x)) - want).abs() < 2e-3, "{x}");
        }
    }
}
