//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};

/// The `.gsi` files of `corpus/<sub>`, sorted.
pub fn corpus(sub: &str) -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(sub);
    let mut v: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "gsi"))
        .collect();
    v.sort();
    v
}

/// A `w × h` RGB image in `[0, 1]` with `f(x, y)` at each pixel.
#[cfg(feature = "encode")]
pub fn image(w: u32, h: u32, f: impl Fn(u32, u32) -> [f32; 3]) -> gsi::fit::Target {
    let data = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .flat_map(|(x, y)| f(x, y))
        .collect();
    gsi::fit::Target {
        width: w,
        height: h,
        data,
    }
}
