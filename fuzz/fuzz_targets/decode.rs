//! Bytes to pixels: the first two bytes choose an output size of 1..=64 × 1..=64, the
//! rest is a file. Whatever the file holds, a render that the limits allow (its size,
//! and its Gaussian–pixel pairs, `Limits::max_render_work`) succeeds and gives finite
//! values, and (for small enough scenes) the tiled renderer agrees bit for
//! bit with a plain per-pixel loop written from `format-spec.md` §6.3-6.4. The 8-bit
//! outputs rendered straight into a caller's buffer (RGB and RGBA, as `gsi::Reader` and
//! `gsi decode` use them) or handed out a few rows at a time (as `gsi decode` writes a
//! PPM) equal the float image converted afterwards.

#![no_main]

mod common;

use gsi::contract::TRANSMITTANCE_MIN;
use gsi::model::{Blend, Scene};
use gsi::render::{project_scene, render};
use libfuzzer_sys::fuzz_target;

/// Largest `Gaussians × pixels` for which the per-pixel reference is run.
const REFERENCE_BUDGET: usize = 1 << 20;

fuzz_target!(|data: &[u8]| {
    let [w, h, ref file @ ..] = *data else { return };
    let (width, height) = (u32::from(w % 64) + 1, u32::from(h % 64) + 1);
    let Some(file) = common::parse_deep(file) else {
        return;
    };
    common::limits()
        .check_output(width, height)
        .expect("1..=64 squared is within the limits");

    let scene = file.records.to_scene();
    // A file may ask for more work than the limits allow (a few bytes can declare
    // thousands of image-sized Gaussians): refused by the count alone, before a pixel.
    let work = gsi::render::render_work(&project_scene(&scene, width, height));
    if common::limits()
        .check_render_work(work, width, height)
        .is_err()
    {
        return;
    }
    let image = render(&scene, width, height).expect("rendering a valid file");
    assert_eq!((image.width, image.height), (width, height));
    assert_eq!(image.data.len(), (width * height * 3) as usize);
    if let Some((k, v)) = image.data.iter().enumerate().find(|(_, v)| !v.is_finite()) {
        panic!("pixel {} channel {} is {v}", k / 3, k % 3);
    }
    let rgb8 = image.to_rgb8();
    assert_eq!(rgb8.len(), image.data.len());
    let mut direct = vec![0u8; rgb8.len()];
    gsi::render::render_rgb8_into(&scene, width, height, &mut direct).expect("8-bit render");
    assert!(
        direct == rgb8,
        "8-bit render differs from the float one converted"
    );
    let mut rows = Vec::with_capacity(rgb8.len());
    gsi::render::render_rgb8_rows(&scene, width, height, &common::limits(), |r| {
        rows.extend_from_slice(r);
        Ok(())
    })
    .expect("8-bit render in rows");
    assert!(
        rows == rgb8,
        "8-bit rows differ from the float render converted"
    );
    let mut rgba = vec![0u8; (width * height * 4) as usize];
    gsi::render::render_rgba8_into(&scene, width, height, &mut rgba).expect("RGBA render");
    assert!(
        rgba == image.to_rgba8(),
        "RGBA render differs from the float one converted"
    );

    if scene
        .gaussians
        .len()
        .saturating_mul((width * height) as usize)
        <= REFERENCE_BUDGET
    {
        let want = reference(&scene, width, height);
        if let Some(k) = (0..want.len()).find(|&k| want[k].to_bits() != image.data[k].to_bits()) {
            panic!(
                "pixel ({}, {}) channel {}: tiled {} vs per-pixel {}",
                k / 3 % width as usize,
                k / 3 / width as usize,
                k % 3,
                image.data[k],
                want[k]
            );
        }
    }
});

/// Spec §6.3–6.4 (by the file's weight rule), one pixel at a time over every projected
/// Gaussian in stored order, then the file's tone curve (§6.6).
fn reference(scene: &Scene, width: u32, height: u32) -> Vec<f32> {
    let proj = project_scene(scene, width, height);
    let mut out = Vec::with_capacity((width * height * 3) as usize);
    for j in 0..height {
        for i in 0..width {
            let mut c = [0f32; 3];
            let mut t = 1f32;
            for g in &proj {
                let Some(alpha) = g.weight_at(i, j, scene.blend, scene.weights) else {
                    continue;
                };
                match scene.blend {
                    Blend::Sum => {
                        for (acc, col) in c.iter_mut().zip(g.color) {
                            *acc += col * alpha;
                        }
                    }
                    Blend::Alpha => {
                        for (acc, col) in c.iter_mut().zip(g.color) {
                            *acc += col * alpha * t;
                        }
                        t *= 1.0 - alpha;
                        if t < TRANSMITTANCE_MIN {
                            break;
                        }
                    }
                }
            }
            if let Some(t) = &scene.tone {
                for (k, v) in c.iter_mut().enumerate() {
                    *v = t.eval(k, *v);
                }
            }
            out.extend_from_slice(&c);
        }
    }
    out
}
