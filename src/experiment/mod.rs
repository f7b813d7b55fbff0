//! Experiments around training runs: sweeps over grids of runs ([`sweep`]), reports with the paper's table and
//! figures ([`report`], [`plot`]), and the paper's published numbers and experiment grids ([`paper`]).
//! These parts treat a run as a directory of files, so they never depend on the training code itself.

pub mod paper;
pub mod plot;
pub mod report;
pub mod sweep;
