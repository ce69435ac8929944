//! Single-bounce specular reflections off building walls (image method) and off the ground.
//!
//! # Geometry
//!
//! A wall is the vertical rectangle over one footprint edge, from the ground to the roof,
//! with outward unit normal n (horizontal). Let d = n·(rx − p₀) > 0 be the receiver's
//! distance in front of the wall.
//!
//! * **Point transmitter** at distance d_t = n·(tx − p₀) > 0 in front of the same wall: its
//!   image is tx′ = tx − 2 d_t n; the reflected path is the straight line rx → tx′, which
//!   meets the wall plane at P = rx + s (tx′ − rx), s = d / (d + d_t). The path exists when
//!   P lies on the wall (between the edge's ends and below the roof) and both legs rx → P
//!   and P → tx are free of buildings. Excess path = |tx′ − rx| − |tx − rx|.
//! * **Plane wave** from unit direction u (a satellite): the wave reflected by the wall
//!   arrives from u′ = u − 2 (n·u) n, the mirror of u, and needs n·u > 0. P = rx + t u′
//!   with t = d / (n·u). The excess path is the difference of the two paths' projections on
//!   the wave's direction: t − u·(P − rx) = t (1 − u·u′) = 2 t (n·u)² = **2 d (n·u)**.
//!   For an emitter straight out along the wall normal at elevation e, n·u = cos e, so the
//!   excess is 2 d cos e (the analytic case the tests check).
//!
//! The ground is the plane z = g with normal +z: the same construction with d = h, the
//! receiver's height above ground, gives an excess 2 h sin e for a plane wave.
//!
//! # Amplitude and phase
//!
//! Fresnel reflection coefficients for a half-space of complex relative permittivity
//! η = ε′ − j σ/(ω ε₀) = ε′ − j 60 λ σ at grazing angle ψ (ITU-R P.1546/P.526 form):
//!
//! ```text
//! Γ_TE = (sin ψ − √(η − cos²ψ)) / (sin ψ + √(η − cos²ψ))        E ⟂ plane of incidence
//! Γ_TM = (η sin ψ − √(η − cos²ψ)) / (η sin ψ + √(η − cos²ψ))    E in the plane of incidence
//! ```
//!
//! For a terrestrial **vertical** linear polarisation, the field is TM for the ground and
//! TE for a vertical wall (whose plane of incidence is nearly horizontal for near-horizontal
//! paths); **horizontal** polarisation is the reverse. The mapping to a wall is exact for a
//! horizontal plane of incidence and an approximation for steep paths.
//!
//! For **GNSS RHCP** the reflected field splits into a co-polar (RHCP) and a cross-polar
//! (LHCP) part (Zavorotny & Voronovich 2000, as used in GNSS reflectometry):
//! Γ_RR = (Γ_TM + Γ_TE)/2, Γ_RL = (Γ_TM − Γ_TE)/2. Near grazing Γ_RR dominates (the
//! reflection stays RHCP); above the Brewster angle Γ_RL dominates (the reflection turns
//! LHCP, entirely so at normal incidence and off metal at any angle). An RHCP receive
//! antenna with cross-polar discrimination XPD sees Γ = Γ_RR + 10^(−XPD/20) Γ_RL, its LHCP
//! response taken in phase with its RHCP one (an assumption: the true relative phase is
//! specific to the antenna).
//!
//! The path amplitude relative to the free-space line of sight is |Γ| times the spreading
//! ratio d_direct / d_reflected for a point transmitter (1 for a plane wave) times the
//! vegetation loss along the legs; its phase is arg Γ − 2π·excess/λ. The Doppler shift due
//! to the receiver's velocity v is v·a/λ with a the unit arrival direction (towards the
//! reflection point); the emitter's own motion shifts every path alike to first order and
//! is the caller's to add.

use num_complex::Complex64;

/// The complex relative permittivity η = ε′ − j σ/(ω ε₀) at `freq_hz`.
pub fn complex_permittivity(eps_r: f64, sigma_s_per_m: f64, freq_hz: f64) -> Complex64 {
    const EPS0: f64 = 8.854_187_812_8e-12;
    Complex64::new(
        eps_r,
        -sigma_s_per_m / (std::f64::consts::TAU * freq_hz * EPS0),
    )
}

/// Fresnel coefficients (Γ_TE, Γ_TM) at grazing angle `psi_rad` ∈ [0, π/2] (see the module
/// documentation for the formulas).
pub fn fresnel(eta: Complex64, psi_rad: f64) -> (Complex64, Complex64) {
    let (s, c) = psi_rad.sin_cos();
    let root = (eta - c * c).sqrt();
    let te = (s - root) / (s + root);
    let tm = (eta * s - root) / (eta * s + root);
    (te, tm)
}

/// The polarisation of a link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Polarisation {
    /// Vertical linear (terrestrial broadcast and cellular default).
    #[default]
    Vertical,
    /// Horizontal linear (much FM and TV broadcast).
    Horizontal,
    /// Right-hand circular, received by an RHCP antenna (GNSS).
    Rhcp,
}

/// The surface a path reflects off.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Surface {
    /// A vertical wall.
    Wall,
    /// The horizontal ground.
    Ground,
}

/// The effective complex reflection coefficient seen by a co-polarised receive antenna.
pub fn effective_coefficient(
    eta: Complex64,
    psi_rad: f64,
    pol: Polarisation,
    surface: Surface,
    xpd_db: f64,
) -> Complex64 {
    let (te, tm) = fresnel(eta, psi_rad);
    match (pol, surface) {
        (Polarisation::Vertical, Surface::Ground) | (Polarisation::Horizontal, Surface::Wall) => tm,
        (Polarisation::Vertical, Surface::Wall) | (Polarisation::Horizontal, Surface::Ground) => te,
        (Polarisation::Rhcp, _) => {
            let co = 0.5 * (tm + te);
            let cross = 0.5 * (tm - te);
            co + cross * 10f64.powf(-xpd_db / 20.0)
        }
    }
}

/// Wraps an angle to (−π, π].
pub fn wrap_phase(x: f64) -> f64 {
    let y = x.rem_euclid(std::f64::consts::TAU);
    if y > std::f64::consts::PI {
        y - std::f64::consts::TAU
    } else {
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_limits() {
        // Normal incidence on a lossless dielectric: Γ_TM = (√ε − 1)/(√ε + 1) = −Γ_TE.
        let eta = Complex64::new(4.0, 0.0);
        let (te, tm) = fresnel(eta, std::f64::consts::FRAC_PI_2);
        assert!((tm.re - 1.0 / 3.0).abs() < 1e-12 && (te.re + 1.0 / 3.0).abs() < 1e-12);
        // Grazing incidence: both −1.
        let (te, tm) = fresnel(eta, 0.0);
        assert!((te + 1.0).norm() < 1e-12 && (tm + 1.0).norm() < 1e-12);
        // Brewster angle tan θ_B = √ε from the normal, i.e. grazing ψ = atan(1/√ε): Γ_TM = 0.
        let psi = (1.0f64 / 2.0).atan();
        assert!(fresnel(eta, psi).1.norm() < 1e-12);
        // RHCP off a perfect conductor turns entirely LHCP at every angle.
        let metal = complex_permittivity(1.0, 1e7, 1.575e9);
        for psi in [0.2, 0.7, 1.3] {
            let g = effective_coefficient(metal, psi, Polarisation::Rhcp, Surface::Wall, 300.0);
            assert!(g.norm() < 1e-3, "{g}");
            let g = effective_coefficient(metal, psi, Polarisation::Rhcp, Surface::Wall, 0.0);
            assert!((g.norm() - 1.0).abs() < 1e-3, "{g}");
        }
    }
}
