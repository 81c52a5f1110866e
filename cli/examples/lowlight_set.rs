//! A synthetic low-light validation set for stage 2, built from well-exposed photographs,
//! and the measurements of LOL's low images that it is matched to.
//!
//! ```sh
//! # What the real low images look like: mean luma and noise against level.
//! cargo run --release --example lowlight_set -- measure ../shared/data/LOL/eval15/low
//! # Darken Kodak into OUT/low (the references, unchanged, go to OUT/high).
//! cargo run --release --example lowlight_set -- make ../shared/data/kodak OUT
//! ```
//!
//! Stage 2's defaults must not be chosen on the 15 LOL pairs the report scores alone
//! (issue 14): this set is the second judge. Each photograph is darkened the way a
//! shorter exposure darkens it: decoded to linear light through the sRGB curve, scaled
//! by a gain, re-encoded through the same curve, then given the noise a small sensor
//! adds at that level, and quantized to 8 bits. The gains spread the dark images' mean
//! luma over the range measured on eval15's low images, and the noise follows the
//! level-dependent standard deviation measured on them (`measure`), so that the Gaussian
//! fit cannot make the set easy by denoising a mild noise.

#[path = "report/lowlight.rs"]
mod lowlight;

use std::path::Path;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    match args.iter().map(String::as_str).collect::<Vec<_>>()[..] {
        ["measure", dir] => lowlight::measure(Path::new(dir)),
        ["make", src, out] => lowlight::make(Path::new(src), Path::new(out)),
        ["rules", kodak, set] => lowlight::rules(Path::new(kodak), Path::new(set)),
        _ => {
            eprintln!("usage: lowlight_set measure LOWDIR | make SRCDIR OUTDIR");
            std::process::exit(2);
        }
    }
}
