//! Helpers shared by the integration tests.
#![allow(dead_code)] // each test binary uses its own subset

use std::path::{Path, PathBuf};

/// The repository's root: the library's folder, also for the tests of `cli/` that
/// include this file; `GSI_REPO` where a test binary runs from another checkout (the GPU
/// kit, `tools/gpu-kit.sh`, runs binaries built elsewhere).
pub fn repo_root() -> PathBuf {
    if let Some(root) = std::env::var_os("GSI_REPO") {
        return PathBuf::from(root);
    }
    let here = Path::new(env!("CARGO_MANIFEST_DIR"));
    if here.join("format-spec.md").exists() {
        here.to_path_buf()
    } else {
        here.join("..")
    }
}

/// The `.gsi` files of `corpus/<sub>`, sorted.
pub fn corpus(sub: &str) -> Vec<PathBuf> {
    let dir = repo_root().join("corpus").join(sub);
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

/// A small deterministic generator (tests must not depend on a random crate's stream).
pub struct Lcg(pub u64);
impl Lcg {
    pub fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    /// Standard normal (Box–Muller).
    pub fn normal(&mut self) -> f64 {
        let u = 1.0 - self.next();
        let v = self.next();
        (-2.0 * u.ln()).sqrt() * (2.0 * std::f64::consts::PI * v).cos()
    }
}

/// The `gsi` binary: `built` (the test's `CARGO_BIN_EXE_gsi`), or `GSI_BIN` where the test
/// binary runs on another machine.
pub fn gsi_exe(built: &str) -> PathBuf {
    std::env::var_os("GSI_BIN").map_or_else(|| PathBuf::from(built), PathBuf::from)
}

/// A folder for a test's files: `built` (the test's `CARGO_TARGET_TMPDIR`), or the system's
/// temporary folder where that does not exist (a test binary run on another machine).
pub fn scratch_dir(built: &str) -> PathBuf {
    let built = Path::new(built);
    if built.is_dir() {
        built.to_path_buf()
    } else {
        std::env::temp_dir()
    }
}
