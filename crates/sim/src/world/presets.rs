//! The papers' systems as named estimator presets.
//!
//! An `[[estimator]]` table may name `preset = "seed000-adaptive"`; the preset's keys are
//! laid under the table's own, key by key and table by table (a table's `[estimator.ekf]`
//! replaces only the keys it lists), so any part of a preset can be overridden and the
//! rest stays the paper's. `hybridnav presets` lists them.

use toml::{Table, Value};

/// One preset: its name, what it is, and its keys (TOML).
pub struct Preset {
    pub name: &'static str,
    pub about: &'static str,
    pub toml: &'static str,
}

/// Every preset, in the papers' order.
pub const PRESETS: &[Preset] = &[
    // Seed 000's three rows come in two forms. The default presets linearise the GPS
    // range rate exactly (its Jacobian has position terms, (v_sat − v)·(I − e eᵀ)/r, as
    // well as the −eᵀ velocity terms); the `-eq17` presets keep eq. 17 as the paper prints
    // it (velocity and clock-drift terms only). The paper discloses the simplification only
    // in the Jacobian itself (§5.2.2); both forms run side by side in the seed 000 worlds so
    // that what the printed Jacobian changes is visible. Each pair differs only in
    // `ekf.rate_position_jacobian` (and the row name).
    Preset {
        name: "seed000-gps",
        about: "seed 000 row 'GPS': the 11-state EKF (eqs. 4-8) on GPS pseudoranges and rates, range-rate Jacobian exact (position and velocity terms)",
        toml: r#"name = "GPS"
sources = ["gps"]
filter = "ekf11"
[ekf]
rate_position_jacobian = true"#,
    },
    Preset {
        name: "seed000-gps-eq17",
        about: "seed 000 row 'GPS' with the range-rate Jacobian as eq. 17 prints it (no position terms)",
        toml: r#"name = "GPS (eq. 17)"
sources = ["gps"]
filter = "ekf11"
[ekf]
rate_position_jacobian = false"#,
    },
    Preset {
        name: "seed000-gps-dtmb",
        about: "seed 000 row 'GPS + DTMB': GPS and DTMB pseudoranges sharing one clock, DTMB clock corrected from good GPS fixes (sec. 3.1), range-rate Jacobian exact",
        toml: r#"name = "GPS+DTMB"
sources = ["gps", "dtmb"]
filter = "ekf11"
dtmb_clock_correction = {}
[ekf]
rate_position_jacobian = true"#,
    },
    Preset {
        name: "seed000-gps-dtmb-eq17",
        about: "seed 000 row 'GPS + DTMB' with the range-rate Jacobian as eq. 17 prints it",
        toml: r#"name = "GPS+DTMB (eq. 17)"
sources = ["gps", "dtmb"]
filter = "ekf11"
dtmb_clock_correction = {}
[ekf]
rate_position_jacobian = false"#,
    },
    Preset {
        name: "seed000-adaptive",
        about: "seed 000 row 'Proposed': GPS + DTMB + FM fixes, modes A/B/C chosen by the fuzzy system, range-rate Jacobian exact",
        toml: r#"name = "Proposed"
sources = ["gps", "dtmb"]
fixes = ["fm"]
filter = "ekf11"
selection = "fuzzy"
dtmb_clock_correction = {}
[ekf]
rate_position_jacobian = true"#,
    },
    Preset {
        name: "seed000-adaptive-eq17",
        about: "seed 000 row 'Proposed' with the range-rate Jacobian as eq. 17 prints it",
        toml: r#"name = "Proposed (eq. 17)"
sources = ["gps", "dtmb"]
fixes = ["fm"]
filter = "ekf11"
selection = "fuzzy"
dtmb_clock_correction = {}
[ekf]
rate_position_jacobian = false"#,
    },
    Preset {
        name: "seed001-pf",
        about: "seed 001: SIR particle filter (20 particles, resampling whenever N_eff < N) on the 2-D Singer model [x, ẋ, y, ẏ, ÿ] with known clocks, GPS + DTMB pseudoranges",
        toml: r#"name = "PF"
sources = ["gps", "dtmb"]
filter = "sir"
[options]
particles = 20
resampling = "systematic"
neff_threshold = 1.0
[process]
model = "singer_2d""#,
    },
    Preset {
        name: "seed002-pdr",
        about: "seed 002 row 'PDR': dead reckoning from step length and heading only",
        toml: r#"name = "PDR"
sources = []
filter = "pdr"
[pdr]
heading_offset_sigma_deg = 3.4
step_scale_sigma = 0.08"#,
    },
    Preset {
        name: "seed002-pdr-mag-dtmb",
        about: "seed 002: PDR corrected by magnetic landmarks, each kept only if consistent with DTMB ranging (sec. 4.1), and by the DTMB TPS-CFO range differences (sec. 3.2, 4.2)",
        toml: r#"name = "PDR+MAG/DTMB"
sources = []
filter = "pdr"
[pdr]
fix_sources = ["magnetic"]
nis_gate = 13.8
range_difference_sources = ["dtmb"]
heading_offset_sigma_deg = 3.4
step_scale_sigma = 0.08"#,
    },
    Preset {
        name: "seed003-ekf",
        about: "seed 003 'EKF': plane variable-speed turning model + one clock per system (a1, a2, a3), GPS/BDS/DTMB, seamless scheme (Table 1)",
        toml: r#"name = "EKF"
sources = ["gps", "bds", "dtmb"]
filter = "ekf"
selection = "seamless"
[process]
model = "plane_turning""#,
    },
    Preset {
        name: "seed003-pf",
        about: "seed 003 'PF': the same model, measurements and scheme, SIR particle filter (500 particles, resampling whenever N_eff < N)",
        toml: r#"name = "PF"
sources = ["gps", "bds", "dtmb"]
filter = "sir"
selection = "seamless"
[options]
particles = 500
resampling = "systematic"
neff_threshold = 1.0
[process]
model = "plane_turning""#,
    },
    Preset {
        name: "seed004-rekf",
        about: "seed 004 'RE-KF': relative-entropy KF (eqs. 33-41) with the eq. 24 residual gate, C = 3, on the 15-state INS error state, loosely coupled with joint GNSS + TC-OFDM position and velocity fixes (eqs. 14-19)",
        toml: r#"name = "RE-KF"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "rekf"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-stf",
        about: "seed 004's comparison 'STF': strong tracking filter (Zhou & Frank, fading factor limited to 10) on the same INS error state and fixes, with the same eq. 24 gate, C = 3",
        toml: r#"name = "STF"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "stf"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-ckf",
        about: "seed 004's comparison 'CKF': cubature Kalman filter on the same INS error state and fixes, with the same eq. 24 gate, C = 3",
        toml: r#"name = "CKF"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "ckf"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-ekf",
        about: "seed 004's comparison 'EKF': the generic EKF (Joseph form) on the same INS error state and fixes, with the same eq. 24 gate, C = 3",
        toml: r#"name = "EKF"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "ekf"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-rekf-tight",
        about: "seed 004's 'RE-KF' tightly coupled: the relative-entropy KF (eqs. 33-41) on the 18-state INS error state + receiver clock, updated by each GNSS and TC-OFDM pseudorange and GNSS range rate (ranges nonlinear in the error state), with the eq. 24 gate, C = 3",
        toml: r#"name = "RE-KF (tight)"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "rekf"
coupling = "tight"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-stf-tight",
        about: "seed 004's 'STF' tightly coupled: the strong tracking filter (fading factor limited to 10) on the 18-state INS error state + receiver clock, updated by each GNSS and TC-OFDM pseudorange and GNSS range rate (ranges nonlinear in the error state), with the eq. 24 gate, C = 3",
        toml: r#"name = "STF (tight)"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "stf"
coupling = "tight"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-ckf-tight",
        about: "seed 004's 'CKF' tightly coupled: the cubature Kalman filter on the 18-state INS error state + receiver clock, updated by each GNSS and TC-OFDM pseudorange and GNSS range rate (ranges nonlinear in the error state), with the eq. 24 gate, C = 3",
        toml: r#"name = "CKF (tight)"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "ckf"
coupling = "tight"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-ekf-tight",
        about: "seed 004's 'EKF' tightly coupled: the generic EKF on the 18-state INS error state + receiver clock, updated by each GNSS and TC-OFDM pseudorange and GNSS range rate (ranges nonlinear in the error state), with the eq. 24 gate, C = 3",
        toml: r#"name = "EKF (tight)"
sources = ["gps", "bds", "tcofdm"]
filter = "ins"
[ins]
kalman = "ekf"
coupling = "tight"
fix_sources = ["gnss", "tcofdm"]
joint_fix = true
fix_velocity_noise_mps = [0.1, 0.25]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-rekf-ranges",
        about: "seed 004's RE-KF with the eq. 24 gate, C = 3, on seed 000's 12-state PVA + clock model with the GNSS + TC-OFDM pseudoranges (no INS)",
        toml: r#"name = "RE-KF (ranges)"
sources = ["gps", "bds", "tcofdm"]
filter = "rekf"
[options]
residual_gate_c = 3.0"#,
    },
    Preset {
        name: "seed004-stf-ranges",
        about: "the strong tracking filter on the same pseudoranges and model (no INS)",
        toml: r#"name = "STF (ranges)"
sources = ["gps", "bds", "tcofdm"]
filter = "stf""#,
    },
    Preset {
        name: "seed004-ckf-ranges",
        about: "the cubature Kalman filter on the same pseudoranges and model (no INS)",
        toml: r#"name = "CKF (ranges)"
sources = ["gps", "bds", "tcofdm"]
filter = "ckf""#,
    },
    Preset {
        name: "seed004-ekf-ranges",
        about: "the EKF (Joseph form) on the same pseudoranges and model (no INS)",
        toml: r#"name = "EKF (ranges)"
sources = ["gps", "bds", "tcofdm"]
filter = "ekf""#,
    },
];

/// The preset named `name`.
pub fn find(name: &str) -> Option<&'static Preset> {
    PRESETS.iter().find(|p| p.name == name)
}

/// Lays `over` on `base`: keys of `over` win, tables merge key by key.
fn overlay(base: &mut Table, over: Table) {
    for (k, v) in over {
        match (base.get_mut(&k), v) {
            (Some(Value::Table(b)), Value::Table(o)) => overlay(b, o),
            (_, v) => {
                base.insert(k, v);
            }
        }
    }
}

/// Expands `preset = "…"` in one estimator table.
///
/// # Errors
/// An unknown preset (the message lists the known ones) or a preset that is not a string.
pub fn expand(mut table: Table) -> Result<Table, String> {
    let Some(p) = table.remove("preset") else {
        return Ok(table);
    };
    let Value::String(name) = p else {
        return Err("preset: expected a string, e.g. preset = \"seed000-gps\"".into());
    };
    let Some(preset) = find(&name) else {
        let known: Vec<&str> = PRESETS.iter().map(|p| p.name).collect();
        return Err(format!(
            "preset: unknown preset '{name}'; expected one of {}",
            known.join(", ")
        ));
    };
    let mut base: Table = preset
        .toml
        .parse()
        .unwrap_or_else(|e| unreachable!("preset {} does not parse: {e}", preset.name));
    overlay(&mut base, table);
    Ok(base)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_preset_parses_and_is_found_by_name() {
        for p in PRESETS {
            let t: Table = p.toml.parse().expect(p.name);
            assert!(t.contains_key("filter"), "{}", p.name);
            assert!(find(p.name).is_some());
        }
    }

    #[test]
    fn table_keys_override_and_nested_tables_merge() {
        let user: Table = r#"preset = "seed003-pf"
name = "PF 100"
[options]
neff_threshold = 0.3"#
            .parse()
            .unwrap();
        let t = expand(user).unwrap();
        assert_eq!(t["name"].as_str(), Some("PF 100"));
        assert_eq!(t["filter"].as_str(), Some("sir"));
        assert_eq!(t["options"]["particles"].as_integer(), Some(500));
        assert_eq!(t["options"]["neff_threshold"].as_float(), Some(0.3));
        assert!(!t.contains_key("preset"));
    }

    /// Each seed 000 preset and its `-eq17` twin expand to the same estimator but for the
    /// range-rate Jacobian key (and the row name, so that both rows fit in one world).
    #[test]
    fn seed000_eq17_presets_differ_only_in_the_jacobian_key() {
        for base in ["seed000-gps", "seed000-gps-dtmb", "seed000-adaptive"] {
            let expanded = |name: &str| {
                let mut t = Table::new();
                t.insert("preset".into(), Value::String(name.into()));
                let mut t = expand(t).unwrap();
                let row = t.remove("name").unwrap();
                let jac = t["ekf"]["rate_position_jacobian"].as_bool().unwrap();
                t.get_mut("ekf")
                    .and_then(Value::as_table_mut)
                    .unwrap()
                    .remove("rate_position_jacobian");
                (t, row, jac)
            };
            let (exact, row, jac) = expanded(base);
            let (eq17, row17, jac17) = expanded(&format!("{base}-eq17"));
            assert!(jac && !jac17, "{base}: {jac} / {jac17}");
            assert_eq!(exact, eq17, "{base}");
            assert_eq!(
                format!("{} (eq. 17)", row.as_str().unwrap()),
                row17.as_str().unwrap()
            );
        }
    }

    #[test]
    fn unknown_presets_are_named_with_the_alternatives() {
        let user: Table = "preset = \"seed009\"".parse().unwrap();
        let e = expand(user).unwrap_err();
        assert!(
            e.contains("seed009") && e.contains("seed000-adaptive"),
            "{e}"
        );
    }
}
