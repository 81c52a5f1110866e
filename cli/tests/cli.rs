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
    // No Gaussians is a usage error, not a file of one Gaussian.
    let out = gsi(&["encode", "x.png", "-o", "x.gsi", "--gaussians", "0"]);
    assert_eq!(out.status.code(), Some(2));
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

/// `-o /dev/null` writes into the device. Renamed over, as a regular output file is, it
/// would leave a regular file at `/dev/null` (for root), and every later program that
/// reads it as empty input would read old output instead.
#[cfg(unix)]
#[test]
fn decoding_to_dev_null_leaves_it_a_device() {
    let null = Path::new("/dev/null");
    let was = std::fs::symlink_metadata(null).unwrap().file_type();
    let good = corpus("valid")[0].clone();
    let out = gsi(&["decode", good.to_str().unwrap(), "-o", "/dev/null"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let now = std::fs::symlink_metadata(null).unwrap().file_type();
    assert_eq!(now, was, "/dev/null changed kind");
    assert!(!now.is_file(), "/dev/null is a regular file");
}

/// A decode renders on the CPU unless `--device gpu` asks for the GPU: by default it does
/// not look for one (which costs more than the decode), and so says nothing of it. With
/// no adapter to be had, a look would fail and say so on stderr.
#[test]
fn decode_looks_for_a_gpu_only_when_asked() {
    let dir = tmp_dir("decode-device");
    let good = corpus("valid")[0].clone();
    let run = |device: Option<&str>, out: &str| {
        let out = dir.join(out);
        let mut args = vec![
            "decode",
            good.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend(device.map(|d| ["--device", d]).iter().flatten());
        Command::new(env!("CARGO_BIN_EXE_gsi"))
            .args(&args)
            .env("WGPU_ADAPTER_NAME", "no-such-adapter-anywhere")
            .output()
            .unwrap()
    };
    for (device, name) in [(None, "default.png"), (Some("auto"), "auto.png")] {
        let out = run(device, name);
        assert!(out.status.success(), "{device:?}");
        assert!(
            out.stderr.is_empty(),
            "{device:?}: {}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(dir.join(name).exists());
    }
    assert_refused(&run(Some("gpu"), "gpu.png"), "--device gpu");
    assert!(!dir.join("gpu.png").exists());
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
    // Effort levels outside 1..=9 are a usage error (clap's exit 2), nothing written.
    for level in ["0", "10", "fast"] {
        let out = gsi(&["encode", p, "-o", o, "--effort", level]);
        assert_eq!(out.status.code(), Some(2), "--effort {level}");
        assert!(!Path::new(o).exists());
    }
    assert_refused(
        &gsi_stdin(&["encode", "-", "-o", o], b"not an image"),
        "junk",
    );
    assert_refused(&gsi(&["encode", "/nonexistent.png", "-o", o]), "missing");
    assert!(!Path::new(o).exists());
    // A byte budget below one Gaussian's file is refused, not exceeded in silence.
    let tiny = gsi(&[
        "encode",
        p,
        "-o",
        o,
        "--bpp",
        "0.001",
        "--iterations",
        "3",
        "--device",
        "cpu",
    ]);
    assert_refused(&tiny, "unreachable bpp");
    assert!(String::from_utf8_lossy(&tiny.stderr).contains("cannot be met"));
    assert!(!Path::new(o).exists());
    for bits in ["13,8,8", "25,8,8,6", "0,8,8,6", "a,b,c,d"] {
        assert_refused(&gsi(&["encode", p, "-o", o, "--bits", bits]), bits);
    }
    let ok = gsi(&[
        "encode",
        p,
        "-o",
        o,
        "--bits",
        "9,6,7,4",
        "--gaussians",
        "4",
        "--iterations",
        "3",
        "--device",
        "cpu",
    ]);
    assert!(
        ok.status.success(),
        "{}",
        String::from_utf8_lossy(&ok.stderr)
    );
    let info = String::from_utf8(gsi(&["info", o, "--json"]).stdout).unwrap();
    // Every file the encoder writes weighs by columns in bands of 32 rows (spec §6.3.2,
    // `GCRT`).
    assert!(
        info.contains("\"bits\": 9")
            && info.contains("bits_per_gaussian")
            && info.contains("\"weights\": \"columns-32\""),
        "{info}"
    );
    std::fs::remove_file(o).unwrap();
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

/// The test image of [`write_png`] as pixels.
fn test_pixels(w: u32, h: u32) -> image::DynamicImage {
    let mut rgb = Vec::new();
    for y in 0..h {
        for x in 0..w {
            rgb.extend([
                (x * 255 / w) as u8,
                (y * 255 / h) as u8,
                ((x * y) % 200) as u8,
            ]);
        }
    }
    image::DynamicImage::ImageRgb8(image::RgbImage::from_raw(w, h, rgb).unwrap())
}

/// Encode `input` with a small fixed budget; the file's bytes.
fn encode_small(input: &Path, output: &Path) -> Vec<u8> {
    let out = gsi(&[
        "encode",
        input.to_str().unwrap(),
        "-o",
        output.to_str().unwrap(),
        "--gaussians",
        "30",
        "--iterations",
        "8",
        "--quiet",
    ]);
    assert!(
        out.status.success(),
        "{}: {}",
        input.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read(output).unwrap()
}

/// `--target-psnr` grows N only so far: a target beyond it is written at its best and
/// the shortfall said, with or without `--quiet`; a target met says nothing more.
#[test]
fn a_missed_target_psnr_is_said_even_when_quiet() {
    let dir = tmp_dir("encode-target");
    let png = dir.join("a.png");
    write_png(&png, 24, 16, image::ExtendedColorType::Rgb8);
    let p = png.to_str().unwrap();
    let o = dir.join("a.gsi");
    let o = o.to_str().unwrap();
    let run = |target: &str, quiet: bool| {
        let mut args = vec![
            "encode",
            p,
            "-o",
            o,
            "--target-psnr",
            target,
            "--iterations",
            "3",
            "--device",
            "cpu",
        ];
        if quiet {
            args.push("--quiet");
        }
        let out = gsi(&args);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(Path::new(o).exists(), "the file is written all the same");
        std::fs::remove_file(o).unwrap();
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    for quiet in [false, true] {
        let said = run("99", quiet);
        assert!(
            said.contains("--target-psnr 99 not reached"),
            "quiet {quiet}: {said}"
        );
        let met = run("5", quiet);
        assert!(!met.contains("not reached"), "quiet {quiet}: {met}");
    }
}

/// The formats users bring (the LIME set is BMP; scanners write TIFF; the web WebP; tools
/// PNM) are read by their bytes, whatever the name says: the same pixels in any lossless
/// format give the same .gsi file, bit for bit, as the PNG does. Grey files are read as
/// grey replicated, 16-bit ones at 16 bits.
#[test]
fn encode_reads_the_formats_people_have() {
    let dir = tmp_dir("formats");
    let img = test_pixels(36, 20);
    let png = dir.join("ref.png");
    img.save(&png).unwrap();
    let reference = encode_small(&png, &dir.join("ref.gsi"));
    for ext in ["bmp", "tiff", "webp", "ppm"] {
        let path = dir.join(format!("a.{ext}"));
        img.save(&path).unwrap();
        let got = encode_small(&path, &dir.join(format!("{ext}.gsi")));
        assert!(got == reference, "{ext} did not read as the PNG's pixels");
        // Named wrongly, read by content.
        let misnamed = dir.join(format!("{ext}-as.png"));
        std::fs::copy(&path, &misnamed).unwrap();
        let got = encode_small(&misnamed, &dir.join(format!("{ext}-as.gsi")));
        assert!(got == reference, "{ext} named .png did not read by content");
    }
    // 16-bit and grey: TIFF against PNG of the same samples.
    let deep = image::DynamicImage::ImageRgb16(img.to_rgb16());
    let grey = image::DynamicImage::ImageLuma8(img.to_luma8());
    for (name, pixels) in [("rgb16", deep), ("grey8", grey)] {
        let (p, t) = (
            dir.join(format!("{name}.png")),
            dir.join(format!("{name}.tif")),
        );
        pixels.save(&p).unwrap();
        pixels.save(&t).unwrap();
        let a = encode_small(&p, &dir.join(format!("{name}-png.gsi")));
        let b = encode_small(&t, &dir.join(format!("{name}-tif.gsi")));
        assert!(a == b, "{name}: TIFF and PNG differ");
    }
    // A JPEG cut short is refused in one line, not fitted with its missing part filled in.
    let jpg = dir.join("whole.jpg");
    img.save(&jpg).unwrap();
    encode_small(&jpg, &dir.join("j.gsi"));
    let bytes = std::fs::read(&jpg).unwrap();
    let cut = dir.join("cut.jpg");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let out = gsi(&[
        "encode",
        cut.to_str().unwrap(),
        "-o",
        dir.join("c.gsi").to_str().unwrap(),
    ]);
    assert_refused(&out, "truncated jpeg");
    assert!(String::from_utf8_lossy(&out.stderr).contains("truncated"));
    assert!(!dir.join("c.gsi").exists());
    // A format gsi does not read is refused by name, with what it does read.
    let gif = dir.join("a.gif");
    std::fs::write(&gif, b"GIF89a\x01\x00\x01\x00\x00\x00\x00;").unwrap();
    let out = gsi(&["encode", gif.to_str().unwrap(), "-o", "x.gsi"]);
    assert_refused(&out, "gif");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(err.contains("a.gif") && err.contains("BMP"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A photograph taken with the phone turned is stored sideways with an EXIF orientation;
/// it is fitted upright, as every viewer shows it: the file is the one the rotated pixels
/// give.
#[test]
fn encode_applies_the_exif_orientation() {
    use image::ImageEncoder;
    let dir = tmp_dir("orientation");
    let img = test_pixels(30, 18);
    // Orientation 6: the stored pixels are shown turned 90° clockwise.
    let exif: Vec<u8> = [
        &b"MM\x00\x2a\x00\x00\x00\x08"[..],
        &[0x00, 0x01],                                     // one entry
        &[0x01, 0x12, 0x00, 0x03, 0, 0, 0, 1, 0, 6, 0, 0], // Orientation, SHORT, 1, 6
        &[0, 0, 0, 0],                                     // no next IFD
    ]
    .concat();
    let sideways = dir.join("sideways.png");
    let mut bytes = Vec::new();
    let mut enc = image::codecs::png::PngEncoder::new(&mut bytes);
    enc.set_exif_metadata(exif).unwrap();
    enc.write_image(img.as_bytes(), 30, 18, image::ExtendedColorType::Rgb8)
        .unwrap();
    std::fs::write(&sideways, bytes).unwrap();
    let upright = dir.join("upright.png");
    img.rotate90().save(&upright).unwrap();
    let a = encode_small(&sideways, &dir.join("sideways.gsi"));
    let b = encode_small(&upright, &dir.join("upright.gsi"));
    assert!(a == b, "the orientation was not applied");
    let info = gsi(&["info", "--json", dir.join("sideways.gsi").to_str().unwrap()]);
    let j: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(
        (j["width"].as_u64(), j["height"].as_u64()),
        (Some(18), Some(30))
    );
    std::fs::remove_dir_all(dir).unwrap();
}

/// `gsi decode` writes PNG, JPEG, WebP (lossless) and PPM by extension: the lossless ones
/// hold the PNG's pixels exactly, the JPEG is close to them.
#[test]
fn decode_writes_png_jpeg_webp_and_ppm() {
    let dir = tmp_dir("decode-formats");
    let file = corpus("valid")
        .into_iter()
        .find(|p| p.extension().is_some_and(|e| e == "gsi"))
        .unwrap();
    let decode = |ext: &str| {
        let out = dir.join(format!("out.{ext}"));
        let r = gsi(&[
            "decode",
            file.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(
            r.status.success(),
            "{ext}: {}",
            String::from_utf8_lossy(&r.stderr)
        );
        let bytes = std::fs::read(&out).unwrap();
        let format = image::guess_format(&bytes).unwrap();
        (format, image::load_from_memory(&bytes).unwrap().to_rgb8())
    };
    let (format, png) = decode("png");
    assert_eq!(format, image::ImageFormat::Png);
    for (ext, want) in [
        ("webp", image::ImageFormat::WebP),
        ("ppm", image::ImageFormat::Pnm),
        ("PNM", image::ImageFormat::Pnm),
    ] {
        let (format, img) = decode(ext);
        assert_eq!(format, want, "{ext}");
        assert!(img == png, "{ext}: not the PNG's pixels");
    }
    let (format, jpeg) = decode("jpg");
    assert_eq!(format, image::ImageFormat::Jpeg);
    let err: f64 = jpeg
        .as_raw()
        .iter()
        .zip(png.as_raw())
        .map(|(&a, &b)| (f64::from(a) - f64::from(b)).powi(2))
        .sum::<f64>()
        / png.as_raw().len() as f64;
    assert!(err < 25.0, "JPEG mean squared error {err}");
    // `--format` names the format whatever the name says.
    let named = dir.join("out.img");
    let r = gsi(&[
        "decode",
        file.to_str().unwrap(),
        "-o",
        named.to_str().unwrap(),
        "--format",
        "webp",
    ]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let bytes = std::fs::read(&named).unwrap();
    assert_eq!(
        image::guess_format(&bytes).unwrap(),
        image::ImageFormat::WebP
    );
    let bad = dir.join("out.gif");
    assert_refused(
        &gsi(&[
            "decode",
            file.to_str().unwrap(),
            "-o",
            bad.to_str().unwrap(),
        ]),
        "gif output",
    );
    assert!(!bad.exists());
    std::fs::remove_dir_all(dir).unwrap();
}

/// Many files in one call: a folder in, a folder out. Each output is the file a call of
/// its own writes; a corrupt input is reported by name while the others are written, and
/// the exit status says one failed; outputs already there are skipped unless `--force`;
/// two inputs that would write one output are refused before any work.
#[test]
fn batches_of_files_in_one_call() {
    let dir = tmp_dir("batch");
    let (inputs, out) = (dir.join("in"), dir.join("out"));
    std::fs::create_dir_all(&inputs).unwrap();
    for (k, name) in ["a.png", "b.bmp", "c.tiff"].iter().enumerate() {
        test_pixels(20 + 4 * k as u32, 14)
            .save(inputs.join(name))
            .unwrap();
    }
    // A dot inside the name stays in the output's name.
    test_pixels(16, 12).save(inputs.join("d.v1.png")).unwrap();
    std::fs::write(inputs.join("broken.png"), b"\x89PNG\r\n\x1a\n not really").unwrap();
    std::fs::write(inputs.join("notes.txt"), b"not an image, not looked at").unwrap();
    let small = ["--gaussians", "30", "--iterations", "8"];
    let run = |args: &[&str]| gsi(&[&["encode"][..], args, &small[..]].concat());
    let (i, o) = (inputs.to_str().unwrap(), format!("{}/", out.display()));
    let batch = run(&[i, "-o", &o, "--jobs", "2"]);
    let err = String::from_utf8_lossy(&batch.stderr);
    assert_eq!(batch.status.code(), Some(1), "{err}");
    assert!(
        err.contains("broken.png") && err.contains("1 of 5 files failed"),
        "{err}"
    );
    assert!(out.join("d.v1.gsi").exists());
    for name in ["a", "b", "c"] {
        let single = dir.join(format!("{name}-single.gsi"));
        let input = std::fs::read_dir(&inputs)
            .unwrap()
            .map(|e| e.unwrap().path())
            .find(|p| p.file_stem().unwrap() == name)
            .unwrap();
        let got = encode_small(&input, &single);
        let batched = std::fs::read(out.join(format!("{name}.gsi"))).unwrap();
        assert!(got == batched, "{name}: the batch wrote another file");
    }
    assert!(!out.join("notes.gsi").exists() && !out.join("broken.gsi").exists());
    // Again: the valid outputs are skipped (their files untouched), the broken one fails.
    let a = out.join("a.gsi");
    std::fs::write(&a, b"GSI? no: not valid").unwrap();
    let b_time = std::fs::metadata(out.join("b.gsi"))
        .unwrap()
        .modified()
        .unwrap();
    let again = run(&[i, "-o", &o]);
    let err = String::from_utf8_lossy(&again.stderr);
    assert_eq!(again.status.code(), Some(1), "{err}");
    assert!(
        err.contains("b.gsi: skipped") && err.contains("c.gsi: skipped"),
        "{err}"
    );
    assert!(
        !err.contains("a.gsi: skipped"),
        "an invalid output was kept: {err}"
    );
    assert!(
        std::fs::read(&a).unwrap().starts_with(b"\x89GSI"),
        "a.gsi not rewritten"
    );
    let b_again = std::fs::metadata(out.join("b.gsi"))
        .unwrap()
        .modified()
        .unwrap();
    assert_eq!(b_time, b_again);
    let forced = run(&[i, "-o", &o, "--force", "--quiet"]);
    assert_eq!(forced.status.code(), Some(1));
    let err = String::from_utf8_lossy(&forced.stderr);
    assert!(
        !err.contains("skipped") && err.contains("broken.png"),
        "{err}"
    );
    // Decode the folder: each image is the one a single decode writes.
    let images = dir.join("images");
    let dec = gsi(&[
        "decode",
        out.to_str().unwrap(),
        "-o",
        images.to_str().unwrap(),
        "--format",
        "webp",
    ]);
    assert!(
        dec.status.success(),
        "{}",
        String::from_utf8_lossy(&dec.stderr)
    );
    for name in ["a", "b", "c"] {
        let single = dir.join(format!("{name}.png"));
        let gsi_file = out.join(format!("{name}.gsi"));
        let r = gsi(&[
            "decode",
            gsi_file.to_str().unwrap(),
            "-o",
            single.to_str().unwrap(),
        ]);
        assert!(r.status.success());
        let want = image::open(&single).unwrap().to_rgb8();
        let got = image::open(images.join(format!("{name}.webp")))
            .unwrap()
            .to_rgb8();
        assert!(want == got, "{name}: the batch decoded another image");
    }
    // Two inputs named alike would overwrite each other: refused before any work.
    let clash = dir.join("clash");
    let twice = run(&[
        inputs.join("a.png").to_str().unwrap(),
        inputs.join("a.png").to_str().unwrap(),
        "-o",
        clash.to_str().unwrap(),
    ]);
    assert_refused(&twice, "clash");
    assert!(std::fs::read_dir(&clash).unwrap().next().is_none());
    // Standard input has no name to write under; standard output is not a folder.
    assert_refused(&run(&["-", i, "-o", &o]), "stdin in a batch");
    assert_refused(&run(&[i, "-o", "-"]), "a batch to stdout");
    assert!(!Path::new("-").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

/// A valid 176-byte file that asks for billions of Gaussian–pixel pairs at 300×300 is
/// refused in one line, quickly, with exit 1 and no output written.
#[test]
fn a_render_past_the_work_limit_is_refused() {
    let dir = tmp_dir("render-work");
    let file = corpus("valid")
        .into_iter()
        .find(|p| p.ends_with("fuzz-decode-render-work.gsi"))
        .expect("the corpus file");
    let out_png = dir.join("x.png");
    let t = std::time::Instant::now();
    let out = gsi(&[
        "decode",
        file.to_str().unwrap(),
        "-o",
        out_png.to_str().unwrap(),
        "--width",
        "300",
        "--height",
        "300",
        "--device",
        "cpu",
    ]);
    assert_refused(&out, "render work");
    assert!(String::from_utf8_lossy(&out.stderr).contains("Gaussian-pixel pairs"));
    assert!(t.elapsed().as_secs_f64() < 5.0, "{:?}", t.elapsed());
    assert!(!out_png.exists());
}
