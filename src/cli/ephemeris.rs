//! `hybridnav ephemeris positions`: broadcast satellite states as CSV, selected as every
//! simulation selects them (`NavData::select`).

use crate::core::{EmitterId, GpsTime};
use crate::gnss::rinex_nav::MaxAge;
use anyhow::{bail, Context, Result};
use std::path::Path;

/// Prints `sat,gpst_week,gpst_tow_s,x_m,y_m,z_m,clock_s` for every requested satellite
/// and epoch that has a usable ephemeris; records the reader dropped are reported on
/// stderr as warnings, and the satellite-epochs without a usable record as a note.
pub(super) fn positions(
    nav: &str,
    start: &str,
    end: &str,
    step: f64,
    sats: &[String],
    max_age: Option<&str>,
) -> Result<()> {
    use std::io::Write;
    let (mut data, _) =
        crate::world::read_nav_source(nav, Path::new("")).map_err(anyhow::Error::msg)?;
    if let Some(spec) = max_age {
        data.max_age = MaxAge::parse(spec)
            .map_err(anyhow::Error::msg)
            .context("--max-age")?;
    }
    for d in &data.dropped {
        eprintln!("warning: {d}");
    }
    let t0 = GpsTime::parse_iso(start)
        .map_err(anyhow::Error::msg)
        .context("--start")?;
    let t1 = GpsTime::parse_iso(end)
        .map_err(anyhow::Error::msg)
        .context("--end")?;
    if !(step.is_finite() && step > 0.0) {
        bail!("--step must be a positive number of seconds, got {step}");
    }
    if t1 < t0 {
        bail!("--end ({t1}) is before --start ({t0})");
    }
    let n_steps = (t1.seconds_since(t0) / step).floor() as u64 + 1;
    if n_steps > 10_000_000 {
        bail!("{n_steps} epochs requested; at most 10 000 000 (use a larger --step)");
    }
    let ids: Vec<EmitterId> = if sats.is_empty() {
        data.satellites()
    } else {
        sats.iter()
            .map(|s| s.parse::<EmitterId>().map_err(anyhow::Error::msg))
            .collect::<Result<_>>()?
    };
    let stdout = std::io::stdout();
    let mut w = std::io::BufWriter::new(stdout.lock());
    writeln!(w, "sat,gpst_week,gpst_tow_s,x_m,y_m,z_m,clock_s")?;
    let mut missing = Vec::new();
    for k in 0..n_steps {
        let t = t0.add_seconds(k as f64 * step);
        for id in &ids {
            match data.select(*id, t) {
                Some(eph) => {
                    let s = eph.state(t);
                    writeln!(
                        w,
                        "{id},{},{:.3},{:.3},{:.3},{:.3},{:.12e}",
                        t.week(),
                        t.tow_s(),
                        s.pos_ecef_m.x,
                        s.pos_ecef_m.y,
                        s.pos_ecef_m.z,
                        s.clock_s
                    )?;
                }
                None => missing.push((*id, t)),
            }
        }
    }
    w.flush()?;
    if !missing.is_empty() {
        eprintln!(
            "note: {} satellite-epochs had no usable ephemeris (the record with toe nearest \
             the epoch is unhealthy, or none is within gps {} s / bds {} s; first: {} at {})",
            missing.len(),
            data.max_age.gps_s,
            data.max_age.bds_s,
            missing[0].0,
            missing[0].1
        );
    }
    Ok(())
}
