//! A satellite seen through the scene: which paths reach the antenna, what the tracking
//! loops make of them, and how the link is classified (line of sight, through foliage,
//! non-line-of-sight, lost).
//!
//! For a satellite in unit ENU direction u, [`crate::propagation::Scene::link`] gives the
//! direct path (attenuated by the walls and foliage it crosses, ITU-R P.833 for foliage,
//! 3GPP TR 38.901 per wall) and the single-bounce reflections off walls and the ground,
//! each with its excess delay, amplitude relative to the unobstructed signal, phase and
//! Doppler. The antenna's gain pattern then weighs each path by the gain in its arrival
//! direction relative to the gain towards the satellite,
//!
//! ```text
//! a_k' = a_k · 10^{(G(el_k) − G(el_sat)) / 20}
//! ```
//!
//! (a ground reflection arrives from below the horizon, where a patch antenna is weak), and
//! [`crate::gnss::multipath::dll_lock`] finds the code tracking error, the prompt power and
//! the path the carrier loop follows. The link's C/N0 is the open-sky value plus
//! 10·log10 of the prompt power; below the lock threshold the satellite is lost.

use crate::gnss::link::{Signal, TrackingConfig};
use crate::gnss::multipath::dll_lock;
use crate::propagation::{Emitter, LinkParams, LinkPaths, LosState, PathKind, Polarisation, Scene};
use nalgebra::Vector3;

/// How a satellite reaches the receiver.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum LinkClass {
    /// The direct path is clear and tracked.
    Los,
    /// The direct path crosses foliage only, and is tracked.
    Foliage,
    /// The direct path is blocked by a building; the loops track a reflection
    /// (or what leaks through the walls) with its bias.
    Nlos,
    /// Nothing usable arrives: no path, or the C/N0 is below the lock threshold.
    Lost,
}

impl LinkClass {
    /// All classes, in display order.
    pub const ALL: [LinkClass; 4] = [
        LinkClass::Los,
        LinkClass::Foliage,
        LinkClass::Nlos,
        LinkClass::Lost,
    ];

    /// A short lower-case label.
    pub fn label(self) -> &'static str {
        match self {
            LinkClass::Los => "los",
            LinkClass::Foliage => "foliage",
            LinkClass::Nlos => "nlos",
            LinkClass::Lost => "lost",
        }
    }
}

/// What the scene does to one satellite link at one instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SceneEffect {
    pub class: LinkClass,
    /// Code tracking error added to the pseudorange (m): multipath or the NLOS bias.
    pub code_error_m: f64,
    /// C/N0 after the scene (dB-Hz).
    pub cn0_dbhz: f64,
    /// Range-rate error (m/s) when the carrier loop follows a reflection: the receiver's
    /// velocity projected on the difference of the arrival directions.
    pub range_rate_error_mps: f64,
}

/// Evaluates one satellite link through `scene`. `u_enu` is the unit ENU vector towards the
/// satellite, `el_rad` its elevation (for the antenna pattern), `open_sky_cn0_dbhz` the C/N0
/// the link would have without the scene. `paths` is the caller's buffer.
///
/// Returns `None` when the scene refuses the geometry (a non-finite position); callers
/// treat that as the scene having no effect.
#[allow(clippy::too_many_arguments)]
pub fn scene_effect(
    scene: &Scene,
    tracking: &TrackingConfig,
    signal: Signal,
    rx_enu_m: &Vector3<f64>,
    rx_vel_enu_mps: &Vector3<f64>,
    u_enu: &Vector3<f64>,
    open_sky_cn0_dbhz: f64,
    paths: &mut LinkPaths,
) -> Option<SceneEffect> {
    let params = LinkParams {
        freq_hz: signal.carrier_hz(),
        polarisation: Polarisation::Rhcp,
        rx_vel_enu_mps: *rx_vel_enu_mps,
    };
    scene
        .link(rx_enu_m, &Emitter::Direction(*u_enu), &params, paths)
        .ok()?;
    let g_sat = tracking.antenna_gain_dbic(u_enu.z.clamp(-1.0, 1.0).asin());
    let mut weighted = [crate::propagation::Path {
        kind: PathKind::Direct,
        excess_delay_s: 0.0,
        amplitude: 0.0,
        phase_rad: 0.0,
        doppler_hz: 0.0,
        arrival_enu: Vector3::z(),
    }; crate::propagation::MAX_PATHS];
    let n = paths.paths().len().min(weighted.len());
    for (w, p) in weighted.iter_mut().zip(paths.paths()) {
        let g = tracking.antenna_gain_dbic(p.arrival_enu.z.clamp(-1.0, 1.0).asin());
        *w = *p;
        w.amplitude = p.amplitude * 10f64.powf((g - g_sat) / 20.0);
    }
    let lost = SceneEffect {
        class: LinkClass::Lost,
        code_error_m: 0.0,
        cn0_dbhz: f64::NEG_INFINITY,
        range_rate_error_mps: 0.0,
    };
    let Some(lock) = dll_lock(
        &weighted[..n],
        signal.chip_length_m(),
        tracking.correlator_spacing_chips,
        tracking.dll_bandwidth_hz,
    ) else {
        return Some(lost);
    };
    let cn0_dbhz = open_sky_cn0_dbhz + 10.0 * lock.prompt_power.log10();
    if !tracking.in_lock(cn0_dbhz) {
        return Some(SceneEffect { cn0_dbhz, ..lost });
    }
    let direct = &weighted[0];
    let carrier = &weighted[lock.carrier_path];
    // The range rate seen through a reflection: −v·(arrival_reflected − arrival_direct).
    let range_rate_error_mps = -rx_vel_enu_mps.dot(&(carrier.arrival_enu - direct.arrival_enu));
    let class = match paths.los {
        LosState::Clear => LinkClass::Los,
        LosState::Foliage { .. } => LinkClass::Foliage,
        LosState::Blocked { .. } => LinkClass::Nlos,
    };
    Some(SceneEffect {
        class,
        code_error_m: lock.code_error_chips * signal.chip_length_m(),
        cn0_dbhz,
        range_rate_error_mps,
    })
}
