//! Any bytes as the payload of the stage-2 chunks `gENH` and `gORC`: `Ok` or `Err`, never
//! a panic or more memory than the limits allow. An accepted enhancer must write back to
//! the same record, and applying it must give finite colours within its clamp or the
//! identity's range; its denoising (layouts 2 to 4) and its tone curve (layouts 3 and
//! 4), finite colours, the curve's within `±64`; its gain map (layouts 4 and 5), finite
//! colours within `±64` that keep their sign; its chroma map (layout 5), finite colours
//! within `±64`, each between the colour and its grey; its speckle removal (layout 6),
//! in both blend modes, finite colours no larger than they were and of the same sign.

#![no_main]

mod common;

use gsi::enhance::Enhancer;
use gsi::format::{EnhancerRecord, OriginalColors};
use gsi::model::{Blend, CovParam, GaussianSet, Scene};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(orc) = OriginalColors::parse(data) {
        let again = orc.to_payload().expect("re-encoding gORC");
        assert_eq!(OriginalColors::parse(&again).expect("re-reading gORC"), orc);
    }
    let Ok(record) = EnhancerRecord::parse(data, &common::limits()) else {
        return;
    };
    let bytes = record.to_payload(1).expect("re-encoding an accepted gENH");
    let again = EnhancerRecord::parse(&bytes, &common::limits()).expect("re-reading gENH");
    assert_eq!(again, record, "gENH changes through a re-encode");

    let e = Enhancer::from_record(&record);
    let positions = [[0.5, 0.5], [0.0, 1.0], [-3.0, 7.0], [f32::NAN, 0.25]];
    let colors = [
        [0.1, 0.2, 0.3],
        [1.0, 0.0, -1.0],
        [64.0, -64.0, 0.0],
        [0.0; 3],
    ];
    // A small scene of these Gaussians with covariances `cov`: odd shapes, or (for the
    // speckle removal) a degenerate one, one far larger than the image and a NaN.
    let odd = [
        [0.1, 0.0, 0.1],
        [0.0; 3],
        [16.0, -16.0, 16.0],
        [0.2, 0.1, 0.0],
    ];
    let extreme = [
        [0.1, 0.0, 0.1],
        [0.0; 3],
        [1e19, -1e19, 1e19],
        [f32::NAN, 0.1, 0.0],
    ];
    let scene_of = |blend, cov: &[[f32; 3]]| Scene {
        weights: gsi::model::WeightRule::PerPixel,
        tone: None,
        width: 7,
        height: 5,
        blend,
        cov_param: CovParam::Cholesky,
        gaussians: GaussianSet {
            positions: positions.to_vec(),
            cov: cov.to_vec(),
            colors: colors.to_vec(),
            opacity: None,
        },
    };
    // Layouts 2 and 3: the denoising (spec §7.2.1) and the tone curve (§7.2.2) over a
    // small scene of odd shapes, a NaN centre and extreme colours included, stay finite
    // in both blend modes.
    if record.denoise.is_some() || record.tone.is_some() {
        for blend in [Blend::Sum, Blend::Alpha] {
            let scene = scene_of(blend, &odd);
            if let Some(d) = &record.denoise {
                let out = gsi::enhance::denoise::denoise(&scene, &colors, d, &common::limits())
                    .expect("four Gaussians are within the limits");
                assert!(out.iter().flatten().all(|x| x.is_finite()), "{out:?}");
            }
            if let Some(t) = &record.tone {
                let out = gsi::enhance::tone::tone(&scene, &colors, t, &common::limits())
                    .expect("four Gaussians are within the limits");
                assert!(
                    out.iter()
                        .flatten()
                        .all(|x| x.is_finite() && x.abs() <= 64.0),
                    "{out:?}"
                );
            }
        }
    }
    // Layout 6: the speckle removal (spec §7.2.5) over extreme footprints shrinks
    // colours towards 0, never past it.
    if let Some(k) = &record.speckle {
        for blend in [Blend::Sum, Blend::Alpha] {
            let scene = scene_of(blend, &extreme);
            for (out, c) in gsi::enhance::speckle::apply(&scene, &colors, k)
                .iter()
                .zip(colors)
            {
                for (o, c) in out.iter().zip(c) {
                    assert!(
                        o.is_finite() && o.abs() <= c.abs() && o * c >= 0.0,
                        "{o} from {c}"
                    );
                }
            }
        }
    }
    if let Some(map) = &record.gain {
        for (out, c) in gsi::enhance::gain::apply(map, &positions, &colors)
            .iter()
            .zip(colors)
        {
            for (o, c) in out.iter().zip(c) {
                assert!(
                    o.is_finite() && o.abs() <= 64.0 && o * c >= 0.0,
                    "{o} from {c}"
                );
            }
        }
    }
    if let Some(map) = &record.chroma {
        for (out, c) in gsi::enhance::chroma::apply(map, &positions, &colors)
            .iter()
            .zip(colors)
        {
            let y = (0.299 * c[0] + 0.587 * c[1]) + 0.114 * c[2];
            for (o, c) in out.iter().zip(c) {
                let (lo, hi) = (c.min(y), c.max(y));
                assert!(o.is_finite() && o.abs() <= 64.0, "{o} from {c}");
                assert!(
                    *o >= lo - 1e-5 * lo.abs().max(1.0) && *o <= hi + 1e-5 * hi.abs().max(1.0),
                    "{o} outside [{lo}, {hi}]"
                );
            }
        }
    }
    for (out, c) in e.apply(&positions, &colors).iter().zip(colors) {
        for (o, c) in out.iter().zip(c) {
            // A convex mix of c (identity) and values clamped to the operator range.
            let (lo, hi) = (e.clamp[0].min(c), e.clamp[1].max(c));
            assert!(o.is_finite(), "{out:?}");
            assert!(
                *o >= lo - 1e-3 * lo.abs().max(1.0) && *o <= hi + 1e-3 * hi.abs().max(1.0),
                "{o} outside [{lo}, {hi}]"
            );
        }
    }
});
