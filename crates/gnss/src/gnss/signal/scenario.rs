//! A world's satellites at signal level: the geometry of every satellite at every epoch of
//! a recording, turned into replicas per propagation path and streamed as baseband IQ.
//!
//! # Time
//!
//! Sample `n` of a recording at `f_s` is taken when the receiver clock reads
//! `T0 + n/f_s` (seconds since the world start, `T0` = `--from-s`); the receiver clock is
//! the trial's [`ClockTrack`] (`δt_r` plus the system's inter-system bias), so the true
//! time of that sample is `t = T0 + n/f_s − δt_r`. The geometry is evaluated on a grid of
//! true times every [`SEGMENT_NS`] (10 ms) and the code and carrier phases are linear in
//! the sample index between grid points (the neglected curvature of the range is below
//! 10⁻⁴ m over 10 ms for a car's accelerations).
//!
//! # One satellite at one epoch (the measurement level's terms, [`crate::gnss::measurement`])
//!
//! ```text
//! τ, r_s          light time and the transmit-time position in the reception frame (Sagnac),
//!                 `transmit_geometry`, as the measurement model
//! ρ = ‖r_s − r_r‖
//! I = I_Klobuchar·(f_L1/f)²·(1 + k + k_s),  T = T_Saastamoinen·(1 + k_T)   (the trial's draws)
//! e_URE                                     the trial's initial broadcast orbit/clock error
//! Δt_sv = af0 + af1(t−toc) + af2(t−toc)² + Δtr − T_GD     (single-frequency user's clock)
//! t_code    = t − (ρ + I + T + e_URE)/c + Δt_sv            satellite time on the code
//! t_carrier = t − (ρ − I + T + e_URE)/c + Δt_sv            the ionosphere advances the phase
//! φ = f_c·(t_carrier − (t + δt_r + ISB))                   carrier cycles after the receiver's LO
//! ```
//!
//! so a receiver that applies the broadcast clock correction (with T_GD) measures
//! `ρ + c(δt_r + ISB) + I + T + e_URE` as the measurement model's pseudorange (before
//! tracking noise and the scene's code error, which here arise in the receiver itself).
//! The random terms come from the same named streams and in the same order as
//! [`crate::gnss::measurement::GnssSource`] draws them (`gnss/tropo`, `gnss/iono`,
//! `gnss/Gnn`), so a recording and a run of one `(seed, trial)` describe one world; the
//! URE is held at its initial draw (its correlation time, 30 min by default, is long
//! beside a recording). The manual shielding windows of a world (a receiver-side
//! experiment) are not applied to the signal.
//!
//! # Paths
//!
//! With a scene, each path `k` of [`crate::propagation::Scene::link`] (direct — through
//! foliage or walls —, ground and wall reflections) is its own replica: the code delayed
//! by its excess delay `Δτ_k`, the carrier shifted by its phase (reflection coefficient
//! and excess path, `phase_rad`) and by its Doppler relative to the direct path
//! `Δf_k = (v_r·a_k − v_r·u)/λ`, the amplitude scaled by its relative amplitude and the
//! antenna gain in its arrival direction relative to the satellite's,
//! `a_k' = a_k·10^{(G(el_k) − G(el_sat))/20}` (as [`crate::gnss::visibility::scene_effect`]).
//! The open-sky amplitude is `√(C/N0_open/f_s)` with C/N0 from the link budget
//! ([`crate::gnss::link::TrackingConfig::cn0_dbhz`]). A satellite whose direct path is
//! blocked contributes its reflections only (NLOS); one with no path contributes nothing.

use crate::core::geodesy::{azimuth_elevation_with, ecef_to_enu_rotation};
use crate::core::receiver_clock::ClockTrack;
use crate::core::rng::TrialRng;
use crate::core::{EmitterId, EnuFrame, Geodetic, GpsTime, SimTime, System, C_MPS};
use crate::engine::trial::truth_at;
use crate::gnss::atmosphere::saastamoinen_m;
use crate::gnss::link::Signal;
use crate::gnss::measurement::{transmit_geometry, GnssConfig, F_L1_HZ};
use crate::gnss::rinex_nav::NavData;
use crate::gnss::signal::baseband::{
    add_noise, CarrierTable, NavSymbols, Quantiser, Replica, ReplicaCursor, SampleFormat,
    PIECE_SAMPLES,
};
use crate::gnss::signal::{b1i, ca_code, d1d2, lnav, SignalError};
use crate::measurement::Truth;
use crate::motion::Trajectory;
use crate::propagation::{Emitter, LinkParams, LinkPaths, PathKind, Polarisation, Scene};
use num_complex::Complex32;
use rand::Rng;
use rand_distr::StandardNormal;
use std::io::Write;
use std::sync::Arc;

/// The geometry grid (ns of true time).
pub const SEGMENT_NS: i64 = 10_000_000;
/// Truth and path rows are written every this many segments (0.1 s).
const ROW_EVERY: i64 = 10;
/// Most samples per second a recording may use.
pub const MAX_RATE_SPS: f64 = 100e6;

/// What to record.
#[derive(Clone, Debug, PartialEq)]
pub struct IqRequest {
    pub signal: Signal,
    /// Receiver-clock start, seconds since the world start.
    pub from_s: f64,
    pub duration_s: f64,
    pub rate_sps: f64,
    pub format: SampleFormat,
}

/// The world a recording is made in: everything the trial fixes.
pub struct IqWorld<'a> {
    pub nav: Arc<NavData>,
    pub start: GpsTime,
    pub frame: &'a EnuFrame,
    pub trajectory: &'a dyn Trajectory,
    pub clock: &'a ClockTrack,
    pub scene: Option<&'a Scene>,
    pub gnss: &'a GnssConfig,
    pub rng: TrialRng,
    /// The world's length (s): the trajectory and the clock are defined on [0, this].
    pub duration_s: f64,
    /// GPST − UTC (s) for the messages' UTC parameters.
    pub leap_seconds: i32,
}

/// One satellite of a recording, for its SigMF annotation.
#[derive(Clone, Debug, PartialEq)]
pub struct SatAnnotation {
    pub sat: EmitterId,
    pub first_sample: u64,
    pub sample_count: u64,
    /// C/N0 (dB-Hz) of its strongest path at its first epoch (open sky × the path's
    /// relative power).
    pub cn0_dbhz: f64,
    /// Most paths it had at one epoch.
    pub max_paths: usize,
    /// Whether its direct path was blocked at some epoch.
    pub nlos: bool,
}

/// What a finished recording holds.
#[derive(Clone, Debug, PartialEq)]
pub struct IqSummary {
    pub samples: u64,
    pub center_freq_hz: f64,
    pub satellites: Vec<SatAnnotation>,
}

/// One path of one satellite at one epoch.
#[derive(Clone, Copy, Debug, PartialEq)]
struct PathState {
    kind: PathKind,
    excess_s: f64,
    /// Relative amplitude after the antenna pattern.
    amplitude: f64,
    phase_rad: f64,
    /// Doppler relative to the direct path's (Hz).
    doppler_rel_hz: f64,
}

/// One satellite at one epoch.
#[derive(Clone, Debug, PartialEq)]
struct SatEpoch {
    code_t_s: f64,
    carrier_cycles: f64,
    cn0_open_dbhz: f64,
    el_rad: f64,
    blocked: bool,
    paths: Vec<PathState>,
}

/// A satellite's channel in the generator.
struct Channel {
    sat: EmitterId,
    code: Vec<u8>,
    nav: Box<dyn NavSymbols>,
    ure_m: f64,
    iono_factor: f64,
    now: Option<SatEpoch>,
    next: Option<SatEpoch>,
    ann: Option<SatAnnotation>,
}

/// The ranging code of a satellite on a signal, as 0/1 chips.
pub fn ranging_code(signal: Signal, prn: u16) -> Option<Vec<u8>> {
    match signal {
        Signal::GpsL1Ca => ca_code::ca_code_bits(prn).map(|c| c.to_vec()),
        Signal::BdsB1i => b1i::b1i_code_bits(prn),
    }
}

fn system_of(signal: Signal) -> System {
    match signal {
        Signal::GpsL1Ca => System::Gps,
        Signal::BdsB1i => System::Bds,
    }
}

fn bad(what: &'static str, reason: String) -> SignalError {
    SignalError::InvalidRequest { what, reason }
}

/// The grid (s) on which `World::receiver_clock` records the clock's states.
const RX_CLOCK_GRID_S: f64 = 0.1;

/// The receiver clock's offset (s) for `sys` at true time `t_s`, interpolated linearly
/// between the recorded states. [`ClockTrack::bias_s`] extrapolates each state with its
/// own drift, so its bias steps by the random walk's increment at every grid point
/// (≈ 10⁻¹⁰ s for a TCXO, a fifth of an L1 cycle): a measurement source never notices,
/// but a carrier loop would see a phase jump every 0.1 s. Joining the recorded states
/// keeps the same values on the grid and a continuous phase between them.
fn rx_offset_s(clock: &ClockTrack, sys: System, t_s: f64) -> f64 {
    let k = (t_s / RX_CLOCK_GRID_S).floor();
    let t0 = k * RX_CLOCK_GRID_S;
    // Evaluate just inside each state's interval so the floor inside the track picks it.
    let b0 = clock.bias_s(t0 + 1e-9) + clock.isb_s(sys, t0 + 1e-9);
    let b1 =
        clock.bias_s(t0 + RX_CLOCK_GRID_S + 1e-9) + clock.isb_s(sys, t0 + RX_CLOCK_GRID_S + 1e-9);
    b0 + (b1 - b0) * ((t_s - t0) / RX_CLOCK_GRID_S)
}

/// The true simulation time (ns) when the receiver clock of `sys` reads `t_rx_s`.
fn true_time_ns(clock: &ClockTrack, sys: System, t_rx_s: f64) -> i64 {
    // One fixed-point step is exact to far below a nanosecond: the bias changes by
    // drift·bias ≈ 10⁻¹² s between the two evaluations.
    let t = t_rx_s - rx_offset_s(clock, sys, t_rx_s);
    ((t_rx_s - rx_offset_s(clock, sys, t)) * 1e9).round() as i64
}

/// The per-trial draws of the measurement model: (tropo factor, per-satellite (URE,
/// iono factor)), from the same streams and in the same order as `GnssSource::new`.
fn trial_draws(w: &IqWorld<'_>, sats: &[EmitterId]) -> (f64, Vec<(f64, f64)>) {
    let e = &w.gnss.errors;
    let z: f64 = w.rng.stream("gnss/tropo").sample(StandardNormal);
    let tropo = e.tropo_residual * z;
    let z: f64 = w.rng.stream("gnss/iono").sample(StandardNormal);
    let iono_common = e.iono_residual * z;
    let per_sat = sats
        .iter()
        .map(|sat| {
            let mut r = w.rng.stream(&format!("gnss/{sat}"));
            let z_ure: f64 = r.sample(StandardNormal);
            let z_iono: f64 = r.sample(StandardNormal);
            let sigma = match sat.system {
                System::Bds => e.ure_bds_m,
                _ => e.ure_gps_m,
            };
            (
                sigma * z_ure,
                iono_common + e.iono_residual_per_sat * z_iono,
            )
        })
        .collect();
    (tropo, per_sat)
}

/// Checks a request against the world before anything is written: the signal's
/// satellites, the rate (at least twice the chip rate), the span (inside the world's
/// duration), the ephemerides (every satellite in view at the start still has a valid
/// ephemeris at the end).
///
/// # Errors
/// [`SignalError::InvalidRequest`] naming the problem.
pub fn validate(w: &IqWorld<'_>, req: &IqRequest) -> Result<Vec<EmitterId>, SignalError> {
    let chip = req.signal.chip_rate_hz();
    if !(req.rate_sps.is_finite() && req.rate_sps >= 2.0 * chip && req.rate_sps <= MAX_RATE_SPS) {
        return Err(bad(
            "--rate-sps",
            format!(
                "{} sps is outside [{:.0}, {:.0}]: the rate must be at least twice the \
                 {:.3} Mchip/s chip rate",
                req.rate_sps,
                2.0 * chip,
                MAX_RATE_SPS,
                chip * 1e-6
            ),
        ));
    }
    if !(req.duration_s.is_finite() && req.duration_s > 0.0) {
        return Err(bad(
            "--duration-s",
            format!(
                "expected a positive number of seconds, got {}",
                req.duration_s
            ),
        ));
    }
    if !(req.from_s.is_finite() && req.from_s >= 0.0) {
        return Err(bad(
            "--from-s",
            format!(
                "expected a non-negative number of seconds, got {}",
                req.from_s
            ),
        ));
    }
    if req.from_s + req.duration_s > w.duration_s + 1e-9 {
        return Err(bad(
            "--duration-s",
            format!(
                "the recording ({} s from {} s) runs past the world's {} s",
                req.duration_s, req.from_s, w.duration_s
            ),
        ));
    }
    let sys = system_of(req.signal);
    let sats: Vec<EmitterId> = w
        .nav
        .satellites()
        .into_iter()
        .filter(|s| s.system == sys && ranging_code(req.signal, s.number).is_some())
        .collect();
    let t_start = w.start.add_seconds(req.from_s);
    let t_end = w.start.add_seconds(req.from_s + req.duration_s);
    let truth = truth_at(
        w.frame,
        w.start,
        w.trajectory,
        SimTime::from_seconds(req.from_s),
    );
    let rx = truth.pos_ecef_m;
    let g = Geodetic::from_ecef(&rx);
    let rot = ecef_to_enu_rotation(g.lat_rad, g.lon_rad);
    let mask = w.gnss.elevation_mask_deg.to_radians();
    let mut in_view = 0;
    for &sat in &sats {
        let Some(eph) = w.nav.select(sat, t_start).filter(|e| e.is_healthy()) else {
            continue;
        };
        let (pos, _) = transmit_geometry(eph, t_start, &rx);
        let (_, el) = azimuth_elevation_with(&rot, &rx, &pos);
        if el < mask {
            continue;
        }
        in_view += 1;
        if w.nav.select(sat, t_end).is_none() {
            return Err(bad(
                "--duration-s",
                format!(
                    "the recording ends at {} but {sat}'s ephemeris (toe {}) is no longer \
                     valid then: the navigation data does not cover the span",
                    t_end.to_iso_gpst(),
                    eph.toe.to_iso_gpst()
                ),
            ));
        }
    }
    if in_view == 0 {
        return Err(bad(
            "--signal",
            format!(
                "no {:?} satellite with a valid ephemeris is above the {}° mask at {}",
                sys,
                w.gnss.elevation_mask_deg,
                t_start.to_iso_gpst()
            ),
        ));
    }
    Ok(sats)
}

/// The satellite's state at the true time of `truth` (module documentation).
#[allow(clippy::too_many_arguments)]
fn sat_epoch(
    w: &IqWorld<'_>,
    signal: Signal,
    sat: EmitterId,
    truth: &Truth,
    rx_clock_s: f64,
    ure_m: f64,
    iono_factor: f64,
    tropo_factor: f64,
    paths_buf: &mut LinkPaths,
) -> Option<SatEpoch> {
    let eph = w.nav.select(sat, truth.t).filter(|e| e.is_healthy())?;
    let rx = truth.pos_ecef_m;
    let g = Geodetic::from_ecef(&rx);
    let rot = ecef_to_enu_rotation(g.lat_rad, g.lon_rad);
    let (pos, _) = transmit_geometry(eph, truth.t, &rx);
    let (az, el) = azimuth_elevation_with(&rot, &rx, &pos);
    if el < w.gnss.elevation_mask_deg.to_radians() {
        return None;
    }
    let range = (pos - rx).norm();
    let f = signal.carrier_hz();
    let iono = w
        .nav
        .klobuchar
        .map_or(0.0, |k| k.delay_l1_m(g.lat_rad, g.lon_rad, az, el, truth.t))
        * (F_L1_HZ / f).powi(2)
        * (1.0 + iono_factor);
    let tropo = saastamoinen_m(g.lat_rad, g.h_m, el, w.gnss.errors.humidity) * (1.0 + tropo_factor);
    let st = eph.state(truth.t.add_seconds(-range / C_MPS));
    let clk = st.clock_s - eph.tgd_s;
    let t_s = truth.sim.seconds();
    let code_t_s = t_s - (range + iono + tropo + ure_m) / C_MPS + clk;
    let carrier_t_s = t_s - (range - iono + tropo + ure_m) / C_MPS + clk;
    let carrier_cycles = f * (carrier_t_s - rx_clock_s);
    let cn0_open_dbhz = w.gnss.tracking.cn0_dbhz(sat.system, el);
    let mut paths = Vec::new();
    let mut blocked = false;
    match w.scene.filter(|_| w.gnss.scene) {
        None => paths.push(PathState {
            kind: PathKind::Direct,
            excess_s: 0.0,
            amplitude: 1.0,
            phase_rad: 0.0,
            doppler_rel_hz: 0.0,
        }),
        Some(scene) => {
            let u_enu = w.frame.enu_vector_of_ecef(&(pos - rx)).normalize();
            let params = LinkParams {
                freq_hz: f,
                polarisation: Polarisation::Rhcp,
                rx_vel_enu_mps: truth.enu.vel_enu_mps,
            };
            if scene
                .link(
                    &truth.enu.pos_enu_m,
                    &Emitter::Direction(u_enu),
                    &params,
                    paths_buf,
                )
                .is_ok()
            {
                let lambda = signal.wavelength_m();
                let direct_doppler = truth.enu.vel_enu_mps.dot(&u_enu) / lambda;
                let tr = &w.gnss.tracking;
                let g_sat = tr.antenna_gain_dbic(el);
                blocked = matches!(paths_buf.los, crate::propagation::LosState::Blocked { .. });
                for p in paths_buf.paths() {
                    let g_k = tr.antenna_gain_dbic(p.arrival_enu.z.clamp(-1.0, 1.0).asin());
                    let amplitude = p.amplitude * 10f64.powf((g_k - g_sat) / 20.0);
                    if amplitude > 0.0 && amplitude.is_finite() {
                        paths.push(PathState {
                            kind: p.kind,
                            excess_s: p.excess_delay_s,
                            amplitude,
                            phase_rad: p.phase_rad,
                            doppler_rel_hz: p.doppler_hz - direct_doppler,
                        });
                    }
                }
            }
        }
    }
    Some(SatEpoch {
        code_t_s,
        carrier_cycles,
        cn0_open_dbhz,
        el_rad: el,
        blocked,
        paths,
    })
}

fn kind_label(k: PathKind) -> String {
    match k {
        PathKind::Direct => "direct".into(),
        PathKind::Ground => "ground".into(),
        PathKind::Wall { building } => format!("wall{building}"),
    }
}

/// Where the outputs go.
pub struct IqSinks<'a> {
    /// The samples, in the request's format.
    pub data: &'a mut dyn Write,
    /// `t_gpst_s,x_m,y_m,z_m` rows.
    pub truth: &'a mut dyn Write,
    /// Per-satellite, per-path rows.
    pub paths: &'a mut dyn Write,
}

/// Records `req` in world `w` (call [`validate`] first; its satellites are `sats`).
///
/// # Errors
/// [`SignalError::Io`] when a sink fails.
pub fn record(
    w: &IqWorld<'_>,
    req: &IqRequest,
    sats: &[EmitterId],
    sinks: &mut IqSinks<'_>,
) -> Result<IqSummary, SignalError> {
    let signal = req.signal;
    let sys = system_of(signal);
    let fs = req.rate_sps;
    let (tropo_factor, draws) = trial_draws(w, sats);
    let mut channels: Vec<Channel> = sats
        .iter()
        .zip(&draws)
        .filter_map(|(&sat, &(ure_m, iono_factor))| {
            let code = ranging_code(signal, sat.number)?;
            let nav: Box<dyn NavSymbols> = match signal {
                Signal::GpsL1Ca => Box::new(lnav::LnavStream::new(
                    Arc::clone(&w.nav),
                    sat,
                    w.leap_seconds,
                )),
                Signal::BdsB1i => Box::new(d1d2::BdsNavStream::new(
                    Arc::clone(&w.nav),
                    sat,
                    w.leap_seconds,
                )),
            };
            Some(Channel {
                sat,
                code,
                nav,
                ure_m,
                iono_factor,
                now: None,
                next: None,
                ann: None,
            })
        })
        .collect();
    let total = (req.duration_s * fs).round() as u64;
    let code_len = match signal {
        Signal::GpsL1Ca => 1023.0,
        Signal::BdsB1i => 2046.0,
    };
    let chip_rate = signal.chip_rate_hz();
    let start_ms = w.start.ns().div_euclid(1_000_000);
    let start_frac_s = w.start.ns().rem_euclid(1_000_000) as f64 * 1e-9;
    let carrier = CarrierTable::default();
    let mut noise = w.rng.stream(&format!("gnss/iq/{sys:?}/noise"));
    let mut paths_buf = LinkPaths::new();
    writeln!(sinks.truth, "t_gpst_s,x_m,y_m,z_m")?;
    writeln!(
        sinks.paths,
        "t_gpst_s,sat,prn,class,el_deg,cn0_open_dbhz,code_phase_chips,doppler_hz,path,kind,\
         excess_delay_m,amplitude,cn0_dbhz,phase_rad,path_doppler_hz"
    )?;
    let t0_ns = true_time_ns(w.clock, sys, req.from_s);
    // Evaluates every channel at epoch `e`; returns the truth and the epoch's fractional
    // sample position.
    let mut eval = |e: i64, channels: &mut [Channel], slot_next: bool| -> (Truth, f64) {
        let sim = SimTime(t0_ns + e * SEGMENT_NS);
        let truth = truth_at(w.frame, w.start, w.trajectory, sim);
        let t_s = sim.seconds();
        let rx_clock_s = t_s + rx_offset_s(w.clock, sys, t_s);
        for ch in channels.iter_mut() {
            let s = sat_epoch(
                w,
                signal,
                ch.sat,
                &truth,
                rx_clock_s,
                ch.ure_m,
                ch.iono_factor,
                tropo_factor,
                &mut paths_buf,
            );
            if slot_next {
                ch.next = s;
            } else {
                ch.now = s;
            }
        }
        (truth, (rx_clock_s - req.from_s) * fs)
    };
    let (mut truth_now, mut p_now) = eval(0, &mut channels, false);
    // The AGC starts at the expected input power.
    let power0 = 1.0
        + channels
            .iter()
            .filter_map(|c| c.now.as_ref())
            .flat_map(|s| {
                let a2 = 10f64.powf(s.cn0_open_dbhz / 10.0) / fs;
                s.paths.iter().map(move |p| a2 * p.amplitude * p.amplitude)
            })
            .sum::<f64>();
    let mut quant = Quantiser::new(req.format, power0);
    let mut block: Vec<Complex32> = Vec::new();
    let mut cursors: Vec<(usize, ReplicaCursor)> = Vec::new();
    let mut bytes: Vec<u8> = Vec::new();
    let mut n_lo: u64 = 0;
    let mut e: i64 = 0;
    while n_lo < total {
        let (truth_next, p_next) = eval(e + 1, &mut channels, true);
        let n_hi = (p_next.ceil().max(0.0) as u64).min(total);
        let dp = p_next - p_now;
        if e % ROW_EVERY == 0 {
            write_rows(
                sinks,
                &truth_now,
                &channels,
                start_frac_s,
                code_len,
                chip_rate,
                dp / fs,
                signal,
            )?;
        }
        if n_hi > n_lo {
            let len = (n_hi - n_lo) as usize;
            block.clear();
            block.resize(len, Complex32::default());
            let x = n_lo as f64 - p_now;
            cursors.clear();
            for (k, ch) in channels.iter_mut().enumerate() {
                let (Some(a), Some(b)) = (ch.now.as_ref(), ch.next.as_ref()) else {
                    continue;
                };
                let code_slope = (b.code_t_s - a.code_t_s) / dp;
                let phase_slope = (b.carrier_cycles - a.carrier_cycles) / dp;
                let amp0 = (10f64.powf(a.cn0_open_dbhz / 10.0) / fs).sqrt();
                for p in &a.paths {
                    let t_code = a.code_t_s + x * code_slope - p.excess_s;
                    let ms_f = (start_frac_s + t_code) * 1000.0;
                    let ms_floor = ms_f.floor();
                    let mut chip = (ms_f - ms_floor) * code_len;
                    if chip >= code_len {
                        chip -= code_len;
                    }
                    let r = Replica {
                        amplitude: (amp0 * p.amplitude) as f32,
                        ms: start_ms + ms_floor as i64,
                        chip,
                        chips_per_sample: code_slope * chip_rate,
                        phase_cycles: a.carrier_cycles
                            + x * phase_slope
                            + p.phase_rad / std::f64::consts::TAU
                            + p.doppler_rel_hz * x / fs,
                        cycles_per_sample: phase_slope + p.doppler_rel_hz / fs,
                    };
                    cursors.push((k, ReplicaCursor::new(&r, ch.code.len(), ch.nav.as_mut())));
                }
                let ann = ch.ann.get_or_insert_with(|| SatAnnotation {
                    sat: ch.sat,
                    first_sample: n_lo,
                    sample_count: 0,
                    cn0_dbhz: a.cn0_open_dbhz
                        + 20.0
                            * a.paths
                                .iter()
                                .map(|p| p.amplitude)
                                .fold(0.0, f64::max)
                                .max(1e-30)
                                .log10(),
                    max_paths: 0,
                    nlos: false,
                });
                ann.sample_count = n_hi - ann.first_sample;
                ann.max_paths = ann.max_paths.max(a.paths.len());
                ann.nlos |= a.blocked;
            }
            // Every replica is added to one piece of the segment before the next piece, so
            // the piece stays in the first-level cache instead of streaming the whole
            // segment through it once per replica.
            for piece in block.chunks_mut(PIECE_SAMPLES) {
                for (k, cursor) in cursors.iter_mut() {
                    let ch = &mut channels[*k];
                    cursor.add(piece, &ch.code, ch.nav.as_mut(), &carrier);
                }
            }
            add_noise(&mut block, &mut noise);
            bytes.clear();
            quant.quantise(&block, &mut bytes);
            sinks.data.write_all(&bytes)?;
            n_lo = n_hi;
        }
        for ch in channels.iter_mut() {
            ch.now = ch.next.take();
        }
        truth_now = truth_next;
        p_now = p_next;
        e += 1;
    }
    let mut satellites: Vec<SatAnnotation> = channels.into_iter().filter_map(|c| c.ann).collect();
    satellites.sort_by_key(|a| a.sat);
    Ok(IqSummary {
        samples: total,
        center_freq_hz: signal.carrier_hz(),
        satellites,
    })
}

/// The truth row and the path rows of one epoch.
#[allow(clippy::too_many_arguments)]
fn write_rows(
    sinks: &mut IqSinks<'_>,
    truth: &Truth,
    channels: &[Channel],
    start_frac_s: f64,
    code_len: f64,
    chip_rate: f64,
    dt_s: f64,
    signal: Signal,
) -> Result<(), SignalError> {
    let t_gpst = truth.t.ns() as f64 * 1e-9;
    let p = truth.pos_ecef_m;
    writeln!(sinks.truth, "{t_gpst:.3},{:.4},{:.4},{:.4}", p.x, p.y, p.z)?;
    let lambda = signal.wavelength_m();
    for ch in channels {
        let (Some(a), Some(b)) = (ch.now.as_ref(), ch.next.as_ref()) else {
            continue;
        };
        let ms_f = (start_frac_s + a.code_t_s) * 1000.0;
        let code_phase = (ms_f - ms_f.floor()) * code_len;
        let doppler = (b.carrier_cycles - a.carrier_cycles) / dt_s;
        let class = if a.blocked {
            if a.paths.is_empty() {
                "lost"
            } else {
                "nlos"
            }
        } else if a.paths.len() > 1 {
            "los+mp"
        } else {
            "los"
        };
        for (k, path) in a.paths.iter().enumerate() {
            writeln!(
                sinks.paths,
                "{t_gpst:.3},{},{},{class},{:.3},{:.2},{:.4},{:.3},{k},{},{:.3},{:.5},{:.2},{:.4},{:.3}",
                ch.sat,
                ch.sat.number,
                a.el_rad.to_degrees(),
                a.cn0_open_dbhz,
                (code_phase - path.excess_s * chip_rate).rem_euclid(code_len),
                doppler,
                kind_label(path.kind),
                path.excess_s * C_MPS,
                path.amplitude,
                a.cn0_open_dbhz + 20.0 * path.amplitude.max(1e-30).log10(),
                path.phase_rad,
                doppler + path.doppler_rel_hz,
            )?;
        }
        let _ = lambda;
    }
    Ok(())
}
