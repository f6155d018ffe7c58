//! The compared models' names: one type for the `model` column of the test
//! stage's tables (`predictions`, `rollout`, `timings`) and of summarize's,
//! which the report reads back. Its text is the column's value, so tables
//! written before the type existed read as the same models.

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
