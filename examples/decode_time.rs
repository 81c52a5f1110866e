//! Parse + dequantize, and whole decodes (with the CPU render at the file's size), of
//! several .gsi files, interleaved in one process 150 times each: on a shared machine the
//! files' medians are then comparable where separate runs are not. For instance a file
//! written with method 2 against the same codes rewritten by `--example recode --packed`.
//!
//! `cargo run --release --example decode_time -- A.gsi B.gsi ...`

fn main() {
    let paths: Vec<String> = std::env::args().skip(1).collect();
    let files: Vec<Vec<u8>> = paths.iter().map(|p| std::fs::read(p).unwrap()).collect();
    let mut parse = vec![Vec::new(); files.len()];
    let mut whole = vec![Vec::new(); files.len()];
    for _ in 0..150 {
        for (i, bytes) in files.iter().enumerate() {
            let t = std::time::Instant::now();
            let f = gsi::format::read_file(&bytes[..], gsi::format::Limits::default()).unwrap();
            let scene = f.records.to_scene();
            parse[i].push(t.elapsed().as_secs_f64() * 1e3);
            let h = f.records.header;
            std::hint::black_box(gsi::render::render(&scene, h.width, h.height).unwrap());
            whole[i].push(t.elapsed().as_secs_f64() * 1e3);
        }
    }
    for (i, p) in paths.iter().enumerate() {
        parse[i].sort_by(f64::total_cmp);
        whole[i].sort_by(f64::total_cmp);
        println!(
            "{p}: parse+dequantize median {:.3} ms, whole decode median {:.3} ms",
            parse[i][75], whole[i][75]
        );
    }
}
