//! The particle-filter family against independent truths: the Kalman filter (the exact
//! posterior and the PCRLB of a linear-Gaussian model) as the particle count grows, no
//! allocation per epoch (a counting allocator), and bad world input refused with
//! file:line:column and the allowed range.

use crate::common::repo;
use hybridnav::core::{StreamRng, System, TrialRng};
use hybridnav::fusion::kalman::Ekf;
use hybridnav::fusion::models::{
    ConstantVelocity, MeasurementModel, PositionFixModel, Pseudoranges, RangeRow, StateLayout,
};
use hybridnav::fusion::particle::{
    KernelPlacement, ParticleBuffer, ParticleFilter, PseudorangeLikelihood, Resampling,
};
use hybridnav::fusion::pcrlb::bound_sequence;
use nalgebra::{DMatrix, SMatrix, SVector, Vector3};
use rand::Rng;
use rand_distr::StandardNormal;
use std::alloc::{GlobalAlloc, Layout, System as SystemAlloc};
use std::cell::Cell;
use std::process::Command;

/// Counts the allocations of the current thread (tests run on their own threads).
struct Counting;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

// SAFETY: every call is forwarded to the system allocator unchanged; the counter is a
// const-initialised thread-local `Cell`, whose access does not allocate.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded with the caller's layout.
        unsafe { SystemAlloc.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's pointer and layout.
        unsafe { SystemAlloc.dealloc(ptr, layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.with(|c| c.set(c.get() + 1));
        // SAFETY: forwarded with the caller's arguments.
        unsafe { SystemAlloc.realloc(ptr, layout, new_size) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

type V4 = SVector<f64, 4>;
type M4 = SMatrix<f64, 4, 4>;

fn normal4(rng: &mut StreamRng) -> V4 {
    V4::from_fn(|_, _| rng.sample(StandardNormal))
}

/// The members of the family that run on a position-and-clock state, on the same buffers.
fn family(n: usize) -> [ParticleFilter<4>; 8] {
    let make =
        |scheme| ParticleFilter::new(ParticleBuffer::<4>::new(n).unwrap(), scheme, 0.5).unwrap();
    [
        make(Resampling::Systematic),
        make(Resampling::Stratified).regularised(),
        make(Resampling::Residual)
            .rao_blackwellised(std::array::from_fn(|s| {
                (s == System::Dtmb.index()).then_some(3)
            }))
            .unwrap(),
        make(Resampling::Systematic).gaussian(),
        make(Resampling::Systematic)
            .regularised()
            .with_progressive_correction(true),
        make(Resampling::Systematic)
            .with_progressive_correction(true)
            .rao_blackwellised(std::array::from_fn(|s| {
                (s == System::Dtmb.index()).then_some(3)
            }))
            .unwrap(),
        make(Resampling::Systematic)
            .regularised()
            .with_kernel(KernelPlacement::Plain),
        make(Resampling::Systematic)
            .regularised()
            .with_kernel(KernelPlacement::ShrunkStatic)
            .with_static_components([false, false, false, true]),
    ]
}

/// No member of the family allocates in an epoch (predict, the linearised proposal,
/// weight by ranges, resample with or without the kernel, moments) once built: SIR,
/// regularised (with each kernel placement) and Rao-Blackwellised (also with progressive
/// correction), Gaussian (its prediction factors the cloud's covariance and redraws it;
/// its linearised update factors the EKF update) and marginalised.
#[test]
fn no_particle_filter_allocates_per_epoch() {
    let layout = StateLayout {
        pos: [Some(0), Some(1), Some(2)],
        vel: [None; 3],
        clock: std::array::from_fn(|s| (s == System::Dtmb.index()).then_some(3)),
        isb: [None; System::COUNT],
        drift: None,
    };
    let rows: Vec<RangeRow> = [
        (3000.0, 0.0),
        (0.0, 4000.0),
        (-2500.0, -2500.0),
        (800.0, -3900.0),
    ]
    .iter()
    .map(|&(x, y)| RangeRow {
        emitter_pos_m: Vector3::new(x, y, 300.0),
        emitter_vel_mps: Vector3::zeros(),
        system: System::Dtmb,
        sigma_m: 5.0,
        sigma_rate_mps: 1.0,
    })
    .collect();
    let model = ConstantVelocity::<4>::new(0.5).unwrap();
    let truth = Vector3::new(10.0, 20.0, 0.0);
    for mut pf in family(2000) {
        let mut rng = TrialRng::new(3, 0).stream("test/alloc");
        pf.init_gaussian(
            &V4::new(0.0, 0.0, 0.0, 50.0),
            &M4::from_diagonal(&V4::new(400.0, 400.0, 1.0, 100.0)),
            &mut rng,
        )
        .unwrap();
        let mut lik = PseudorangeLikelihood::with_capacity(rows.len());
        // A warm-up epoch, then the counted ones.
        let mut epoch = |pf: &mut ParticleFilter<4>, rng: &mut StreamRng| {
            pf.predict(&model, 1.0, rng).unwrap();
            lik.clear(layout.pos);
            for r in &rows {
                let n: f64 = rng.sample(StandardNormal);
                lik.push(
                    &layout,
                    r,
                    (r.emitter_pos_m - truth).norm() + 50.0 + 5.0 * n,
                );
            }
            // The linearised proposal (the Gaussian filter's from its kept prediction),
            // then the bootstrap weights on the same ranges.
            let q = hybridnav::fusion::models::ProcessModel::q(&model, &pf.mean(), 1.0);
            pf.update_linearised(&q, &lik, rng).unwrap();
            pf.update_ranges(&lik, rng);
            pf.resample(rng);
            pf.resample_regularised(rng);
            std::hint::black_box((pf.mean(), pf.covariance(), pf.n_eff()));
        };
        epoch(&mut pf, &mut rng);
        let before = allocations();
        for _ in 0..20 {
            epoch(&mut pf, &mut rng);
        }
        assert_eq!(allocations() - before, 0, "{:?} allocated", pf.variant());
    }
    // The marginalised filter needs states the ranges do not see: 2-D constant velocity
    // (x, ẋ, y, ẏ), positions sampled, velocities by the per-particle Kalman filters.
    let layout2 = StateLayout {
        pos: [Some(0), Some(2), None],
        vel: [Some(1), Some(3), None],
        clock: [None; System::COUNT],
        isb: [None; System::COUNT],
        drift: None,
    };
    let cv2 = ConstantVelocity::<4>::new(0.5).unwrap();
    let mut pf = ParticleFilter::new(
        ParticleBuffer::<4>::new(2000).unwrap(),
        Resampling::Systematic,
        0.5,
    )
    .unwrap()
    .marginalised(layout2.pos, [None; System::COUNT])
    .unwrap();
    let mut rng = TrialRng::new(3, 1).stream("test/alloc-mpf");
    pf.init_gaussian(
        &V4::new(0.0, 0.0, 0.0, 0.0),
        &M4::from_diagonal(&V4::new(400.0, 4.0, 400.0, 4.0)),
        &mut rng,
    )
    .unwrap();
    let mut lik = PseudorangeLikelihood::with_capacity(rows.len());
    let mut epoch = |pf: &mut ParticleFilter<4>, rng: &mut StreamRng| {
        pf.predict(&cv2, 1.0, rng).unwrap();
        lik.clear(layout2.pos);
        for r in &rows {
            let d = r.emitter_pos_m - Vector3::new(10.0, 20.0, 0.0);
            lik.push(&layout2, r, d.norm());
        }
        pf.update_ranges(&lik, rng);
        pf.resample(rng);
        std::hint::black_box((pf.mean(), pf.covariance(), pf.n_eff()));
    };
    epoch(&mut pf, &mut rng);
    let before = allocations();
    for _ in 0..20 {
        epoch(&mut pf, &mut rng);
    }
    assert_eq!(
        allocations() - before,
        0,
        "the marginalised filter allocated"
    );
}

/// On a linear-Gaussian model (constant velocity, 2-D position fixes) the KF is the exact
/// posterior mean and its covariance is the PCRLB, so each filter's mean-square error is
/// the bound plus its distance to the KF. That excess must fall as the particle count
/// grows, roughly as 1/N: the log–log slope over N = 250 … 4000 is at most −0.5 for the
/// regularised PF and for SIR (the kernel's bias also vanishes, as h_opt → 0), the
/// marginalised PF and the Gaussian PF (exact on this model but for its sampling error).
#[test]
fn particle_filters_approach_the_bound_as_n_grows() {
    let cv = ConstantVelocity::<4>::new(0.2).unwrap();
    let fix =
        PositionFixModel::<4, 2>::new([0, 2], SMatrix::<f64, 2, 2>::identity() * 4.0).unwrap();
    let x0 = V4::new(0.0, 1.0, 0.0, 0.5);
    let p0 = M4::from_diagonal(&V4::new(9.0, 1.0, 9.0, 1.0));
    let (runs, steps) = (8, 20);
    // The bound of the position (trace of its block), checked against the KF below.
    let f = DMatrix::from_fn(4, 4, |i, j| nalgebra::Matrix4::from(cv_f())[(i, j)]);
    let q = {
        let q = hybridnav::fusion::models::ProcessModel::q(&cv, &x0, 1.0);
        DMatrix::from_fn(4, 4, |i, j| q[(i, j)])
    };
    let h = DMatrix::from_row_slice(2, 4, &[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0]);
    let info = h.transpose() * h / 4.0;
    let p0d = DMatrix::from_fn(4, 4, |i, j| p0[(i, j)]);
    let bounds = bound_sequence(&p0d, &f, &q, &vec![info; steps]).unwrap();
    let counts = [250usize, 1000, 4000];
    for variant in ["sir", "regularised", "musso", "marginalised", "gaussian"] {
        let mut excess = Vec::new();
        for &n in &counts {
            let (mut sq_diff, mut count) = (0.0, 0.0);
            for run in 0..runs {
                let trial = TrialRng::new(29, run);
                let mut rng = trial.stream("test/pf_bound/truth");
                let mut x = x0 + p0.cholesky().unwrap().l() * normal4(&mut rng);
                let mut kf = Ekf::new(x0, p0).unwrap();
                let mut prng = trial.stream("test/pf_bound/particles");
                let pf = ParticleFilter::new(
                    ParticleBuffer::<4>::new(n).unwrap(),
                    Resampling::Systematic,
                    0.5,
                )
                .unwrap();
                let mut pf = match variant {
                    "sir" => pf,
                    "regularised" => pf.regularised(),
                    "musso" => pf.regularised().with_kernel(KernelPlacement::Plain),
                    "gaussian" => pf.gaussian(),
                    _ => pf
                        .marginalised([Some(0), Some(2), None], [None; System::COUNT])
                        .unwrap(),
                };
                pf.init_gaussian(&x0, &p0, &mut prng).unwrap();
                let gq = hybridnav::fusion::models::ProcessModel::q(&cv, &x0, 1.0)
                    .cholesky()
                    .unwrap()
                    .l();
                for (k, bound) in bounds.iter().enumerate() {
                    x = cv_f() * x + gq * normal4(&mut rng);
                    let z = SVector::<f64, 2>::new(
                        x[0] + 2.0 * rng.sample::<f64, _>(StandardNormal),
                        x[2] + 2.0 * rng.sample::<f64, _>(StandardNormal),
                    );
                    kf.predict(&cv, 1.0).unwrap();
                    kf.update(&fix, &z);
                    // The KF's covariance is the bound.
                    let p = kf.covariance();
                    assert!(
                        (p[(0, 0)] - bound[(0, 0)]).abs() < 1e-9 * bound[(0, 0)],
                        "epoch {k}"
                    );
                    pf.predict(&cv, 1.0, &mut prng).unwrap();
                    assert!(!pf.update(&fix, &z, &mut prng).degenerate);
                    let m = pf.mean();
                    sq_diff += (m[0] - kf.state()[0]).powi(2) + (m[2] - kf.state()[2]).powi(2);
                    count += 1.0;
                }
            }
            excess.push(sq_diff / count);
        }
        let lx: Vec<f64> = counts.iter().map(|n| (*n as f64).ln()).collect();
        let ly: Vec<f64> = excess.iter().map(|e| e.ln()).collect();
        let (mx, my) = (lx.iter().sum::<f64>() / 3.0, ly.iter().sum::<f64>() / 3.0);
        let slope = lx
            .iter()
            .zip(&ly)
            .map(|(x, y)| (x - mx) * (y - my))
            .sum::<f64>()
            / lx.iter().map(|x| (x - mx).powi(2)).sum::<f64>();
        let bound_mse = bounds.iter().map(|b| b[(0, 0)] + b[(2, 2)]).sum::<f64>() / steps as f64;
        eprintln!("{variant}: bound MSE {bound_mse:.3} m², excess {excess:?}, slope {slope:.2}");
        assert!(
            slope <= -0.5,
            "{variant}: excess over the bound falls with slope {slope}"
        );
        // At 4000 particles the filter is within 5 % of the bound's MSE.
        assert!(
            excess[2] < 0.05 * bound_mse,
            "{variant}: {excess:?} vs {bound_mse}"
        );
    }
    let _ = Pseudoranges::<4, 1>::new;
    let _ = <PositionFixModel<4, 2> as MeasurementModel<4, 2>>::r;
}

fn cv_f() -> M4 {
    hybridnav::fusion::models::ProcessModel::jacobian(
        &ConstantVelocity::<4>::new(0.2).unwrap(),
        &V4::zeros(),
        1.0,
    )
}

/// A world whose particle filter has zero particles, an N_eff threshold outside [0, 1], a
/// proposal it cannot draw from, or a filter its model cannot run is refused with exit code 2, file:line:column and the
/// allowed range.
#[test]
fn bad_particle_filter_input_is_refused_with_its_place_and_range() {
    let world = std::fs::read_to_string(repo().join("worlds/seed003-seamless.toml")).unwrap();
    let dir = std::env::temp_dir().join(format!("hybridnav-it-particle-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let cases = [
        (
            "options = { particles = 100 }",
            "options = { particles = 0 }",
            ":92:25:",
            "expected 2 to 1 000 000",
        ),
        (
            "options = { particles = 100 }",
            "options = { particles = 100, neff_threshold = 1.5 }",
            ":92:47:",
            "expected a fraction in [0, 1]",
        ),
        (
            "options = { particles = 100 }",
            "options = { particles = 100, neff_threshold = -0.1 }",
            ":92:47:",
            "expected a fraction in [0, 1]",
        ),
        (
            "filter = \"rbpf\"\noptions = { particles = 500",
            "filter = \"rbpf\"\nprocess = { model = \"pva_clock\" }\noptions = { particles = 500",
            "filter",
            "runs on a paper process model",
        ),
        // The Gaussian PF takes the family's checks: its particle count and its model;
        // the marginalised PF takes no linearised proposal (it draws from its exact
        // prediction).
        (
            "name = \"GPF-100\"\nfilter = \"gpf\"\noptions = { particles = 100 }",
            "name = \"GPF-100\"\nfilter = \"gpf\"\noptions = { particles = 0 }",
            ":181:25:",
            "expected 2 to 1 000 000",
        ),
        (
            "filter = \"mpf\"\noptions = { particles = 100, neff_threshold = 0.5 }",
            "filter = \"mpf\"\noptions = { particles = 100, neff_threshold = 0.5, pf_proposal = \"linearised\" }",
            "filter",
            "the marginalised filter draws from its exact prediction",
        ),
        (
            "name = \"GPF-100\"\nfilter = \"gpf\"\noptions = { particles = 100 }",
            "name = \"GPF-100\"\nfilter = \"gpf\"\noptions = { particles = 100, gpf_covariance = \"biased\" }",
            ":181:",
            "expected `weighted` or `unbiased`",
        ),
        (
            "filter = \"gpf\"\noptions = { particles = 500",
            "filter = \"gpf\"\nprocess = { model = \"pva_clock\" }\noptions = { particles = 500",
            ":186:10:",
            "runs on a paper process model",
        ),
        // Progressive correction splits the bootstrap weighting of the regularised and
        // Rao-Blackwellised PFs only.
        (
            "filter = \"mpf\"\noptions = { particles = 100, neff_threshold = 0.5 }",
            "filter = \"mpf\"\noptions = { particles = 100, neff_threshold = 0.5, pf_correction = \"progressive\" }",
            "filter",
            "pf_correction = \"progressive\" is for filter = \"pf\" or \"rbpf\" with pf_proposal = \"prior\"",
        ),
        (
            "options = { particles = 100, neff_threshold = 0.5, pf_proposal = \"linearised\", pf_kernel = \"musso\" }",
            "options = { particles = 100, neff_threshold = 0.5, pf_proposal = \"linearised\", pf_kernel = \"musso\", pf_correction = \"progressive\" }",
            "filter",
            "pf_correction = \"progressive\" is for filter = \"pf\" or \"rbpf\" with pf_proposal = \"prior\"",
        ),
        (
            "options = { particles = 100 }",
            "options = { particles = 100, pf_correction = \"staged\" }",
            ":92:",
            "expected `single` or `progressive`",
        ),
    ];
    for (i, (find, replace, place, expect)) in cases.iter().enumerate() {
        assert!(world.contains(find), "case {i}: {find:?} not in the world");
        let path = dir.join(format!("bad{i}.toml"));
        std::fs::write(&path, world.replacen(find, replace, 1)).unwrap();
        let out = Command::new(env!("CARGO_BIN_EXE_hybridnav"))
            .args(["check"])
            .arg(&path)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "case {i}: {err}");
        assert!(err.contains(&format!("bad{i}.toml")), "case {i}: {err}");
        assert!(err.contains(place), "case {i}: expected {place} in {err}");
        assert!(
            err.contains(expect),
            "case {i}: expected {expect:?} in {err}"
        );
        assert!(!err.contains("panicked"), "case {i}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// The bound a run reports is the bound of the world: `summary.json`'s
/// `pcrlb_pos_rmse_m` for seed 003's estimators equals `World::pcrlb_pos_rmse_m` computed
/// from the library for the same seed and trials, `efficiency` is the summary's RMSE over
/// it, and the report's table shows both.
#[test]
fn a_run_reports_the_worlds_bound_in_its_summary_and_report() {
    let world_path = crate::common::repo().join("worlds/seed003-seamless.toml");
    let out = crate::common::tmp_dir("pcrlb-report");
    let _ = std::fs::remove_dir_all(&out);
    let o = crate::common::hybridnav(&[
        "run",
        world_path.to_str().expect("utf-8 path"),
        "--trials",
        "2",
        "--seed",
        "3",
        "--quiet",
        "--out",
        out.to_str().expect("utf-8 path"),
    ]);
    assert!(o.status.success(), "{}", crate::common::stderr(&o));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let world = hybridnav::world::load_world(&world_path).unwrap();
    let bounds = world.pcrlb_pos_rmse_m(3, 2);
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    let ests = summary["estimators"].as_array().unwrap();
    assert_eq!(ests.len(), bounds.len());
    let mut bounded = 0;
    for (e, b) in ests.iter().zip(&bounds) {
        let Some(b) = b else {
            assert!(e["pcrlb_pos_rmse_m"].is_null(), "{e}");
            continue;
        };
        bounded += 1;
        let reported = e["pcrlb_pos_rmse_m"].as_f64().unwrap();
        assert!((reported - b).abs() <= 1e-9 * b, "{reported} vs {b}");
        let rmse = e["error_3d_m"]["rmse"].as_f64().unwrap();
        let eff = e["efficiency"].as_f64().unwrap();
        assert!((eff - rmse / b).abs() <= 1e-9 * eff, "{eff} vs {rmse}/{b}");
        assert!(
            html.contains(&format!("<td>{b:.2}</td><td>{eff:.2}</td>")),
            "report lacks the bound of {}",
            e["name"]
        );
    }
    assert!(bounded >= 3, "seed 003's EKF and PFs share one model");
    let _ = std::fs::remove_dir_all(&out);
}

/// Issue 23's few-particle goals on the committed worlds at their own seed (seed 003, 20
/// trials; seed 001, 200 trials, the count its table needs): each row's RMSE within its
/// factor of the PCRLB, its mean position NEES within twice its degrees of freedom, and
/// no reset. Seed 003: the Gaussian PF with the linearised importance function at 100
/// particles within 1.5× (measured 1.13×), at 500 within 1.2× (1.00×), and the regularised
/// and Rao-Blackwellised PF at 500 within 1.2× (with their default progressive
/// correction), the Rao-Blackwellised PF with the linearised proposal, Musso et al.'s
/// kernel and the paper's resampling test (θ = 1) at 100 within 1.5× (1.24×), and the
/// Rao-Blackwellised PF with the prior proposal, Musso et al.'s kernel and (the default)
/// progressive correction at 100 within 1.5×, and the regularised PF with the clocks
/// sampled, Musso et al.'s kernel on the driven states and Liu & West's shrinkage on the
/// constant clocks at 100 within 1.5× (1.47×); the same kernels with the linearised
/// proposal on the paper's resampling test (θ = 1) at 100 within 1.5× (1.28×), and with
/// N_eff < N/2 at 100 within 1.5× (1.20×) and at 500 within 1.2× (1.14×); and the
/// issue's ordering PF-500 < PF-100 < SIR-100 with the linearised proposal and those
/// kernels on θ = 1 (at 500 it is 1.23×, just outside the goal, docs/reproductions.md);
/// the Rao-Blackwellised PF with the linearised proposal, Musso et al.'s kernel and θ = 1
/// at 100 within 1.5× (1.24×), at 500 within 1.2× (1.17×) and the same ordering on the
/// two; seed 001: the same Gaussian
/// PF with the unbiased covariance at 20 particles within 1.3× (1.25×), and the
/// regularised PF with the linearised proposal, Musso et al.'s kernel and the paper's
/// resampling test (θ = 1) at 20 particles within 1.3× (1.21×). The rows with Musso's
/// kernel after the linearised proposal take its covariance from the proposal's centres
/// (docs/reproductions.md, "Musso's kernel from the centres").
///
/// The defaults of `filter = "pf"` and `"rbpf"` (the linearised proposal, Liu & West's
/// kernel, a resampling at every epoch) are held to every goal: at 500 particles within
/// 1.2× (1.01× and 1.00×), at 100 within 1.5× (1.09× and 1.05×), each with its mean NEES
/// within twice its dof (1.21 and 1.15 times it at 100) and no reset, the ordering
/// PF-500 < PF-100 < SIR-100, and beating the former default at 100, the prior proposal
/// with progressive correction on N_eff < N/2 (`RPF-100-prior`); on seed 001 the
/// regularised and Rao-Blackwellised PF-20 within 1.3× (1.08× and 1.10×, NEES 0.93 and
/// 0.99 for their 1 dof). Over master seeds 1–5 (seed 003 50 trials, seed 001 200) they
/// are at 1.07–1.10× (RPF-100), 1.05–1.10× (RBPF-100), mean NEES 3.4–3.8 for 3 dof, and
/// 1.07–1.11× (RPF-20, RBPF-20), NEES 0.93–0.99 for 1 (docs/reproductions.md, "The
/// linearised proposal as the default", "The unbiased covariance in Liu & West's kernel",
/// "The kernel sized by the effective sample size", "The kernel carries the Monte Carlo
/// error" and "The kernel from the centres of the linearised proposal").
#[test]
fn the_few_particle_goals_hold_on_the_paper_worlds() {
    // (world file, trials, [(row, largest RMSE / PCRLB, NEES held to 2× its dof)]).
    type Case<'a> = (&'a str, &'a str, &'a [(&'a str, f64, bool)]);
    let cases: [Case; 2] = [
        (
            "seed003-seamless.toml",
            "20",
            &[
                ("GPF-100-lin", 1.5, true),
                ("GPF-500-lin", 1.2, true),
                ("RPF-500", 1.2, true),
                ("RBPF-500", 1.2, true),
                ("RPF-100", 1.5, true),
                ("RBPF-100", 1.5, true),
                ("RBPF-100-lin-Musso-theta1", 1.5, true),
                ("RBPF-100-Musso", 1.5, true),
                ("RPF-100-Musso-LW-static", 1.5, true),
                ("RPF-100-lin-Musso-LW-static-theta1", 1.5, true),
                ("RPF-100-lin-Musso-LW-static", 1.5, true),
                ("RPF-500-lin-Musso-LW-static", 1.2, true),
                ("RBPF-500-lin-Musso-theta1", 1.2, true),
            ],
        ),
        (
            "seed001-pf2d.toml",
            "200",
            &[
                // Within 1.3× of the bound, but over-confident (mean NEES 2.3–2.6 for its one
                // degree of freedom): its NEES is not held to the goal.
                ("GPF-20-lin-unbiased", 1.3, false),
                ("RPF-20-lin-Musso-theta1", 1.3, true),
                ("RPF-20", 1.3, true),
                ("RBPF-20", 1.3, true),
            ],
        ),
    ];
    for (file, trials, rows) in cases {
        let out = crate::common::tmp_dir(&format!("pf-goals-{file}"));
        let _ = std::fs::remove_dir_all(&out);
        let summary = crate::common::run_summary(
            &repo().join("worlds").join(file),
            &out,
            &["--trials", trials],
        );
        let ests = summary["estimators"].as_array().unwrap();
        let row = |name: &str| {
            ests.iter()
                .find(|e| e["name"] == name)
                .unwrap_or_else(|| panic!("{file} has no row {name}"))
        };
        for (name, limit, consistent) in rows {
            let e = row(name);
            let eff = e["efficiency"].as_f64().unwrap();
            let nees = e["nees"]["mean"].as_f64().unwrap();
            let dof = e["nees"]["dof"].as_f64().unwrap();
            eprintln!("{file} {name}: rmse/PCRLB {eff:.3}, mean NEES {nees:.2} (dof {dof})");
            assert!(eff <= *limit, "{file} {name}: {eff} > {limit}");
            if *consistent {
                assert!(nees <= 2.0 * dof, "{file} {name}: NEES {nees}, dof {dof}");
            }
            assert_eq!(e["numerical_failures"].as_u64(), Some(0), "{file} {name}");
        }
        if file.starts_with("seed003") {
            // Issue 23's ordering, each recipe at both particle counts.
            let rmse = |name: &str| row(name)["error_3d_m"]["rmse"].as_f64().unwrap();
            let sir100 = rmse("PF-100");
            for (r500, r100) in [
                (
                    "RPF-500-lin-Musso-LW-static-theta1",
                    "RPF-100-lin-Musso-LW-static-theta1",
                ),
                ("RBPF-500-lin-Musso-theta1", "RBPF-100-lin-Musso-theta1"),
                ("RPF-500", "RPF-100"),
                ("RBPF-500", "RBPF-100"),
            ] {
                let (pf500, pf100) = (rmse(r500), rmse(r100));
                assert!(
                    pf500 < pf100 && pf100 < sir100,
                    "{r500} {pf500} < {r100} {pf100} < SIR-100 {sir100} fails"
                );
            }
            // The defaults at 100 particles (held to the goal's 1.5× above) against the
            // former default.
            let former = rmse("RPF-100-prior");
            for r100 in ["RPF-100", "RBPF-100"] {
                let pf100 = rmse(r100);
                assert!(pf100 < former, "{r100} {pf100} ≥ RPF-100-prior {former}");
            }
        }
        let _ = std::fs::remove_dir_all(&out);
    }
}

/// The report's RMSE-against-time curves, checked against the trials they come from: for
/// seed 003 (4 trials), each estimator's curve equals the RMSE across trials computed
/// here from the trials' own records at every instant, and its epoch-mean square equals
/// the square of the summary's RMSE (a second path: the sorted spill of every error).
/// The bound curve is the world's: its epoch-mean square is `pcrlb_pos_rmse_m`², it lies
/// under the RMSE of every estimator that shares its model once the prior has been
/// forgotten (the mean over the second half, where the filters are in steady state), and
/// the EKF, efficient on this nearly linear model, stays within 1.5× of it there.
#[test]
fn the_rmse_against_time_lies_on_or_above_its_bound() {
    use hybridnav::montecarlo::{reduce::RunReducer, run_trials};
    let world = hybridnav::world::load_world(&repo().join("worlds/seed003-seamless.toml"))
        .expect("seed 003 world");
    let opts = crate::common::run_options(4, 3);
    let trials = run_trials(&world, &opts).expect("trials");
    let spill = crate::common::tmp_dir("rmse-vs-time");
    std::fs::create_dir_all(&spill).unwrap();
    let mut reducer = RunReducer::new(&world, &spill);
    for t in &trials {
        reducer.push(t).unwrap();
    }
    let reduced = reducer.finish(&world, &opts).unwrap();
    let curves = &reduced.curves;
    let n_est = world.file.estimators.len();
    assert_eq!(curves.rmse_vs_time.len(), n_est);
    assert_eq!(curves.pcrlb_vs_time.len(), n_est);
    let mut bounded = 0;
    for (k, est) in reduced.summary.estimators.iter().enumerate() {
        // Independently: the last record of each instant of each trial, squared, averaged.
        let mut by_t: std::collections::BTreeMap<u64, Vec<f64>> = Default::default();
        for t in &trials {
            let mut last: std::collections::BTreeMap<u64, f64> = Default::default();
            for ep in &t.estimators[k].epochs {
                if let Some(e) = ep.err_3d_m {
                    last.insert(ep.t_s.to_bits(), e);
                }
            }
            for (ts, e) in last {
                by_t.entry(ts).or_default().push(e);
            }
        }
        let curve = &curves.rmse_vs_time[k];
        assert_eq!(curve.len(), by_t.len(), "{}", est.name);
        for ((t_s, rmse), (ts, errs)) in curve.iter().zip(&by_t) {
            assert_eq!(t_s.to_bits(), *ts);
            let want = (errs.iter().map(|e| e * e).sum::<f64>() / errs.len() as f64).sqrt();
            assert!(
                (rmse - want).abs() <= 1e-12 * want.max(1.0),
                "{rmse} vs {want}"
            );
        }
        let full = by_t.values().all(|v| v.len() == trials.len());
        if full {
            let ms = curve.iter().map(|(_, r)| r * r).sum::<f64>() / curve.len() as f64;
            let rmse = est.error_3d_m.as_ref().unwrap().rmse;
            assert!(
                (ms.sqrt() - rmse).abs() <= 1e-9 * rmse,
                "{} vs {rmse}",
                ms.sqrt()
            );
        }
        let Some(bound) = &curves.pcrlb_vs_time[k] else {
            continue;
        };
        bounded += 1;
        let b_rmse = est.pcrlb_pos_rmse_m.unwrap();
        let ms = bound.iter().map(|(_, b)| b * b).sum::<f64>() / bound.len() as f64;
        assert!((ms.sqrt() - b_rmse).abs() <= 1e-9 * b_rmse);
        // The second half of the run, where both curves are on the same instants.
        let half = world.duration_s / 2.0;
        let mean_sq = |c: &[(f64, f64)]| {
            let v: Vec<f64> = c
                .iter()
                .filter(|(t, _)| *t >= half)
                .map(|(_, y)| y * y)
                .collect();
            (v.iter().sum::<f64>() / v.len() as f64).sqrt()
        };
        let (r2, b2) = (mean_sq(curve), mean_sq(bound));
        // Four trials give the RMSE a relative standard error of about 1/√(2·4·50) over
        // the 50 s half: a 10 % margin is three of them.
        assert!(
            r2 >= 0.9 * b2,
            "{}: RMSE {r2:.2} m under its bound {b2:.2} m",
            est.name
        );
        if est.name == "EKF" {
            assert!(r2 <= 1.5 * b2, "EKF RMSE {r2:.2} m vs bound {b2:.2} m");
        }
    }
    assert!(bounded >= 3, "seed 003's EKF and PFs share one model");
    let _ = std::fs::remove_dir_all(&spill);
}

/// Seed 001's filters estimate on the truth's plane, and the paper's x moves uniformly
/// without process noise from the known X(0), so their position NEES has 1 degree of
/// freedom, not 3: every estimate's vertical error, and its east error until the
/// estimator's first reset in the trial, taken from the trial records in the world's ENU
/// frame, are zero to a micrometre (their NEES terms, against the fixed 0.01 m² vertical
/// variance and the 1 mm² covariance floor, below 1e-6). A reset restarts the filter from
/// a least-squares fix, whose x errs; the run's summary therefore reports dof 1 for every
/// seed 001 row that never resets, between 1 and 2 for one that does (the mean over its
/// epochs, 2 after a reset), and 3 for seed 003's 3-D rows.
#[test]
fn planar_filters_report_the_nees_of_their_one_uncertain_axis() {
    use hybridnav::montecarlo::{reduce::RunReducer, run_trials};
    for (file, dof) in [("seed001-pf2d.toml", 1.0), ("seed003-seamless.toml", 3.0)] {
        let world = hybridnav::world::load_world(&repo().join("worlds").join(file)).unwrap();
        let opts = crate::common::run_options(2, 5);
        let trials = run_trials(&world, &opts).expect("trials");
        if dof == 1.0 {
            let (mut checked, mut restarted_epochs) = (0, 0);
            for t in &trials {
                for est in &t.estimators {
                    let mut restarted = false;
                    for ep in &est.epochs {
                        restarted |= ep.numerical_failure;
                        let Some(e) = ep.est_ecef_m else { continue };
                        let d = Vector3::from(e) - Vector3::from(ep.truth_ecef_m);
                        let enu = world.frame.enu_vector_of_ecef(&d);
                        let at = format!("{} at {}", est.name, ep.t_s);
                        assert!(enu.z.abs() < 1e-6, "{at}: up error {}", enu.z);
                        if restarted {
                            restarted_epochs += 1;
                        } else {
                            assert!(enu.x.abs() < 1e-6, "{at}: east error {}", enu.x);
                        }
                        checked += 1;
                    }
                }
            }
            assert!(checked > 1000, "{checked} estimates");
            assert!(
                restarted_epochs > 0,
                "no seed 001 row was reset in these trials"
            );
        }
        let spill = crate::common::tmp_dir(&format!("nees-dof-{file}"));
        std::fs::create_dir_all(&spill).unwrap();
        let mut reducer = RunReducer::new(&world, &spill);
        for t in &trials {
            reducer.push(t).unwrap();
        }
        let reduced = reducer.finish(&world, &opts).unwrap();
        for e in &reduced.summary.estimators {
            let n = e.nees.as_ref().expect("a NEES");
            if e.numerical_failures == 0 || dof == 3.0 {
                assert_eq!(n.dof, dof, "{file} {}", e.name);
            } else {
                assert!(
                    n.dof > 1.0 && n.dof <= 2.0,
                    "{file} {}: dof {}",
                    e.name,
                    n.dof
                );
            }
        }
        let _ = std::fs::remove_dir_all(&spill);
    }
}

/// The defaults of the paper models' particle filters, as the loader resolves them: a
/// regularised or Rao-Blackwellised PF that names no proposal and no threshold runs bit
/// for bit as one that asks for the linearised proposal and a resampling at every epoch,
/// and differs from one that asks for the prior proposal on N_eff < N/2; the bootstrap
/// `sir` keeps the prior proposal and the usual threshold ½. One trial of seed 003 each,
/// each row alone in its world under one name (so one random stream).
#[test]
fn the_paper_particle_filters_resolve_their_defaults() {
    use hybridnav::world::parse_world;
    use hybridnav::world::trial::run_trial;
    let text = std::fs::read_to_string(repo().join("worlds/seed003-seamless.toml")).unwrap();
    let head = &text[..text.find("[[estimator]]").unwrap()];
    let errors = |filter: &str, options: &str| -> Vec<Option<f64>> {
        let world_text = format!(
            "{head}[[estimator]]\nname = \"F\"\nsources = [\"gps\", \"bds\", \"dtmb\"]\n\
             filter = \"{filter}\"\nselection = \"seamless\"\n\
             process = {{ model = \"plane_turning\" }}\noptions = {{ particles = 100{options} }}\n"
        );
        let world = parse_world(&world_text, std::path::Path::new("defaults.toml")).unwrap();
        let r = run_trial(&world, 1, 0).unwrap();
        r.estimators[0].epochs.iter().map(|e| e.err_3d_m).collect()
    };
    for filter in ["pf", "rbpf"] {
        let default = errors(filter, "");
        assert_eq!(default.len(), 100, "{filter}");
        assert_eq!(
            default,
            errors(
                filter,
                ", pf_proposal = \"linearised\", neff_threshold = 1.0"
            ),
            "{filter}: the default is not the linearised proposal on theta = 1"
        );
        assert_ne!(
            default,
            errors(filter, ", pf_proposal = \"prior\", neff_threshold = 0.5"),
            "{filter}"
        );
    }
    assert_eq!(
        errors("sir", ""),
        errors("sir", ", pf_proposal = \"prior\", neff_threshold = 0.5"),
        "sir: the default is not the bootstrap filter on theta = 1/2"
    );
}
