//! `[comparison]`: the protocol every estimator of a paper's table shares.
//!
//! A comparison of filters is fair only when the filters differ in the filter and nothing
//! else. Before this table each preset carried its own data-layer gate, so seed 004's RE-KF
//! was the only filter with the eq.-24 residual gate and its "advantage" was partly the
//! gate. The table names what the compared rows share:
//!
//! - the **data-layer residual gate** `|d_j| ≤ C·√ε_jj` of seed 004 (eq. 24), or `"none"`;
//! - the engine's **divergence watch** (`engine::health`: the NIS or the share of gated
//!   measurements outside their bound for `window_epochs` scoring instants at a per-epoch
//!   tail probability `false_alarm`) and its reset policy (the estimator is re-initialised
//!   from its next least-squares fix, the one policy the engine has);
//!
//! and an estimator may depart from it only through a `[[comparison.deviation]]` that cites
//! where its paper says so. Loading applies the protocol to every compared estimator's own
//! configuration; an estimator whose table sets a different value without a deviation, or
//! whose filter has no such gate, is an error naming the estimator and the key.
//! `summary.json` lists, per estimator, the protocol it ran under (gates, watch, resets,
//! deviations with their citations), and the tables mark deviating rows.

use super::schema::{EstimatorSpec, FilterKind};
use crate::engine::health::HealthConfig;
use crate::inertial::ins_family::InsKalmanKind;
use crate::metrics::summary::{EstimatorProtocol, ProtocolDeviation};
use schemars::JsonSchema;
use serde::{Deserialize, Serialize};

/// `[comparison]`.
#[derive(Clone, Debug, Default, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct ComparisonSection {
    /// The rows of the comparison, by estimator name; default every estimator of the world.
    #[serde(default)]
    pub estimators: Option<Vec<String>>,
    /// The data-layer residual gate every compared filter applies: seed 004's `C` of
    /// `|d_j| ≤ C·√ε_jj` (eq. 24), or `"none"`. Absent: each estimator keeps its own
    /// (listed in `summary.json`).
    #[serde(default)]
    pub residual_gate_c: Option<GateSetting>,
    /// The divergence watch the compared estimators share; default the engine's (10
    /// instants at a per-instant tail probability of 10⁻⁴).
    #[serde(default)]
    pub divergence: Option<DivergenceWatch>,
    /// Where a compared estimator departs from the protocol because its paper says so.
    #[serde(default, rename = "deviation")]
    pub deviations: Vec<Deviation>,
}

/// A residual gate factor, or `"none"`.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize, JsonSchema)]
#[serde(untagged)]
pub enum GateSetting {
    /// `C > 0`.
    Factor(f64),
    /// No data-layer gate.
    Off(NoGate),
}

/// The word `"none"`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum NoGate {
    None,
}

impl GateSetting {
    fn factor(self) -> Option<f64> {
        match self {
            GateSetting::Factor(c) => Some(c),
            GateSetting::Off(_) => None,
        }
    }
}

/// `[comparison.divergence]`: the engine's divergence watch ([`HealthConfig`]).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct DivergenceWatch {
    /// Consecutive scoring instants out of bounds that declare a divergence.
    #[schemars(range(min = 1, max = 100_000))]
    pub window_epochs: u32,
    /// The per-instant tail probability of the NIS bound.
    #[schemars(range(min = 1e-12, max = 0.5))]
    pub false_alarm: f64,
}

/// What a deviation may concern.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize, JsonSchema)]
#[serde(rename_all = "snake_case")]
pub enum ProtocolKey {
    /// The estimator keeps its own data-layer gate.
    ResidualGateC,
    /// The estimator keeps the engine's default divergence watch.
    Divergence,
}

impl ProtocolKey {
    fn name(self) -> &'static str {
        match self {
            ProtocolKey::ResidualGateC => "residual_gate_c",
            ProtocolKey::Divergence => "divergence",
        }
    }
}

/// One `[[comparison.deviation]]`.
#[derive(Clone, Debug, Deserialize, Serialize, JsonSchema)]
#[serde(deny_unknown_fields)]
pub struct Deviation {
    /// The estimator (its name).
    pub estimator: String,
    /// What it keeps of its own.
    pub key: ProtocolKey,
    /// Where its paper says so (paper, section or equation).
    pub cite: String,
}

/// The protocol as applied to a world: per estimator, in the world's order.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Applied {
    pub protocols: Vec<EstimatorProtocol>,
    pub health: Vec<HealthConfig>,
}

/// Where an estimator's data-layer gate lives, and its value when its table leaves it out.
enum GateSlot<'a> {
    /// The filter has no data-layer gate.
    Absent,
    /// `slot`, and the value the filter uses when `slot` is `None`.
    Present {
        slot: &'a mut Option<f64>,
        key: &'static str,
        default: Option<f64>,
    },
}

fn gate_slot(e: &mut EstimatorSpec) -> GateSlot<'_> {
    match e.filter {
        FilterKind::Ekf
        | FilterKind::Ukf
        | FilterKind::Ckf
        | FilterKind::Stf
        | FilterKind::Rekf => {
            // The RE-KF's data layer defaults to C = 3 (family and paper models alike).
            let default = (e.filter == FilterKind::Rekf).then_some(3.0);
            let options = e.options.get_or_insert_with(Default::default);
            GateSlot::Present {
                slot: &mut options.residual_gate_c,
                key: "options.residual_gate_c",
                default,
            }
        }
        FilterKind::Ins => {
            let ins = e.ins.get_or_insert_with(Default::default);
            if ins.kalman == InsKalmanKind::Builtin {
                GateSlot::Absent
            } else {
                GateSlot::Present {
                    slot: &mut ins.residual_gate_c,
                    key: "ins.residual_gate_c",
                    default: None,
                }
            }
        }
        FilterKind::Ekf11
        | FilterKind::Wls
        | FilterKind::Pdr
        | FilterKind::Pf
        | FilterKind::Sir
        | FilterKind::Rbpf
        | FilterKind::Mpf
        | FilterKind::Gpf => GateSlot::Absent,
    }
}

/// The effective data-layer gate of an estimator (without changing it).
fn gate_of(e: &EstimatorSpec) -> Option<f64> {
    let mut probe = e.clone();
    match gate_slot(&mut probe) {
        GateSlot::Absent => None,
        GateSlot::Present { slot, default, .. } => slot.or(default),
    }
}

/// The innovation χ²(1) gate of the filters that have one (seed 000's model and the
/// filter family), as the estimator will run it.
fn chi2_gate_of(e: &EstimatorSpec) -> Option<f64> {
    // The family's particle filter weighs every range: it has no innovation gate.
    (e.runs_pva_clock() && e.filter != FilterKind::Pf)
        .then(|| e.ekf.unwrap_or_default().gate_chi2)
        .flatten()
}

/// Validates `[comparison]` against the estimators and applies it to their configuration.
///
/// # Errors
/// `(key path, message)` of the first problem: an unknown row or deviation, a value out
/// of range, a compared estimator whose table sets a different gate without a deviation,
/// or one whose filter has no data-layer gate.
pub fn apply(
    section: Option<&ComparisonSection>,
    estimators: &mut [EstimatorSpec],
) -> Result<Applied, (String, String)> {
    let empty = ComparisonSection::default();
    let c = section.unwrap_or(&empty);
    let known = |name: &str| estimators.iter().any(|e| e.name == name);
    let list = |names: &[String]| {
        names
            .iter()
            .map(|n| format!("'{n}'"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let all: Vec<String> = estimators.iter().map(|e| e.name.clone()).collect();
    if let Some(rows) = &c.estimators {
        if rows.is_empty() {
            return Err((
                "comparison.estimators".into(),
                "expected at least one estimator name".into(),
            ));
        }
        for (j, n) in rows.iter().enumerate() {
            if !known(n) {
                return Err((
                    format!("comparison.estimators[{j}]"),
                    format!(
                        "no estimator is named '{n}'; the world's are {}",
                        list(&all)
                    ),
                ));
            }
        }
    }
    let compared = |name: &str| {
        c.estimators
            .as_ref()
            .is_none_or(|r| r.iter().any(|n| n == name))
    };
    if let Some(GateSetting::Factor(g)) = c.residual_gate_c {
        if !(g.is_finite() && g > 0.0 && g <= 1.0e3) {
            return Err((
                "comparison.residual_gate_c".into(),
                format!("{g}: expected a gate factor C in (0, 1000] or \"none\""),
            ));
        }
    }
    if let Some(d) = c.divergence {
        if d.window_epochs == 0 || d.window_epochs > 100_000 {
            return Err((
                "comparison.divergence.window_epochs".into(),
                format!("{}: expected 1 to 100 000 instants", d.window_epochs),
            ));
        }
        if !(d.false_alarm > 0.0 && d.false_alarm <= 0.5) {
            return Err((
                "comparison.divergence.false_alarm".into(),
                format!("{}: expected a probability in (0, 0.5]", d.false_alarm),
            ));
        }
    }
    for (j, d) in c.deviations.iter().enumerate() {
        let at = |k: &str| format!("comparison.deviation[{j}].{k}");
        if !known(&d.estimator) {
            return Err((
                at("estimator"),
                format!(
                    "no estimator is named '{}'; the world's are {}",
                    d.estimator,
                    list(&all)
                ),
            ));
        }
        if !compared(&d.estimator) {
            return Err((
                at("estimator"),
                format!(
                    "'{}' is not a row of the comparison (comparison.estimators), so it has no protocol to depart from",
                    d.estimator
                ),
            ));
        }
        if d.cite.trim().is_empty() {
            return Err((
                at("cite"),
                "expected where the paper says so (paper, section or equation)".into(),
            ));
        }
        if c.deviations[..j]
            .iter()
            .any(|o| o.estimator == d.estimator && o.key == d.key)
        {
            return Err((
                at("key"),
                format!("'{}' departs from {} twice", d.estimator, d.key.name()),
            ));
        }
        let shared = match d.key {
            ProtocolKey::ResidualGateC => c.residual_gate_c.is_some(),
            ProtocolKey::Divergence => c.divergence.is_some(),
        };
        if !shared {
            return Err((
                at("key"),
                format!(
                    "[comparison] sets no {}, so there is nothing to depart from",
                    d.key.name()
                ),
            ));
        }
    }

    let mut applied = Applied::default();
    for (i, e) in estimators.iter_mut().enumerate() {
        let name = e.name.clone();
        let is_compared = compared(&name);
        let deviates = |k: ProtocolKey| {
            c.deviations
                .iter()
                .find(|d| d.key == k && d.estimator == name)
                .map(|d| ProtocolDeviation {
                    key: k.name().to_string(),
                    cite: d.cite.clone(),
                })
        };
        let mut deviations = Vec::new();
        if let (true, Some(shared)) = (is_compared, c.residual_gate_c) {
            if let Some(d) = deviates(ProtocolKey::ResidualGateC) {
                deviations.push(d);
            } else {
                let filter = format!("{:?}", e.filter).to_lowercase();
                match gate_slot(e) {
                    // A filter without a data layer already follows "none".
                    GateSlot::Absent if shared.factor().is_none() => {}
                    GateSlot::Absent => {
                        return Err((
                            format!("estimator[{i}]"),
                            format!(
                                "'{name}' (filter \"{filter}\") has no data-layer residual gate, which [comparison] residual_gate_c gives every compared row: leave it out of comparison.estimators, or add a [[comparison.deviation]] citing its paper"
                            ),
                        ));
                    }
                    GateSlot::Present { slot, key, default } => {
                        let want = shared.factor();
                        let own = slot.or(default);
                        if slot.is_some() && own != want {
                            return Err((
                                format!("estimator[{i}].{key}"),
                                format!(
                                    "'{name}' sets its own gate ({}) but [comparison] residual_gate_c is {}: remove it, or add a [[comparison.deviation]] citing where its paper says so",
                                    show_gate(own),
                                    show_gate(want)
                                ),
                            ));
                        }
                        if want.is_none() && default.is_some() {
                            return Err((
                                format!("estimator[{i}]"),
                                format!(
                                    "'{name}' always gates its data layer (C = {}), so it cannot follow residual_gate_c = \"none\": add a [[comparison.deviation]] citing its paper",
                                    default.unwrap_or_default()
                                ),
                            ));
                        }
                        *slot = want;
                    }
                }
            }
        }
        let mut health = HealthConfig::default();
        if let (true, Some(w)) = (is_compared, c.divergence) {
            if let Some(d) = deviates(ProtocolKey::Divergence) {
                deviations.push(d);
            } else {
                health = HealthConfig {
                    window_epochs: w.window_epochs,
                    false_alarm: w.false_alarm,
                };
            }
        }
        applied.protocols.push(EstimatorProtocol {
            compared: is_compared && section.is_some(),
            residual_gate_c: gate_of(e),
            gate_chi2: chi2_gate_of(e),
            divergence_window_epochs: health.window_epochs,
            divergence_false_alarm: health.false_alarm,
            reset: "reinitialise from the next least-squares fix".to_string(),
            deviations,
        });
        applied.health.push(health);
    }
    Ok(applied)
}

fn show_gate(c: Option<f64>) -> String {
    c.map_or_else(|| "\"none\"".to_string(), |c| format!("C = {c}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn estimators(toml_text: &str) -> Vec<EstimatorSpec> {
        #[derive(Deserialize)]
        struct F {
            estimator: Vec<EstimatorSpec>,
        }
        toml::from_str::<F>(toml_text).unwrap().estimator
    }

    fn section(toml_text: &str) -> ComparisonSection {
        toml::from_str(toml_text).unwrap()
    }

    const FOUR: &str = r#"
[[estimator]]
name = "EKF"
sources = ["gps"]
filter = "ekf"
[[estimator]]
name = "RE-KF"
sources = ["gps"]
filter = "rekf"
[[estimator]]
name = "STF"
sources = ["gps"]
filter = "stf"
options = { residual_gate_c = 2.0 }
[[estimator]]
name = "WLS"
sources = ["gps"]
filter = "wls"
"#;

    /// The shared gate reaches every compared filter that leaves it out; the one that sets
    /// its own is refused until it cites its paper, and then keeps its own; a row whose
    /// filter has no data layer is refused unless it is left out of the comparison.
    #[test]
    fn the_shared_gate_reaches_every_row_and_departures_need_a_citation() {
        let mut e = estimators(FOUR);
        let only3 = section("estimators = [\"EKF\", \"RE-KF\", \"STF\"]\nresidual_gate_c = 3.0\n");
        let (key, msg) = apply(Some(&only3), &mut e).unwrap_err();
        assert_eq!(key, "estimator[2].options.residual_gate_c");
        assert!(msg.contains("'STF'") && msg.contains("C = 2") && msg.contains("C = 3"));

        let mut e = estimators(FOUR);
        let cited = section(
            "estimators = [\"EKF\", \"RE-KF\", \"STF\"]\nresidual_gate_c = 3.0\n[[deviation]]\nestimator = \"STF\"\nkey = \"residual_gate_c\"\ncite = \"a paper, §3\"\n",
        );
        let a = apply(Some(&cited), &mut e).unwrap();
        let gates: Vec<Option<f64>> = a.protocols.iter().map(|p| p.residual_gate_c).collect();
        assert_eq!(gates, [Some(3.0), Some(3.0), Some(2.0), None]);
        assert_eq!(e[0].options.unwrap().residual_gate_c, Some(3.0));
        assert_eq!(a.protocols[2].deviations[0].cite, "a paper, §3");
        assert!(a.protocols[0].compared && !a.protocols[3].compared);

        let mut e = estimators(FOUR);
        let everyone = section("residual_gate_c = 3.0\n[[deviation]]\nestimator = \"STF\"\nkey = \"residual_gate_c\"\ncite = \"x\"\n");
        let (key, msg) = apply(Some(&everyone), &mut e).unwrap_err();
        assert_eq!(key, "estimator[3]");
        assert!(msg.contains("'WLS'") && msg.contains("no data-layer residual gate"));
    }

    /// `"none"` removes the gate where it is optional and refuses the RE-KF, whose data
    /// layer always gates.
    #[test]
    fn no_gate_is_refused_for_the_rekf_without_a_citation() {
        let mut e = estimators(FOUR);
        let none = section("estimators = [\"EKF\", \"RE-KF\"]\nresidual_gate_c = \"none\"\n");
        let (key, msg) = apply(Some(&none), &mut e).unwrap_err();
        assert_eq!(key, "estimator[1]");
        assert!(msg.contains("always gates"), "{msg}");
        // A filter without a data layer follows "none" as it is.
        let mut e = estimators(FOUR);
        let none = section("estimators = [\"EKF\", \"WLS\"]\nresidual_gate_c = \"none\"\n");
        let a = apply(Some(&none), &mut e).unwrap();
        assert_eq!(a.protocols[0].residual_gate_c, None);
        assert!(a.protocols[3].compared);
    }

    /// The shared watch reaches the compared rows only; without a table every estimator
    /// has the engine's default and is not marked compared.
    #[test]
    fn the_divergence_watch_is_shared_by_the_compared_rows() {
        let mut e = estimators(FOUR);
        let watch = section(
            "estimators = [\"EKF\", \"RE-KF\"]\ndivergence = { window_epochs = 30, false_alarm = 1e-6 }\n",
        );
        let a = apply(Some(&watch), &mut e).unwrap();
        assert_eq!(a.health[0].window_epochs, 30);
        assert_eq!(a.health[1].false_alarm, 1e-6);
        assert_eq!(a.health[2], HealthConfig::default());
        let a = apply(None, &mut estimators(FOUR)).unwrap();
        assert!(a
            .protocols
            .iter()
            .all(|p| !p.compared && p.deviations.is_empty()));
        assert_eq!(a.protocols[1].residual_gate_c, Some(3.0));
    }

    /// Mistakes name their key.
    #[test]
    fn unknown_rows_and_empty_citations_are_named() {
        let cases = [
            ("estimators = [\"EKF\", \"UKF\"]\n", "comparison.estimators[1]", "'UKF'"),
            ("residual_gate_c = -1.0\n", "comparison.residual_gate_c", "expected a gate factor"),
            (
                "residual_gate_c = 3.0\n[[deviation]]\nestimator = \"EKF\"\nkey = \"residual_gate_c\"\ncite = \" \"\n",
                "comparison.deviation[0].cite",
                "expected where the paper says so",
            ),
            (
                "[[deviation]]\nestimator = \"EKF\"\nkey = \"divergence\"\ncite = \"x\"\n",
                "comparison.deviation[0].key",
                "nothing to depart from",
            ),
        ];
        for (text, key, msg) in cases {
            let (k, m) = apply(Some(&section(text)), &mut estimators(FOUR)).unwrap_err();
            assert_eq!(k, key, "{text}");
            assert!(m.contains(msg), "{text}: {m}");
        }
    }
}
