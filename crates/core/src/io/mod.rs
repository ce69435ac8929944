//! Reading and writing files: bounded reads of inputs, atomic files, advisory locks,
//! tables, and the external sort behind exact percentiles.

pub mod atomic;
pub mod lock;
pub mod read;
pub mod spill;
pub mod table;
