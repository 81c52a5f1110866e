//! Stage 2 in the container: what `gsi enhance` promises about bytes, and that its
//! outputs stay finite and in range on degenerate inputs.

use gsi::enhance::fit::{fit, EnhanceOptions};
use gsi::enhance::Outcome;
use gsi::enhance::{self, features::FeatureBank, loss::LossParams, Enhancer};
use gsi::format::{to_bytes, BitDepths, ChunkType, ChunkedFile, Limits, Records, WriteOptions};
use gsi::model::{Blend, Scene};
use gsi::synth::{random_scene, SceneSpec};
use std::path::Path;
use std::process::{Command, Output, Stdio};

const BITS: BitDepths = BitDepths {
    position: 12,
    covariance: 8,
    angle: 8,
    angle_by_shape: false,
    color_by_footprint: false,
    color: 8,
    opacity: 6,
};

/// A dark scene of `n` Gaussians (colours scaled by `gain`), written as a stage-1 file.
fn dark_file(seed: u64, n: usize, blend: Blend, gain: f32) -> Vec<u8> {
    let mut scene = random_scene(seed, SceneSpec::new(48, 32, n, blend));
    for c in &mut scene.gaussians.colors {
        *c = c.map(|x| x * gain);
    }
    let opts = WriteOptions {
        settings: Some("test=dark".into()),
        psnr: Some(40.0),
        ..WriteOptions::default()
    };
    to_bytes(&Records::from_scene(&scene, BITS), &opts).unwrap()
}

fn quick() -> EnhanceOptions {
    EnhanceOptions {
        iterations: 40,
        experts: 4,
        ..EnhanceOptions::default()
    }
}

/// [`quick`] with the denoising that runs before the mixture (off by default).
fn denoised() -> EnhanceOptions {
    EnhanceOptions {
        denoise: Some(gsi::enhance::denoise::DenoiseOptions::default()),
        ..quick()
    }
}

fn parse(bytes: &[u8]) -> ChunkedFile {
    ChunkedFile::parse(bytes, Limits::default()).unwrap()
}

fn payload(f: &ChunkedFile, ty: ChunkType) -> Option<&[u8]> {
    f.chunks.iter().find(|c| c.ty == ty).map(|c| &c.data[..])
}

/// The front door's result for a file it must enhance: its bytes and what it did.
fn run(bytes: &[u8], opts: &EnhanceOptions, keep: bool, limits: &Limits) -> enhance::Enhanced {
    match enhance::enhance(
        &parse(bytes),
        opts,
        keep,
        limits,
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap()
    {
        Outcome::Enhanced(done) => *done,
        other => panic!("not enhanced: {other:?}"),
    }
}

fn enhanced(bytes: &[u8], keep: bool) -> Vec<u8> {
    run(bytes, &quick(), keep, &Limits::default()).bytes
}

/// Every colour record finite and within the operators' clamp or the original range,
/// and the decoded image finite.
fn assert_sane(bytes: &[u8]) {
    let f = parse(bytes);
    let scene: Scene = f.file.records.to_scene();
    for c in scene.gaussians.colors.iter().flatten() {
        assert!(c.is_finite() && c.abs() <= 64.0, "colour {c}");
    }
    let img = gsi::render::render(&scene, scene.width, scene.height).unwrap();
    assert!(img.data.iter().all(|x| x.is_finite()));
}

#[test]
fn geometry_is_copied_byte_for_byte_and_only_colours_change() {
    for blend in [Blend::Sum, Blend::Alpha] {
        let before = dark_file(1, 60, blend, 0.15);
        let opts = EnhanceOptions {
            experts: 4,
            ..EnhanceOptions::default()
        };
        let after = run(&before, &opts, true, &Limits::default()).bytes;
        let (b, a) = (parse(&before), parse(&after));
        for ty in [
            ChunkType::HEADER,
            ChunkType::POSITIONS,
            ChunkType::COVARIANCE,
            ChunkType::OPACITY,
        ] {
            assert_eq!(payload(&b, ty), payload(&a, ty), "{ty} changed");
        }
        assert_ne!(
            payload(&b, ChunkType::COLORS),
            payload(&a, ChunkType::COLORS)
        );
        let luma = |f: &ChunkedFile| {
            let scene = f.file.records.to_scene();
            let img = gsi::render::render(&scene, 48, 32).unwrap();
            gsi::enhance::fit::mean_luma(&img.data)
        };
        assert!(
            luma(&a) > luma(&b) + 0.05,
            "{blend:?}: {} -> {}",
            luma(&b),
            luma(&a)
        );
        // gCRM now describes the enhanced file and no longer claims the stage-1 PSNR.
        let meta = a.file.metadata.as_ref().unwrap();
        assert_eq!(meta.file_bytes, after.len() as u64);
        assert_eq!(meta.psnr, None);
        assert!(meta.settings.starts_with("test=dark\nstage2="));
    }
}

#[test]
fn revert_restores_the_original_file_exactly() {
    let before = dark_file(2, 50, Blend::Sum, 0.2);
    let once = enhanced(&before, true);
    assert_eq!(parse(&once).revert().unwrap(), before);
    // Enhancing again starts from the kept original, and still reverts exactly.
    let twice = enhanced(&once, true);
    assert_eq!(
        payload(&parse(&twice), ChunkType::ORIGINAL_COLORS),
        payload(&parse(&once), ChunkType::ORIGINAL_COLORS)
    );
    assert_eq!(parse(&twice).revert().unwrap(), before);
    // Without gORC there is nothing to revert to.
    let discarded = enhanced(&before, false);
    assert!(payload(&parse(&discarded), ChunkType::ORIGINAL_COLORS).is_none());
    assert!(parse(&discarded).revert().is_err());
    assert!(parse(&before).revert().is_err());
}

#[test]
fn apply_from_reproduces_the_fitted_colours() {
    for blend in [Blend::Alpha, Blend::Sum] {
        apply_from_reproduces(blend);
    }
}

fn apply_from_reproduces(blend: Blend) {
    let before = dark_file(3, 70, blend, 0.2);
    let lim = Limits::default();
    // In `sum` blending the Gaussians fitted to noise removed first (gENH layout 6),
    // then denoised (layout 2 alone), then the mixture, then shown through GTRC: every
    // step an enhancer of this blend mode takes.
    let after = run(&before, &denoised(), true, &lim).bytes;
    let record = parse(&after).enhancer(&lim).unwrap().unwrap();
    assert!(record.denoise.is_some(), "{blend:?}: no denoising stored");
    let file = parse(&after);
    assert!(
        file.file.records.tone.is_some(),
        "{blend:?}: no tone curve stored"
    );
    let layout = payload(&file, ChunkType::ENHANCER).unwrap();
    let sum = blend == Blend::Sum;
    assert_eq!(record.speckle.is_some(), sum, "{blend:?}: speckle record");
    let want = if sum { (6, 0x11) } else { (2, 0) };
    assert_eq!((layout[0], layout[3]), want, "{blend:?}: layout");
    // Applying the stored enhancer to the same original gives the same file.
    let again = enhance::apply_from(&parse(&before), &parse(&after), true, &lim).unwrap();
    assert_eq!(again, after);
    // …and to the enhanced file itself (it starts from gORC), too.
    let again = enhance::apply_from(&parse(&after), &parse(&after), true, &lim).unwrap();
    assert_eq!(again, after);
    // Another frame: same enhancer, different colours, no fitting.
    let other = dark_file(4, 30, blend, 0.25);
    let applied = enhance::apply_from(&parse(&other), &parse(&after), false, &lim).unwrap();
    assert_sane(&applied);
    assert_eq!(
        payload(&parse(&applied), ChunkType::ENHANCER),
        payload(&parse(&after), ChunkType::ENHANCER)
    );
    // A source with no enhancer is refused.
    assert!(enhance::apply_from(&parse(&other), &parse(&before), false, &lim).is_err());
}

/// A scene whose footprints overlap past the neighbour search's share of the memory
/// limit is still enhanced, without denoising (layout 6 with the speckle record alone),
/// and the caller is told why.
#[test]
fn too_much_overlap_for_denoising_is_enhanced_without_it() {
    let before = dark_file(5, 400, Blend::Sum, 0.05);
    let tight = Limits {
        max_alloc: 8 * 50_000,
        ..Limits::default()
    };
    let done = run(&before, &denoised(), true, &tight);
    let fitted = done.fitted;
    assert!(fitted.record.denoise.is_none());
    let why = fitted.denoise_skipped.expect("the skip is reported");
    assert!(why.contains("without denoising"), "{why}");
    let file = parse(&done.bytes);
    let layout = payload(&file, ChunkType::ENHANCER).unwrap();
    assert_eq!((layout[0], layout[3]), (6, 0x10));
    // The tone curve needs no neighbour search: it is there either way.
    assert!(file.file.records.tone.is_some());
    // With the default limits the same file is denoised.
    let fitted = run(&before, &denoised(), true, &Limits::default()).fitted;
    assert!(fitted.record.denoise.is_some() && fitted.denoise_skipped.is_none());
    // By default nothing is denoised, and nothing is skipped.
    let fitted = run(&before, &quick(), true, &Limits::default()).fitted;
    assert!(fitted.record.denoise.is_none() && fitted.denoise_skipped.is_none());
}

/// A dark room lit by a lamp: a dark scene whose left fifth is bright.
fn lamp_file(seed: u64, blend: Blend) -> Vec<u8> {
    let mut scene = random_scene(seed, SceneSpec::new(64, 48, 300, blend));
    for (p, c) in scene
        .gaussians
        .positions
        .iter()
        .zip(&mut scene.gaussians.colors)
    {
        *c = if p[0] < 0.2 {
            [0.95, 0.9, 0.8]
        } else {
            c.map(|x| 0.03 * x)
        };
    }
    to_bytes(&Records::from_scene(&scene, BITS), &WriteOptions::default()).unwrap()
}

/// Where a lamp holds the curve back, the shadows are lifted by a gain map; where they
/// were within a few noise levels of black, a chroma map follows it (gENH layout 5, both
/// records bits; layout 6 in `sum` blending, after the speckle removal); the file
/// applies to itself and to its original exactly, and reverts exactly.
#[test]
fn a_lamp_lit_room_gets_a_gain_map_that_applies_and_reverts_exactly() {
    let lim = Limits::default();
    for blend in [Blend::Sum, Blend::Alpha] {
        let before = lamp_file(21, blend);
        let done = run(&before, &quick(), true, &lim);
        let plan = done.plan.as_ref().unwrap();
        assert!(plan.capped, "{blend:?}: the lamp should cap the curve");
        let map = done.fitted.record.gain.as_ref().expect("a gain map");
        assert!(
            plan.beta > 0.0 && map.gains.quantizers[0].max > 1.5,
            "{plan:?}"
        );
        let after = parse(&done.bytes);
        let layout = payload(&after, ChunkType::ENHANCER).unwrap();
        assert!(
            done.fitted.record.chroma.is_some(),
            "{blend:?}: a chroma map"
        );
        let (version, bits) = match blend {
            Blend::Sum => (6, 28),
            Blend::Alpha => (5, 12),
        };
        assert_eq!(layout[0], version, "{blend:?}: layout");
        assert_eq!(layout[3] & bits, bits, "{blend:?}: records bits");
        assert_sane(&done.bytes);
        // Nothing shown is clipped (the shoulder stays below 250).
        let scene = after.file.records.to_scene();
        let rgb = gsi::render::render(&scene, 64, 48).unwrap().to_rgb8();
        assert!(rgb.iter().all(|&v| v < 250), "{blend:?}: a clipped pixel");
        let shown =
            gsi::enhance::fit::mean_luma(&gsi::render::render(&scene, 64, 48).unwrap().data);
        assert!(
            (shown - done.mean_luma.1).abs() < 0.03,
            "{blend:?}: {shown} vs {:?}",
            done.mean_luma
        );
        let again = enhance::apply_from(&parse(&before), &after, true, &lim).unwrap();
        assert_eq!(again, done.bytes, "{blend:?}: apply-from");
        assert_eq!(after.revert().unwrap(), before, "{blend:?}: revert");
    }
}

/// The front door leaves alone what it should, and says why.
#[test]
fn the_front_door_decides() {
    let lim = Limits::default();
    let bright = dark_file(22, 200, Blend::Sum, 1.0);
    match enhance::enhance(
        &parse(&bright),
        &quick(),
        true,
        &lim,
        gsi::Device::Cpu,
        &mut |_| {},
    )
    .unwrap()
    {
        Outcome::NotLowLight(a) => assert!(!a.is_low_light() && a.dark_share < 0.25, "{a:?}"),
        other => panic!("{other:?}"),
    }
    let forced = EnhanceOptions {
        force: true,
        ..quick()
    };
    run(&bright, &forced, true, &lim);
    // Enhanced before, original discarded: refused unless forced.
    let dark = dark_file(23, 80, Blend::Sum, 0.15);
    let discarded = enhanced(&dark, false);
    let again = enhance::enhance(
        &parse(&discarded),
        &quick(),
        true,
        &lim,
        gsi::Device::Cpu,
        &mut |_| {},
    );
    assert!(matches!(again.unwrap(), Outcome::OriginalDiscarded));
    run(&discarded, &forced, true, &lim);
}

#[test]
fn degenerate_scenes_stay_finite_and_in_range() {
    let black = dark_file(5, 40, Blend::Sum, 0.0);
    let one = dark_file(6, 1, Blend::Alpha, 0.1);
    let none = dark_file(7, 0, Blend::Sum, 0.1);
    let forced = EnhanceOptions {
        force: true,
        ..quick()
    };
    for (bytes, is_black) in [(&black, true), (&one, false), (&none, true)] {
        // A black image (no Gaussian, or none with light) is left alone unless forced;
        // forced, the enhancer still gives finite colours in range.
        let out = match enhance::enhance(
            &parse(bytes),
            &quick(),
            true,
            &Limits::default(),
            gsi::Device::Cpu,
            &mut |_| {},
        )
        .unwrap()
        {
            Outcome::Enhanced(done) if !is_black => done.bytes,
            Outcome::NotLowLight(a) if is_black => {
                assert!(a.is_black() && a.verdict() == "nothing to lift", "{a:?}");
                run(bytes, &forced, true, &Limits::default()).bytes
            }
            other => panic!("black {is_black}: {other:?}"),
        };
        assert_sane(&out);
        assert_eq!(parse(&out).revert().unwrap(), *bytes);
    }
}

#[test]
fn one_operator_and_extreme_exposures_stay_finite_and_in_range() {
    let bytes = dark_file(8, 50, Blend::Alpha, 0.15);
    let scene = parse(&bytes).file.records.to_scene();
    let cases = [
        EnhanceOptions {
            experts: 1,
            ..quick()
        },
        EnhanceOptions {
            params: LossParams {
                exposure_target: 0.999,
                ..LossParams::default()
            },
            ..quick()
        },
        EnhanceOptions {
            params: LossParams {
                exposure_target: 1e-4,
                ..LossParams::default()
            },
            ..quick()
        },
        EnhanceOptions {
            learning_rate: 10.0,
            ..quick()
        },
    ];
    for opts in cases {
        let f = fit(&scene, &opts, &FeatureBank, gsi::Device::Cpu, &mut |p| {
            assert!(p.terms.total.is_finite() && p.map.tv.is_finite() && p.map.entropy.is_finite());
        });
        for c in f.colors.iter().flatten() {
            // Alpha blending: every operator clamps to [0, 1] and the identity keeps the
            // original colour, so the mix stays in [0, 1].
            assert!(
                (0.0..=1.0).contains(c),
                "{c} with K {} E {}",
                opts.experts,
                opts.params.exposure_target
            );
        }
        assert!(f
            .enhancer
            .params
            .iter()
            .chain(&f.enhancer.map)
            .all(|x| x.is_finite()));
        assert!(f.mean_luma.1.is_finite());
    }
    // K = 1 is the identity whatever it was fitted to.
    let f = fit(
        &scene,
        &EnhanceOptions {
            experts: 1,
            ..quick()
        },
        &FeatureBank,
        gsi::Device::Cpu,
        &mut |_| {},
    );
    assert_eq!(f.colors, scene.gaussians.colors);
    assert_eq!(Enhancer::from_record(&f.record).experts, 1);
}

#[test]
fn fitting_is_reproducible_from_its_seed() {
    let bytes = dark_file(9, 80, Blend::Sum, 0.2);
    assert_eq!(enhanced(&bytes, true), enhanced(&bytes, true));
}

// --- the command line -----------------------------------------------------------

fn gsi(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_gsi"))
        .args(args)
        .output()
        .unwrap()
}

/// `gsi args` with `input` on standard input (fed from a thread, so that a large output
/// cannot deadlock the pipe).
fn gsi_piped(args: &[&str], input: &[u8]) -> Output {
    let mut child = Command::new(env!("CARGO_BIN_EXE_gsi"))
        .args(args)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    let input = input.to_vec();
    let feeder = std::thread::spawn(move || std::io::Write::write_all(&mut stdin, &input));
    let out = child.wait_with_output().unwrap();
    feeder.join().unwrap().unwrap();
    out
}

fn tmp(name: &str) -> std::path::PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("enhance-cli");
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

#[test]
fn cli_in_place_revert_and_apply_from() {
    let before = dark_file(10, 60, Blend::Sum, 0.15);
    let path = tmp("frame.gsi");
    std::fs::write(&path, &before).unwrap();
    let p = path.to_str().unwrap();
    let out = gsi(&[
        "enhance",
        p,
        "--in-place",
        "--iterations",
        "30",
        "--denoise",
        "--quiet",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let after = std::fs::read(&path).unwrap();
    assert_ne!(after, before);
    let info = gsi(&["info", p, "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
    assert_eq!(json["enhancer"]["experts"], 16);
    assert_eq!(json["enhancer"]["revertible"], true);
    assert_eq!(json["enhancer"]["denoise"]["passes"], 1);
    let t = json["enhancer"]["speckle"]["threshold"].as_f64().unwrap();
    assert!((t - 3.0 * 1.3 / 255.0).abs() < 1e-6, "{t}");
    assert!(json["enhancer"]["tone"].is_null());
    assert_eq!(json["tone_curve"]["knots"], 64);
    assert_eq!(json["tone_curve"]["curves"], 1);
    assert_eq!(json["file_bytes"].as_u64(), Some(after.len() as u64));
    let text = String::from_utf8(gsi(&["info", p]).stdout).unwrap();
    assert!(
        text.contains("enhanced: Gaussians within the noise removed (threshold 0.0153), then denoised (1 pass, range ")
            && text.contains("then 16 colour operators")
            && text.contains("shown through a tone curve (GTRC, 1 curve of 64 knots"),
        "{text}"
    );

    // A failure (a source without an enhancer) leaves the file untouched, with exit 1.
    let plain = tmp("plain.gsi");
    std::fs::write(&plain, &before).unwrap();
    let out = gsi(&[
        "enhance",
        p,
        "--in-place",
        "--apply-from",
        plain.to_str().unwrap(),
    ]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(String::from_utf8_lossy(&out.stderr).lines().count(), 1);
    assert_eq!(std::fs::read(&path).unwrap(), after);

    // --apply-from onto the original gives the fitted file.
    let copy = tmp("copy.gsi");
    let out = gsi(&[
        "enhance",
        plain.to_str().unwrap(),
        "-o",
        copy.to_str().unwrap(),
        "--apply-from",
        p,
    ]);
    assert!(out.status.success());
    assert_eq!(std::fs::read(&copy).unwrap(), after);

    let out = gsi(&["enhance", p, "--in-place", "--revert"]);
    assert!(out.status.success());
    assert_eq!(std::fs::read(&path).unwrap(), before);
    // Nothing left to revert.
    let out = gsi(&["enhance", p, "--in-place", "--revert"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(std::fs::read(&path).unwrap(), before);

    // --keep-speckle stores no speckle record.
    let kept = tmp("kept.gsi");
    let k = kept.to_str().unwrap();
    let out = gsi(&[
        "enhance",
        p,
        "-o",
        k,
        "--iterations",
        "5",
        "--keep-speckle",
        "--quiet",
    ]);
    assert!(out.status.success());
    let json: serde_json::Value =
        serde_json::from_slice(&gsi(&["info", k, "--json"]).stdout).unwrap();
    assert!(json["enhancer"]["speckle"].is_null(), "{json}");
}

/// `--exposure E` and `--exposure auto` reach the exposure they aim at (issue 14's
/// exposure test, here on a small dark file; BENCHMARKS.md has it on eval15 and the
/// synthetic Kodak set), and say so on the summary line.
#[test]
fn cli_exposure_lands_on_its_target() {
    // Enough Gaussians to cover the image: uncovered background stays black whatever
    // the gain, and would cap the mean luma the mixture can reach.
    let dark = dark_file(12, 400, Blend::Alpha, 0.12);
    let path = tmp("aim.gsi");
    std::fs::write(&path, &dark).unwrap();
    let p = path.to_str().unwrap();
    for e in ["0.35", "0.50", "auto"] {
        let out_path = tmp(&format!("aim-{e}.gsi"));
        let o = out_path.to_str().unwrap();
        let out = gsi(&["enhance", p, "-o", o, "--exposure", e, "--iterations", "30"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(out.status.success(), "{err}");
        // "enhanced: N% under-exposed, mean luma A -> B (aimed at T), ..."
        let line = err.lines().find(|l| l.contains("aimed at")).expect(&err);
        let num = |after: &str| -> f32 {
            let rest = &line[line.find(after).unwrap() + after.len()..];
            rest.trim_start()
                .split(|c: char| !(c.is_ascii_digit() || c == '.'))
                .next()
                .unwrap()
                .parse()
                .unwrap()
        };
        let (got, target) = (num("->"), num("aimed at"));
        if e != "auto" {
            assert_eq!(format!("{target:.2}"), e);
        }
        assert!((got - target).abs() <= 0.05, "{e}: {line}");
        std::fs::remove_file(out_path).unwrap();
    }
}

#[test]
fn cli_leaves_a_bright_image_alone_unless_forced() {
    let bright = dark_file(11, 60, Blend::Alpha, 1.0);
    let path = tmp("bright.gsi");
    std::fs::write(&path, &bright).unwrap();
    let p = path.to_str().unwrap();
    let out = gsi(&["enhance", p, "--in-place", "--iterations", "20"]);
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a low-light image"));
    assert_eq!(std::fs::read(&path).unwrap(), bright);
    let out = gsi(&[
        "enhance",
        p,
        "--in-place",
        "--iterations",
        "20",
        "--force",
        "--quiet",
    ]);
    assert!(out.status.success());
    assert_ne!(std::fs::read(&path).unwrap(), bright);
}

#[test]
fn cli_works_in_a_pipe_and_refuses_bad_usage() {
    let before = dark_file(12, 40, Blend::Sum, 0.15);
    let out = gsi_piped(
        &["enhance", "-", "-o", "-", "--iterations", "20", "--quiet"],
        &before,
    );
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_eq!(parse(&out.stdout).revert().unwrap(), before);

    let path = tmp("usage.gsi");
    std::fs::write(&path, &before).unwrap();
    let p = path.to_str().unwrap();
    for args in [
        vec!["enhance", p],                                              // no destination
        vec!["enhance", p, "--in-place", "-o", "x.gsi"],                 // two destinations
        vec!["enhance", p, "--in-place", "--revert", "--apply-from", p], // two modes
        vec!["enhance", p, "--in-place", "--exposure", "1.5"],           // not a mean luma
        vec!["enhance", p, "--in-place", "--exposure", "bright"],
        vec!["enhance", p, "--in-place", "--tone", "0"], // not an exponent in (0, 4]
        vec!["enhance", p, "--in-place", "--tone", "4.5"],
        vec!["enhance", p, "--in-place", "--tone", "NaN"],
    ] {
        assert_eq!(gsi(&args).status.code(), Some(2), "{args:?}");
    }
    for args in [
        vec!["enhance", p, "--in-place", "--experts", "0"],
        vec!["enhance", "-", "--in-place"],
    ] {
        let out = gsi(&args);
        assert_eq!(out.status.code(), Some(1), "{args:?}");
        assert_eq!(std::fs::read(&path).unwrap(), before);
    }
    // Not a gsi file at all.
    let junk = tmp("junk.gsi");
    std::fs::write(&junk, b"not a gsi file").unwrap();
    let out = gsi(&["enhance", junk.to_str().unwrap(), "--in-place"]);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(std::fs::read(&junk).unwrap(), b"not a gsi file");
}

/// `gsi enhance --in-place` over a folder: every file is the one a call of its own
/// writes; a file enhanced before is skipped unless `--force`; a corrupt one is reported
/// while the rest are done, and the exit status says so.
#[test]
fn cli_batch_in_place() {
    let dir = tmp("batch");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let files: Vec<_> = (0..3)
        .map(|k| {
            let path = dir.join(format!("f{k}.gsi"));
            std::fs::write(&path, dark_file(20 + k, 40, Blend::Sum, 0.15)).unwrap();
            path
        })
        .collect();
    std::fs::write(dir.join("broken.gsi"), b"\x89GSI\r\n\x1a\n truncated").unwrap();
    let quick = ["--iterations", "6", "--jobs", "2"];
    // Each alone, into copies: what the batch must write.
    let want: Vec<Vec<u8>> = files
        .iter()
        .map(|f| {
            let single = f.with_extension("single");
            let out = gsi(&[
                "enhance",
                f.to_str().unwrap(),
                "-o",
                single.to_str().unwrap(),
                "--iterations",
                "6",
                "--quiet",
            ]);
            assert!(
                out.status.success(),
                "{}",
                String::from_utf8_lossy(&out.stderr)
            );
            let bytes = std::fs::read(&single).unwrap();
            std::fs::remove_file(single).unwrap();
            bytes
        })
        .collect();
    let d = dir.to_str().unwrap();
    let out = gsi(&[&["enhance", d, "--in-place"][..], &quick[..]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("broken.gsi") && err.contains("1 of 4 files failed"),
        "{err}"
    );
    for (f, want) in files.iter().zip(&want) {
        assert!(&std::fs::read(f).unwrap() == want, "{}", f.display());
    }
    // Again: the enhanced files are skipped, untouched.
    let out = gsi(&[&["enhance", d, "--in-place"][..], &quick[..]].concat());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("skipped, enhanced before").count(), 3, "{err}");
    for (f, want) in files.iter().zip(&want) {
        assert!(&std::fs::read(f).unwrap() == want, "{}", f.display());
    }
    // Reverted as a batch: the stage-1 files come back.
    std::fs::remove_file(dir.join("broken.gsi")).unwrap();
    let out = gsi(&["enhance", d, "--in-place", "--revert", "--quiet"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (k, f) in files.iter().enumerate() {
        assert_eq!(
            std::fs::read(f).unwrap(),
            dark_file(20 + k as u64, 40, Blend::Sum, 0.15)
        );
    }
    std::fs::remove_dir_all(dir).unwrap();
}

/// A file that is not low-light, read from standard input with `-o -`: left unchanged,
/// and written unchanged to standard output.
#[test]
fn cli_a_bright_file_through_pipes_comes_back_unchanged() {
    let bright = dark_file(11, 60, Blend::Alpha, 1.0);
    let out = gsi_piped(&["enhance", "-", "-o", "-", "--iterations", "3"], &bright);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(err.contains("not a low-light image"), "{err}");
    assert!(out.stdout == bright, "the file did not come back unchanged");
}

/// Bad and degenerate inputs: a 1×1 image is enhanced; a black one and a white one are
/// left alone with the reason (the black one enhanced with `--force`); a file without
/// colour records, and an enhanced file whose original colours were discarded, are
/// refused in one line with exit 1 and the file left as it was.
#[test]
fn cli_bad_and_degenerate_inputs() {
    let write = |name: &str, bytes: &[u8]| {
        let p = tmp(name);
        std::fs::write(&p, bytes).unwrap();
        p
    };
    let tiny = {
        let scene = random_scene(40, SceneSpec::new(1, 1, 1, Blend::Sum));
        let mut r = Records::from_scene(&scene, BITS);
        r.colors = gsi::format::Attribute::fit(&[[0.01f32, 0.02, 0.01]], [8; 3]);
        to_bytes(&r, &WriteOptions::default()).unwrap()
    };
    let enhance_in_place = |p: &std::path::Path, extra: &[&str]| {
        let mut args = vec![
            "enhance",
            p.to_str().unwrap(),
            "--in-place",
            "--iterations",
            "5",
        ];
        args.extend_from_slice(extra);
        gsi(&args)
    };
    let p = write("one-pixel.gsi", &tiny);
    let out = enhance_in_place(&p, &[]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_ne!(
        std::fs::read(&p).unwrap(),
        tiny,
        "the one-pixel image was not enhanced"
    );
    assert_sane(&std::fs::read(&p).unwrap());

    // Black: nothing to lift, said in one line, the file as it was; `--force` enhances it.
    let black = dark_file(41, 30, Blend::Sum, 0.0);
    let p = write("black.gsi", &black);
    let out = enhance_in_place(&p, &[]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("the image is black") && err.contains("nothing to lift, left unchanged"),
        "{err}"
    );
    assert_eq!(
        err.lines().filter(|l| l.contains("black.gsi")).count(),
        1,
        "{err}"
    );
    assert_eq!(std::fs::read(&p).unwrap(), black);
    let out = enhance_in_place(&p, &["--force"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert_ne!(std::fs::read(&p).unwrap(), black);
    assert_sane(&std::fs::read(&p).unwrap());

    let white = write("white.gsi", &dark_file(42, 200, Blend::Sum, 4.0));
    let out = gsi(&["enhance", white.to_str().unwrap(), "--in-place"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        out.status.success() && err.contains("0% of the image is under-exposed"),
        "{err}"
    );
    assert!(err.contains("left unchanged"), "{err}");

    // No GCOL: refused by the parser, named, nothing written.
    let good = dark_file(43, 30, Blend::Sum, 0.1);
    let f = parse(&good);
    let mut no_colours = gsi::format::SIGNATURE.to_vec();
    for c in f.chunks.iter().filter(|c| c.ty != ChunkType::COLORS) {
        no_colours.extend_from_slice(&(c.data.len() as u32).to_be_bytes());
        no_colours.extend_from_slice(&c.ty.0);
        no_colours.extend_from_slice(&c.data);
        no_colours.extend_from_slice(&gsi::format::chunk_crc(c.ty, &c.data).to_be_bytes());
    }
    let p = write("no-colours.gsi", &no_colours);
    let out = gsi(&["enhance", p.to_str().unwrap(), "--in-place"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().count(), 1, "{err}");
    assert!(err.contains("GCOL"), "{err}");
    assert_eq!(std::fs::read(&p).unwrap(), no_colours);

    // Enhanced, original discarded: refused unless --force.
    let p = write("discarded.gsi", &enhanced(&good, false));
    let before = std::fs::read(&p).unwrap();
    let out = gsi(&["enhance", p.to_str().unwrap(), "--in-place"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(err.contains("original colours were discarded"), "{err}");
    assert_eq!(std::fs::read(&p).unwrap(), before);
}
