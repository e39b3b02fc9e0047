//! Fuzz the RGL tensor-file reader and the measured-BSDF structure check: any bytes must give a table or
//! a one-line error, never a panic or an allocation driven by an unchecked header size.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ndfit::export::rgl::TensorFile;
use ndfit::export::rgl::{check_structure, Flavour};

fuzz_target!(|data: &[u8]| {
    match TensorFile::parse(data) {
        Ok(t) => {
            for flavour in [Flavour::Rgb, Flavour::Spectral] {
                if let Err(e) = check_structure(&t, flavour) {
                    assert!(!e.to_string().contains('\n'));
                }
            }
            // What parses writes back to a file that parses to the same fields.
            let again = TensorFile::parse(&t.to_bytes()).expect("a written tensor file parses");
            assert_eq!(again, t);
        }
        Err(e) => assert!(!e.to_string().contains('\n')),
    }
});
