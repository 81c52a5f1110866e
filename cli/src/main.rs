//! `gsi`: the command-line front end. Exit status: 0 success, 1 invalid input or a
//! failed operation (one line on stderr naming the problem), 2 usage error.

mod batch;
mod compare;
mod decode;
mod device;
mod encode;
mod enhance;
mod image_io;
mod info;
mod io;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

#[derive(Parser)]
#[command(
    name = "gsi",
    version,
    about = "Images stored as 2D Gaussians: encode, inspect and decode .gsi files"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Fit Gaussians to an image and write a .gsi file.
    Encode(encode::Args),
    /// Brighten a low-light .gsi file in place of its colours (zero-shot, no reference).
    Enhance(enhance::Args),
    /// Describe a .gsi file: size, Gaussians, compression figures, chunks.
    Info(info::Args),
    /// Render a .gsi file to PNG, JPEG, WebP or PPM at any size.
    Decode(decode::Args),
    /// Compare an image with a reference: PSNR, SSIM, MS-SSIM, GT-mean variants, LOE, DE, EME.
    Compare(compare::Args),
}

/// An error already phrased for the user.
pub struct Failure(pub String);

impl<E: std::fmt::Display> From<E> for Failure {
    fn from(e: E) -> Self {
        Failure(e.to_string())
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Encode(a) => encode::run(a),
        Command::Enhance(a) => enhance::run(a),
        Command::Info(a) => info::run(a),
        Command::Decode(a) => decode::run(a),
        Command::Compare(a) => compare::run(a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(Failure(msg)) => {
            eprintln!("gsi: {msg}");
            ExitCode::from(1)
        }
    }
}

/// Read and validate a whole file, naming the path in any error.
pub fn read_gsi(path: &std::path::Path) -> Result<gsi::format::GsiFile, Failure> {
    let input = io::open_input(path).map_err(|e| Failure(format!("{}: {e}", path.display())))?;
    gsi::format::read_file(input, gsi::format::Limits::default())
        .map_err(|e| Failure(format!("{}: {e}", path.display())))
}
