//! Rewrite a .gsi file's attributes with the 1.0 codings (stored or zstd, `--packed`) or
//! with method 3 where it is smaller (`--coded`, the encoder's choice), keeping every
//! code, and print the bits per Gaussian of each attribute before and after. The codes,
//! hence the pixels, do not change: only their bytes do. A `sum` file is put in curve order
//! for `--coded`, as the encoder writes it. Colours stored by footprint (method 5) have no
//! other coding and keep it either way.
//!
//! `cargo run --release --example recode -- IN.gsi OUT.gsi --packed|--coded`

use gsi::format::{read_file, to_bytes, Limits, Records, WriteOptions};

fn bits(records: &Records, coded: bool) -> Vec<f64> {
    let n = f64::from(records.header.count.max(1));
    [&records.positions, &records.covariance, &records.colors]
        .into_iter()
        .chain(records.opacity.as_ref())
        .map(|a| {
            records
                .attribute_payload(a, 19, coded)
                .expect("in-memory payload")
                .len() as f64
                * 8.0
                / n
        })
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output, how] = &args[..] else {
        return Err("usage: recode IN.gsi OUT.gsi --packed|--coded".into());
    };
    let coded = match how.as_str() {
        "--packed" => false,
        "--coded" => true,
        _ => return Err(format!("{how}: expected --packed or --coded").into()),
    };
    let file = read_file(std::fs::File::open(input)?, Limits::default())?;
    let mut records = file.records.clone();
    records.header.version_minor = 0;
    if coded {
        records.sort_spatially();
    }
    let show = |b: &[f64]| {
        let names = ["GPOS", "GCOV", "GCOL", "GOPA"];
        let each: Vec<String> = b
            .iter()
            .zip(names)
            .map(|(x, n)| format!("{n} {x:.1}"))
            .collect();
        format!("{:.1} ({})", b.iter().sum::<f64>(), each.join(", "))
    };
    println!("{input}: N {}", records.header.count);
    println!("  packed: {}", show(&bits(&file.records, false)));
    println!("  coded : {}", show(&bits(&records, true)));
    let opts = WriteOptions {
        psnr: file.metadata.as_ref().and_then(|m| m.psnr),
        settings: file.metadata.map(|m| m.settings),
        context_coding: coded,
        ..WriteOptions::default()
    };
    std::fs::write(output, to_bytes(&records, &opts)?)?;
    Ok(())
}
