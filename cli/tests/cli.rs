//! The `gsi` binary end to end: exit codes, messages, stdin/stdout, atomic output.

use gsi::synth::SplitMix64;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn gsi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gsi"))
        .args(args)
        .output()
        .unwrap()
}

fn gsi_stdin(args: &[&str], input: &[u8]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_gsi"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    // The child may exit before reading everything (invalid input): ignore broken pipes.
    let _ = child.stdin.take().unwrap().write_all(input);
    child.wait_with_output().unwrap()
}

#[path = "../../tests/common/mod.rs"]
mod common;
use common::corpus;

fn tmp_dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("gsi-cli-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// A refusal: exit 1, one line on stderr, no panic.
fn assert_refused(out: &Output, what: &str) {
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(
        out.status.code(),
        Some(1),
        "{what}: status {:?}, stderr {err}",
        out.status
    );
    assert_eq!(err.trim_end().lines().count(), 1, "{what}: {err}");
    assert!(err.starts_with("gsi: "), "{what}: {err}");
}

#[test]
fn info_and_decode_succeed_on_every_valid_file() {
    let dir = tmp_dir("valid");
    for path in corpus("valid") {
        let p = path.to_str().unwrap();
        let out = gsi(&["info", "--json", p]);
        assert!(
            out.status.success(),
            "{p}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        for key in [
            "width",
            "height",
            "gaussians",
            "blend",
            "file_bytes",
            "bpp",
            "cr_dof",
            "cr_bytes",
            "chunks",
        ] {
            assert!(j.get(key).is_some(), "{p}: no {key}");
        }
        assert_eq!(j["file_bytes"], std::fs::metadata(&path).unwrap().len());
        assert_eq!(j["chunks"][0]["type"], "GHDR");
        let png = dir.join("out.png");
        let out = gsi(&["decode", p, "-o", png.to_str().unwrap()]);
        assert!(
            out.status.success(),
            "{p}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let img = image::open(&png).unwrap();
        assert_eq!(
            (img.width(), img.height()),
            (
                j["width"].as_u64().unwrap() as u32,
                j["height"].as_u64().unwrap() as u32
            ),
            "{p}"
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn every_invalid_file_is_refused_with_a_message() {
    for path in corpus("invalid") {
        let p = path.to_str().unwrap();
        assert_refused(&gsi(&["info", p]), p);
        assert_refused(&gsi(&["decode", p, "-o", "/dev/null"]), p);
    }
}

#[test]
fn the_message_names_chunk_and_offset() {
    let p = corpus("invalid")
        .into_iter()
        .find(|p| p.to_string_lossy().contains("bad-crc-gcol"))
        .unwrap();
    let out = gsi(&["info", p.to_str().unwrap()]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("CRC mismatch in chunk GCOL at byte "), "{err}");
}

#[test]
fn random_corruptions_never_panic() {
    let valid = corpus("valid");
    let mut rng = SplitMix64::new(7);
    for round in 0..120 {
        let bytes = std::fs::read(&valid[round % valid.len()]).unwrap();
        let mut b = bytes.clone();
        let r = rng.next_u64() as usize;
        match round % 4 {
            0 => {
                for _ in 0..1 + r % 4 {
                    let at = rng.next_u64() as usize % b.len();
                    b[at] ^= 1 + (rng.next_u64() % 255) as u8;
                }
            }
            1 => b.truncate(r % b.len()),
            2 => {
                let at = r % b.len();
                b.splice(at..at, (0..1 + r % 64).map(|_| rng.next_u64() as u8));
            }
            _ => {
                // A huge length field in a random chunk position.
                let at = 8 + r % (b.len() - 12);
                b[at..at + 4].copy_from_slice(&(0xF000_0000u32 | r as u32).to_be_bytes());
            }
        }
        if b == bytes {
            continue;
        }
        let out = gsi_stdin(&["decode", "-", "-o", "/dev/null", "--width", "16"], &b);
        let code = out.status.code();
        assert!(
            code == Some(0) || code == Some(1),
            "round {round}: status {:?} {}",
            out.status,
            String::from_utf8_lossy(&out.stderr)
        );
        if code == Some(1) {
            assert_refused(&out, &format!("round {round}"));
        }
    }
}

#[test]
fn junk_input_is_refused() {
    assert_refused(&gsi_stdin(&["info", "-"], b"not a gsi file at all"), "junk");
    assert_refused(&gsi_stdin(&["info", "-"], b""), "empty");
    assert_refused(&gsi(&["info", "/nonexistent/file.gsi"]), "missing file");
}

#[test]
fn usage_errors_exit_2() {
    assert_eq!(gsi(&["decode"]).status.code(), Some(2));
    assert_eq!(gsi(&["frobnicate"]).status.code(), Some(2));
    let p = corpus("valid")[0].to_str().unwrap().to_owned();
    assert_eq!(
        gsi(&["decode", &p, "-o", "x.png", "--scale", "2", "--width", "3"])
            .status
            .code(),
        Some(2)
    );
}

#[test]
fn decode_sizes_and_pipes() {
    let p = corpus("valid")
        .into_iter()
        .find(|p| p.to_string_lossy().contains("sum-lsr-500"))
        .unwrap();
    let bytes = std::fs::read(&p).unwrap();
    // stdin to stdout, scaled.
    let out = gsi_stdin(&["decode", "-", "-o", "-", "--scale", "0.5"], &bytes);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::load_from_memory(&out.stdout).unwrap();
    assert_eq!((img.width(), img.height()), (48, 32));
    let dir = tmp_dir("sizes");
    for (args, want) in [
        (vec!["--width", "200"], (200, 133)),
        (vec!["--height", "10"], (15, 10)),
        (vec!["--width", "7", "--height", "300"], (7, 300)),
        (vec!["--scale", "3"], (288, 192)),
    ] {
        let o = dir.join("o.png");
        let mut a = vec!["decode", p.to_str().unwrap(), "-o", o.to_str().unwrap()];
        a.extend(args.iter());
        let out = gsi(&a);
        assert!(
            out.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        let img = image::open(&o).unwrap();
        assert_eq!((img.width(), img.height()), want, "{args:?}");
    }
    // Refused sizes: zero, negative, absurd.
    for args in [
        vec!["--width", "0"],
        vec!["--scale=-1"],
        vec!["--scale", "0"],
        vec!["--scale", "1e9"],
    ] {
        let mut a = vec!["decode", p.to_str().unwrap(), "-o", "/dev/null"];
        a.extend(args.iter());
        assert_refused(&gsi(&a), &format!("{args:?}"));
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_failed_decode_leaves_the_output_untouched() {
    let dir = tmp_dir("atomic");
    let out_png = dir.join("keep.png");
    std::fs::write(&out_png, b"precious").unwrap();
    let bad = corpus("invalid")
        .into_iter()
        .find(|p| p.to_string_lossy().contains("bad-crc"))
        .unwrap();
    assert_refused(
        &gsi(&[
            "decode",
            bad.to_str().unwrap(),
            "-o",
            out_png.to_str().unwrap(),
        ]),
        "bad",
    );
    assert_eq!(std::fs::read(&out_png).unwrap(), b"precious");
    // Unsupported output format: refused before anything is written.
    let good = corpus("valid")[0].clone();
    assert_refused(
        &gsi(&[
            "decode",
            good.to_str().unwrap(),
            "-o",
            dir.join("x.bmp").to_str().unwrap(),
        ]),
        "bmp",
    );
    assert!(!dir.join("x.bmp").exists());
    // Nothing but the original is left in the folder (no temporary files).
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A small test image written as a PNG of the given colour type.
fn write_png(path: &Path, w: u32, h: u32, color: image::ExtendedColorType) {
    let mut rgb = Vec::new();
    for y in 0..h {
        for x in 0..w {
            rgb.extend([(x * 255 / w.max(1)) as u8, (y * 255 / h.max(1)) as u8, 90]);
        }
    }
    let img = image::DynamicImage::ImageRgb8(image::RgbImage::from_raw(w, h, rgb).unwrap());
    let img = match color {
        image::ExtendedColorType::L16 => image::DynamicImage::ImageLuma16(img.to_luma16()),
        image::ExtendedColorType::Rgba8 => image::DynamicImage::ImageRgba8(img.to_rgba8()),
        image::ExtendedColorType::Rgb16 => image::DynamicImage::ImageRgb16(img.to_rgb16()),
        _ => img,
    };
    img.save(path).unwrap();
}

#[test]
fn encode_decode_roundtrip_through_files_and_pipes() {
    let dir = tmp_dir("encode");
    for (name, color) in [
        ("rgb8", image::ExtendedColorType::Rgb8),
        ("grey16", image::ExtendedColorType::L16),
        ("rgba8", image::ExtendedColorType::Rgba8),
        ("rgb16", image::ExtendedColorType::Rgb16),
    ] {
        let png = dir.join(format!("{name}.png"));
        write_png(&png, 40, 24, color);
        let gsi_path = dir.join(format!("{name}.gsi"));
        let out = gsi(&[
            "encode",
            png.to_str().unwrap(),
            "-o",
            gsi_path.to_str().unwrap(),
            "--gaussians",
            "40",
            "--iterations",
            "30",
        ]);
        assert!(
            out.status.success(),
            "{name}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        // The summary line names N, bytes, bpp, Cr and PSNR.
        let err = String::from_utf8_lossy(&out.stderr);
        for word in ["N 40", "bytes", "bpp", "Cr", "PSNR"] {
            assert!(err.contains(word), "{name}: {err}");
        }
        let info = gsi(&["info", "--json", gsi_path.to_str().unwrap()]);
        let j: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
        assert_eq!(
            (j["width"].as_u64(), j["height"].as_u64()),
            (Some(40), Some(24))
        );
        assert!(
            j["psnr"].as_f64().is_some_and(|p| p > 15.0),
            "{name}: {}",
            j["psnr"]
        );
    }
    // stdin to stdout, then decode from stdin.
    let bytes = std::fs::read(dir.join("rgb8.png")).unwrap();
    let out = gsi_stdin(
        &[
            "encode",
            "-",
            "-o",
            "-",
            "--gaussians",
            "20",
            "--iterations",
            "10",
            "--quiet",
        ],
        &bytes,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.stderr.is_empty(),
        "--quiet printed {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let dec = gsi_stdin(&["decode", "-", "-o", "-"], &out.stdout);
    assert!(dec.status.success());
    let img = image::load_from_memory(&dec.stdout).unwrap();
    assert_eq!((img.width(), img.height()), (40, 24));
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn encode_refuses_what_it_cannot_do() {
    let dir = tmp_dir("encode-refuse");
    let png = dir.join("a.png");
    write_png(&png, 8, 8, image::ExtendedColorType::Rgb8);
    let p = png.to_str().unwrap();
    let o = dir.join("a.gsi");
    let o = o.to_str().unwrap();
    // `--device gpu` with no adapter to be had (none matches this name) is refused.
    let no_gpu = Command::new(env!("CARGO_BIN_EXE_gsi"))
        .args(["encode", p, "-o", o, "--device", "gpu"])
        .env("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")
        .output()
        .unwrap();
    assert_refused(&no_gpu, "gpu");
    assert!(!std::path::Path::new(o).exists());
    assert_refused(&gsi(&["encode", p, "-o", o, "--bpp", "0"]), "bpp 0");
    assert_refused(
        &gsi(&["encode", p, "-o", o, "--iterations", "0"]),
        "0 iterations",
    );
    assert_refused(
        &gsi_stdin(&["encode", "-", "-o", o], b"not an image"),
        "junk",
    );
    assert_refused(&gsi(&["encode", "/nonexistent.png", "-o", o]), "missing");
    assert!(!Path::new(o).exists());
    // Two budgets at once are a usage error.
    assert_eq!(
        gsi(&["encode", p, "-o", o, "--bpp", "1", "--gaussians", "3"])
            .status
            .code(),
        Some(2)
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// A reader that stops early (`gsi info f | head -1`) closes the pipe: `gsi` stops quietly,
/// with exit 0 and no panic, where `println!` would panic on the broken pipe.
#[test]
fn a_closed_stdout_is_not_a_panic() {
    let file = corpus("valid")[0].clone();
    for args in [
        vec!["info", file.to_str().unwrap()],
        vec!["info", "--json", file.to_str().unwrap()],
    ] {
        let mut child = Command::new(env!("CARGO_BIN_EXE_gsi"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take()); // nobody reads
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{args:?}: {err}");
        assert!(!err.contains("panicked"), "{args:?}: {err}");
    }
}

/// A header edited to claim a large image (CRC fixed) decodes at that size on the CPU's
/// 8-bit path (BENCHMARKS.md measures its memory against the float path's).
#[test]
fn an_enlarged_header_decodes_at_its_size() {
    let src = std::fs::read(&corpus("valid")[0]).unwrap();
    // GHDR is the first chunk: signature (8), length (4), type (4), payload (18), CRC (4).
    let mut bytes = src.clone();
    bytes[16 + 2..16 + 6].copy_from_slice(&3000u32.to_be_bytes());
    bytes[16 + 6..16 + 10].copy_from_slice(&2000u32.to_be_bytes());
    let crc = gsi::format::chunk_crc(gsi::format::ChunkType::HEADER, &bytes[16..34]);
    bytes[34..38].copy_from_slice(&crc.to_be_bytes());
    let dir = tmp_dir("huge");
    let (input, output) = (dir.join("big.gsi"), dir.join("big.png"));
    std::fs::write(&input, &bytes).unwrap();
    let out = gsi(&[
        "decode",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
        "--device",
        "cpu",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let img = image::open(&output).unwrap();
    assert_eq!((img.width(), img.height()), (3000, 2000));
    std::fs::remove_dir_all(&dir).unwrap();
}
