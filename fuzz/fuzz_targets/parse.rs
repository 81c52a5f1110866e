//! Any bytes through the container decoder: `Ok` or `Err`, never a panic, never more
//! than the limits allow. A valid file must also survive re-encoding unchanged, and its
//! `gCRM` settings text (§7.1.1) read into typed fields and written again must read back
//! into the same fields.

#![no_main]

mod common;

use gsi::format::{read_file, to_bytes, WriteOptions};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some(file) = common::parse_deep(data) else {
        return;
    };
    if let Some(meta) = &file.metadata {
        let settings = gsi::format::EncoderSettings::parse(&meta.settings);
        let again = gsi::format::EncoderSettings::parse(&settings.to_text());
        assert_eq!(again, settings, "settings change through a write");
    }

    // Whatever the decoder accepts, the encoder writes back to the same records (codes,
    // quantizers, header fields) and ancillary chunks, with method 3 where the file is of
    // the minor that may use it (a file of an earlier minor is written without it, so that
    // its minor stays). A fast zstd level keeps runs quick.
    let opts = WriteOptions {
        zstd_level: 1,
        psnr: None,
        settings: None,
        ancillary: file.ancillary.clone(),
        context_coding: file.records.header.version_minor >= gsi::format::VERSION_MINOR_CODED_RAW,
    };
    let bytes = to_bytes(&file.records, &opts).expect("re-encoding a parsed file");
    let again = read_file(&bytes[..], gsi::format::Limits::unlimited())
        .expect("re-reading a re-encoded file");
    assert_eq!(
        again.records, file.records,
        "records change through a re-encode"
    );
    assert_eq!(
        again.ancillary, file.ancillary,
        "ancillary chunks change through a re-encode"
    );
    assert_eq!(again.file_bytes, bytes.len() as u64);
});
