//! Integration tests: readers, writers, preprocessing and surface statistics.

mod formats;
pub mod gen;
mod peers;
mod x3p;
