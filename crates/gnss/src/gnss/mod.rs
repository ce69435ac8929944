//! GNSS: broadcast navigation files, satellite orbits and clocks, atmosphere models, the
//! receiver's clock and link budget, and the pseudorange measurement model.

pub mod atmosphere;
pub mod ephemeris;
pub mod link;
pub mod measurement;
pub mod multipath;
pub mod rinex_nav;
pub mod rinex_obs;
pub mod signal;
pub mod sp3;
pub mod synth;
pub mod visibility;
