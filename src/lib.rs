//! hybridnav: a discrete-event, signal-level simulator for multi-source positioning.
//!
//! See `docs/architecture.md` for the bird's-eye view, the code map and the invariants.

pub mod beacons;
pub mod cli;
pub mod core;
pub mod dtmb;
pub mod engine;
pub mod export;
pub mod fm;
pub mod fusion;
pub mod gnss;
pub mod inertial;
pub mod io;
pub mod layout;
pub mod magnetic;
pub mod measurement;
pub mod metrics;
pub mod montecarlo;
pub mod motion;
pub mod propagation;
pub mod report;
pub mod tcofdm;
pub mod world;
