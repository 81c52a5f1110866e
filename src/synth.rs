//! Deterministic test data: random Gaussian sets ([`gsi_synth`]) and the checked-in
//! corpus; for tests, benches and tools, never used by the library itself.

pub use gsi_synth::{random_scene, SceneSpec, SplitMix64};

/// One file of the checked-in corpus (`corpus/`), as the generator makes it.
pub struct CorpusFile {
    /// File name without directory; invalid files are named `<error kind>--<what>.gsi`.
    pub name: String,
    pub bytes: Vec<u8>,
    /// `None` for a valid file, else the kind of error a decoder must report.
    pub expect: Option<crate::format::ErrorKind>,
}

/// The deterministic corpus: valid files of many shapes and malformed files of every
/// error kind. `cargo run --example gen_corpus` writes it; `tests/corpus.rs` checks the
/// checked-in copy is exactly what this returns.
pub fn corpus() -> Vec<CorpusFile> {
    corpus::valid()
        .into_iter()
        .chain(corpus::invalid())
        .collect()
}

mod corpus {
    use super::{random_scene, CorpusFile, SceneSpec};
    use crate::format::{self, BitDepths, ChunkType, ErrorKind, RawChunk, Records, WriteOptions};
    use crate::model::{Blend, CovParam, GaussianSet, Scene, WeightRule};

    fn write(records: &Records, settings: &str) -> Vec<u8> {
        let opts = WriteOptions {
            settings: Some(settings.into()),
            ..WriteOptions::default()
        };
        format::to_bytes(records, &opts).expect("in-memory write")
    }

    fn valid_file(name: &str, records: &Records) -> CorpusFile {
        CorpusFile {
            name: format!("{name}.gsi"),
            bytes: write(records, "generator=gsi-synth"),
            expect: None,
        }
    }

    /// `records` with every attribute in `method` (2, §5.4, or 3, §5.4.4) and the given
    /// modes (positions, covariance, colours, opacity), as the minor version that method
    /// needs and with no `gCRM`: each mode meets the decoder whether or not the encoder
    /// would have chosen it.
    fn coded(records: &Records, modes: [&[u8]; 4], method: u8) -> Vec<u8> {
        coded_each(records, modes.map(|m| (m, method)))
    }

    /// [`coded`] with each attribute in a method of its own (colours by footprint in
    /// method 5, §5.4.6, read with the covariance's sizes), as the least minor version
    /// that all of them need.
    fn coded_each(records: &Records, each: [(&[u8], u8); 4]) -> Vec<u8> {
        let mut header = records.header;
        header.version_minor = each
            .iter()
            .map(|&(_, m)| format::minor_for_method(m))
            .max()
            .unwrap_or(0);
        let attributes = [
            (ChunkType::POSITIONS, Some(&records.positions), each[0]),
            (ChunkType::COVARIANCE, Some(&records.covariance), each[1]),
            (ChunkType::COLORS, Some(&records.colors), each[2]),
            (ChunkType::OPACITY, records.opacity.as_ref(), each[3]),
        ];
        let sizes = records.footprint_sizes();
        let mut chunks = vec![(ChunkType::HEADER, header.to_bytes().to_vec())];
        for (ty, a, (m, method)) in attributes {
            if let Some(a) = a {
                let payload = a.to_coded_payload(m, method, sizes.as_deref());
                chunks.push((ty, payload.expect("valid modes")));
            }
        }
        chunks.push((ChunkType::END, Vec::new()));
        assemble(&chunks)
    }

    fn random(seed: u64, spec: SceneSpec) -> Records {
        Records::from_scene(&random_scene(seed, spec), BitDepths::default())
    }

    /// A `log-scale-rotation` scene of `n` Gaussians at the `sum` encoder's depths, its
    /// angles shaped (§5.4.5), in curve order.
    fn shaped(seed: u64, blend: Blend, n: usize) -> Records {
        let scene = random_scene(
            seed,
            SceneSpec {
                cov_param: CovParam::LogScaleRotation,
                with_opacity: blend == Blend::Alpha,
                ..SceneSpec::new(192, 128, n, blend)
            },
        );
        let bits = BitDepths {
            position: 12,
            covariance: 6,
            angle: 7,
            angle_by_shape: true,
            color_by_footprint: false,
            color: 8,
            opacity: 6,
        };
        let mut r = Records::from_scene(&scene, bits);
        assert!(r.covariance.shape.is_some(), "shaped");
        r.sort_spatially();
        r
    }

    /// [`shaped`], its colours stored by footprint (§5.4.6) as the encoder stores them.
    fn by_footprint(seed: u64, blend: Blend, n: usize) -> Records {
        let mut r = shaped(seed, blend, n);
        let colors = r.to_scene().gaussians.colors;
        let sizes = r
            .footprint_sizes()
            .expect("a log-scale-rotation covariance");
        r.colors = format::Attribute::footprint_colors(&colors, &sizes, 8);
        assert!(r.colors.footprint.is_some(), "by footprint");
        r
    }

    /// The edges of §5.4.6's rule: 256 Gaussians with every pair of 4-bit log-scale codes
    /// over [−15, 0] (values −15 + q, so `p0 + p1` from −30 to 0 and `s` from −17 to 0),
    /// under β = −12, so that classes clamp at both ends (`s` below −12 and above −5)
    /// and every `s` is a negative non-integer but 0 (`floor`, not truncation).
    fn footprint_edges() -> Records {
        let mut r = random(21, SceneSpec::new(64, 48, 256, Blend::Sum));
        let scale = format::Quantizer {
            bits: 4,
            min: -15.0,
            max: 0.0,
        };
        let angle = r.covariance.quantizers[2];
        let n = 256;
        let codes: Vec<u32> = (0..n)
            .map(|i| i / 16)
            .chain((0..n).map(|i| i % 16))
            .chain(r.covariance.codes[2 * n as usize..].iter().copied())
            .collect();
        r.header.cov_param = CovParam::LogScaleRotation;
        r.covariance = format::Attribute {
            quantizers: vec![scale, scale, angle],
            codes,
            shape: None,
            footprint: None,
        };
        r.colors.footprint = Some(-12);
        r
    }

    pub fn valid() -> Vec<CorpusFile> {
        use Blend::{Alpha, Sum};
        use CovParam::{Cholesky, LogScaleRotation as Lsr};
        let spec = |w, h, n, blend, cov_param, with_opacity| SceneSpec {
            cov_param,
            with_opacity,
            ..SceneSpec::new(w, h, n, blend)
        };
        let mut out = vec![
            CorpusFile {
                name: "tiny.gsi".into(),
                bytes: format::tests_support::tiny_file(),
                expect: None,
            },
            valid_file(
                "empty-0-gaussians",
                &random(1, spec(32, 24, 0, Sum, Cholesky, false)),
            ),
            valid_file(
                "one-pixel-1-gaussian",
                &random(2, spec(1, 1, 1, Sum, Lsr, false)),
            ),
            valid_file("row-1x200", &random(3, spec(200, 1, 20, Sum, Lsr, false))),
            valid_file(
                "column-1x200",
                &random(4, spec(1, 200, 20, Alpha, Cholesky, true)),
            ),
            valid_file(
                "sum-cholesky-100",
                &random(5, spec(64, 48, 100, Sum, Cholesky, false)),
            ),
            valid_file(
                "sum-lsr-500-opacity",
                &random(6, spec(96, 64, 500, Sum, Lsr, true)),
            ),
            valid_file(
                "alpha-lsr-500-opacity",
                &random(7, spec(96, 64, 500, Alpha, Lsr, true)),
            ),
            valid_file(
                "alpha-cholesky-300-no-opacity",
                &random(8, spec(80, 80, 300, Alpha, Cholesky, false)),
            ),
            valid_file(
                "sum-lsr-3000",
                &random(9, spec(192, 128, 3000, Sum, Lsr, false)),
            ),
            valid_file(
                "alpha-lsr-3000-opacity",
                &random(10, spec(192, 128, 3000, Alpha, Lsr, true)),
            ),
        ];
        // Low bit depths, as an aggressive encoder would choose.
        let low = BitDepths {
            position: 10,
            covariance: 6,
            angle: 6,
            angle_by_shape: false,
            color_by_footprint: false,
            color: 5,
            opacity: 4,
        };
        let scene = random_scene(11, spec(128, 96, 800, Alpha, Lsr, true));
        out.push(valid_file(
            "alpha-lsr-800-low-bits",
            &Records::from_scene(&scene, low),
        ));
        out.push(valid_file(
            "degenerate-covariances-cholesky",
            &degenerate(Cholesky),
        ));
        out.push(valid_file("degenerate-covariances-lsr", &degenerate(Lsr)));
        // An unknown ancillary chunk is skipped.
        let records = random(12, spec(40, 30, 30, Sum, Lsr, false));
        let opts = WriteOptions {
            ancillary: vec![RawChunk {
                ty: ChunkType(*b"zzTe"),
                data: b"skip me".to_vec(),
            }],
            ..WriteOptions::default()
        };
        out.push(CorpusFile {
            name: "unknown-ancillary-chunk.gsi".into(),
            bytes: format::to_bytes(&records, &opts).expect("in-memory write"),
            expect: None,
        });
        // Method 2 (§5.4): a `sum` file along its Morton curve as the encoder writes it,
        // and files in every mode, at the widest and at no depth.
        const M2: u8 = format::METHOD_CODED;
        const M3: u8 = format::METHOD_CODED_RAW;
        let mut sorted = random(14, spec(192, 128, 3000, Sum, Lsr, false));
        sorted.sort_spatially();
        out.push(CorpusFile {
            name: "coded-sum-lsr-3000-morton.gsi".into(),
            bytes: coded(&sorted, [&[3, 3], &[0, 1, 2], &[0, 1, 1], &[]], M2),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded-alpha-cholesky-500-every-mode.gsi".into(),
            bytes: coded(
                &random(15, spec(96, 64, 500, Alpha, Cholesky, true)),
                [&[2, 2], &[2, 0, 1], &[0, 2, 1], &[2]],
                M2,
            ),
            expect: None,
        });
        // Method 3 (§5.4.4), version 1.6: the same, with mode 4 (raw) where an encoder
        // writes it (an angle) and elsewhere.
        out.push(CorpusFile {
            name: "coded3-sum-lsr-3000-morton.gsi".into(),
            bytes: coded(&sorted, [&[3, 3], &[0, 0, 4], &[0, 1, 1], &[]], M3),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded3-alpha-cholesky-500-every-mode.gsi".into(),
            bytes: coded(
                &random(15, spec(96, 64, 500, Alpha, Cholesky, true)),
                [&[2, 2], &[4, 2, 1], &[0, 1, 2], &[4]],
                M3,
            ),
            expect: None,
        });
        // Method 4 (§5.4.5), version 1.7: angles at the precision of their shape, as the
        // encoder writes `sum` files, and beside opacity in an `alpha` file.
        const M4: u8 = format::METHOD_SHAPED;
        out.push(CorpusFile {
            name: "coded4-sum-lsr-3000-shaped.gsi".into(),
            bytes: coded(
                &shaped(14, Sum, 3000),
                [&[3, 3], &[0, 1, 5], &[0, 1, 1], &[]],
                M4,
            ),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded4-alpha-lsr-500-shaped-opacity.gsi".into(),
            bytes: coded(
                &shaped(18, Alpha, 500),
                [&[2, 2], &[4, 2, 5], &[0, 1, 2], &[4]],
                M4,
            ),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded4-sum-lsr-64-edges.gsi".into(),
            bytes: coded(&shaped_edges(), [&[3, 3], &[0, 0, 5], &[0, 1, 1], &[]], M4),
            expect: None,
        });
        // Method 5 (§5.4.6), version 1.8: colours at the precision of their footprint, as
        // the encoder writes `sum` files (angles shaped), beside opacity in an `alpha`
        // file, and at the edges of the class rule.
        const M5: u8 = format::METHOD_FOOTPRINT;
        out.push(CorpusFile {
            name: "coded5-sum-lsr-3000-footprint.gsi".into(),
            bytes: coded_each(
                &by_footprint(22, Sum, 3000),
                [(&[3, 3], M3), (&[0, 1, 5], M4), (&[0, 1, 1], M5), (&[], M3)],
            ),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded5-alpha-lsr-500-footprint-opacity.gsi".into(),
            bytes: coded_each(
                &by_footprint(23, Alpha, 500),
                [
                    (&[2, 2], M3),
                    (&[4, 2, 5], M4),
                    (&[4, 2, 0], M5),
                    (&[4], M3),
                ],
            ),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded5-sum-lsr-256-classes.gsi".into(),
            bytes: coded_each(
                &footprint_edges(),
                [(&[3, 3], M3), (&[4, 4, 0], M3), (&[0, 2, 1], M5), (&[], M3)],
            ),
            expect: None,
        });
        let wide = BitDepths {
            position: 24,
            covariance: 24,
            angle: 24,
            angle_by_shape: false,
            color_by_footprint: false,
            color: 12,
            opacity: 9,
        };
        let mut wide_records =
            Records::from_scene(&random_scene(16, spec(64, 48, 200, Sum, Lsr, true)), wide);
        wide_records.sort_spatially();
        out.push(CorpusFile {
            name: "coded-sum-24-bit.gsi".into(),
            bytes: coded(&wide_records, [&[3, 3], &[0, 1, 0], &[2, 1, 1], &[0]], M2),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded3-sum-24-bit.gsi".into(),
            bytes: coded(&wide_records, [&[3, 3], &[0, 1, 4], &[2, 1, 1], &[0]], M3),
            expect: None,
        });
        let empty = random(17, spec(32, 24, 0, Sum, Lsr, false));
        out.push(CorpusFile {
            name: "coded-empty-0-gaussians.gsi".into(),
            bytes: coded(&empty, [&[3, 3], &[0, 0, 0], &[0, 0, 0], &[]], M2),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded3-empty-0-gaussians.gsi".into(),
            bytes: coded(&empty, [&[3, 3], &[0, 0, 4], &[0, 0, 0], &[]], M3),
            expect: None,
        });
        out.push(CorpusFile {
            name: "coded-degenerate-covariances.gsi".into(),
            bytes: coded(
                &degenerate(Lsr),
                [&[2, 2], &[0, 1, 2], &[0, 1, 1], &[2]],
                M2,
            ),
            expect: None,
        });
        // Stage 2: a file enhanced in the container (gENH and gORC before GEND); the
        // `denoised` ones with a layout-2 gENH (spec §7.2.1), the `toned` ones with a
        // layout-3 gENH (§7.2.2), with both records and with the tone record alone; the
        // `gained` ones with a layout-4 gENH (a gain map, §7.2.3) and a GTRC (§6.6); the
        // `chroma` ones with a layout-5 gENH (a chroma map, §7.2.4), after a gain map and
        // alone.
        // The `speckle` ones with a layout-6 gENH (§7.2.5), alone, with every other
        // record, and in an `alpha` file (where the step changes nothing).
        let st = |denoised, toned, gained, chroma, speckle| Stage2 {
            denoised,
            toned,
            gained,
            chroma,
            speckle,
        };
        for (name, blend, stored) in [
            (
                "enhanced-sum-160",
                Sum,
                st(false, false, false, false, false),
            ),
            (
                "enhanced-alpha-160",
                Alpha,
                st(false, false, false, false, false),
            ),
            (
                "enhanced-denoised-sum-160",
                Sum,
                st(true, false, false, false, false),
            ),
            (
                "enhanced-denoised-alpha-160",
                Alpha,
                st(true, false, false, false, false),
            ),
            (
                "enhanced-denoised-toned-sum-160",
                Sum,
                st(true, true, false, false, false),
            ),
            (
                "enhanced-toned-alpha-160",
                Alpha,
                st(false, true, false, false, false),
            ),
            (
                "enhanced-denoised-gained-sum-160",
                Sum,
                st(true, false, true, false, false),
            ),
            (
                "enhanced-gained-alpha-160",
                Alpha,
                st(false, false, true, false, false),
            ),
            (
                "enhanced-gained-chroma-sum-160",
                Sum,
                st(false, false, true, true, false),
            ),
            (
                "enhanced-chroma-alpha-160",
                Alpha,
                st(false, false, false, true, false),
            ),
            (
                "enhanced-speckle-sum-160",
                Sum,
                st(false, false, false, false, true),
            ),
            (
                "enhanced-speckle-all-sum-160",
                Sum,
                st(true, true, true, true, true),
            ),
            (
                "enhanced-speckle-alpha-160",
                Alpha,
                st(false, false, false, false, true),
            ),
        ] {
            let mut scene = random_scene(13, spec(64, 40, 160, blend, Lsr, blend == Alpha));
            for c in &mut scene.gaussians.colors {
                *c = c.map(|x| 0.2 * x);
            }
            out.push(CorpusFile {
                name: format!("{name}.gsi"),
                bytes: enhanced(
                    &write(
                        &Records::from_scene(&scene, BitDepths::default()),
                        "generator=gsi-synth",
                    ),
                    stored,
                ),
                expect: None,
            });
        }
        // A tone curve per channel (GTRC with three curves) on a plain stage-1 file.
        let mut records = random(14, SceneSpec::new(40, 30, 100, Blend::Sum));
        records.tone = Some(three_curves());
        out.push(valid_file("tone-curve-3-curves-sum-100", &records));
        // The column rule (spec §6.3.2) in bands of 16 rows (GCRW), as every encoder of
        // version 1.4 wrote it, and of 32 (GCRT), as every encoder of 1.5 writes it: both
        // blend modes over several bands of rows, thin and steep Gaussians (σ from 0.05
        // px, which the rule weighs per pixel), and degenerate covariances.
        for (prefix, weights) in [
            ("columns", WeightRule::Columns),
            ("columns32", WeightRule::Columns32),
        ] {
            let columns = |seed, w, h, n, blend, cov_param, with_opacity, sigma_px| {
                let scene = random_scene(
                    seed,
                    SceneSpec {
                        sigma_px,
                        weights,
                        ..spec(w, h, n, blend, cov_param, with_opacity)
                    },
                );
                Records::from_scene(&scene, BitDepths::default())
            };
            out.push(valid_file(
                &format!("{prefix}-sum-lsr-800"),
                &columns(18, 96, 80, 800, Sum, Lsr, false, (0.05, 12.0)),
            ));
            out.push(valid_file(
                &format!("{prefix}-alpha-cholesky-500-opacity"),
                &columns(19, 80, 72, 500, Alpha, Cholesky, true, (0.05, 12.0)),
            ));
            let mut degenerate_columns = degenerate(Lsr);
            degenerate_columns.weights = weights;
            out.push(valid_file(
                &format!("{prefix}-degenerate-covariances"),
                &degenerate_columns,
            ));
        }
        out
    }

    /// A curve per channel: powers 0.5, 0.6 and 0.7, scaled by 1.2 and capped at 0.97.
    pub(super) fn three_curves() -> crate::model::ToneCurve {
        let values = [0.5f64, 0.6, 0.7]
            .iter()
            .flat_map(|&g| {
                let c = crate::model::ToneCurve::sample(33, |x| (1.2 * x.powf(g)).min(0.97))
                    .expect("33 knots");
                c.values().to_vec()
            })
            .collect();
        crate::model::ToneCurve::new(3, values).expect("three curves of 33 knots")
    }

    /// `bytes` rewritten by a fixed pseudo-random enhancer (K = 4, hidden 3, a 3×2 map),
    /// as `gsi enhance` would store one; with `denoised`, one that smooths the colours
    /// first (two passes, range 0.05); with `toned`, one that ends with a tone curve
    /// (`1.3·x^0.7`, three passes); with `gained`, one with a 4×3 gain map (1 to 6) after
    /// the mixture, shown through a `GTRC` curve (`min(1.8·sqrt(x), 0.97)`, 64 knots);
    /// with `chroma`, one with a 5×4 chroma map (0 to 1) after that; with `speckle`, one
    /// that first removes the Gaussians within a threshold of 0.1 (spec §7.2.5), high
    /// enough that these dim random colours take both of its branches.
    pub(super) fn enhanced(bytes: &[u8], stored: Stage2) -> Vec<u8> {
        let Stage2 {
            denoised,
            toned,
            gained,
            chroma,
            speckle,
        } = stored;
        use crate::enhance::{apply_record, colors_like, mixture::clamp_for, Enhancer};
        let file = format::ChunkedFile::parse(bytes, format::Limits::default()).expect("own file");
        let scene = file.file.records.to_scene();
        let mut rng = super::SplitMix64::new(77);
        let per = Enhancer::params_per_operator(3);
        let e = Enhancer {
            experts: 4,
            hidden: 3,
            clamp: clamp_for(scene.blend),
            map_width: 3,
            map_height: 2,
            map: (0..24).map(|_| rng.range(-2.0, 2.0)).collect(),
            params: (0..3 * per).map(|_| rng.range(-0.7, 0.7)).collect(),
        };
        let fit = format::FitSettings {
            weights: [50.0, 25.0, 32.5, 2.91, 0.44, 500.0, 0.01],
            exposure: 0.5,
            saturation_tau: 0.1,
            contrast_gamma: 1.05,
            iterations: 0,
            seed: 77,
        };
        let mut record = e.to_record(fit);
        // The map at the full MAP_BITS, as written before the logits were kept to a
        // step: the checked-in files of that time stay what they were.
        let map: Vec<[f32; 1]> = e.map.iter().map(|&x| [x]).collect();
        record.map = format::Attribute::fit(&map, [crate::enhance::mixture::MAP_BITS]);
        record.denoise = denoised.then_some(format::Denoise {
            range: 0.05,
            strength: 1.0,
            passes: 2,
        });
        record.tone = toned.then_some(format::Tone {
            exponent: 0.7,
            scale: 1.3,
            passes: 3,
        });
        record.gain = gained.then(|| {
            let gains: Vec<[f32; 1]> = (0..12).map(|_| [rng.range(1.0, 6.0)]).collect();
            format::GainMap {
                width: 4,
                height: 3,
                gains: format::Attribute::fit(&gains, [8]),
            }
        });
        record.chroma = chroma.then(|| {
            let scales: Vec<[f32; 1]> = (0..20).map(|_| [rng.range(0.0, 1.0)]).collect();
            format::ChromaMap {
                width: 5,
                height: 4,
                scales: format::Attribute::fit(&scales, [8]),
            }
        });
        record.speckle = speckle.then_some(format::Speckle { threshold: 0.1 });
        let curve = (gained || chroma).then(|| {
            crate::model::ToneCurve::sample(64, |x| (1.8 * x.sqrt()).min(0.97)).expect("64 knots")
        });
        let applied = apply_record(&record, &scene, &format::Limits::default())
            .expect("a small scene is within the limits");
        let colors = colors_like(&applied, &file.file.records.colors);
        file.with_colors(&colors, &record, curve.as_ref(), true, 19)
            .expect("in-memory rewrite")
    }

    /// Which of stage 2's stored steps [`enhanced`] writes besides the mixture.
    #[derive(Clone, Copy, Default)]
    pub(super) struct Stage2 {
        pub denoised: bool,
        pub toned: bool,
        pub gained: bool,
        pub chroma: bool,
        pub speckle: bool,
    }

    /// Records whose covariances are singular, vanishing or enormous, and Gaussians far
    /// outside the image: the renderer's clamps (spec §6.1–6.2) must keep them finite.
    fn degenerate(cov_param: CovParam) -> Records {
        let extremes: Vec<[f32; 3]> = match cov_param {
            CovParam::Cholesky => vec![
                [0.0, 0.0, 0.0],
                [0.0, 1.0, 0.0],
                [1e-30, 0.0, 1e-30],
                [3e38, -3e38, 3e38],
                [16.0, 16.0, 0.0],
                [0.05, 0.05, 0.0],
            ],
            CovParam::LogScaleRotation => vec![
                [-1e30, -1e30, 0.0],
                [1e30, 1e30, 1e30],
                [-30.0, 3.0, 0.7],
                [-3.0, -3.0, -3e38],
                [0.0, -40.0, 1.0],
                [-2.5, -9.0, 0.3],
            ],
        };
        let n = extremes.len() * 3;
        let positions = (0..n).map(|i| match i % 3 {
            0 => [0.5, 0.5],
            1 => [-1e6, 3e6],
            _ => [1.01, -0.01],
        });
        let g = GaussianSet {
            positions: positions.collect(),
            cov: (0..n).map(|i| extremes[i / 3]).collect(),
            colors: (0..n).map(|i| [1.0, -0.5, i as f32 * 0.1]).collect(),
            opacity: Some((0..n).map(|i| (i % 4) as f32 / 3.0).collect()),
        };
        let scene = Scene {
            weights: crate::model::WeightRule::PerPixel,
            tone: None,
            width: 24,
            height: 16,
            blend: Blend::Alpha,
            cov_param,
            gaussians: g,
        };
        Records::from_scene(
            &scene,
            BitDepths {
                position: 24,
                covariance: 24,
                angle: 24,
                angle_by_shape: false,
                color_by_footprint: false,
                color: 8,
                opacity: 8,
            },
        )
    }

    /// Split a file into its chunks (no validation: the input is our own valid file).
    fn chunks(bytes: &[u8]) -> Vec<(ChunkType, Vec<u8>)> {
        let mut out = Vec::new();
        let mut at = 8;
        while at < bytes.len() {
            let len = u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap()) as usize;
            let ty = ChunkType(bytes[at + 4..at + 8].try_into().unwrap());
            out.push((ty, bytes[at + 8..at + 8 + len].to_vec()));
            at += 12 + len;
        }
        out
    }

    /// Frame chunks into a file with correct CRCs.
    fn assemble(chunks: &[(ChunkType, Vec<u8>)]) -> Vec<u8> {
        let mut out = format::SIGNATURE.to_vec();
        for (ty, data) in chunks {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            out.extend_from_slice(&ty.0);
            out.extend_from_slice(data);
            out.extend_from_slice(&format::chunk_crc(*ty, data).to_be_bytes());
        }
        out
    }

    pub fn invalid() -> Vec<CorpusFile> {
        let base_records = random(20, SceneSpec::new(48, 32, 64, Blend::Alpha));
        let base = write(&base_records, "generator=gsi-synth");
        let parts = chunks(&base);
        let idx = |ty: ChunkType| {
            parts
                .iter()
                .position(|(t, _)| *t == ty)
                .expect("chunk present")
        };
        // Re-frame after editing one chunk's payload (CRC stays valid).
        let edit = |ty: ChunkType, f: &dyn Fn(&mut Vec<u8>)| {
            let mut p = parts.clone();
            f(&mut p[idx(ty)].1);
            assemble(&p)
        };
        let mut files: Vec<(ErrorKind, &str, Vec<u8>)> = Vec::new();
        use ErrorKind as K;
        files.push((K::Truncated, "empty-file", Vec::new()));
        {
            // A gENH shorter than its fixed part (spec §3): refused by length.
            let mut p = parts.clone();
            let end = p.len() - 1;
            p.insert(end, (ChunkType::ENHANCER, vec![1, 4, 3, 0]));
            files.push((K::BadChunkLength, "short-genh", assemble(&p)));
        }
        files.push((K::Truncated, "signature-only", format::SIGNATURE.to_vec()));
        // GTRC (spec §6.6), critical: every way its payload can break the spec refuses
        // the file.
        {
            let good = format::trc::to_payload(&three_curves());
            let with_trc = |payloads: &[Vec<u8>]| {
                let mut p = parts.clone();
                let end = p.len() - 1;
                for d in payloads {
                    p.insert(end, (ChunkType::TONE_CURVE, d.clone()));
                }
                assemble(&p)
            };
            let edited = |f: &dyn Fn(&mut Vec<u8>)| {
                let mut d = good.clone();
                f(&mut d);
                with_trc(&[d])
            };
            files.push((K::InvalidValue, "gtrc-2-curves", edited(&|d| d[0] = 2)));
            files.push((
                K::InvalidValue,
                "gtrc-reserved-not-0",
                edited(&|d| d[1] = 1),
            ));
            files.push((
                K::InvalidValue,
                "gtrc-1-knot",
                edited(&|d| d[2..4].copy_from_slice(&1u16.to_be_bytes())),
            ));
            files.push((
                K::BadChunkLength,
                "gtrc-length-mismatch",
                edited(&|d| d.truncate(d.len() - 2)),
            ));
            files.push((
                K::BadChunkLength,
                "gtrc-6-bytes",
                edited(&|d| d.truncate(6)),
            ));
            files.push((
                K::ChunkOrder,
                "duplicate-gtrc",
                with_trc(&[good.clone(), good.clone()]),
            ));
        }
        // GCRW and GCRT (spec §6.3.2), critical and empty: a payload, a second one, or
        // one of each refuses the file.
        {
            let with = |chunks: &[(ChunkType, &[u8])]| {
                let mut p = parts.clone();
                for (k, (ty, d)) in chunks.iter().enumerate() {
                    p.insert(1 + k, (*ty, d.to_vec()));
                }
                assemble(&p)
            };
            let (crw, crt) = (ChunkType::COLUMN_WEIGHTS, ChunkType::COLUMN_WEIGHTS_32);
            files.push((K::BadChunkLength, "gcrw-1-byte", with(&[(crw, &[0])])));
            files.push((
                K::ChunkOrder,
                "duplicate-gcrw",
                with(&[(crw, &[]), (crw, &[])]),
            ));
            files.push((K::BadChunkLength, "gcrt-1-byte", with(&[(crt, &[0])])));
            files.push((
                K::ChunkOrder,
                "duplicate-gcrt",
                with(&[(crt, &[]), (crt, &[])]),
            ));
            files.push((
                K::ChunkOrder,
                "gcrw-and-gcrt",
                with(&[(crw, &[]), (crt, &[])]),
            ));
            files.push((
                K::ChunkOrder,
                "gcrt-and-gcrw",
                with(&[(crt, &[]), (crw, &[])]),
            ));
        }
        files.push((
            K::Truncated,
            "cut-inside-gcol",
            base[..parts_offset(&parts, idx(ChunkType::COLORS)) + 20].to_vec(),
        ));
        files.push((K::Truncated, "no-gend", base[..base.len() - 12].to_vec()));
        let mut crlf = base.clone();
        crlf.splice(4..6, [b'\n']); // "\r\n" -> "\n", as a text-mode transfer would do
        files.push((K::BadSignature, "text-mode-mangled", crlf));
        files.push((K::BadSignature, "png-signature", {
            let mut b = base.clone();
            b[1..4].copy_from_slice(b"PNG");
            b
        }));
        files.push((K::CrcMismatch, "bad-crc-gcol", {
            let mut b = base.clone();
            let at = parts_offset(&parts, idx(ChunkType::COLORS)) + 8 + 40;
            b[at] ^= 0x10;
            b
        }));
        files.push((K::UnknownCriticalChunk, "unknown-critical-chunk", {
            let mut p = parts.clone();
            p.insert(p.len() - 1, (ChunkType(*b"GXYZ"), vec![0; 4]));
            assemble(&p)
        }));
        files.push((K::BadChunkType, "chunk-type-not-letters", {
            let mut p = parts.clone();
            p.insert(p.len() - 1, (ChunkType(*b"g1 ?"), vec![]));
            assemble(&p)
        }));
        files.push((K::ChunkOrder, "ghdr-not-first", {
            let mut p = parts.clone();
            p.swap(0, idx(ChunkType::POSITIONS));
            assemble(&p)
        }));
        files.push((K::ChunkOrder, "duplicate-gpos", {
            let mut p = parts.clone();
            p.insert(
                idx(ChunkType::POSITIONS),
                parts[idx(ChunkType::POSITIONS)].clone(),
            );
            assemble(&p)
        }));
        // Stage 2's chunks may each appear once (spec §2.4), though a renderer does not
        // parse them.
        for (ty, what) in [
            (ChunkType::ENHANCER, "duplicate-genh"),
            (ChunkType::ORIGINAL_COLORS, "duplicate-gorc"),
        ] {
            let mut p = chunks(&enhanced(&base, Stage2::default()));
            let at = p.iter().position(|(t, _)| *t == ty).expect("stage-2 chunk");
            p.insert(at, p[at].clone());
            files.push((K::ChunkOrder, what, assemble(&p)));
        }
        files.push((K::ChunkOrder, "duplicate-ghdr", {
            let mut p = parts.clone();
            p.insert(1, parts[0].clone());
            assemble(&p)
        }));
        files.push((K::MissingChunk, "no-gcol", {
            let mut p = parts.clone();
            p.remove(idx(ChunkType::COLORS));
            assemble(&p)
        }));
        files.push((
            K::BadChunkLength,
            "ghdr-17-bytes",
            edit(ChunkType::HEADER, &|d| {
                d.pop();
            }),
        ));
        files.push((K::BadChunkLength, "gend-with-payload", {
            let mut p = parts.clone();
            p.last_mut().unwrap().1 = vec![0];
            assemble(&p)
        }));
        files.push((
            K::BadChunkLength,
            "gpos-shorter-than-preamble",
            edit(ChunkType::POSITIONS, &|d| d.truncate(10)),
        ));
        files.push((
            K::UnsupportedVersion,
            "version-2",
            edit(ChunkType::HEADER, &|d| d[0] = 2),
        ));
        files.push((
            K::InvalidValue,
            "zero-width",
            edit(ChunkType::HEADER, &|d| d[2..6].fill(0)),
        ));
        files.push((
            K::InvalidValue,
            "zero-height",
            edit(ChunkType::HEADER, &|d| d[6..10].fill(0)),
        ));
        files.push((
            K::InvalidValue,
            "blend-mode-9",
            edit(ChunkType::HEADER, &|d| d[14] = 9),
        ));
        files.push((
            K::InvalidValue,
            "cov-param-5",
            edit(ChunkType::HEADER, &|d| d[15] = 5),
        ));
        files.push((
            K::LimitExceeded,
            "count-4-billion",
            edit(ChunkType::HEADER, &|d| d[10..14].fill(0xff)),
        ));
        files.push((
            K::LimitExceeded,
            "width-4-billion",
            edit(ChunkType::HEADER, &|d| d[2..6].fill(0xff)),
        ));
        files.push((K::LimitExceeded, "chunk-length-4-gib", {
            let mut b = base[..parts_offset(&parts, idx(ChunkType::POSITIONS))].to_vec();
            b.extend_from_slice(&0xFFFF_FF00u32.to_be_bytes());
            b.extend_from_slice(b"GPOS");
            b.extend_from_slice(&[0; 64]);
            b
        }));
        files.push((
            K::InvalidValue,
            "count-mismatch-packed-length",
            edit(ChunkType::HEADER, &|d| d[13] ^= 1),
        ));
        files.push((
            K::InvalidValue,
            "quantizer-25-bits",
            edit(ChunkType::COLORS, &|d| d[1] = 25),
        ));
        files.push((
            K::InvalidValue,
            "quantizer-nan-range",
            edit(ChunkType::COLORS, &|d| {
                d[2..6].copy_from_slice(&f32::NAN.to_be_bytes())
            }),
        ));
        files.push((
            K::InvalidValue,
            "quantizer-infinite-range",
            edit(ChunkType::POSITIONS, &|d| {
                d[6..10].copy_from_slice(&f32::INFINITY.to_be_bytes())
            }),
        ));
        files.push((
            K::InvalidValue,
            "quantizer-reversed-range",
            edit(ChunkType::COVARIANCE, &|d| {
                let (lo, hi) = (d[2..6].to_vec(), d[6..10].to_vec());
                d[2..6].copy_from_slice(&hi);
                d[6..10].copy_from_slice(&lo);
            }),
        ));
        files.push((
            K::InvalidValue,
            "wrong-component-count",
            edit(ChunkType::COLORS, &|d| d[0] = 4),
        ));
        files.push((
            K::InvalidValue,
            "compression-method-7",
            edit(ChunkType::COLORS, &|d| d[28] = 7),
        ));
        files.push((
            K::Decompression,
            "zstd-garbage",
            edit(ChunkType::COVARIANCE, &|d| {
                d[28] = 1;
                for b in &mut d[33..] {
                    *b = 0xA5;
                }
            }),
        ));
        files.push((
            K::Decompression,
            "zstd-bomb",
            edit(ChunkType::COLORS, &|d| {
                // A valid zstd frame of 64 KiB of zeros where ~200 bytes are declared.
                d[28] = 1;
                d.truncate(33);
                d.extend_from_slice(&zstd::bulk::compress(&vec![0u8; 1 << 16], 3).unwrap());
            }),
        ));
        files.push((
            K::InvalidValue,
            "gcrm-nan-psnr",
            edit(ChunkType::COMPRESSION_META, &|d| {
                d[9] = 1;
                d[22..26].copy_from_slice(&f32::NAN.to_be_bytes());
            }),
        ));
        files.push((
            K::InvalidValue,
            "gcrm-settings-not-utf8",
            edit(ChunkType::COMPRESSION_META, &|d| {
                d.extend_from_slice(&[0xff, 0xfe])
            }),
        ));
        coded_invalid(&base_records, &mut files);
        coded_raw_invalid(&base_records, &mut files);
        coded_shaped_invalid(&mut files);
        coded_footprint_invalid(&mut files);
        files
            .into_iter()
            .map(|(kind, what, bytes)| CorpusFile {
                name: format!("{}--{what}.gsi", kind.name()),
                bytes,
                expect: Some(kind),
            })
            .collect()
    }

    /// Malformed payloads of method 2 (§5.4), each in a file that is otherwise `records`
    /// coded and valid.
    fn coded_invalid(records: &Records, files: &mut Vec<(ErrorKind, &'static str, Vec<u8>)>) {
        use ErrorKind as K;
        let n = records.header.count as usize;
        let base = coded(records, [&[3, 3], &[0, 1, 2], &[0, 1, 1], &[2]], 2);
        let parts = chunks(&base);
        let at = |ty: ChunkType| parts.iter().position(|(t, _)| *t == ty).expect("chunk");
        let with = |ty: ChunkType, payload: Vec<u8>| {
            let mut p = parts.clone();
            p[at(ty)].1 = payload;
            assemble(&p)
        };
        let edit = |ty: ChunkType, f: &dyn Fn(&mut Vec<u8>)| {
            let mut d = parts[at(ty)].1.clone();
            f(&mut d);
            with(ty, d)
        };
        // A 3-component payload: packed_len at 29, modes at 33, the stream from 36.
        files.push((K::Decompression, "coded-stream-truncated", {
            edit(ChunkType::COLORS, &|d| {
                d.pop();
            })
        }));
        files.push((K::Decompression, "coded-stream-bytes-left", {
            edit(ChunkType::COLORS, &|d| d.push(0))
        }));
        files.push((K::Decompression, "coded-stream-starts-ffffffff", {
            edit(ChunkType::COLORS, &|d| {
                d[36..40].copy_from_slice(&[0xFF; 4])
            })
        }));
        files.push((K::InvalidValue, "coded-mode-9", {
            edit(ChunkType::COLORS, &|d| d[34] = 9)
        }));
        files.push((K::InvalidValue, "coded-across-on-first-component", {
            edit(ChunkType::COVARIANCE, &|d| d[33] = 1)
        }));
        files.push((K::InvalidValue, "coded-morton-on-three-components", {
            edit(ChunkType::COVARIANCE, &|d| {
                d[33..36].copy_from_slice(&[3, 3, 3])
            })
        }));
        files.push((K::InvalidValue, "coded-packed-length-mismatch", {
            edit(ChunkType::COLORS, &|d| d[32] ^= 1)
        }));
        // Streams coded for 4-bit codes, declared 3 bits wide: what they hold leaves the
        // declared range. `codes` is component 0 (or component 1 of a pair).
        let narrowed = |k: usize, codes: &dyn Fn(usize) -> u32, modes: &[u8]| {
            let comps = modes.len();
            let q = format::Quantizer {
                bits: 4,
                min: 0.0,
                max: 1.0,
            };
            let mut all = vec![0u32; comps * n];
            for i in 0..n {
                all[k * n + i] = codes(i);
            }
            let a = format::Attribute {
                quantizers: vec![q; comps],
                codes: all,
                shape: None,
                footprint: None,
            };
            let mut d = a.to_coded_payload(modes, 2, None).expect("valid modes");
            d[1 + 9 * k] = 3;
            let packed = (n * (4 * comps - 1)).div_ceil(8) as u32;
            let at = 2 + 9 * comps;
            d[at..at + 4].copy_from_slice(&packed.to_be_bytes());
            d
        };
        files.push((K::Decompression, "coded-residual-out-of-range", {
            with(
                ChunkType::COLORS,
                narrowed(0, &|i| if i == 1 { 11 } else { 5 }, &[2, 0, 0]),
            )
        }));
        files.push((K::Decompression, "coded-magnitude-too-wide", {
            with(ChunkType::COLORS, narrowed(0, &|_| 15, &[2, 0, 0]))
        }));
        files.push((K::Decompression, "coded-morton-code-out-of-range", {
            with(
                ChunkType::POSITIONS,
                narrowed(1, &|i| if i == 2 { 12 } else { 3 }, &[3, 3]),
            )
        }));
        // Mode 4 is method 3's alone.
        files.push((K::InvalidValue, "coded-raw-mode-in-method-2", {
            edit(ChunkType::COLORS, &|d| d[35] = 4)
        }));
    }

    /// Malformed payloads of method 3 (§5.4.4), each in a file that is otherwise `records`
    /// coded and valid. The `GCOV` payload (three components) has its method at 28, its
    /// modes at 33, the length of its raw bits at 36, its stream from 40; its last
    /// component is raw, so its raw bits end in padding.
    fn coded_raw_invalid(records: &Records, files: &mut Vec<(ErrorKind, &'static str, Vec<u8>)>) {
        use ErrorKind as K;
        let base = coded(records, [&[3, 3], &[0, 1, 4], &[0, 1, 1], &[4]], 3);
        let parts = chunks(&base);
        let at = |ty: ChunkType| parts.iter().position(|(t, _)| *t == ty).expect("chunk");
        let edit = |ty: ChunkType, f: &dyn Fn(&mut Vec<u8>)| {
            let mut p = parts.clone();
            f(&mut p[at(ty)].1);
            assemble(&p)
        };
        let raw_len = |d: &[u8]| u32::from_be_bytes(d[36..40].try_into().expect("4 bytes"));
        let set_raw_len = |d: &mut Vec<u8>, n: u32| d[36..40].copy_from_slice(&n.to_be_bytes());
        assert_eq!(parts[at(ChunkType::COVARIANCE)].1[28], 3, "method 3");
        files.push((K::Decompression, "coded3-raw-length-past-payload", {
            edit(ChunkType::COVARIANCE, &|d| {
                let n = (d.len() - 40 + 1) as u32;
                set_raw_len(d, n)
            })
        }));
        files.push((K::Decompression, "coded3-raw-bits-cut", {
            edit(ChunkType::COVARIANCE, &|d| {
                let n = raw_len(d);
                d.pop();
                set_raw_len(d, n - 1);
            })
        }));
        files.push((K::Decompression, "coded3-raw-bytes-left", {
            edit(ChunkType::COVARIANCE, &|d| {
                let n = raw_len(d);
                d.push(0);
                set_raw_len(d, n + 1);
            })
        }));
        files.push((K::Decompression, "coded3-raw-padding-ones", {
            edit(ChunkType::COVARIANCE, &|d| {
                *d.last_mut().expect("raw bytes") |= 1
            })
        }));
        files.push((K::Decompression, "coded3-stream-bytes-left", {
            // A byte put between the stream and the raw bits, which stay as they were.
            edit(ChunkType::COVARIANCE, &|d| {
                let at = d.len() - raw_len(d) as usize;
                d.insert(at, 0);
            })
        }));
        files.push((K::InvalidValue, "coded3-mode-5", {
            edit(ChunkType::COVARIANCE, &|d| d[35] = 5)
        }));
    }

    /// The edges of §5.4.5's rule, which fitted files rarely reach: 64 Gaussians with every
    /// pair of 3-bit log-scale codes over [−7, 7] (values −7 + 2q, so `e` from 0 to 14 and
    /// `p0 + p1` from −14 to 14), a 10-bit angle and o = −2^−20. A sum just below an integer
    /// (`floor`, not truncation: `e` = 14 at `p0 + p1` = 0 keeps 9 bits, not 10), round
    /// Gaussians whose `floor(...)` is 10 (they keep nothing, not 3), `keep` from 0 to 10.
    fn shaped_edges() -> Records {
        use format::angle::{full_code, shape_bits};
        let mut r = random(20, SceneSpec::new(64, 48, 64, Blend::Sum));
        let scale = format::Quantizer {
            bits: 3,
            min: -7.0,
            max: 7.0,
        };
        let angle = format::Quantizer {
            bits: 10,
            min: -std::f32::consts::FRAC_PI_4,
            max: std::f32::consts::FRAC_PI_4,
        };
        let offset = -1.0 / (1u32 << 20) as f32;
        let n = 64;
        let mut codes: Vec<u32> = (0..n).map(|i| i / 8).chain((0..n).map(|i| i % 8)).collect();
        for i in 0..n as usize {
            let (p0, p1) = (scale.dequantize(codes[i]), scale.dequantize(codes[64 + i]));
            let keep = shape_bits(p0, p1, offset, angle.bits);
            let coarse = (i as u32 * 37) & ((1u32 << keep) - 1);
            codes.push(full_code(coarse, keep, angle.bits));
        }
        r.header.cov_param = CovParam::LogScaleRotation;
        r.covariance = format::Attribute {
            quantizers: vec![scale, scale, angle],
            codes,
            shape: Some(offset),
            footprint: None,
        };
        r
    }

    /// Malformed payloads of method 4 (§5.4.5), each in a file that is otherwise shaped and
    /// valid. The `GCOV` payload has its modes at 33, the shape offset at 36, the length
    /// of its raw bits at 40, its stream from 44.
    fn coded_shaped_invalid(files: &mut Vec<(ErrorKind, &'static str, Vec<u8>)>) {
        use ErrorKind as K;
        let records = shaped(19, Blend::Sum, 300);
        let base = coded(&records, [&[3, 3], &[0, 1, 5], &[0, 1, 1], &[]], 4);
        let parts = chunks(&base);
        let at = |ty: ChunkType| parts.iter().position(|(t, _)| *t == ty).expect("chunk");
        let edit = |f: &dyn Fn(&mut Vec<u8>)| {
            let mut p = parts.clone();
            f(&mut p[at(ChunkType::COVARIANCE)].1);
            assemble(&p)
        };
        let raw_len = |d: &[u8]| u32::from_be_bytes(d[40..44].try_into().expect("4 bytes"));
        assert_eq!(parts[at(ChunkType::COVARIANCE)].1[28], 4, "method 4");
        files.push((K::InvalidValue, "coded4-shape-offset-nan", {
            edit(&|d| d[36..40].copy_from_slice(&f32::NAN.to_be_bytes()))
        }));
        files.push((K::InvalidValue, "coded4-shaped-first-component", {
            edit(&|d| d[33] = 5)
        }));
        files.push((K::InvalidValue, "coded4-mode-6", edit(&|d| d[35] = 6)));
        files.push((K::Decompression, "coded4-shape-offset-moved", {
            // Four bits more for every angle: the raw bits end before the last code.
            edit(&|d| {
                let o = f32::from_be_bytes(d[36..40].try_into().expect("4 bytes"));
                d[36..40].copy_from_slice(&(o + 4.0).to_be_bytes())
            })
        }));
        files.push((K::Decompression, "coded4-shaped-raw-bits-cut", {
            edit(&|d| {
                let n = raw_len(d);
                d.pop();
                d[40..44].copy_from_slice(&(n - 1).to_be_bytes());
            })
        }));
    }

    /// Malformed payloads of method 5 (§5.4.6), and method 5 where it is not allowed, each
    /// in a file that is otherwise valid. The `GCOL` payload has its base at 33, its modes
    /// at 34, the length of its raw bits at 37, its stream from 41.
    fn coded_footprint_invalid(files: &mut Vec<(ErrorKind, &'static str, Vec<u8>)>) {
        use ErrorKind as K;
        const M3: u8 = format::METHOD_CODED_RAW;
        const M5: u8 = format::METHOD_FOOTPRINT;
        let records = by_footprint(24, Blend::Sum, 300);
        let base = coded_each(
            &records,
            [(&[3, 3], M3), (&[0, 1, 5], 4), (&[0, 1, 1], M5), (&[], M3)],
        );
        let parts = chunks(&base);
        let at = |ty: ChunkType| parts.iter().position(|(t, _)| *t == ty).expect("chunk");
        let edit_in = |ty: ChunkType, f: &dyn Fn(&mut Vec<u8>)| {
            let mut p = parts.clone();
            f(&mut p[at(ty)].1);
            assemble(&p)
        };
        let edit = |f: &dyn Fn(&mut Vec<u8>)| edit_in(ChunkType::COLORS, f);
        let raw_len = |d: &[u8]| u32::from_be_bytes(d[37..41].try_into().expect("4 bytes"));
        assert_eq!(parts[at(ChunkType::COLORS)].1[28], M5, "method 5");
        files.push((K::InvalidValue, "coded5-mode-3", edit(&|d| d[35] = 3)));
        files.push((K::InvalidValue, "coded5-mode-5", edit(&|d| d[36] = 5)));
        files.push((
            K::Decompression,
            "coded5-no-base",
            edit(&|d| d.truncate(33)),
        ));
        files.push((K::Decompression, "coded5-raw-bits-cut", {
            edit(&|d| {
                let n = raw_len(d);
                d.pop();
                d[37..41].copy_from_slice(&(n - 1).to_be_bytes());
            })
        }));
        // Method 5 in `GCOV` (whose own log-scales it would need) and in `GPOS`.
        files.push((K::InvalidValue, "coded5-in-gcov", {
            edit_in(ChunkType::COVARIANCE, &|d| d[28] = M5)
        }));
        files.push((K::InvalidValue, "coded5-in-gpos", {
            edit_in(ChunkType::POSITIONS, &|d| d[19] = M5)
        }));
        // `GCOL` before the `GCOV` it is read with (§2.4).
        files.push((K::ChunkOrder, "coded5-colours-before-covariance", {
            let mut p = parts.clone();
            let (cov, col) = (at(ChunkType::COVARIANCE), at(ChunkType::COLORS));
            p.swap(cov, col);
            assemble(&p)
        }));
        // A `cholesky` file: its covariance holds no log-scales.
        files.push((K::InvalidValue, "coded5-cholesky", {
            let mut p = parts.clone();
            let h = at(ChunkType::HEADER);
            p[h].1[15] = 0;
            assemble(&p)
        }));
    }

    /// Byte offset of chunk `i` in the file `chunks` came from.
    fn parts_offset(parts: &[(ChunkType, Vec<u8>)], i: usize) -> usize {
        8 + parts[..i].iter().map(|(_, d)| 12 + d.len()).sum::<usize>()
    }
}
