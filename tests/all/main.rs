//! The one integration-test binary, with themed modules.

mod common;

mod answer;
mod batch;
mod bench;
mod cli;
mod export;
mod export_blender;
mod export_mirror;
mod export_rgl;
mod facade;
mod fit;
mod fused_resolution;
mod grid_turn;
mod hostile;
mod layers;
mod models;
mod ndf;
mod ndf_storage;
mod options;
mod plane_fold;
mod profile;
mod quantized;
mod readers;
mod render;
mod scale;
mod synth;
mod tails;
mod tiled_info;
mod trace;
mod trace_rgl;
mod wave;
mod wave_rgl;
mod zerocopy;
