//! The compared models' names: one type for the `model` column of the test
//! stage's tables (`predictions`, `rollout`, `timings`) and of summarize's,
//! which the report reads back ([`ModelId`]), and one for the plan stage's
//! (`planning`: [`PolicyId`]). Their text is the column's value, so tables
//! written before the types existed read as the same models. No other
//! module names a compared model by its text (`tests/structure.rs` checks).

use std::fmt;
use std::str::FromStr;

use serde::{Deserialize, Deserializer, Serialize, Serializer};

/// A model the test stage predicts with and the report compares.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum ModelId {
    /// The variant's trained ALN, whatever its form (a hybrid when it
    /// learns a correction of the nominal simulator): `aln`.
    Aln,
    /// No change predicted: `persistence`.
    Persistence,
    /// A robust linear fit of the change: `linear`.
    Linear,
    /// Gradient-boosted trees, the learned peer: `boosted`.
    Boosted,
    /// The nominal simulator plus a robust linear correction:
    /// `linear+nominal`.
    LinearNominal,
    /// The nominal simulator plus a boosted correction: `boosted+nominal`.
    BoostedNominal,
    /// The simulator re-stepping each logged frame in `steps` steps:
    /// `simulator@<steps>/frame`.
    Simulator {
        /// Integration steps a frame.
        steps: u64,
    },
}

impl ModelId {
    /// Every model whose name takes no number.
    pub const FIXED: [ModelId; 6] = [
        ModelId::Aln,
        ModelId::Persistence,
        ModelId::Linear,
        ModelId::Boosted,
        ModelId::LinearNominal,
        ModelId::BoostedNominal,
    ];

    /// The integration steps a frame of the simulator re-stepping each
    /// frame; `None` for a learned model or persistence.
    pub fn simulator_steps(self) -> Option<u64> {
        match self {
            ModelId::Simulator { steps } => Some(steps),
            ModelId::Aln
            | ModelId::Persistence
            | ModelId::Linear
            | ModelId::Boosted
            | ModelId::LinearNominal
            | ModelId::BoostedNominal => None,
        }
    }

    /// Whether it is the simulator re-stepping each frame.
    pub fn is_simulator(self) -> bool {
        self.simulator_steps().is_some()
    }

    /// Whether it is a hybrid baseline: the nominal simulator plus a
    /// learned correction (an ALN trained as one is still `aln`).
    pub fn is_hybrid(self) -> bool {
        match self {
            ModelId::LinearNominal | ModelId::BoostedNominal => true,
            ModelId::Aln
            | ModelId::Persistence
            | ModelId::Linear
            | ModelId::Boosted
            | ModelId::Simulator { .. } => false,
        }
    }
}

impl fmt::Display for ModelId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ModelId::Aln => f.write_str("aln"),
            ModelId::Persistence => f.write_str("persistence"),
            ModelId::Linear => f.write_str("linear"),
            ModelId::Boosted => f.write_str("boosted"),
            ModelId::LinearNominal => f.write_str("linear+nominal"),
            ModelId::BoostedNominal => f.write_str("boosted+nominal"),
            ModelId::Simulator { steps } => write!(f, "simulator@{steps}/frame"),
        }
    }
}

impl FromStr for ModelId {
    type Err = String;

    /// The model a `model` column names; anything else is an error naming
    /// what it may be.
    fn from_str(s: &str) -> Result<ModelId, String> {
        if let Some(id) = ModelId::FIXED.into_iter().find(|id| id.to_string() == s) {
            return Ok(id);
        }
        s.strip_prefix("simulator@")
            .and_then(|rest| rest.strip_suffix("/frame"))
            .and_then(|k| k.parse().ok())
            .filter(|&steps| steps > 0)
            .map(|steps| ModelId::Simulator { steps })
            .ok_or_else(|| {
                format!(
                    "`{s}` names no compared model; expected one of {}, or simulator@<k>/frame \
                     with k ≥ 1",
                    ModelId::FIXED.map(|id| format!("`{id}`")).join(", ")
                )
            })
    }
}

impl Serialize for ModelId {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for ModelId {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<ModelId, D::Error> {
        let text = String::deserialize(deserializer)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}

/// A policy of the plan stage: a forward model a planner plans with, or a
/// reference that plans nothing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum PolicyId {
    /// The variant's trained ALN: `aln`.
    Aln,
    /// The robust linear fit: `linear`.
    Linear,
    /// The nominal simulator (the scene as written, without its plant),
    /// `steps` integration steps a frame: `simulator@<steps>`.
    Simulator {
        /// Integration steps a frame.
        steps: u64,
    },
    /// The plant's own simulator — its actuators, delay and noise — which
    /// no user has: `plant@<steps>`.
    Plant {
        /// Integration steps a frame.
        steps: u64,
    },
    /// Zero torques: `zero`.
    Zero,
    /// The scene's random controller: `random`.
    Random,
    /// A PD loop on the nominal model's gravity compensation, the controls
    /// engineer's first try: `gravity-pd`.
    GravityPd,
    /// The same with an integral: `gravity-pid`.
    GravityPid,
}

impl PolicyId {
    /// Every policy whose name takes no number.
    pub const FIXED: [PolicyId; 6] = [
        PolicyId::Aln,
        PolicyId::Linear,
        PolicyId::Zero,
        PolicyId::Random,
        PolicyId::GravityPd,
        PolicyId::GravityPid,
    ];

    /// The policy that plans with the test stage's `model`, where the
    /// plan stage has one.
    pub fn planning_with(model: ModelId) -> Option<PolicyId> {
        match model {
            ModelId::Aln => Some(PolicyId::Aln),
            ModelId::Linear => Some(PolicyId::Linear),
            ModelId::Simulator { steps } => Some(PolicyId::Simulator { steps }),
            ModelId::Persistence
            | ModelId::Boosted
            | ModelId::LinearNominal
            | ModelId::BoostedNominal => None,
        }
    }
}

impl fmt::Display for PolicyId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PolicyId::Aln => f.write_str("aln"),
            PolicyId::Linear => f.write_str("linear"),
            PolicyId::Simulator { steps } => write!(f, "simulator@{steps}"),
            PolicyId::Plant { steps } => write!(f, "plant@{steps}"),
            PolicyId::Zero => f.write_str("zero"),
            PolicyId::Random => f.write_str("random"),
            PolicyId::GravityPd => f.write_str("gravity-pd"),
            PolicyId::GravityPid => f.write_str("gravity-pid"),
        }
    }
}

impl FromStr for PolicyId {
    type Err = String;

    /// The policy a planning table's `model` column names; anything else
    /// is an error naming what it may be.
    fn from_str(s: &str) -> Result<PolicyId, String> {
        if let Some(id) = PolicyId::FIXED.into_iter().find(|id| id.to_string() == s) {
            return Ok(id);
        }
        let steps = |prefix: &str| -> Option<u64> {
            s.strip_prefix(prefix)?.parse().ok().filter(|&k| k > 0)
        };
        if let Some(steps) = steps("simulator@") {
            return Ok(PolicyId::Simulator { steps });
        }
        if let Some(steps) = steps("plant@") {
            return Ok(PolicyId::Plant { steps });
        }
        Err(format!(
            "`{s}` names no policy; expected one of {}, simulator@<k> or plant@<k> with k ≥ 1",
            PolicyId::FIXED.map(|id| format!("`{id}`")).join(", ")
        ))
    }
}

impl Serialize for PolicyId {
    fn serialize<S: Serializer>(&self, serializer: S) -> Result<S::Ok, S::Error> {
        serializer.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for PolicyId {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<PolicyId, D::Error> {
        let text = String::deserialize(deserializer)?;
        text.parse().map_err(serde::de::Error::custom)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_model_reads_back_from_its_name() {
        let simulators = [1, 10].map(|steps| ModelId::Simulator { steps });
        for id in ModelId::FIXED.into_iter().chain(simulators) {
            assert_eq!(id.to_string().parse::<ModelId>(), Ok(id));
            let json = serde_json::to_string(&id).unwrap();
            assert_eq!(json, format!("\"{id}\""));
            assert_eq!(serde_json::from_str::<ModelId>(&json).unwrap(), id);
        }
        assert_eq!(
            ModelId::Simulator { steps: 2 }.to_string(),
            "simulator@2/frame"
        );
    }

    #[test]
    fn every_policy_reads_back_from_its_name() {
        let numbered = [1, 10].map(|steps| PolicyId::Simulator { steps });
        let plants = [2].map(|steps| PolicyId::Plant { steps });
        for id in PolicyId::FIXED.into_iter().chain(numbered).chain(plants) {
            assert_eq!(id.to_string().parse::<PolicyId>(), Ok(id));
            let json = serde_json::to_string(&id).unwrap();
            assert_eq!(serde_json::from_str::<PolicyId>(&json).unwrap(), id);
        }
        assert_eq!(PolicyId::Plant { steps: 4 }.to_string(), "plant@4");
        assert_eq!(
            PolicyId::planning_with(ModelId::Simulator { steps: 2 }),
            Some(PolicyId::Simulator { steps: 2 })
        );
        assert_eq!(PolicyId::planning_with(ModelId::Persistence), None);
        for bad in ["", "simulator@0", "simulator@2/frame", "plant@", "zeros"] {
            let error = bad.parse::<PolicyId>().unwrap_err();
            assert!(
                error.contains(&format!("`{bad}`")) && error.contains("plant@<k>"),
                "{error}"
            );
        }
    }

    #[test]
    fn other_names_are_refused_saying_what_is_expected() {
        for bad in [
            "",
            "ALN",
            "simulator@0/frame",
            "simulator@2",
            "plant@1",
            "linear+",
        ] {
            let error = bad.parse::<ModelId>().unwrap_err();
            assert!(
                error.contains(&format!("`{bad}`")) && error.contains("simulator@<k>/frame"),
                "{error}"
            );
        }
    }
}
