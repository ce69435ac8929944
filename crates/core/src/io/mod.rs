//! Writing results: atomic files, tables, and the external sort behind exact percentiles.

pub mod atomic;
pub mod spill;
pub mod table;
