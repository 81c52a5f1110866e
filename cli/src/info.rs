//! `gsi info`: what a file holds and how compact it is (the library's [`gsi::info`]).

use crate::{read_gsi, Failure};
use std::path::PathBuf;

#[derive(clap::Args)]
pub struct Args {
    /// The .gsi file (`-` for standard input).
    file: PathBuf,
    /// Print JSON instead of text.
    #[arg(long)]
    json: bool,
}

pub fn run(args: Args) -> Result<(), Failure> {
    let f = read_gsi(&args.file)?;
    let out = if args.json {
        serde_json::to_string_pretty(&gsi::info::to_json(&f))?
    } else {
        gsi::info::to_text(&f)
    };
    crate::io::print_line(&out)?;
    Ok(())
}
