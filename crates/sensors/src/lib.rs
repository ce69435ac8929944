//! hybridnav-sensors: part of hybridnav (see the workspace's `docs/architecture.md` for the layers).
//!
//! The modules of the crates below this one are imported at the root under their usual
//! names, so code here reaches them as `crate::core::…`, `crate::fusion::…`, as it did
//! when hybridnav was one crate; the compiler stops any path that reaches a layer above.

#![deny(unsafe_code)]

#[allow(unused_imports)]
use hybridnav_core::{core, engine, io, measurement, metrics, motion};
#[allow(unused_imports)]
use hybridnav_fusion::fusion;
#[allow(unused_imports)]
use hybridnav_gnss::{gnss, propagation};

pub mod beacons;
pub mod fm;
pub mod inertial;
pub mod magnetic;
