//! Speed and accuracy measurements of every knob (`ndfit bench`).
//!
//! The pipeline scan -> empirical NDF -> fit runs on synthetic scans with known truth ([`scene`]: the
//! visible half of a skewed ellipsoid, whose NDF is exactly Walter et al.'s eq. 1) at several sizes; one
//! knob at a time is moved from the defaults ([`sweep`]). Each point records the median time of every
//! stage ([`pipeline`]), the peak resident memory ([`mem`]: `VmHWM` reset per stage), and the accuracy
//! against the truth ([`accuracy`]: the NDF difference metric of `data_formats/objective.md` and the
//! parameter errors). [`analysis`] extracts the Pareto front of time against error and the cost model
//! (log-log exponents), [`plot`] draws the front, `presets` holds the presets picked from it, and
//! [`numpy`] runs the reference numpy + nlopt pipeline in the same run for the speed-up ratios; [`report`] renders the tables of `docs/PERFORMANCE.md` from a run; [`trace`](mod@trace) measures the
//! tracer's throughput (`ndfit bench --trace`); [`wave`](mod@wave) times `ndfit wave` against the numpy
//! `ndfitpy.wave` and the accuracy cost of its level ratio (`ndfit bench --wave`).

pub mod accuracy;
pub mod analysis;
pub mod answer;
pub mod floors;
pub(crate) mod knobs;
pub mod mem;
pub mod numpy;
pub mod pipeline;
pub mod plot;
pub(crate) mod presets;
pub mod process;
pub mod report;
pub mod scene;
pub mod sweep;
pub mod trace;
pub mod wave;

pub use knobs::{Binning, Knobs, Storage};
pub use presets::Preset;
pub use sweep::{Plan, Row};
