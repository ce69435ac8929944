//! Writing results: atomic files and the run summary.

pub mod atomic;
pub mod table;
