//! Link visibility along a world's trajectory: for every epoch, every satellite above the
//! elevation mask and every transmitter, how the link reaches the receiver through the
//! scene. `hybridnav check` prints the shares; tests read the per-epoch counts.
//!
//! Satellites are classified as the GNSS source would track them
//! ([`crate::gnss::visibility::scene_effect`]: line of sight, through foliage, NLOS — a
//! reflection or wall leakage above the lock threshold — or lost). Terrestrial links are
//! classified by geometry alone, since their budgets belong to their receivers: `los`,
//! `foliage`, `nlos` (blocked, with at least one reflection) and `lost` (blocked with no
//! reflection; the signal may still get through the walls with their penetration loss).
//! Manual `[[shielding]]` windows are not applied: this is what the scene does.

use crate::core::{Geodetic, SimTime, System, TrialRng};
use crate::engine::trial::truth_at;
use crate::gnss::link::Signal;
use crate::gnss::measurement::satellite_in_view;
use crate::gnss::visibility::{scene_effect, LinkClass};
use crate::propagation::{Emitter, LinkParams, LinkPaths, LosState, Polarisation};
use crate::world::scene::TransmitterKind;
use crate::world::World;
use std::collections::BTreeMap;

/// A row of the statistics: a satellite system or a transmitter kind.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum LinkGroup {
    Satellites(System),
    Transmitters(TransmitterKind),
}

impl LinkGroup {
    pub fn label(self) -> &'static str {
        match self {
            LinkGroup::Satellites(s) => s.name(),
            LinkGroup::Transmitters(k) => k.label(),
        }
    }
}

/// The links of one epoch, counted by group and class.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct EpochVisibility {
    pub t_s: f64,
    pub counts: BTreeMap<(LinkGroup, LinkClass), u32>,
    /// Whether the receiver is inside a building or an indoor zone.
    pub indoor: bool,
}

impl EpochVisibility {
    /// The number of links of `group` in `class`.
    pub fn count(&self, group: LinkGroup, class: LinkClass) -> u32 {
        self.counts.get(&(group, class)).copied().unwrap_or(0)
    }
}

/// The most epochs a visibility survey (`hybridnav check --step`) visits: each traces
/// every link through the scene, so 10⁵ epochs already take minutes on a large scene;
/// the survey is a summary, and a coarser step shows the same shares.
pub const MAX_SURVEY_EPOCHS: f64 = 100_000.0;

/// Visibility every `step_s` along the trajectory of trial 0 of the world's seed (a
/// deterministic trajectory is the same in every trial; a stochastic one is shown for one
/// draw).
///
/// # Errors
/// When the trajectory cannot be built, or the step would survey more than
/// [`MAX_SURVEY_EPOCHS`] epochs (checked before anything is computed).
pub fn survey(world: &World, step_s: f64) -> Result<Vec<EpochVisibility>, String> {
    let step_s = if step_s.is_finite() && step_s > 0.0 {
        step_s
    } else {
        1.0
    };
    let epochs = (world.duration_s / step_s).floor() + 1.0;
    if epochs > MAX_SURVEY_EPOCHS {
        return Err(format!(
            "--step {step_s} s over duration_s = {} s would survey {epochs:.3e} epochs; \
             expected at most {MAX_SURVEY_EPOCHS} (use --step {:.2e} or coarser)",
            world.duration_s,
            1.01 * world.duration_s / (MAX_SURVEY_EPOCHS - 1.0)
        ));
    }
    let trajectory = world.build_trajectory(&TrialRng::new(world.file.montecarlo.seed, 0))?;
    let gnss = world.file.sensors.gnss.as_ref();
    let mut paths = LinkPaths::new();
    let mut out = Vec::new();
    let n = (world.duration_s / step_s).floor() as usize;
    for k in 0..=n {
        let sim = SimTime::from_seconds(k as f64 * step_s);
        let truth = truth_at(&world.frame, world.start, trajectory.as_ref(), sim);
        let rx_enu = truth.enu.pos_enu_m;
        let mut ep = EpochVisibility {
            t_s: sim.seconds(),
            ..EpochVisibility::default()
        };
        if let Some(scene) = &world.scene {
            ep.indoor = scene.check_receiver(&rx_enu).ok().flatten().is_some();
        }
        if let Some(g) = gnss {
            let rx_geo = Geodetic::from_ecef(&truth.pos_ecef_m);
            let rot = crate::core::geodesy::ecef_to_enu_rotation(rx_geo.lat_rad, rx_geo.lon_rad);
            let mask = g.elevation_mask_deg.to_radians();
            for sat in world.nav.satellites() {
                if !g.systems.contains(&sat.system) {
                    continue;
                }
                let Some((pos, _, _, el)) =
                    satellite_in_view(&world.nav, sat, truth.t, &truth.pos_ecef_m, &rot, mask)
                else {
                    continue;
                };
                let open_cn0 = g.tracking.cn0_dbhz(sat.system, el);
                let class = match (&world.scene, Signal::of_system(sat.system)) {
                    (Some(scene), Some(signal)) if g.scene => {
                        let u = world
                            .frame
                            .enu_vector_of_ecef(&(pos - truth.pos_ecef_m))
                            .normalize();
                        scene_effect(
                            scene,
                            &g.tracking,
                            signal,
                            &rx_enu,
                            &truth.enu.vel_enu_mps,
                            &u,
                            open_cn0,
                            &mut paths,
                        )
                        .map_or(LinkClass::Los, |e| e.class)
                    }
                    _ if g.tracking.in_lock(open_cn0) => LinkClass::Los,
                    _ => LinkClass::Lost,
                };
                *ep.counts
                    .entry((LinkGroup::Satellites(sat.system), class))
                    .or_default() += 1;
            }
        }
        for t in &world.transmitters {
            let class = match &world.scene {
                None => LinkClass::Los,
                Some(scene) => {
                    let params = LinkParams {
                        freq_hz: t.freq_hz,
                        polarisation: Polarisation::Vertical,
                        rx_vel_enu_mps: truth.enu.vel_enu_mps,
                    };
                    match scene.link(&rx_enu, &Emitter::Point(t.pos_enu_m), &params, &mut paths) {
                        Err(_) => LinkClass::Lost,
                        Ok(()) => match paths.los {
                            LosState::Clear => LinkClass::Los,
                            LosState::Foliage { .. } => LinkClass::Foliage,
                            LosState::Blocked { .. } if paths.paths().len() > 1 => LinkClass::Nlos,
                            LosState::Blocked { .. } => LinkClass::Lost,
                        },
                    }
                }
            };
            *ep.counts
                .entry((LinkGroup::Transmitters(t.kind), class))
                .or_default() += 1;
        }
        out.push(ep);
    }
    Ok(out)
}

/// The shares of each class per group over a survey, as a printable table.
pub fn table(epochs: &[EpochVisibility]) -> String {
    use std::fmt::Write;
    let mut totals: BTreeMap<LinkGroup, [u64; 4]> = BTreeMap::new();
    for ep in epochs {
        for ((g, c), n) in &ep.counts {
            let idx = LinkClass::ALL.iter().position(|x| x == c).unwrap_or(3);
            totals.entry(*g).or_default()[idx] += u64::from(*n);
        }
    }
    let mut s = String::new();
    let indoor = epochs.iter().filter(|e| e.indoor).count();
    let _ = writeln!(
        s,
        "link visibility over {} epochs ({} indoor), share of links:",
        epochs.len(),
        indoor
    );
    let _ = writeln!(
        s,
        "  {:<10} {:>8} {:>8} {:>8} {:>8} {:>10}",
        "system", "LOS", "foliage", "NLOS", "lost", "links/ep"
    );
    for (g, c) in &totals {
        let sum: u64 = c.iter().sum();
        let pct = |v: u64| 100.0 * v as f64 / sum.max(1) as f64;
        let _ = writeln!(
            s,
            "  {:<10} {:>7.1}% {:>7.1}% {:>7.1}% {:>7.1}% {:>10.1}",
            g.label(),
            pct(c[0]),
            pct(c[1]),
            pct(c[2]),
            pct(c[3]),
            sum as f64 / epochs.len().max(1) as f64
        );
    }
    s
}
