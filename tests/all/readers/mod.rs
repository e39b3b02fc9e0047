//! Integration tests: readers, writers, preprocessing and surface statistics.

mod cli_info;
mod formats;
pub mod gen;
mod npy_layouts;
mod npy_strided;
mod npy_zero_copy;
mod one_copy;
mod peers;
mod preprocess;
mod robust;
mod x3p;
mod x3p_deflated;
