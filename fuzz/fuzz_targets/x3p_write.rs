//! Fuzz the X3P writer: any grid of f64 bit patterns (NaN, infinities, subnormals) and any spacing must
//! either be refused with a one-line error or written so that the reader gives back the same grid
//! (non-finite heights as invalid points).
#![no_main]

use libfuzzer_sys::fuzz_target;
use ndfit::io::{read_bytes, x3p_bytes, Format, ReadOptions};
use ndfit::Heightfield;

fuzz_target!(|data: &[u8]| {
    if data.len() < 10 {
        return;
    }
    let nx = 1 + data[0] as usize % 16;
    let dx = f64::from_le_bytes(data[1..9].try_into().unwrap());
    let z: Vec<f64> = data[9..].chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect();
    let ny = z.len() / nx;
    if ny == 0 {
        return;
    }
    let z = z[..nx * ny].to_vec();
    let hf = match Heightfield::new(nx, ny, dx, dx, z) {
        Ok(hf) => hf,
        Err(e) => return assert!(!e.to_string().contains('\n')),
    };
    match x3p_bytes(&hf) {
        Ok(bytes) => {
            let back = read_bytes(Format::X3p, &bytes, &ReadOptions::default()).expect("the writer's X3P reads back");
            assert_eq!((back.nx, back.ny), (hf.nx, hf.ny));
            for (a, b) in hf.z.iter().zip(back.z.iter()) {
                assert!(a == b || (!a.is_finite() && b.is_nan()), "{a} read back as {b}");
            }
        }
        Err(e) => assert!(!e.to_string().contains('\n')),
    }
});
