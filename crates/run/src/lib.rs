//! hybridnav-run: Monte Carlo runs of a world, their store and their report (see the
//! workspace's `docs/architecture.md` for the layers).
//!
//! The modules of the crates below this one are imported at the root under their usual
//! names, so code here reaches them as `crate::core::…`, `crate::world::…`, as it did
//! when hybridnav was one crate; the compiler stops any path that reaches a layer above.

#![deny(unsafe_code)]

#[allow(unused_imports)]
use hybridnav_core::{core, engine, io, measurement, metrics, motion};
#[allow(unused_imports)]
use hybridnav_dtmb::{dtmb, tcofdm};
#[allow(unused_imports)]
use hybridnav_fusion::fusion;
#[allow(unused_imports)]
use hybridnav_gnss::{gnss, propagation};
#[allow(unused_imports)]
use hybridnav_sensors::{beacons, fm, inertial, magnetic};
#[allow(unused_imports)]
use hybridnav_sim::world;

pub mod montecarlo;
pub mod report;
