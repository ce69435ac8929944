//! A world's DTMB tower as its receiver hears it along the trajectory, as baseband IQ for
//! a SigMF recording (`hybridnav dtmb iq --world`).
//!
//! Recording sample `n` (7.56 Msps) is taken when the receiver clock reads
//! `start + T0 + n/f_s` (`T0` = `--from-s`). The tower emits frame `k` (frame 0 at the
//! world's start, superframes aligned with it) when its clock reads `start + k·T_frame`,
//! i.e. at GPS time `start + k·T_frame − δt_tower`, `δt_tower = clock_offset + drift·t`.
//! Path `p` of the link (excess delay `Δτ_p` over the geometric range `ρ`) then puts the
//! start of frame `k` at recording sample
//!
//! ```text
//! n_k = f_s (k·T_frame − T0 − δt_tower + ρ/c + Δτ_p + δt_rx + ISB_DTMB)   (× (1 + ε) with SFO)
//! ```
//!
//! the same clocks as the `dtmb` source's pseudorange `ρ + c(δt_rx + ISB − δt_tower)`.
//! The geometry (platform truth, `Scene::link` paths and Dopplers, link budget with
//! shadowing, receiver and tower clocks) is evaluated at the middle of every frame-long
//! block of the recording and held through the block, so the paths are updated every
//! frame (0.63 ms for PN945; the delay drift inside a block is below 10⁻³ sample at car
//! speeds). The link is computed by [`DtmbSource`]'s own `tower_link` (the world's
//! `[sensors.dtmb]`, or its defaults), the receiver clock as in `World::build_trial`, so a
//! recording and a run of the same `(seed, trial)` see the same link and clocks.
//!
//! Scaling: the noise is white with unit variance per complex sample over the 7.56 MHz
//! band (`hybridnav:noise_power` = 1) and the paths are scaled so that a free-space LoS
//! path's frame power over the noise is the link budget's `γ_ref` (`hybridnav:snr_ref_db`):
//! a constant noise floor, the signal level following the link. The annotated
//! `hybridnav:snr_db` is the received frame power over the noise,
//! `γ_ref + 10 log10 Σ_pq Re(g_p g_q*) sinc(Δτ_p − Δτ_q)` (paths combined coherently over
//! the flat band: a ground reflection 0.002 samples behind the direct path in antiphase
//! cancels, not adds). A blocked link (no path) leaves noise.
//!
//! **Co-channel towers.** Every DTMB tower on the requested tower's carrier adds its own
//! copy: its paths, its range, its clock (offset and drift), its Dopplers and its link
//! budget's power, with `n_k` above evaluated per tower. The towers of one
//! single-frequency network (`sfn` in the world file) transmit one signal, the payload of
//! the network's first tower (`dtmb/Dnn/tx` of that tower); other co-channel towers their
//! own. Each tower's frame starts are annotated (`hybridnav:tower`), so a recording of an
//! SFN carries one annotation per tower and frame, sorted by sample.
//!
//! [`tower_channel_at`] gives the requested tower's paths, their Dopplers and the link
//! SNR for one such block without recording (`dtmb ber --world`, which holds the paths'
//! delays and gains and rotates each with its Doppler).
//!
//! Random streams of `TrialRng::new(seed, trial)`: `motion/trajectory`,
//! `receiver/clock/init`, `receiver/clock`, the shadowing of the master seed (as a run),
//! the payloads `dtmb/Dnn/tx` (the signal-level source's) and the noise
//! `dtmb/iq/Dnn/noise` of the requested tower.

use crate::core::{SimTime, System, TrialRng, C_MPS};
use crate::dtmb::channel::Channel;
use crate::dtmb::frame::{CarrierMode, Qam};
use crate::dtmb::multipath::{ChannelConfig, Path};
use crate::dtmb::pn::{PnMode, SAMPLE_RATE_HZ};
use crate::dtmb::sigmf::{peak_component, Annotation, SampleFormat, SigmfWriter};
use crate::dtmb::source::{DtmbLevel, DtmbSource, TowerSpec};
use crate::dtmb::transmitter::{FrameSchedule, SampleSource, Transmitter, TxConfig};
use crate::dtmb::DtmbError;
use crate::measurement::Truth;
use crate::world::scene::TransmitterKind;
use crate::world::World;
use num_complex::{Complex32, Complex64};
use serde_json::{json, Map, Value};
use std::sync::Arc;

/// Samples of margin ahead of the earliest path in the channel's delays, so the delays
/// stay positive while the platform approaches the tower (256 samples ≈ 10 km).
const DELAY_MARGIN_SAMPLES: f64 = 256.0;

/// Most frames a recording may hold (as [`crate::dtmb::sigmf::stream_iq`]); the
/// samples are streamed, the annotations (one per tower and frame) held in memory.
pub const MAX_FRAMES: usize = crate::dtmb::sigmf::MAX_IQ_FRAMES;

/// What to record.
#[derive(Clone, Debug, PartialEq)]
pub struct WorldIqRequest {
    /// The tower id (`D01`); `None` for the world's first DTMB tower.
    pub tower: Option<String>,
    /// Start of the recording in seconds from the world's start (receiver clock).
    pub from_s: f64,
    /// Number of frames (the recording holds `frames · frame_len` samples).
    pub frames: usize,
    /// Master seed.
    pub seed: u64,
    /// Trial index.
    pub trial: u64,
    /// Data-layer options that replace, key by key, those of the recorded tower's
    /// `[[transmitter]]` (`dtmb iq --world --payload/--qam/--fec/--interleaver/--carriers`);
    /// for a tower of a single-frequency network they apply to the network's signal.
    pub data_layer: DataLayerOverride,
}

/// Data-layer options given for a recording, each replacing the tower table's own.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DataLayerOverride {
    /// A transport stream, as a path (not relative to the world file).
    pub payload: Option<std::path::PathBuf>,
    pub qam: Option<String>,
    pub fec: Option<String>,
    pub interleaver: Option<usize>,
    pub carriers: Option<usize>,
}

/// A recording made by [`world_iq`], ready for [`crate::dtmb::sigmf::write_sigmf_with`].
#[derive(Clone, Debug)]
pub struct WorldIq {
    /// The samples (7.56 Msps, unit noise variance).
    pub samples: Vec<Complex32>,
    /// Everything else: annotations, metadata, the towers.
    pub meta: WorldIqMeta,
}

/// What a recording of [`world_iq_stream`] holds besides its samples.
#[derive(Clone, Debug)]
pub struct WorldIqMeta {
    /// The number of samples (`frames · frame_len`).
    pub samples: u64,
    /// One annotation per frame start inside the recording.
    pub annotations: Vec<Annotation>,
    /// Per annotation: `hybridnav:` keys (frame, phase, emission time, true first-path
    /// sample, range, pseudorange, SNR).
    pub annotation_extra: Vec<Map<String, Value>>,
    /// `global` keys: world, trial, seed, tower, start, noise power, description.
    pub global_extra: Map<String, Value>,
    /// Carrier frequency of the tower (Hz).
    pub center_freq_hz: f64,
    /// The tower's header mode.
    pub mode: PnMode,
    /// The requested tower's id.
    pub tower: String,
    /// Every tower in the recording: the requested one and its co-channel towers, in the
    /// world file's order.
    pub towers: Vec<String>,
    /// Link SNR (dB over 7.56 MHz) at the middle of the first block.
    pub snr_db: f64,
}

/// `sin(πx)/(πx)`.
fn sinc(x: f64) -> f64 {
    if x.abs() < 1e-9 {
        1.0
    } else {
        let a = std::f64::consts::PI * x;
        a.sin() / a
    }
}

fn bad(name: &'static str, reason: String) -> DtmbError {
    DtmbError::InvalidParameter { name, reason }
}

/// The transmitter's samples with the index shifted by `offset` (the channel's receiver
/// index starts at the recording's first sample; the transmitter's at the world start).
struct Shifted<'a> {
    tx: &'a mut Transmitter,
    offset: i64,
}

impl SampleSource for Shifted<'_> {
    fn generate(&mut self, start_sample: i64, out: &mut [Complex32]) {
        self.tx.generate(start_sample + self.offset, out);
    }
}

/// Records `req.frames` frames of a world's DTMB tower as the receiver on the platform
/// hears it from `req.from_s` on (see the module documentation).
///
/// # Errors
/// [`DtmbError::InvalidParameter`] naming the problem: a world without DTMB towers, an
/// unknown tower id, a start outside the world's duration or a recording running past
/// it, zero or too many frames, a trajectory or link that cannot be built.
pub fn world_iq(world: &World, req: &WorldIqRequest) -> Result<WorldIq, DtmbError> {
    let mut samples = Vec::new();
    let meta = world_iq_stream(world, req, &mut |b| {
        samples.extend_from_slice(b);
        Ok(())
    })?;
    Ok(WorldIq { samples, meta })
}

/// [`world_iq`] with the samples handed to `sink` one frame-long block at a time, in
/// order, so memory stays flat in the recording's length (the annotations are kept).
///
/// # Errors
/// As [`world_iq`], and the first error of `sink`, which stops the recording.
pub fn world_iq_stream(
    world: &World,
    req: &WorldIqRequest,
    sink: &mut dyn FnMut(&[Complex32]) -> Result<(), DtmbError>,
) -> Result<WorldIqMeta, DtmbError> {
    let (t, group) = select_towers(world, req)?;
    let mode = t.pn_mode();
    let n = mode.frame_len();
    let t_frame = mode.frame_duration_s();
    let LinkSetup {
        rng,
        trajectory,
        clock,
        specs,
        me,
        mut link,
        rx_ppm,
    } = link_setup(world, req, t, &group)?;
    let eps = rx_ppm * 1e-6;
    let tx_cfg = TxConfig {
        schedule: FrameSchedule {
            mode,
            t0: world.start,
            tower_clock_offset_s: 0.0,
        },
        carrier: CarrierMode::Multi3780,
        qam: Qam::Qam64,
        si_vector: 0,
    };
    // One signal per network (its first tower's payload), one per tower outside one.
    let owner_of = |i: usize| -> usize {
        specs[i]
            .sfn
            .as_ref()
            .and_then(|net| specs.iter().position(|o| o.sfn.as_ref() == Some(net)))
            .unwrap_or(i)
    };
    let mut signals: Vec<Signal> = Vec::new();
    for i in 0..specs.len() {
        let o = owner_of(i);
        if !signals.iter().any(|sg| sg.owner == o) {
            signals.push(Signal {
                owner: o,
                // The options given for the recording go to the recorded tower's signal
                // (its network's, in a single-frequency network).
                tx: owner_transmitter(
                    world,
                    &specs[o],
                    tx_cfg,
                    &rng,
                    (o == owner_of(me)).then_some(&req.data_layer),
                )?,
                channel: None,
                offset: None,
                paths: Vec::new(),
            });
        }
    }
    let mut noise = rng.stream(&format!("dtmb/iq/{}/noise", specs[me].id));
    let total = req.frames * n;
    let mut block = vec![Complex32::default(); n];
    let mut extra = vec![Complex32::default(); n];
    let mut annotations: Vec<(Annotation, Map<String, Value>)> = Vec::new();
    let mut snr_first = f64::NEG_INFINITY;
    // Per tower and block: (taps, first excess delay, x of the first path, SNR, ...).
    let mut links: Vec<TowerBlock> = Vec::with_capacity(specs.len());
    for j in 0..req.frames {
        // Receiver-clock time of the block's middle, taken as the trajectory's time (the
        // receiver clock's bias, ≤ ms, moves the platform by millimetres).
        let t_s = req.from_s + (j as f64 + 0.5) * t_frame;
        let truth = crate::engine::trial::truth_at(
            &world.frame,
            world.start,
            trajectory.as_ref(),
            SimTime::from_seconds(t_s),
        );
        let rx_bias_s = clock.bias_s(t_s) + clock.isb_s(System::Dtmb, t_s);
        links.clear();
        for (i, spec) in specs.iter().enumerate() {
            let l = tower_block(
                world, &mut link, i, spec, &truth, t_s, rx_bias_s, req.from_s,
            );
            if j == 0 && i == me && l.power > 0.0 {
                snr_first = l.snr_db;
            }
            links.push(l);
        }
        // Each signal's channel: the paths of its towers, scaled to their link budgets.
        for sg in signals.iter_mut() {
            let members: Vec<usize> = (0..specs.len())
                .filter(|&i| owner_of(i) == sg.owner)
                .collect();
            signal_paths(sg, &members, &links, mode, t_s)?;
        }
        // Sum the signals, then the noise once.
        let start = (j * n) as i64;
        block.iter_mut().for_each(|x| *x = Complex32::default());
        for sg in signals.iter_mut() {
            if sg.paths.is_empty() {
                continue;
            }
            let ch_cfg =
                ChannelConfig::from_oscillators(sg.paths.clone(), 0.0, rx_ppm, t.freq_hz, None);
            match sg.channel.as_mut() {
                Some(ch) => ch.set_paths(ch_cfg.paths, mode)?,
                None => sg.channel = Some(Channel::new(ch_cfg, mode, n)?),
            }
            let Some(ch) = sg.channel.as_mut() else {
                unreachable!("the channel was just built");
            };
            let out = &mut extra[..block.len()];
            ch.process(
                &mut Shifted {
                    tx: &mut sg.tx,
                    offset: sg.offset.unwrap_or(0),
                },
                start,
                out,
                &mut noise,
            )?;
            for (b, e) in block.iter_mut().zip(out.iter()) {
                *b += e;
            }
        }
        crate::dtmb::noise::add_awgn(&mut block, 1.0, &mut noise);
        for (l, spec) in links.iter().zip(&specs) {
            annotate_frame_starts(
                world,
                mode,
                spec,
                l,
                start,
                block.len(),
                n,
                eps,
                total,
                &truth,
                rx_bias_s,
                &mut annotations,
            );
        }
        sink(&block)?;
    }
    // SigMF lists annotations by sample; a tower's frames stay in order (stable sort).
    annotations.sort_by_key(|(a, _)| a.sample_start);
    let (annotations, annotation_extra): (Vec<_>, Vec<_>) = annotations.into_iter().unzip();
    let tower_ids: Vec<String> = group.iter().map(|o| o.id.clone()).collect();
    let g = global_extra(world, req, t, mode, &tower_ids);
    Ok(WorldIqMeta {
        samples: total as u64,
        annotations,
        annotation_extra,
        global_extra: g,
        center_freq_hz: t.freq_hz,
        mode,
        tower: t.id.clone(),
        towers: tower_ids,
        snr_db: snr_first,
    })
}

/// Writes [`world_iq`]'s recording as SigMF (`BASE.sigmf-data`, `.sigmf-meta`) block by
/// block, the output byte-identical to [`crate::dtmb::sigmf::write_sigmf_with`] of the
/// in-memory recording; a `ci8` recording is made twice, first for its peak (the scale),
/// the same samples both times (named random streams).
///
/// # Errors
/// As [`world_iq`] and [`SigmfWriter`].
pub fn write_world_sigmf(
    world: &World,
    req: &WorldIqRequest,
    base: &std::path::Path,
    format: SampleFormat,
) -> Result<WorldIqMeta, DtmbError> {
    let peak = match format {
        SampleFormat::Cf32 => 0.0,
        SampleFormat::Ci8 => {
            let mut peak = 0.0f32;
            world_iq_stream(world, req, &mut |b| {
                peak = peak.max(peak_component(b));
                Ok(())
            })?;
            peak
        }
    };
    // The carrier is known once the towers are chosen; the writer needs it up front.
    let (t, _) = select_towers(world, req)?;
    let mut w = SigmfWriter::create(base, format, SAMPLE_RATE_HZ, t.freq_hz, peak)?;
    let meta = world_iq_stream(world, req, &mut |b| w.write(b))?;
    w.finish(
        meta.annotations.iter().cloned(),
        &meta.annotation_extra,
        &meta.global_extra,
    )?;
    Ok(meta)
}

/// The id and header mode of the tower a request records, after checking the request as
/// [`world_iq`] does first (frame count, start and end inside the world's duration).
///
/// # Errors
/// As [`world_iq`]'s checks of the request.
pub fn requested_tower(world: &World, req: &WorldIqRequest) -> Result<(String, PnMode), DtmbError> {
    let (t, _) = select_towers(world, req)?;
    Ok((t.id.clone(), t.pn_mode()))
}

/// The link of a recording's towers as `World::build_trial` makes it: the trial's
/// random streams, trajectory and receiver clock, the towers' specs (`me` the requested
/// one) and the measurement-level source that computes each tower's paths and budget.
struct LinkSetup {
    rng: TrialRng,
    trajectory: Box<dyn crate::motion::Trajectory>,
    clock: Arc<crate::core::receiver_clock::ClockTrack>,
    specs: Vec<TowerSpec>,
    me: usize,
    link: DtmbSource,
    rx_ppm: f64,
}

fn link_setup(
    world: &World,
    req: &WorldIqRequest,
    t: &crate::world::scene::Transmitter,
    group: &[&crate::world::scene::Transmitter],
) -> Result<LinkSetup, DtmbError> {
    let rng = TrialRng::new(req.seed, req.trial);
    let trajectory = world
        .build_trajectory(&rng)
        .map_err(|e| bad("trajectory", e))?;
    // The receiver clock and the towers exactly as `World::build_trial` makes them (the
    // group shares one PN mode, checked by `select_towers`).
    let clock = Arc::new(world.receiver_clock(&rng));
    let specs: Vec<TowerSpec> = group.iter().map(|o| o.tower_spec(System::Dtmb)).collect();
    let me = group.iter().position(|o| o.id == t.id).unwrap_or(0);
    let mut cfg = world.file.sensors.dtmb.clone().unwrap_or_default();
    // The link needs no signal-level state of its own.
    cfg.level = DtmbLevel::Measurement;
    let rx_ppm = cfg.rx_oscillator_ppm;
    let link = DtmbSource::new(
        cfg,
        specs.clone(),
        world.scene.clone(),
        world.frame.clone(),
        Arc::clone(&clock),
        None,
        &rng,
        SimTime::from_seconds(world.duration_s),
    )
    .map_err(|i| bad("sensors.dtmb", format!("{}: {}", i.key, i.message)))?;
    Ok(LinkSetup {
        rng,
        trajectory,
        clock,
        specs,
        me,
        link,
        rx_ppm,
    })
}

/// One tower's multipath towards the receiver at one instant (`dtmb ber --world`).
#[derive(Clone, Debug)]
pub struct TowerChannel {
    /// The tower's id.
    pub tower: String,
    /// Its header mode.
    pub mode: PnMode,
    /// Its carrier (Hz).
    pub freq_hz: f64,
    /// The instant (seconds from the world's start, receiver clock).
    pub at_s: f64,
    /// Geometric range (m).
    pub range_m: f64,
    /// The link budget's SNR over 7.56 MHz of a free-space LoS path (dB).
    pub snr_ref_db: f64,
    /// The received SNR of the paths combined coherently (dB), as a recording annotates
    /// it (`hybridnav:snr_db`); `−∞` when the link is blocked.
    pub snr_db: f64,
    /// Per path: excess delay over the range (samples at 7.56 Msps) and complex gain
    /// relative to the link budget's reference.
    pub paths: Vec<(f64, Complex64)>,
    /// Per path (as `paths`): its Doppler shift (Hz) for the receiver's motion at that
    /// instant, as a recording applies it (the scene's per-path Dopplers, or without a
    /// scene the direct path's for every path).
    pub dopplers_hz: Vec<f64>,
    /// The receiver's oscillator error (ppm), the world's
    /// `sensors.dtmb.rx_oscillator_ppm` (0 without the section): with one reference for
    /// the local oscillator and the sample clock, a CFO of `−ppm·10⁻⁶ f_c` and a sample
    /// clock of `f_s(1 + ppm·10⁻⁶)`, as `dtmb iq --world` records.
    pub rx_oscillator_ppm: f64,
    /// The data layer's options of the tower's `[[transmitter]]`, each replaced by the
    /// request's (`qam`, `fec`, `interleaver`, `carriers`).
    pub qam: Option<String>,
    pub fec: Option<String>,
    pub interleaver: Option<usize>,
    pub carriers: Option<usize>,
}

/// The requested tower's paths and link budget at `req.from_s` (the block of one frame
/// there), computed as [`world_iq`] computes them for that block: the same trajectory,
/// clocks, scene paths and shadowing. Co-channel towers are not included.
///
/// # Errors
/// As [`world_iq`]'s checks of the request (frames = 1 suffices).
pub fn tower_channel_at(world: &World, req: &WorldIqRequest) -> Result<TowerChannel, DtmbError> {
    let (t, group) = select_towers(world, req)?;
    let mode = t.pn_mode();
    let LinkSetup {
        trajectory,
        clock,
        specs,
        me,
        mut link,
        rx_ppm,
        ..
    } = link_setup(world, req, t, &group)?;
    let t_s = req.from_s + 0.5 * mode.frame_duration_s();
    let truth = crate::engine::trial::truth_at(
        &world.frame,
        world.start,
        trajectory.as_ref(),
        SimTime::from_seconds(t_s),
    );
    let rx_bias_s = clock.bias_s(t_s) + clock.isb_s(System::Dtmb, t_s);
    let l = tower_block(
        world, &mut link, me, &specs[me], &truth, t_s, rx_bias_s, req.from_s,
    );
    let o = &req.data_layer;
    Ok(TowerChannel {
        tower: t.id.clone(),
        mode,
        freq_hz: t.freq_hz,
        at_s: t_s,
        range_m: l.range_m,
        snr_ref_db: l.snr_ref_db,
        snr_db: if l.taps.is_empty() {
            f64::NEG_INFINITY
        } else {
            l.snr_db
        },
        paths: l.taps.iter().map(|&(d, g, _)| (d, g)).collect(),
        dopplers_hz: l.taps.iter().map(|&(_, _, f)| f).collect(),
        rx_oscillator_ppm: rx_ppm,
        qam: o.qam.clone().or_else(|| t.spec.qam.clone()),
        fec: o.fec.clone().or_else(|| t.spec.fec.clone()),
        interleaver: o.interleaver.or(t.spec.interleaver),
        carriers: o.carriers.or(t.spec.carriers),
    })
}

/// Tower `i`'s link during the block whose middle is at `t_s` (receiver clock): its
/// range, link budget, clock and paths from the measurement-level link, with the received
/// power of its coherently combined paths.
#[allow(clippy::too_many_arguments)]
fn tower_block(
    world: &World,
    link: &mut DtmbSource,
    i: usize,
    spec: &TowerSpec,
    truth: &Truth,
    t_s: f64,
    rx_bias_s: f64,
    from_s: f64,
) -> TowerBlock {
    // Every tower of a recording is on the requested tower's carrier.
    let lambda = C_MPS / spec.freq_hz;
    let fs = SAMPLE_RATE_HZ;
    let (range_m, snr_ref_db, dopplers) = link.tower_link(i, truth);
    let tower_clock_s = spec.clock_offset_s + spec.clock_drift_s_per_s * t_s;
    let no_scene_doppler = if world.scene.is_none() {
        // The direct path's Doppler: the platform's velocity towards the tower.
        let u = (spec.pos_enu_m - truth.enu.pos_enu_m).normalize();
        truth.enu.vel_enu_mps.dot(&u) / lambda
    } else {
        0.0
    };
    let taps: Vec<(f64, Complex64, f64)> = link
        .taps()
        .iter()
        .enumerate()
        .filter(|(_, tp)| tp.gain.norm_sqr() > 0.0)
        .map(|(p, tp)| {
            let d = if world.scene.is_none() {
                no_scene_doppler
            } else {
                dopplers[p]
            };
            (tp.delay_samples, tp.gain, d)
        })
        .collect();
    // Received power: the paths combine coherently through the band's (flat)
    // autocorrelation, sinc of their delay difference in samples.
    let power: f64 = taps
        .iter()
        .flat_map(|a| taps.iter().map(move |b| (a, b)))
        .map(|(a, b)| (a.1 * b.1.conj()).re * sinc(a.0 - b.0))
        .sum();
    let snr_db = snr_ref_db + 10.0 * power.max(1e-30).log10();
    // x: transmitter sample minus recording sample of a path (no SFO).
    let base = fs * (from_s - rx_bias_s - range_m / C_MPS + tower_clock_s);
    let first_delay = taps.iter().map(|t| t.0).fold(f64::INFINITY, f64::min);
    TowerBlock {
        range_m,
        power,
        snr_ref_db,
        snr_db,
        tower_clock_s,
        base,
        first_delay,
        taps,
    }
}

/// Annotates every frame start (first path) of one tower inside the block of recording
/// samples `start .. start + len`: frame `k` starts at `n = (1 + ε)(k·N − x_first)`.
#[allow(clippy::too_many_arguments)]
fn annotate_frame_starts(
    world: &World,
    mode: PnMode,
    spec: &TowerSpec,
    l: &TowerBlock,
    start: i64,
    len: usize,
    n: usize,
    eps: f64,
    total: usize,
    truth: &Truth,
    rx_bias_s: f64,
    annotations: &mut Vec<(Annotation, Map<String, Value>)>,
) {
    if l.taps.is_empty() {
        return;
    }
    let x1 = l.base - l.first_delay;
    let lo = start as f64;
    let hi = lo + len as f64;
    let mut k = ((lo / (1.0 + eps) + x1) / n as f64).ceil() as i64;
    loop {
        let pos = (1.0 + eps) * (k as f64 * n as f64 - x1);
        if pos >= hi {
            break;
        }
        if pos >= lo {
            annotations.push(frame_annotation(
                world, mode, spec, l, k, pos, total, truth, rx_bias_s,
            ));
        }
        k += 1;
    }
}

/// The recording's `global` keys: a description, the world and trial it comes from,
/// the towers, the PN mode and the start.
fn global_extra(
    world: &World,
    req: &WorldIqRequest,
    t: &crate::world::scene::Transmitter,
    mode: PnMode,
    tower_ids: &[String],
) -> Map<String, Value> {
    let name = &world.file.world.name;
    let mut g = Map::new();
    g.insert(
        "core:description".into(),
        json!(format!(
            "DTMB (GB 20600-2006) tower {} ({}, {}){} as heard by the receiver of world \
             {name:?} trial {} seed {} from {} s, generated by hybridnav",
            t.id,
            mode.name(),
            t.spec
                .channel
                .map_or("no channel".into(), |c| format!("DS-{c}")),
            if tower_ids.len() > 1 {
                format!(" with its co-channel towers ({})", tower_ids.join(", "))
            } else {
                String::new()
            },
            req.trial,
            req.seed,
            req.from_s
        )),
    );
    g.insert("hybridnav:world".into(), json!(name));
    g.insert(
        "hybridnav:world_file".into(),
        json!(world.path.display().to_string()),
    );
    g.insert("hybridnav:world_hash".into(), json!(world.hash));
    g.insert("hybridnav:trial".into(), json!(req.trial));
    g.insert("hybridnav:seed".into(), json!(req.seed));
    g.insert("hybridnav:tower".into(), json!(t.id));
    g.insert("hybridnav:towers".into(), json!(tower_ids));
    // The receiver oscillator's error, as `dtmb iq` without a world records it.
    let ppm = world
        .file
        .sensors
        .dtmb
        .as_ref()
        .map_or(0.0, |d| d.rx_oscillator_ppm);
    if ppm != 0.0 {
        g.insert("hybridnav:rx_oscillator_ppm".into(), json!(ppm));
    }
    if let Some(net) = &t.spec.sfn {
        g.insert("hybridnav:sfn".into(), json!(net));
    }
    g.insert("hybridnav:pn_mode".into(), json!(mode.name()));
    g.insert("hybridnav:from_s".into(), json!(req.from_s));
    g.insert(
        "hybridnav:start_gpst".into(),
        json!(world.start.add_seconds(req.from_s).to_iso_gpst()),
    );
    g.insert("hybridnav:noise_power".into(), json!(1.0));
    g.insert("hybridnav:path_update".into(), json!("every frame"));
    g
}

/// A signal's channel in one block: the paths of its towers (`members`, the network's
/// towers or the lone tower), each scaled to its link budget and delayed relative to the
/// recording's offset, fixed by the first block with a path.
///
/// # Errors
/// When a path's delay has left the channel's window: the platform moved more than the
/// margin towards or away from the tower during the recording.
fn signal_paths(
    sg: &mut Signal,
    members: &[usize],
    links: &[TowerBlock],
    mode: PnMode,
    t_s: f64,
) -> Result<(), DtmbError> {
    let fs = SAMPLE_RATE_HZ;
    sg.paths.clear();
    let latest_x = members
        .iter()
        .flat_map(|&i| links[i].taps.iter().map(move |tp| (i, tp.0)))
        .map(|(i, d)| links[i].base - d)
        .fold(f64::NEG_INFINITY, f64::max);
    if sg.offset.is_none() && latest_x.is_finite() {
        sg.offset = Some((latest_x.ceil() + DELAY_MARGIN_SAMPLES) as i64);
    }
    let off = sg.offset.unwrap_or(0) as f64;
    for &i in members {
        let l = &links[i];
        let amp = (10f64.powf(l.snr_ref_db / 10.0) / mode.nominal_frame_power()).sqrt();
        for &(d, g, dop) in &l.taps {
            sg.paths.push(Path {
                delay_s: (off - (l.base - d)) / fs,
                gain: g * amp,
                doppler_hz: dop,
                delay_rate: 0.0,
            });
        }
    }
    if let Some(p) = sg
        .paths
        .iter()
        .find(|p| !(p.delay_s >= 0.0 && p.delay_s < 1.0))
    {
        return Err(bad(
            "from_s",
            format!(
                "at {t_s:.4} s the path delay moved {:.0} samples from the recording's \
                 start, beyond the {DELAY_MARGIN_SAMPLES} samples of margin: record fewer frames",
                p.delay_s * fs - DELAY_MARGIN_SAMPLES
            ),
        ));
    }
    Ok(())
}

/// The requested tower (the world's first DTMB tower by default) and every DTMB tower on
/// its carrier, in the world file's order, after checking the request: a frame count in
/// range, a recording inside the world's duration, one PN mode on the carrier.
fn select_towers<'w>(
    world: &'w World,
    req: &WorldIqRequest,
) -> Result<
    (
        &'w crate::world::scene::Transmitter,
        Vec<&'w crate::world::scene::Transmitter>,
    ),
    DtmbError,
> {
    let towers: Vec<_> = world
        .transmitters
        .iter()
        .filter(|t| t.kind == TransmitterKind::Dtmb)
        .collect();
    let name = &world.file.world.name;
    let Some(first) = towers.first() else {
        return Err(bad(
            "world",
            format!(
                "world {name:?} ({}) has no DTMB tower ([[transmitter]] with kind = \"dtmb\")",
                world.path.display()
            ),
        ));
    };
    let t = match &req.tower {
        None => *first,
        Some(id) => *towers
            .iter()
            .find(|t| t.id.eq_ignore_ascii_case(id))
            .ok_or_else(|| {
                let ids: Vec<&str> = towers.iter().map(|t| t.id.as_str()).collect();
                bad(
                    "tower",
                    format!(
                        "world {name:?} has no DTMB tower {id:?}; its DTMB towers are {}",
                        ids.join(", ")
                    ),
                )
            })?,
    };
    if req.frames == 0 || req.frames > MAX_FRAMES {
        return Err(bad(
            "frames",
            format!("must lie in 1..={MAX_FRAMES}, got {}", req.frames),
        ));
    }
    let mode = t.pn_mode();
    let t_frame = mode.frame_duration_s();
    let dur = world.duration_s;
    if !(req.from_s.is_finite() && req.from_s >= 0.0 && req.from_s < dur) {
        return Err(bad(
            "from_s",
            format!(
                "start {} s is outside the world's duration [0, {dur}) s",
                req.from_s
            ),
        ));
    }
    let end_s = req.from_s + req.frames as f64 * t_frame;
    if end_s > dur {
        return Err(bad(
            "from_s",
            format!(
                "{} frames from {} s end at {end_s:.4} s, after the world's duration {dur} s",
                req.frames, req.from_s
            ),
        ));
    }
    // The requested tower and every DTMB tower on its carrier.
    let group: Vec<_> = towers
        .iter()
        .filter(|o| o.freq_hz == t.freq_hz)
        .copied()
        .collect();
    if let Some(o) = group.iter().find(|o| o.pn_mode() != mode) {
        return Err(bad(
            "tower",
            format!(
                "towers {} ({}) and {} ({}) share {:.0} MHz with different PN modes; a \
                 recording holds one frame structure",
                t.id,
                mode.name(),
                o.id,
                o.pn_mode().name(),
                t.freq_hz * 1e-6
            ),
        ));
    }
    Ok((t, group))
}

/// One transmitted signal of a recording: a network's (or a lone tower's) transmitter,
/// the channel of its towers' paths, and the transmitter-sample offset of the recording.
struct Signal {
    owner: usize,
    tx: Transmitter,
    channel: Option<Channel>,
    offset: Option<i64>,
    paths: Vec<Path>,
}

/// One tower's link during one block.
struct TowerBlock {
    range_m: f64,
    /// Received power of the combined paths relative to the link budget's.
    power: f64,
    snr_ref_db: f64,
    snr_db: f64,
    tower_clock_s: f64,
    /// Transmitter sample minus recording sample of a path with no excess delay.
    base: f64,
    first_delay: f64,
    /// (excess delay in samples, gain, Doppler in Hz) per path.
    taps: Vec<(f64, Complex64, f64)>,
}

/// The annotation of frame `k` of one tower, whose first path starts at recording sample
/// `pos`, with its `hybridnav:` keys.
#[allow(clippy::too_many_arguments)]
fn frame_annotation(
    world: &World,
    mode: PnMode,
    spec: &TowerSpec,
    l: &TowerBlock,
    k: i64,
    pos: f64,
    total: usize,
    truth: &crate::measurement::Truth,
    rx_bias_s: f64,
) -> (Annotation, Map<String, Value>) {
    let n = mode.frame_len();
    let s0 = pos.round().min((total - 1) as f64) as u64;
    let fis = k.rem_euclid(mode.frames_per_superframe() as i64) as usize;
    let phase = mode.phase_of_frame(fis);
    let emission = world
        .start
        .add_seconds(k as f64 * mode.frame_duration_s() - l.tower_clock_s);
    let ann = Annotation {
        sample_start: s0,
        sample_count: (n as u64).min(total as u64 - s0),
        label: format!("{} frame {k} {} phase {phase}", spec.id, mode.name()),
    };
    let mut m = Map::new();
    m.insert("hybridnav:tower".into(), json!(spec.id.to_string()));
    m.insert("hybridnav:frame".into(), json!(k));
    m.insert("hybridnav:frame_in_superframe".into(), json!(fis));
    m.insert("hybridnav:pn_phase".into(), json!(phase));
    m.insert("hybridnav:emission_gps_week".into(), json!(emission.week()));
    m.insert(
        "hybridnav:emission_gps_tow_s".into(),
        json!(emission.tow_s()),
    );
    m.insert(
        "hybridnav:emission_gpst".into(),
        json!(emission.to_iso_gpst()),
    );
    m.insert("hybridnav:first_path_sample".into(), json!(pos));
    m.insert(
        "hybridnav:first_path_excess_delay_samples".into(),
        json!(l.first_delay),
    );
    m.insert("hybridnav:range_m".into(), json!(l.range_m));
    m.insert(
        "hybridnav:pseudorange_m".into(),
        json!(l.range_m + C_MPS * (rx_bias_s - l.tower_clock_s)),
    );
    m.insert("hybridnav:snr_db".into(), json!(l.snr_db));
    m.insert("hybridnav:snr_ref_db".into(), json!(l.snr_ref_db));
    // Each path: excess delay (samples), power relative to the first (dB), phase (rad),
    // Doppler (Hz).
    let g0 = l
        .taps
        .iter()
        .find(|t| t.0 == l.first_delay)
        .map_or(1.0, |t| t.1.norm_sqr());
    let paths: Vec<Value> = l
        .taps
        .iter()
        .map(|(d, g, dop)| json!([d, 10.0 * (g.norm_sqr() / g0).log10(), g.arg(), dop]))
        .collect();
    m.insert("hybridnav:paths".into(), Value::Array(paths));
    let p = truth.enu.pos_enu_m;
    m.insert("hybridnav:platform_enu_m".into(), json!([p.x, p.y, p.z]));
    (ann, m)
}

/// The transmitter of the tower `id`: with a data layer when its `[[transmitter]]` names a
/// profile or payload (`qam`, `fec`, `interleaver`, `carriers`, `payload`; the payload path
/// relative to the world file) or `overrides` gives one (each of its options replacing the
/// table's), else random bodies.
fn owner_transmitter(
    world: &World,
    tower: &TowerSpec,
    tx_cfg: TxConfig,
    rng: &TrialRng,
    overrides: Option<&DataLayerOverride>,
) -> Result<Transmitter, DtmbError> {
    let mut stream = rng.stream(&format!("dtmb/{}/tx", tower.id));
    let none = DataLayerOverride::default();
    let o = overrides.unwrap_or(&none);
    let own = world
        .transmitters
        .iter()
        .find(|t| t.kind == TransmitterKind::Dtmb && t.tower_spec(System::Dtmb).id == tower.id);
    let id = own.map_or_else(|| tower.id.to_string(), |t| t.id.clone());
    let spec = own.map(|t| &t.spec);
    let payload = o.payload.clone().or_else(|| {
        spec.and_then(|s| s.payload.as_ref()).map(|p| {
            world
                .path
                .parent()
                .map(|d| d.join(p))
                .unwrap_or_else(|| std::path::PathBuf::from(p))
        })
    });
    let layer = crate::dtmb::data_layer::data_layer_from_options(
        payload.as_deref(),
        o.qam.as_deref().or(spec.and_then(|s| s.qam.as_deref())),
        o.fec.as_deref().or(spec.and_then(|s| s.fec.as_deref())),
        o.interleaver.or(spec.and_then(|s| s.interleaver)),
        o.carriers.or(spec.and_then(|s| s.carriers)),
    )
    .map_err(|e| bad("transmitter data layer", format!("transmitter {id}: {e}")))?;
    Ok(match layer {
        Some(l) => Transmitter::with_data_layer_from(tx_cfg, l, None, &mut stream),
        None => Transmitter::new(tx_cfg, &mut stream),
    })
}
