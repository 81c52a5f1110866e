//! The C example, compiled with `cc` against libgsi.a, decodes the corpus to the same
//! pixels as `gsi decode` and turns every malformed file into an error code.

use std::path::{Path, PathBuf};
use std::process::Command;

#[path = "../../tests/common/mod.rs"]
mod common;
use common::corpus;

/// Build the static library the way a C user would (`cargo build --lib`): the test
/// harness itself builds the crate as an rlib only. Returns the path of `libgsi.a`.
fn build_staticlib() -> PathBuf {
    let root = common::repo_root();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(root)
        .args([
            "build",
            "-p",
            "gsi",
            "--lib",
            "--no-default-features",
            "--features",
            "capi,parallel",
            "--message-format=json",
            // Its own target folder: built in the shared one, the lean `libgsi.rlib`
            // would replace the full one that the doctests link against afterwards.
            "--target-dir",
        ])
        .arg(Path::new(env!("CARGO_TARGET_TMPDIR")).join("capi-build"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "cargo build --lib failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
        .filter(|m| m["reason"] == "compiler-artifact" && m["target"]["name"] == "gsi")
        .flat_map(|m| m["filenames"].as_array().cloned().unwrap_or_default())
        .filter_map(|f| f.as_str().map(PathBuf::from))
        .find(|f| f.extension().is_some_and(|e| e == "a"))
        .expect("cargo reported no libgsi.a")
}

fn build_example(dir: &Path) -> PathBuf {
    let root = common::repo_root();
    let lib = build_staticlib();
    let exe = dir.join("decode_c");
    let out = Command::new(std::env::var("CC").unwrap_or_else(|_| "cc".into()))
        .args(["-std=c99", "-Wall", "-Wextra", "-Werror", "-O1"])
        .arg("-I")
        .arg(root.join("include"))
        .arg(root.join("examples/c/decode.c"))
        .arg(&lib)
        .args(["-lpthread", "-ldl", "-lm", "-o"])
        .arg(&exe)
        .output()
        .expect("a C compiler (cc) is needed for this test");
    assert!(
        out.status.success(),
        "cc failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    exe
}

/// RGB bytes of a binary PPM written by the example.
fn ppm_rgb(path: &Path) -> (u32, u32, Vec<u8>) {
    let b = std::fs::read(path).unwrap();
    let text_end = b
        .iter()
        .enumerate()
        .filter(|(_, &c)| c == b'\n')
        .nth(2)
        .unwrap()
        .0
        + 1;
    let head = std::str::from_utf8(&b[..text_end]).unwrap();
    let f: Vec<u32> = head
        .split_whitespace()
        .skip(1)
        .take(2)
        .map(|x| x.parse().unwrap())
        .collect();
    (f[0], f[1], b[text_end..].to_vec())
}

#[test]
fn c_example_matches_gsi_decode_and_refuses_bad_files() {
    let dir = std::env::temp_dir().join(format!("gsi-capi-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let exe = build_example(&dir);
    for path in corpus("valid") {
        for size in [None, Some((37u32, 19u32))] {
            let ppm = dir.join("c.ppm");
            let png = dir.join("r.png");
            let mut c = Command::new(&exe);
            c.arg(&path).arg(&ppm);
            let mut r = Command::new(env!("CARGO_BIN_EXE_gsi"));
            r.arg("decode").arg(&path).arg("-o").arg(&png);
            if let Some((w, h)) = size {
                c.args([w.to_string(), h.to_string()]);
                r.args(["--width", &w.to_string(), "--height", &h.to_string()]);
            }
            let out = c.output().unwrap();
            assert!(
                out.status.success(),
                "{}: {}",
                path.display(),
                String::from_utf8_lossy(&out.stderr)
            );
            assert!(r.status().unwrap().success());
            let (w, h, rgb) = ppm_rgb(&ppm);
            let want = image::open(&png).unwrap().to_rgb8();
            assert_eq!((w, h), want.dimensions(), "{}", path.display());
            assert!(
                rgb == want.into_raw(),
                "{}: C and CLI pixels differ",
                path.display()
            );
        }
    }
    for path in corpus("invalid") {
        let out = Command::new(&exe)
            .arg(&path)
            .arg(dir.join("x.ppm"))
            .output()
            .unwrap();
        let code = out
            .status
            .code()
            .unwrap_or_else(|| panic!("{}: killed by a signal", path.display()));
        assert!(
            (1..=13).contains(&code),
            "{}: exit {code}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert!(
            String::from_utf8_lossy(&out.stderr).starts_with("gsi error"),
            "{}",
            path.display()
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}
