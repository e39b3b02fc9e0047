//! Integration tests: readers, writers, preprocessing and surface statistics.

mod peers;
mod x3p;
