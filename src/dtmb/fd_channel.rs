//! The frequency-domain implementation of the multipath channel ([`super::Channel`]).
//!
//! **What it computes.** The channel of [`super::channel`] gives receiver sample `n`
//!
//! ```text
//! y[n] = Σ_p g_p e^{j2π(f_p + Δf) n r / f_s} x(n r − τ_p f_s),   r = 1/(1 + ε),
//! ```
//!
//! with `x(u) = Σ_m x[m] φ(u − m)` the windowed-sinc waveform. Write `d_p(n) = n − (n r −
//! τ_p f_s) = n ε' + τ_p f_s` (`ε' = 1 − r`) for the delay in samples; then
//! `x(n − d_p) = Σ_j h_p[j] x[n − j]` with the FIR `h_p[j] = φ(j − d_p)` (32 taps).
//!
//! **Block algorithm (overlap-save).** Output sub-blocks of `B` samples with centre `n_c`.
//! Against a base instant `n_b` at which the taps are built, the delay is
//! `d_p(n) = d_p(n_b) + δ(n)`, `δ(n) = ε'(n − n_b)`, and the path's carrier phase, after a
//! common rotation at `f_c` is taken out exactly per sample, is
//! `c_p e^{jω_p (n − n_c)}` with `c_p = g_p e^{j2π f_p,res r n_c / f_s}`,
//! `ω_p = 2π f_p,res r / f_s`, `f_p,res = f_p + Δf − f_c`. To first order in the small
//! quantities `ω_p (n − n_c)` and `δ(n)`,
//!
//! ```text
//! y[n] ≈ e^{j2π f_c n r/f_s} { Σ_p c_p [x_p − δ_c x'_p] + (n − n_c) Σ_p c_p [jω_p x_p − ε' x'_p] }
//! ```
//!
//! with `x_p = x(n − d_p(n_b))`, `x'_p` its derivative (FIR taps `φ'(j − d_p)`) and
//! `δ_c = δ(n_c)`. Both braces are LTI filters of `x`, so one forward FFT of the input
//! segment, two spectral products `X·H₀`, `X·H₁` with `H₀ = Σ c_p (D_p − δ_c D'_p)`,
//! `H₁ = Σ c_p (jω_p D_p − ε' D'_p)` (`D_p`, `D'_p` the DFTs of the taps, computed once per
//! base) and two inverse FFTs give the whole sub-block. The per-path spectra are exact DFTs
//! of the FIR taps, so there is no circular-shift approximation; the only approximations
//! are the dropped second-order terms: `(ω_p B/2)²/2 ≤ 1.25·10⁻³` (the sub-block is
//! shortened until `|ω_p| B/2 ≤ 0.05`) and `δ²|x''|/2` with `|δ| ≤ 0.02` samples (the
//! base is rebuilt when the SFO drift exceeds it), about −60 dB relative to the signal
//! (tested against the time-domain reference).

use super::channel::{kernel, ChannelConfig, KERNEL_HALF_WIDTH};
use super::pn::SAMPLE_RATE_HZ;
use super::transmitter::SampleSource;
use num_complex::{Complex32, Complex64};
use rustfft::{Fft, FftPlanner};
use std::f64::consts::PI;
use std::sync::Arc;

/// Largest residual Doppler phase excursion over half a sub-block (rad).
const MAX_HALF_PHASE_RAD: f64 = 0.05;
/// Largest SFO delay drift from the base before the per-path spectra are rebuilt (samples).
const MAX_DRIFT_SAMPLES: f64 = 0.02;
/// Below this many outputs per sub-block the frequency-domain path is not worth it.
pub(crate) const MIN_SUB_BLOCK: usize = 32;
/// Step of the central difference for the kernel derivative (samples).
const DERIV_STEP: f64 = 1e-5;

/// `φ'(u)` by a central difference (truncation ~1e-10, far below f32).
fn kernel_derivative(u: f64) -> f64 {
    (kernel(u + DERIV_STEP) - kernel(u - DERIV_STEP)) / (2.0 * DERIV_STEP)
}

/// State of the frequency-domain channel: plans, per-path spectra and work buffers.
pub(crate) struct FdChannel {
    n: usize,
    fwd: Arc<dyn Fft<f32>>,
    inv: Arc<dyn Fft<f32>>,
    scratch: Vec<Complex32>,
    /// The base receiver sample `n_b` of the spectra, `None` before the first build.
    base: Option<f64>,
    /// Tap index range of the combined filter at the base.
    j_lo: i64,
    j_hi: i64,
    /// Per path `p`, four arrays of `n` values at `4pn + qn`: Re D, Im D, Re D', Im D'
    /// (split so the per-bin loop over paths vectorises across bins).
    spectra: Vec<f32>,
    seg: Vec<Complex32>,
    y1: Vec<Complex32>,
    /// Common rotation frequency and per-path residual Doppler (Hz).
    f_common_hz: f64,
    f_res_hz: Vec<f64>,
    /// Longest sub-block the Doppler bound allows.
    max_valid: usize,
}

impl std::fmt::Debug for FdChannel {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FdChannel")
            .field("n", &self.n)
            .finish_non_exhaustive()
    }
}

impl Clone for FdChannel {
    fn clone(&self) -> Self {
        Self {
            n: self.n,
            fwd: Arc::clone(&self.fwd),
            inv: Arc::clone(&self.inv),
            scratch: self.scratch.clone(),
            base: self.base,
            j_lo: self.j_lo,
            j_hi: self.j_hi,
            spectra: self.spectra.clone(),
            seg: self.seg.clone(),
            y1: self.y1.clone(),
            f_common_hz: self.f_common_hz,
            f_res_hz: self.f_res_hz.clone(),
            max_valid: self.max_valid,
        }
    }
}

impl FdChannel {
    /// The FFT size, common rotation, residual Dopplers and longest sub-block for `cfg`,
    /// or `None` when the paths' Doppler spread or the SFO would force sub-blocks too
    /// short for the frequency domain to pay.
    fn plan(cfg: &ChannelConfig) -> Option<(usize, f64, Vec<f64>, usize)> {
        let (dmin, dmax) = cfg.paths.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            (a.min(p.delay_s), b.max(p.delay_s))
        });
        let span = ((dmax - dmin) * SAMPLE_RATE_HZ).ceil() as usize;
        let taps_max = span + 2 * KERNEL_HALF_WIDTH + 2;
        let n = (4 * taps_max).next_power_of_two().clamp(512, 1 << 16);
        let (fmin, fmax) = cfg.paths.iter().fold((f64::MAX, f64::MIN), |(a, b), p| {
            (a.min(p.doppler_hz), b.max(p.doppler_hz))
        });
        let f_mid = 0.5 * (fmin + fmax);
        let f_common_hz = cfg.cfo_hz + f_mid;
        let f_res_hz: Vec<f64> = cfg.paths.iter().map(|p| p.doppler_hz - f_mid).collect();
        let r = 1.0 / (1.0 + cfg.sfo_ppm * 1e-6);
        let eps = (1.0 - r).abs();
        let w_max =
            f_res_hz.iter().fold(0.0f64, |a, f| a.max(f.abs())) * 2.0 * PI * r / SAMPLE_RATE_HZ;
        let mut max_valid = n.checked_sub(taps_max)?;
        if w_max > 0.0 {
            max_valid = max_valid.min((2.0 * MAX_HALF_PHASE_RAD / w_max) as usize);
        }
        if eps > 0.0 {
            max_valid = max_valid.min((2.0 * MAX_DRIFT_SAMPLES / eps) as usize);
        }
        (max_valid >= MIN_SUB_BLOCK && cfg.paths.len() <= MAX_FD_PATHS).then_some((
            n,
            f_common_hz,
            f_res_hz,
            max_valid,
        ))
    }

    /// Plans the engine for `cfg` (see [`FdChannel::plan`]).
    pub(crate) fn new(cfg: &ChannelConfig) -> Option<Self> {
        let (n, f_common_hz, f_res_hz, max_valid) = Self::plan(cfg)?;
        let mut planner = FftPlanner::<f32>::new();
        let fwd = planner.plan_fft_forward(n);
        let inv = planner.plan_fft_inverse(n);
        let scratch_len = fwd
            .get_inplace_scratch_len()
            .max(inv.get_inplace_scratch_len());
        let zeros = vec![Complex32::default(); n];
        Some(Self {
            n,
            fwd,
            inv,
            scratch: vec![Complex32::default(); scratch_len],
            base: None,
            j_lo: 0,
            j_hi: 0,
            spectra: vec![0.0; 4 * n * cfg.paths.len()],
            seg: zeros.clone(),
            y1: zeros,
            f_common_hz,
            f_res_hz,
            max_valid,
        })
    }

    /// Adapts the engine to new paths (a moving receiver), keeping the FFT plans and
    /// buffers when the FFT size is unchanged; returns `false` when the frequency domain
    /// does not suit `cfg` (the caller then uses the time-domain reference).
    pub(crate) fn reconfigure(&mut self, cfg: &ChannelConfig) -> bool {
        let Some((n, f_common_hz, f_res_hz, max_valid)) = Self::plan(cfg) else {
            return false;
        };
        if n != self.n {
            match Self::new(cfg) {
                Some(fresh) => *self = fresh,
                None => return false,
            }
            return true;
        }
        self.spectra.resize(4 * n * cfg.paths.len(), 0.0);
        self.f_common_hz = f_common_hz;
        self.f_res_hz = f_res_hz;
        self.max_valid = max_valid;
        self.base = None;
        true
    }

    /// Rebuilds the per-path tap spectra at base receiver sample `n_b`.
    fn rebuild(&mut self, cfg: &ChannelConfig, n_b: f64) {
        let r = 1.0 / (1.0 + cfg.sfo_ppm * 1e-6);
        let eps = 1.0 - r;
        let k = KERNEL_HALF_WIDTH as i64;
        let delays: Vec<f64> = cfg
            .paths
            .iter()
            .map(|p| n_b * eps + p.delay_s * SAMPLE_RATE_HZ)
            .collect();
        let (dmin, dmax) = delays
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &d| (a.min(d), b.max(d)));
        self.j_lo = dmin.floor() as i64 - k + 1;
        self.j_hi = dmax.floor() as i64 + k;
        let n = self.n;
        for (p, &d) in delays.iter().enumerate() {
            // One complex FFT carries both real tap sets: F = DFT(h + j h'), and by
            // Hermitian symmetry D = (F[k] + F*[−k])/2, D' = (F[k] − F*[−k])/(2j).
            let buf = &mut self.seg;
            buf.iter_mut().for_each(|x| *x = Complex32::default());
            let first = d.floor() as i64 - k + 1;
            for j in first..first + 2 * k {
                let t = j as f64 - d;
                buf[(j - self.j_lo) as usize] =
                    Complex32::new(kernel(t) as f32, kernel_derivative(t) as f32);
            }
            self.fwd.process_with_scratch(buf, &mut self.scratch);
            let sp = &mut self.spectra[4 * n * p..4 * n * (p + 1)];
            for kk in 0..n {
                let a = buf[kk];
                let b = buf[(n - kk) % n].conj();
                let d = (a + b) * 0.5;
                let diff = (a - b) * 0.5;
                sp[kk] = d.re;
                sp[n + kk] = d.im;
                sp[2 * n + kk] = diff.im;
                sp[3 * n + kk] = -diff.re;
            }
        }
        self.base = Some(n_b);
    }

    /// The longest sub-block the plan allows for the current taps.
    fn valid_len(&self) -> usize {
        let taps = (self.j_hi - self.j_lo + 1) as usize;
        (self.n - taps + 1).min(self.max_valid)
    }

    /// Fills `out` with the noiseless channel output for receiver samples
    /// `rx_start .. rx_start + out.len()`.
    pub(crate) fn process<S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
    ) {
        #[cfg(target_arch = "x86_64")]
        {
            if std::arch::is_x86_feature_detected!("avx2") {
                // SAFETY: the CPU supports AVX2, checked just above.
                unsafe { self.process_avx2(cfg, src, rx_start, out) };
                return;
            }
        }
        self.process_impl(cfg, src, rx_start, out);
    }

    /// [`FdChannel::process_impl`] compiled for AVX2: the spectral loops run eight lanes
    /// wide. The arithmetic is element-wise, so results equal the baseline build's.
    ///
    /// # Safety
    /// The CPU must support AVX2.
    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    unsafe fn process_avx2<S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
    ) {
        self.process_impl(cfg, src, rx_start, out);
    }

    #[inline(always)]
    fn process_impl<S: SampleSource + ?Sized>(
        &mut self,
        cfg: &ChannelConfig,
        src: &mut S,
        rx_start: i64,
        out: &mut [Complex32],
    ) {
        let r = 1.0 / (1.0 + cfg.sfo_ppm * 1e-6);
        let eps = 1.0 - r;
        let n = self.n;
        let inv_n = 1.0 / n as f32;
        let mut pos = 0usize;
        while pos < out.len() {
            let n0 = rx_start + pos as i64;
            // The sub-block length is bounded by the taps of the current base; a rebuild
            // can change the taps by one, so take the bound after any rebuild.
            let mut b_len = (out.len() - pos).min(self.max_valid);
            let mut n_c = n0 as f64 + (b_len as f64 - 1.0) / 2.0;
            let needs_base = match self.base {
                None => true,
                Some(nb) => {
                    let lo = eps * (n0 as f64 - nb);
                    let hi = eps * ((n0 + b_len as i64 - 1) as f64 - nb);
                    lo.abs() > MAX_DRIFT_SAMPLES || hi.abs() > MAX_DRIFT_SAMPLES
                }
            };
            if needs_base {
                self.rebuild(cfg, n_c);
            }
            let valid = self.valid_len();
            if b_len > valid {
                b_len = valid;
                n_c = n0 as f64 + (b_len as f64 - 1.0) / 2.0;
            }
            let n_b = self.base.unwrap_or(n_c);
            let taps = (self.j_hi - self.j_lo + 1) as usize;
            src.generate(n0 - self.j_hi, &mut self.seg);
            self.fwd
                .process_with_scratch(&mut self.seg, &mut self.scratch);

            let delta_c = (eps * (n_c - n_b)) as f32;
            let eps32 = eps as f32;
            let want_b = eps != 0.0;
            let want_c = self.f_res_hz.iter().any(|&f| f != 0.0);
            let want_y1 = want_b || want_c;
            // Per path: the complex gain at the centre and ω.
            let np = cfg.paths.len();
            let mut coef = [(0f32, 0f32, 0f32); MAX_FD_PATHS];
            for (p, path) in cfg.paths.iter().enumerate() {
                let f_res = self.f_res_hz[p];
                let cycles = (f_res * r * n_c / SAMPLE_RATE_HZ).fract();
                let c = path.gain * Complex64::from_polar(1.0, 2.0 * PI * cycles);
                let w = (2.0 * PI * f_res * r / SAMPLE_RATE_HZ) as f32;
                coef[p] = (c.re as f32, c.im as f32, w);
            }
            // One pass over the bins: for 8 bins at a time, A = Σ c D, B = Σ c D',
            // C = Σ jω c D in registers, then Y0 = X (A − δ_c B)/N, Y1 = X (C − ε' B)/N.
            let spectra = &self.spectra;
            for ((k0, xs), ys) in (0..n)
                .step_by(LANES)
                .zip(self.seg.chunks_exact_mut(LANES))
                .zip(self.y1.chunks_exact_mut(LANES))
            {
                let mut ar = [0f32; LANES];
                let mut ai = [0f32; LANES];
                let mut br = [0f32; LANES];
                let mut bi = [0f32; LANES];
                let mut cr = [0f32; LANES];
                let mut ci = [0f32; LANES];
                for (p, &(gr, gi, w)) in coef[..np].iter().enumerate() {
                    let base = 4 * n * p + k0;
                    let dr = &spectra[base..base + LANES];
                    let di = &spectra[base + n..base + n + LANES];
                    let er = &spectra[base + 2 * n..base + 2 * n + LANES];
                    let ei = &spectra[base + 3 * n..base + 3 * n + LANES];
                    for l in 0..LANES {
                        let tr = gr * dr[l] - gi * di[l];
                        let ti = gr * di[l] + gi * dr[l];
                        ar[l] += tr;
                        ai[l] += ti;
                        cr[l] -= w * ti;
                        ci[l] += w * tr;
                        br[l] += gr * er[l] - gi * ei[l];
                        bi[l] += gr * ei[l] + gi * er[l];
                    }
                }
                for l in 0..LANES {
                    let x = xs[l] * inv_n;
                    let h0 = Complex32::new(ar[l] - delta_c * br[l], ai[l] - delta_c * bi[l]);
                    let h1 = Complex32::new(cr[l] - eps32 * br[l], ci[l] - eps32 * bi[l]);
                    xs[l] = x * h0;
                    ys[l] = x * h1;
                }
            }
            if want_y1 {
                self.inv
                    .process_with_scratch(&mut self.y1, &mut self.scratch);
            }
            self.inv
                .process_with_scratch(&mut self.seg, &mut self.scratch);

            // Combine, then rotate by the common frequency.
            let first = taps - 1;
            let dst = &mut out[pos..pos + b_len];
            let y0 = &self.seg[first..first + b_len];
            let y1 = &self.y1[first..first + b_len];
            let off0 = (n0 as f64 - n_c) as f32;
            if want_y1 {
                for (i, ((o, a), b)) in dst.iter_mut().zip(y0).zip(y1).enumerate() {
                    *o = a + b * (off0 + i as f32);
                }
            } else {
                dst.copy_from_slice(y0);
            }
            if self.f_common_hz != 0.0 {
                rotate(dst, n0, self.f_common_hz * r / SAMPLE_RATE_HZ);
            }
            pos += b_len;
        }
    }
}

/// Lanes of the vectorised loops (the FFT sizes are powers of two ≥ 512, multiples of it).
const LANES: usize = 8;
/// Most paths the frequency-domain engine takes (more use the time-domain reference).
pub(crate) const MAX_FD_PATHS: usize = 32;
/// Samples between restarts of the f32 phasors from f64.
const ROT_RESTART: usize = 512;

/// Multiplies `v[i]` by `e^{j2π f (n0 + i)}` (`f` in cycles per sample). Eight phasors,
/// one per lane, advance by `e^{j2π·8f}` so the loop vectorises; every 512 samples they
/// restart from f64 phases so the f32 rounding never accumulates beyond ~64 steps
/// (relative error ~1e-6).
#[inline(always)]
pub(crate) fn rotate(v: &mut [Complex32], n0: i64, f_cycles: f64) {
    let step = Complex64::from_polar(1.0, 2.0 * PI * f_cycles * LANES as f64);
    let (sr, si) = (step.re as f32, step.im as f32);
    for (ci, chunk) in v.chunks_mut(ROT_RESTART).enumerate() {
        let m0 = n0 + (ci * ROT_RESTART) as i64;
        let mut pr = [0f32; LANES];
        let mut pi = [0f32; LANES];
        for l in 0..LANES {
            let cycles = (f_cycles * (m0 + l as i64) as f64).fract();
            let z = Complex64::from_polar(1.0, 2.0 * PI * cycles);
            pr[l] = z.re as f32;
            pi[l] = z.im as f32;
        }
        let mut it = chunk.chunks_exact_mut(LANES);
        for group in &mut it {
            for l in 0..LANES {
                let x = group[l];
                group[l] = Complex32::new(x.re * pr[l] - x.im * pi[l], x.re * pi[l] + x.im * pr[l]);
                let nr = pr[l] * sr - pi[l] * si;
                pi[l] = pr[l] * si + pi[l] * sr;
                pr[l] = nr;
            }
        }
        for (l, x) in it.into_remainder().iter_mut().enumerate() {
            *x = Complex32::new(x.re * pr[l] - x.im * pi[l], x.re * pi[l] + x.im * pr[l]);
        }
    }
}
