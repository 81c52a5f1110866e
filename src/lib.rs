//! gsi: images stored as 2D Gaussians.
//!
//! A `.gsi` file holds a few thousand anisotropic Gaussians (position, covariance, colour,
//! opacity) in checksummed, quantized, compressed chunks (`format-spec.md`). Decoding is
//! rendering: the Gaussians are evaluated at the pixel centres of an output of any size.
//!
//! Four representations, each with one home: bytes ([`format`](mod@format)), records (quantized
//! attributes, [`format::Records`]), the float model ([`model`]) and pixels ([`mod@render`]).
//!
//! # Embedding the decoder
//!
//! The default features give the decoder (container, model, CPU renderer on all cores with
//! rayon) and the C API, depending on `bitvec`, `byteorder`, `crc32fast`, `zstd` and
//! `rayon` only; `default-features = false` drops rayon. The stages are features: `encode`
//! (fitting and enhancement), `gpu` (wgpu), `image` (`image::open` of `.gsi` files, see
//! `gsi::image_support`). The `gsi` command-line tool is the separate `gsi-cli` package.
//!
//! One call decodes a file from any reader at any size, with limits suited to untrusted
//! input; a [`Reader`] renders into buffers you own, in 8-bit RGB/RGBA or `f32`:
//!
//! ```
//! # let bytes = gsi::format::tests_support::tiny_file();
//! let image = gsi::decode(&bytes[..], 400, 300)?; // 8-bit RGB
//! assert_eq!(image.data.len(), 400 * 300 * 3);
//!
//! let mut reader = gsi::Reader::new(&bytes[..])?;
//! reader.set_pixel_format(gsi::PixelFormat::Rgba8);
//! let mut buf = vec![0u8; reader.output_buffer_size()?]; // at the stored size
//! reader.read_image(&mut buf)?;
//! # Ok::<(), gsi::Error>(())
//! ```
//!
//! Underneath, the layers are public too.
//!
//! Open from any reader, with limits suited to untrusted input, and look at the header
//! before committing to the rest:
//!
//! ```
//! use gsi::format::{Decoder, Limits};
//! # let bytes = gsi::format::tests_support::tiny_file();
//! let limits = Limits { max_gaussians: 100_000, max_alloc: 64 << 20, ..Limits::default() };
//! let mut decoder = Decoder::with_limits(&bytes[..], limits);
//! let header = decoder.read_header()?; // reads only the signature and GHDR
//! assert_eq!((header.width, header.height, header.count), (4, 3, 2));
//! let file = decoder.finish()?; // the attributes, CRC-checked and dequantizable
//! # Ok::<(), gsi::format::Error>(())
//! ```
//!
//! Render into a buffer you own, at any size (positions and covariances are normalized,
//! so a thumbnail and a 4× enlargement come from the same file):
//!
//! ```
//! # let bytes = gsi::format::tests_support::tiny_file();
//! let scene = gsi::format::read_file(&bytes[..], Default::default())?.records.to_scene();
//! let (w, h) = (400, 300);
//! let mut rgb = vec![0f32; (w * h * 3) as usize];
//! gsi::render::render_into(&scene, w, h, &mut rgb)?;
//! assert!(rgb.iter().all(|v| v.is_finite()));
//! # Ok::<(), gsi::format::Error>(())
//! ```
//!
//! The reader never seeks, so a socket or a pipe works as well as a file. Here a file
//! arrives over a loopback TCP connection:
//!
//! ```
//! use std::io::Write;
//! use std::net::{TcpListener, TcpStream};
//! # let bytes = gsi::format::tests_support::tiny_file();
//! let listener = TcpListener::bind("127.0.0.1:0").unwrap();
//! let addr = listener.local_addr().unwrap();
//! let sender = std::thread::spawn(move || {
//!     let (mut conn, _) = listener.accept().unwrap();
//!     for piece in bytes.chunks(7) {
//!         conn.write_all(piece).unwrap(); // arrives in small pieces
//!     }
//! });
//! let stream = TcpStream::connect(addr).unwrap();
//! let file = gsi::format::read_file(std::io::BufReader::new(stream), Default::default())?;
//! let image = gsi::render::render(&file.records.to_scene(), 8, 6)?;
//! assert_eq!(image.to_rgba8().len(), 8 * 6 * 4);
//! sender.join().unwrap();
//! # Ok::<(), gsi::format::Error>(())
//! ```
//!
//! From C, the same decoder is `include/gsi.h` (feature `capi`, in the staticlib and
//! cdylib); `examples/c/decode.c` shows its use.

// The layers are crates (README "Architecture"), lowest first: gsi-format (contract,
// model, format) -> gsi-render (render, decode) -> gsi-gpu (device, gpu) -> gsi-optim,
// gsi-metrics -> gsi-fit, gsi-enhance -> this facade (capi, image_support, info, synth).
// Cargo holds the arrows; the modules keep the paths they had in one crate.
pub use gsi_format::{contract, format, model};
#[cfg(feature = "encode")]
pub use gsi_gpu::device;
#[cfg(feature = "gpu")]
pub use gsi_gpu::gpu;
pub use gsi_render::render;
#[cfg(feature = "image")]
pub mod image_support;
#[cfg(feature = "info")]
pub mod info;

// Stage 2: applying and reverting a stored enhancer is in every build, fitting one is
// feature `encode`.
pub use gsi_enhance::enhance;
#[cfg(feature = "encode")]
pub use gsi_fit::fit;
#[cfg(feature = "encode")]
pub use gsi_metrics::metrics;
#[cfg(feature = "encode")]
pub use gsi_optim::optim;

/// Deterministic test data (random scenes, the corpus); for tests, benches and tools, never
/// used by the library itself.
#[cfg(feature = "encode")]
#[doc(hidden)]
pub mod synth;

#[cfg(feature = "capi")]
pub mod capi;

#[cfg(feature = "encode")]
pub use device::Device;
pub use format::{Error, ErrorKind, Header, Limits, Result};
pub use gsi_render::decode::{decode, scaled_size, Image, PixelFormat, Reader};
pub use model::{Blend, CovParam, GaussianSet, Scene, WeightRule};
pub use render::{render, RgbImage};
