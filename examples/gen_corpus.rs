//! Writes the deterministic corpus into `corpus/`: `cargo run --example gen_corpus`.
//!
//! Valid files go to `corpus/valid/`, with `corpus/valid/golden.txt` holding the CRC-32 of
//! each file's RGB8 render at its stored size and at twice that size. Malformed files go
//! to `corpus/invalid/`, named `<error kind>--<what>.gsi`. Files that did not come from
//! the generator (fuzzing regressions, `fuzz-*.gsi`) are kept, and hashed like the rest.

use gsi::format::{read_file, Limits};
use std::fmt::Write as _;
use std::path::Path;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("corpus");
    for f in gsi::synth::corpus() {
        let dir = root.join(if f.expect.is_some() {
            "invalid"
        } else {
            "valid"
        });
        std::fs::create_dir_all(&dir)?;
        std::fs::write(dir.join(&f.name), &f.bytes)?;
    }
    // Golden hashes for every valid file, fuzzing regressions included.
    let mut names: Vec<String> = std::fs::read_dir(root.join("valid"))?
        .map(|e| e.map(|e| e.file_name().to_string_lossy().into_owned()))
        .collect::<Result<_, _>>()?;
    names.retain(|n| n.ends_with(".gsi"));
    names.sort();
    let mut golden = String::from("# name  width x height  crc32(rgb8)  -- regenerate with `cargo run --example gen_corpus`\n");
    for name in names {
        let bytes = std::fs::read(root.join("valid").join(&name))?;
        let scene = read_file(&bytes[..], Limits::default())?.records.to_scene();
        for s in [1, 2] {
            let (w, h) = (scene.width * s, scene.height * s);
            let rgb = gsi::render::render(&scene, w, h)?.to_rgb8();
            writeln!(golden, "{name} {w}x{h} {:08x}", crc32fast::hash(&rgb))?;
        }
    }
    std::fs::write(root.join("valid/golden.txt"), golden)?;
    Ok(())
}
