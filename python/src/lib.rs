//! `gsi._gsi`: the extension module under the Python package `gsi` (`python/gsi/`).
//!
//! It speaks bytes: images, pixels and Gaussian attributes cross as contiguous sample
//! buffers with their shape beside them, and `gsi/__init__.py` turns them into numpy arrays
//! and back. Every decision is the library's (how samples become the encoder's input, the
//! options' defaults and checks, the low-light decision, the output size, what `info`
//! reports), so that the same image and options give the bytes `gsi encode` writes and the
//! same file gives the pixels `gsi decode` writes. The GIL is released while the library
//! works; a progress callback takes it back for each report.

use gsi::enhance as stage2;
use gsi::enhance::fit::EnhanceOptions;
use gsi::fit::{self, Budget, EncodeOptions};
use gsi::format::{ChunkedFile, Limits};
use gsi::model::{Blend, CovParam, GaussianSet, Scene, ToneCurve, WeightRule};
use gsi::{PixelFormat, Reader};
use pyo3::create_exception;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyByteArray, PyBytes, PyDict};

create_exception!(
    _gsi,
    Error,
    PyValueError,
    "A file, an image or an option gsi refuses; the message is the command-line tool's."
);

fn fail(e: impl std::fmt::Display) -> PyErr {
    Error::new_err(e.to_string())
}

/// Where a stage runs, by the names `--device` takes.
fn open_device(device: &str) -> Result<Option<gsi::gpu::Gpu>, String> {
    match device {
        "cpu" => Ok(None),
        "gpu" => gsi::gpu::Gpu::new()
            .map(Some)
            .map_err(|e| format!("device=\"gpu\": {e}")),
        // A hardware adapter, or the CPU without a word, as `--device auto` does.
        "auto" => Ok(gsi::gpu::Gpu::new_hardware().ok()),
        other => Err(format!(
            "device {other:?}: expected \"cpu\", \"gpu\" or \"auto\""
        )),
    }
}

/// A Python callable given progress reports as dicts, with the GIL taken back for each.
/// The first exception it raises (Ctrl-C included) stops the reports and is raised when
/// the call returns: the library's stages have no way to stop half-way.
struct Reporter<'a> {
    callback: Option<&'a Py<PyAny>>,
    raised: Option<PyErr>,
}

impl<'a> Reporter<'a> {
    fn new(callback: Option<&'a Py<PyAny>>) -> Self {
        Reporter {
            callback,
            raised: None,
        }
    }

    fn report(&mut self, fill: impl FnOnce(&Bound<'_, PyDict>) -> PyResult<()>) {
        let Some(cb) = self.callback else { return };
        if self.raised.is_some() {
            return;
        }
        let result = Python::attach(|py| -> PyResult<()> {
            py.check_signals()?;
            let d = PyDict::new(py);
            fill(&d)?;
            cb.call1(py, (d,))?;
            Ok(())
        });
        self.raised = result.err();
    }

    fn finish<T>(self, value: T) -> PyResult<T> {
        match self.raised {
            Some(e) => Err(e),
            None => Ok(value),
        }
    }
}

/// The encoder's input from samples as the front ends take them: 8 (`u8`), 16 (`u16`)
/// or 32 (`f32`, each in `[0, 1]`) bits, native byte order, `height · width · 3` of them.
fn target(samples: &[u8], bits: u8, width: u32, height: u32) -> Result<fit::Target, String> {
    let bad = || {
        format!(
            "{} bytes of {bits}-bit samples are not a {width}x{height} RGB image",
            samples.len()
        )
    };
    match bits {
        8 => fit::Target::from_rgb8(width, height, samples).ok_or_else(bad),
        16 => {
            let v: Vec<u16> = samples
                .chunks_exact(2)
                .map(|c| u16::from_ne_bytes([c[0], c[1]]))
                .collect();
            fit::Target::from_rgb16(width, height, &v).ok_or_else(bad)
        }
        32 => {
            let data: Vec<f32> = f32s(samples).collect();
            if let Some(x) = data.iter().find(|x| !(0.0..=1.0).contains(*x)) {
                return Err(format!("float samples must lie in [0, 1]; found {x}"));
            }
            let n = (width as usize) * (height as usize) * 3;
            if data.len() != n || samples.len() % 4 != 0 {
                return Err(bad());
            }
            Ok(fit::Target {
                width,
                height,
                data,
            })
        }
        _ => Err(format!("{bits}-bit samples: expected 8, 16 or 32")),
    }
}

fn blend_named(name: &str) -> Result<Blend, String> {
    [Blend::Sum, Blend::Alpha]
        .into_iter()
        .find(|b| b.name() == name)
        .ok_or_else(|| format!("blend {name:?}: expected \"sum\" or \"alpha\""))
}

fn weights_named(name: &str) -> Result<WeightRule, String> {
    [
        WeightRule::Columns32,
        WeightRule::Columns,
        WeightRule::PerPixel,
    ]
    .into_iter()
    .find(|w| w.name() == name)
    .ok_or_else(|| {
        format!("weights {name:?}: expected \"columns-32\", \"columns\" or \"per-pixel\"")
    })
}

fn cov_param_named(name: &str) -> Result<CovParam, String> {
    [CovParam::Cholesky, CovParam::LogScaleRotation]
        .into_iter()
        .find(|c| c.name() == name)
        .ok_or_else(|| {
            format!("cov_param {name:?}: expected \"cholesky\" or \"log-scale-rotation\"")
        })
}

/// One of `bpp`, `gaussians` and `target_psnr`, checked as `gsi encode` checks them
/// (1 bpp when none is given).
fn budget(
    bpp: Option<f32>,
    gaussians: Option<i64>,
    target_psnr: Option<f32>,
) -> Result<Budget, String> {
    match (bpp, gaussians, target_psnr) {
        (None, None, None) => Ok(Budget::Bpp(1.0)),
        (Some(b), None, None) if b.is_finite() && b > 0.0 => Ok(Budget::Bpp(b)),
        (Some(b), None, None) => Err(format!("bpp {b} must be positive")),
        (None, Some(n), None) if n >= 1 => {
            Ok(Budget::Gaussians(usize::try_from(n).unwrap_or(usize::MAX)))
        }
        (None, Some(n), None) => Err(format!("gaussians {n} must be at least 1")),
        (None, None, Some(p)) if p.is_finite() && p > 0.0 => Ok(Budget::TargetPsnr(p)),
        (None, None, Some(p)) => Err(format!("target_psnr {p} must be positive")),
        _ => Err("give at most one of bpp, gaussians and target_psnr".into()),
    }
}

/// Fit Gaussians to `samples` and return the file's bytes.
#[pyfunction]
#[pyo3(signature = (samples, bits, width, height, *, bpp=None, gaussians=None, target_psnr=None, effort=None, blend="sum", seed=0, device="cpu", progress=None))]
#[allow(clippy::too_many_arguments)]
fn encode<'py>(
    py: Python<'py>,
    samples: &[u8],
    bits: u8,
    width: u32,
    height: u32,
    bpp: Option<f32>,
    gaussians: Option<i64>,
    target_psnr: Option<f32>,
    effort: Option<u8>,
    blend: &str,
    seed: u64,
    device: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyBytes>> {
    let mut opts = EncodeOptions {
        budget: budget(bpp, gaussians, target_psnr).map_err(fail)?,
        blend: blend_named(blend).map_err(fail)?,
        seed,
        ..EncodeOptions::default()
    };
    // Without a level the options stay the default effort's.
    if let Some(level) = effort {
        fit::Effort::new(level)
            .ok_or_else(|| fail(format!("effort {level} is not in 1..=9")))?
            .apply(&mut opts);
    }
    let target = target(samples, bits, width, height).map_err(fail)?;
    let mut reporter = Reporter::new(progress.as_ref());
    let bytes = py.detach(|| -> Result<Vec<u8>, String> {
        let gpu = open_device(device)?;
        let on = gpu.as_ref().map_or(gsi::Device::Cpu, gsi::Device::Gpu);
        let mut report = |p: &fit::Progress| {
            reporter.report(|d| {
                d.set_item("stage", "encode")?;
                d.set_item("work", p.work)?;
                d.set_item("iteration", p.iteration)?;
                d.set_item("total", p.total)?;
                d.set_item("gaussians", p.gaussians)?;
                d.set_item("psnr", p.psnr)
            })
        };
        fit::encode(&target, &opts, on, &mut report)
            .map(|e| e.bytes)
            .map_err(|e| e.to_string())
    });
    let bytes = reporter.finish(bytes)?.map_err(fail)?;
    Ok(PyBytes::new(py, &bytes))
}

/// Render a file at `width × height` (a missing side follows the aspect ratio): the
/// pixels (8-bit RGB, or `f32` RGB in native byte order) and the size.
#[pyfunction]
#[pyo3(signature = (data, width=None, height=None, float=false))]
fn decode<'py>(
    py: Python<'py>,
    data: &[u8],
    width: Option<u32>,
    height: Option<u32>,
    float: bool,
) -> PyResult<(Bound<'py, PyByteArray>, u32, u32)> {
    let (pixels, w, h) = py
        .detach(|| -> gsi::format::Result<_> {
            let mut reader = Reader::new(data)?;
            let header = reader.header();
            let (w, h) = gsi::scaled_size((header.width, header.height), width, height)?;
            reader.set_output_size(w, h)?;
            reader.set_pixel_format(if float {
                PixelFormat::RgbF32
            } else {
                PixelFormat::Rgb8
            });
            let mut buf = vec![0u8; reader.output_buffer_size()?];
            reader.read_image(&mut buf)?;
            Ok((buf, w, h))
        })
        .map_err(fail)?;
    Ok((PyByteArray::new(py, &pixels), w, h))
}

/// Stage 2 on a file: `(bytes, None)` when enhanced (or an enhancer applied from
/// `apply_from`), `(data, why)` when the image is left as it is.
#[pyfunction]
#[pyo3(signature = (data, *, iterations=None, exposure=None, experts=None, learning_rate=None, weights=None, tone=None, local=true, shadow_colour=false, speckle=false, denoise=false, force=false, discard_original=false, apply_from=None, seed=0, device="cpu", progress=None))]
#[allow(clippy::too_many_arguments)]
fn enhance<'py>(
    py: Python<'py>,
    data: &[u8],
    iterations: Option<u32>,
    exposure: Option<Bound<'py, PyAny>>,
    experts: Option<usize>,
    learning_rate: Option<f32>,
    weights: Option<Vec<f32>>,
    tone: Option<f32>,
    local: bool,
    shadow_colour: bool,
    speckle: bool,
    denoise: bool,
    force: bool,
    discard_original: bool,
    apply_from: Option<&[u8]>,
    seed: u64,
    device: &str,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Bound<'py, PyBytes>, Option<String>)> {
    let limits = Limits::default();
    let keep = !discard_original;
    let file = ChunkedFile::parse(data, limits).map_err(fail)?;
    if let Some(source) = apply_from {
        let out = py
            .detach(|| {
                let source = ChunkedFile::parse(source, limits)?;
                stage2::apply_from(&file, &source, keep, &limits)
            })
            .map_err(fail)?;
        return Ok((PyBytes::new(py, &out), None));
    }
    let defaults = EnhanceOptions::default();
    let exposure = match exposure {
        None => gsi::enhance::exposure::Exposure::default(),
        Some(e) if e.extract::<String>().is_ok_and(|s| s == "auto") => {
            gsi::enhance::exposure::Exposure::Metered
        }
        Some(e) => gsi::enhance::exposure::Exposure::Exactly(
            e.extract::<f32>()
                .map_err(|_| fail(format!("exposure {e}: a mean luma in (0, 1), or \"auto\"")))?,
        ),
    };
    let weights = match weights {
        None => defaults.weights,
        Some(w) => {
            let w: [f32; 7] = w.try_into().map_err(|w: Vec<f32>| {
                fail(format!(
                    "weights: seven numbers are needed, not {}",
                    w.len()
                ))
            })?;
            gsi::enhance::loss::LossWeights::from_array(w)
        }
    };
    let curve = defaults.curve.map(|c| gsi::enhance::curve::CurveOptions {
        exponent: tone.unwrap_or(c.exponent),
        local,
        chroma: !shadow_colour,
    });
    let opts = EnhanceOptions {
        iterations: iterations.unwrap_or(defaults.iterations),
        experts: experts.unwrap_or(defaults.experts),
        learning_rate: learning_rate.unwrap_or(defaults.learning_rate),
        weights,
        exposure,
        denoise: denoise.then(gsi::enhance::denoise::DenoiseOptions::default),
        speckle: !speckle,
        curve,
        force,
        seed,
        ..defaults
    };
    let mut reporter = Reporter::new(progress.as_ref());
    let outcome = py.detach(|| -> Result<stage2::Outcome, String> {
        let gpu = open_device(device)?;
        let on = gpu.as_ref().map_or(gsi::Device::Cpu, gsi::Device::Gpu);
        let total = opts.iterations.max(1);
        let mut report = |p: &stage2::fit::Progress| {
            reporter.report(|d| {
                d.set_item("stage", "enhance")?;
                d.set_item("work", f64::from(p.iteration) / f64::from(total))?;
                d.set_item("iteration", p.iteration)?;
                d.set_item("total", p.iterations)?;
                d.set_item("loss", p.terms.total)
            })
        };
        stage2::enhance(&file, &opts, keep, &limits, on, &mut report).map_err(|e| e.to_string())
    });
    match reporter.finish(outcome)?.map_err(fail)? {
        stage2::Outcome::Enhanced(done) => Ok((PyBytes::new(py, &done.bytes), None)),
        stage2::Outcome::NotLowLight(a) => Ok((
            PyBytes::new(py, data),
            Some(format!(
                "{a}: {}, left unchanged (force=True enhances it anyway)",
                a.verdict()
            )),
        )),
        stage2::Outcome::OriginalDiscarded => Err(fail(
            "already enhanced and its original colours were discarded; force=True enhances the enhanced colours again",
        )),
    }
}

/// The file as it was before stage 2, byte for byte.
#[pyfunction]
fn revert<'py>(py: Python<'py>, data: &[u8]) -> PyResult<Bound<'py, PyBytes>> {
    let out = py
        .detach(|| ChunkedFile::parse(data, Limits::default())?.revert())
        .map_err(fail)?;
    Ok(PyBytes::new(py, &out))
}

/// What `gsi info --json` prints for the file, as a JSON string.
#[pyfunction]
fn info(py: Python<'_>, data: &[u8]) -> PyResult<String> {
    py.detach(|| {
        gsi::format::read_file(data, Limits::default()).map(|f| gsi::info::to_json(&f).to_string())
    })
    .map_err(fail)
}

/// Values as Python bytes, native byte order.
fn ne_bytes<'py, const N: usize>(
    py: Python<'py>,
    values: impl Iterator<Item = [u8; N]>,
) -> Bound<'py, PyBytes> {
    PyBytes::new(py, &values.flatten().collect::<Vec<u8>>())
}

fn f32_bytes<'py, const K: usize>(py: Python<'py>, rows: &[[f32; K]]) -> Bound<'py, PyBytes> {
    ne_bytes(py, rows.iter().flatten().map(|x| x.to_ne_bytes()))
}

/// The Gaussians of a file as the renderer sees them: a dict of sizes, names and
/// attribute buffers (`f32` or `u16`, native byte order), with each covariance also as
/// `[σ_uu, σ_uv, σ_vv]` in normalized units.
#[pyfunction]
fn read<'py>(py: Python<'py>, data: &[u8]) -> PyResult<Bound<'py, PyDict>> {
    let scene = py
        .detach(|| gsi::format::read_file(data, Limits::default()).map(|f| f.records.to_scene()))
        .map_err(fail)?;
    let g = &scene.gaussians;
    let matrices: Vec<[f32; 3]> = g
        .cov
        .iter()
        .map(|&p| scene.cov_param.covariance(p))
        .collect();
    let d = PyDict::new(py);
    d.set_item("width", scene.width)?;
    d.set_item("height", scene.height)?;
    d.set_item("blend", scene.blend.name())?;
    d.set_item("cov_param", scene.cov_param.name())?;
    d.set_item("weights", scene.weights.name())?;
    d.set_item("positions", f32_bytes(py, &g.positions))?;
    d.set_item("cov", f32_bytes(py, &g.cov))?;
    d.set_item("covariance", f32_bytes(py, &matrices))?;
    d.set_item("colors", f32_bytes(py, &g.colors))?;
    d.set_item(
        "opacity",
        g.opacity
            .as_ref()
            .map(|o| ne_bytes(py, o.iter().map(|x| x.to_ne_bytes()))),
    )?;
    d.set_item(
        "tone",
        scene.tone.as_ref().map(|t| {
            let values = ne_bytes(py, t.values().iter().map(|x| x.to_ne_bytes()));
            (t.curves(), values)
        }),
    )?;
    Ok(d)
}

fn f32s(bytes: &[u8]) -> impl Iterator<Item = f32> + '_ {
    bytes
        .chunks_exact(4)
        .map(|c| f32::from_ne_bytes([c[0], c[1], c[2], c[3]]))
}

fn rows<const K: usize>(name: &str, bytes: &[u8], n: usize) -> Result<Vec<[f32; K]>, String> {
    if bytes.len() != n * K * 4 {
        return Err(format!(
            "{name}: {} bytes for {n} Gaussians of {K} floats",
            bytes.len()
        ));
    }
    let v: Vec<f32> = f32s(bytes).collect();
    if let Some(x) = v.iter().find(|x| !x.is_finite()) {
        return Err(format!("{name} holds {x}; every value must be finite"));
    }
    Ok(v.chunks_exact(K)
        .map(|c| std::array::from_fn(|k| c[k]))
        .collect())
}

/// A scene from its parts (as [`read`] gives them, perhaps edited), rendered as [`decode`]
/// renders a file, at the size it sizes one: the pixels and their size.
#[pyfunction]
#[pyo3(signature = (width, height, blend, cov_param, weights, positions, cov, colors, opacity, tone, out_width=None, out_height=None, float=false))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    width: u32,
    height: u32,
    blend: &str,
    cov_param: &str,
    weights: &str,
    positions: &[u8],
    cov: &[u8],
    colors: &[u8],
    opacity: Option<&[u8]>,
    tone: Option<(u8, Vec<u16>)>,
    out_width: Option<u32>,
    out_height: Option<u32>,
    float: bool,
) -> PyResult<(Bound<'py, PyByteArray>, u32, u32)> {
    let scene = (|| -> Result<Scene, String> {
        let n = positions.len() / 8;
        let opacity = match opacity {
            None => None,
            Some(o) => Some(
                rows::<1>("opacity", o, n)?
                    .into_iter()
                    .map(|[a]| a)
                    .collect(),
            ),
        };
        Ok(Scene {
            weights: weights_named(weights)?,
            width,
            height,
            blend: blend_named(blend)?,
            cov_param: cov_param_named(cov_param)?,
            gaussians: GaussianSet {
                positions: rows("positions", positions, n)?,
                cov: rows("cov", cov, n)?,
                colors: rows("colors", colors, n)?,
                opacity,
            },
            tone: match tone {
                None => None,
                Some((curves, values)) => Some(
                    ToneCurve::new(curves, values)
                        .ok_or("tone: 1 or 3 curves of 2 to 1024 knots each are needed")?,
                ),
            },
        })
    })()
    .map_err(fail)?;
    let (pixels, out_width, out_height) = py
        .detach(|| -> gsi::format::Result<(Vec<u8>, u32, u32)> {
            let (out_width, out_height) = gsi::scaled_size((width, height), out_width, out_height)?;
            Limits::default().check_output(out_width, out_height)?;
            let px = out_width as usize * out_height as usize;
            if float {
                let mut buf = vec![0u8; px * 12];
                gsi::render::render_f32_bytes_into(&scene, out_width, out_height, &mut buf)?;
                Ok((buf, out_width, out_height))
            } else {
                let mut buf = vec![0u8; px * 3];
                gsi::render::render_rgb8_into(&scene, out_width, out_height, &mut buf)?;
                Ok((buf, out_width, out_height))
            }
        })
        .map_err(fail)?;
    Ok((PyByteArray::new(py, &pixels), out_width, out_height))
}

#[pymodule]
fn _gsi(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("Error", m.py().get_type::<Error>())?;
    m.add_function(wrap_pyfunction!(encode, m)?)?;
    m.add_function(wrap_pyfunction!(decode, m)?)?;
    m.add_function(wrap_pyfunction!(enhance, m)?)?;
    m.add_function(wrap_pyfunction!(revert, m)?)?;
    m.add_function(wrap_pyfunction!(info, m)?)?;
    m.add_function(wrap_pyfunction!(read, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    Ok(())
}
