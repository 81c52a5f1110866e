//! Any bytes as the payload of the stage-2 chunks `gENH` and `gORC`: `Ok` or `Err`, never
//! a panic or more memory than the limits allow. An accepted enhancer must write back to
//! the same record, and applying it must give finite colours within its clamp or the
//! identity's range.

#![no_main]

mod common;

use gsi::enhance::Enhancer;
use gsi::format::{EnhancerRecord, OriginalColors};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(orc) = OriginalColors::parse(data) {
        let again = orc.to_payload().expect("re-encoding gORC");
        assert_eq!(OriginalColors::parse(&again).expect("re-reading gORC"), orc);
    }
    let Ok(record) = EnhancerRecord::parse(data, &common::limits()) else {
        return;
    };
    let bytes = record.to_payload(1).expect("re-encoding an accepted gENH");
    let again = EnhancerRecord::parse(&bytes, &common::limits()).expect("re-reading gENH");
    assert_eq!(again, record, "gENH changes through a re-encode");

    let e = Enhancer::from_record(&record);
    let positions = [[0.5, 0.5], [0.0, 1.0], [-3.0, 7.0], [f32::NAN, 0.25]];
    let colors = [
        [0.1, 0.2, 0.3],
        [1.0, 0.0, -1.0],
        [64.0, -64.0, 0.0],
        [0.0; 3],
    ];
    for (out, c) in e.apply(&positions, &colors).iter().zip(colors) {
        for (o, c) in out.iter().zip(c) {
            // A convex mix of c (identity) and values clamped to the operator range.
            let (lo, hi) = (e.clamp[0].min(c), e.clamp[1].max(c));
            assert!(o.is_finite(), "{out:?}");
            assert!(
                *o >= lo - 1e-3 * lo.abs().max(1.0) && *o <= hi + 1e-3 * hi.abs().max(1.0),
                "{o} outside [{lo}, {hi}]"
            );
        }
    }
});
