//! The one integration-test binary (as ripgrep does): each module tests one area through
//! the public API or the `hybridnav` binary.

mod architecture;
mod cli;
mod cluster;
mod common;
mod covariance_psd;
mod dtmb_signal;
mod dtmb_stream;
mod dtmb_ts;
mod environment;
mod export;
mod export_rinex;
mod fm;
mod fusion_engine;
mod fusion_family;
mod fusion_filters;
mod gnss_iq;
mod gnss_orbits;
mod hostile;
mod inertial;
mod landmark;
mod layout;
mod metrics;
mod montecarlo;
mod motion_models;
mod numerical_health;
mod particle;
mod propagation;
mod reliability;
mod report;
mod reproductions;
mod reproductions_abstract;
mod skeleton;
mod tcofdm;
mod world_mistakes;
mod world_schema;
