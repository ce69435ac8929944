//! The benchmark scene shared by `benches/fusion.rs` and `benches/filters.rs` (and mirrored
//! by `benches/python/ekf_epoch_bench.py`), so both time the same problem.

use hybridnav::core::{EmitterId, EnuFrame, Geodetic, System};
use hybridnav::measurement::RangeMeasurement;
use nalgebra::Vector3;

/// Twelve emitters (8 GPS, 4 BDS) spread over the sky of a Beijing receiver, with their
/// true pseudoranges and range rates for a receiver at rest with zero clock.
pub fn scene() -> (Vector3<f64>, Vec<RangeMeasurement>) {
    let frame = EnuFrame::new(Geodetic::from_deg(39.98, 116.35, 60.0));
    let r = frame.origin_ecef();
    let ms = (0..12)
        .map(|i| {
            let az = (i as f64 * 30.0 + 7.0).to_radians();
            let el = (15.0 + (i * 37 % 70) as f64).to_radians();
            let u = Vector3::new(el.cos() * az.sin(), el.cos() * az.cos(), el.sin());
            let p = frame.ecef_of_enu(&(u * 20_200e3));
            // A tangential velocity of GPS magnitude.
            let v = frame.ecef_vector_of_enu(&Vector3::new(-u.y, u.x, 0.0).normalize()) * 3_874.0;
            let los = (p - r).normalize();
            let system = if i < 8 { System::Gps } else { System::Bds };
            RangeMeasurement {
                emitter: EmitterId::new(system, i as u16 + 1),
                emitter_pos_ecef_m: p,
                emitter_vel_ecef_mps: v,
                pseudorange_m: (p - r).norm(),
                sigma_m: 3.0,
                range_rate_mps: Some(los.dot(&v)),
                sigma_rate_mps: 0.05,
                cn0_dbhz: 45.0,
                elevation_rad: el,
            }
        })
        .collect();
    (r, ms)
}
