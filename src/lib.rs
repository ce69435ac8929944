//! hybridnav: a discrete-event, signal-level simulator for multi-source positioning.
//!
//! This crate is the facade and the command line: it re-exports every layer of the
//! workspace under the module paths the product has always had (`hybridnav::gnss::…`,
//! `hybridnav::world::…`), and owns the top layer itself: the dataset exporters
//! (`export`), transmitter-layout design (`layout`) and the CLI (`cli`).
//!
//! See `docs/architecture.md` for the bird's-eye view, the layers and the invariants.

#![deny(unsafe_code)]

pub use hybridnav_core::{core, engine, io, measurement, metrics, motion};
pub use hybridnav_dtmb::{dtmb, tcofdm};
pub use hybridnav_fusion::fusion;
pub use hybridnav_gnss::{gnss, propagation};
pub use hybridnav_run::{montecarlo, report};
pub use hybridnav_sensors::{beacons, fm, inertial, magnetic};
pub use hybridnav_sim::world;

pub mod cli;
pub mod export;
pub mod layout;
pub mod reproduce;
pub mod spp;
