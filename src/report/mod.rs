//! Measurements and reports: what the CLI's benchmark commands compute and print.

pub mod accel_bench;
pub mod all_pairs;
pub mod build_bench;
pub mod charts;
pub mod font;
pub mod frame_bench;
pub mod ray_sweep;
pub mod rays;
pub mod rungs;
pub mod wide_bench;
