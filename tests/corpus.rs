//! The checked-in corpus: valid files render to their golden pixels, malformed files are
//! refused with the error kind their name gives, and the generator still makes them.

use gsi::format::{read_file, Limits};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

fn corpus_dir(sub: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("corpus")
        .join(sub)
}

mod common;

fn golden() -> BTreeMap<(String, String), String> {
    std::fs::read_to_string(corpus_dir("valid/golden.txt"))
        .unwrap()
        .lines()
        .filter(|l| !l.starts_with('#'))
        .map(|l| {
            let f: Vec<&str> = l.split_whitespace().collect();
            ((f[0].to_owned(), f[1].to_owned()), f[2].to_owned())
        })
        .collect()
}

#[test]
fn valid_files_render_to_golden_pixels() {
    let golden = golden();
    let files = common::corpus("valid");
    assert!(files.len() >= 10, "corpus/valid has {} files", files.len());
    let mut checked = 0;
    for path in files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let bytes = std::fs::read(&path).unwrap();
        let file =
            read_file(&bytes[..], Limits::default()).unwrap_or_else(|e| panic!("{name}: {e}"));
        let scene = file.records.to_scene();
        for s in [1, 2] {
            let (w, h) = (scene.width * s, scene.height * s);
            let img = gsi::render::render(&scene, w, h).unwrap();
            assert!(
                img.data.iter().all(|x| x.is_finite()),
                "{name}: non-finite pixel"
            );
            let got = format!("{:08x}", crc32fast::hash(&img.to_rgb8()));
            let want = golden
                .get(&(name.clone(), format!("{w}x{h}")))
                .unwrap_or_else(|| panic!("{name} {w}x{h} has no golden hash"));
            assert_eq!(&got, want, "{name} at {w}x{h}");
            checked += 1;
        }
    }
    assert_eq!(
        checked,
        golden.len(),
        "golden.txt lists files that are missing"
    );
}

#[test]
fn invalid_files_are_refused_with_their_kind() {
    let files = common::corpus("invalid");
    assert!(
        files.len() >= 25,
        "corpus/invalid has {} files",
        files.len()
    );
    for path in files {
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        let want = name.split("--").next().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        match read_file(&bytes[..], Limits::default()) {
            Ok(_) => panic!("{name} was accepted"),
            Err(e) => assert_eq!(e.kind().name(), want, "{name}: {e}"),
        }
    }
}

#[test]
fn generator_reproduces_the_checked_in_corpus() {
    for f in gsi::synth::corpus() {
        let dir = if f.expect.is_some() {
            "invalid"
        } else {
            "valid"
        };
        let on_disk = std::fs::read(corpus_dir(dir).join(&f.name))
            .unwrap_or_else(|e| panic!("{}: {e}", f.name));
        assert!(
            on_disk == f.bytes,
            "{} differs from the generator: run `cargo run --example gen_corpus`",
            f.name
        );
        // The generator's own expectation agrees with the file name.
        if let Some(kind) = f.expect {
            assert!(f.name.starts_with(&format!("{}--", kind.name())));
        }
    }
}

/// Every enhanced file of the corpus, of every `gENH` layout (1 to 6, with and without a
/// `GTRC`), applies its own enhancer to its original colours byte for byte, and reverts
/// to a file without stage 2's chunks.
#[test]
fn enhanced_files_reapply_and_revert_exactly() {
    use gsi::format::{ChunkType, ChunkedFile};
    let mut layouts = std::collections::BTreeSet::new();
    for entry in std::fs::read_dir(corpus_dir("valid")).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "gsi") {
            continue;
        }
        let bytes = std::fs::read(&path).unwrap();
        let file = ChunkedFile::parse(&bytes, Limits::default()).unwrap();
        let Some(genh) = file.chunks.iter().find(|c| c.ty == ChunkType::ENHANCER) else {
            continue;
        };
        layouts.insert(genh.data[0]);
        let again = gsi::enhance::apply_from(&file, &file, true, &Limits::default()).unwrap();
        assert_eq!(again, bytes, "{}", path.display());
        let reverted = ChunkedFile::parse(&file.revert().unwrap(), Limits::default()).unwrap();
        assert!(
            reverted.chunks.iter().all(|c| ![
                ChunkType::ENHANCER,
                ChunkType::ORIGINAL_COLORS,
                ChunkType::TONE_CURVE
            ]
            .contains(&c.ty)),
            "{}",
            path.display()
        );
    }
    assert_eq!(layouts.into_iter().collect::<Vec<_>>(), [1, 2, 3, 4, 5, 6]);
}
