//! Fuzz the x3p reader: any bytes must give a Heightfield or an error, never a panic, a hang or
//! an allocation driven by an unchecked header size.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ndfit::io::{read_bytes, Format, ReadOptions};

fuzz_target!(|data: &[u8]| {
    let opts = ReadOptions { dx: Some(1e-6), dy: None, z_scale: Some(1e-9), format: None };
    if let Err(e) = read_bytes(Format::X3p, data, &opts) {
        // Errors must be one line.
        assert!(!e.to_string().contains('\n'));
    }
});
