//! gsi: images stored as 2D Gaussians.
//!
//! A `.gsi` file holds a few thousand anisotropic Gaussians (position, covariance, colour,
//! opacity) in checksummed, quantized, compressed chunks (`format-spec.md`). Decoding is
//! rendering: the Gaussians are evaluated at the pixel centres of an output of any size.
//!
//! Four representations, each with one home: bytes ([`format`](mod@format)), records (quantized
//! attributes, [`format::Records`]), the float model ([`model`]) and pixels ([`render`]).
//!
//! # Embedding the decoder
//!
//! With `default-features = false` the crate is the decoder alone: container, model and
//! CPU renderer, depending on `bitvec`, `byteorder`, `crc32fast` and `zstd` only. Add the
//! `parallel` feature to render tiles on all cores with rayon.
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

pub mod enhance;
#[cfg(feature = "encode")]
pub mod fit;
pub mod format;
#[cfg(feature = "gpu")]
pub mod gpu;
pub mod metrics;
pub mod model;
pub mod render;
#[doc(hidden)]
pub mod synth;

#[cfg(feature = "capi")]
pub mod capi;
