//! The one integration-test binary, with themed modules.

mod common;

mod batch;
mod bench;
mod cli;
mod fit;
mod hostile;
mod models;
mod ndf;
mod ndf_storage;
mod readers;
mod scale;
mod synth;
