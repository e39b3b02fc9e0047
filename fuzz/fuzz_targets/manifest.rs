//! Fuzz batch manifests: any bytes as a manifest CSV must give scan specs with distinct keys and
//! output names that stay inside the output folder, or a one-line error; never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use ndfit::batch::manifest::read_manifest;

fuzz_target!(|data: &[u8]| {
    let dir = tempfile::tempdir().expect("tempdir");
    let path = dir.path().join("manifest.csv");
    std::fs::write(&path, data).expect("write");
    match read_manifest(&path) {
        Ok(specs) => {
            let mut keys: Vec<&str> = specs.iter().map(|s| s.key.as_str()).collect();
            keys.sort_unstable();
            assert!(keys.windows(2).all(|w| w[0] != w[1]), "duplicate keys");
            for s in &specs {
                assert!(s.out_rel().components().all(|c| matches!(c, std::path::Component::Normal(_))), "{:?} escapes", s.out_rel());
            }
            // Colliding output names are refused by the runner's check, in one line.
            if let Err(e) = ndfit::batch::runner::check_output_names(&specs) {
                assert!(!e.to_string().contains('\n'));
            }
        }
        Err(e) => assert!(!e.to_string().contains('\n')),
    }
});
