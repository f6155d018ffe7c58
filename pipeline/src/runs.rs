//! Tracking across runs: what `alnlab runs list`, `show` and `diff` compute
//! from the run records ([`crate::records`]) — a variant's parameters and
//! its headline metrics, across replicates as a mean with a 95% interval.

use std::collections::BTreeMap;
use std::path::Path;

use alnlab_common::{Error, Result};
use alnlab_report::metrics::Metrics;
use alnlab_summarize::paired::Interval;
use serde::Serialize;

use crate::records::{self, RunRecord, Stored, VariantRecord};

/// The metrics `runs list` shows for every variant: the mean errors of the
/// ALN and of the two baselines every run has, and the ALN's time per state
/// on one thread, batched and one state at a time.
pub const HEADLINE: [&str; 5] = [
    "error/aln",
    "error/persistence",
    "error/linear",
    "ns_per_state/aln/batched",
    "ns_per_state/aln/single",
];

/// One figure of a variant: its mean across the replicates that have it,
/// with the 95% t-interval across them when there are two or more.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Figure {
    pub mean: f64,
    /// The interval's bounds (`None` for a single replicate).
    pub low: Option<f64>,
    pub high: Option<f64>,
    /// How many replicates have the figure.
    pub n: usize,
}

impl Figure {
    /// The figure of `values`, one per replicate.
    fn of(values: &[f64]) -> Option<Figure> {
        let interval = Interval::of(values)?;
        let bounded = values.len() > 1;
        Some(Figure {
            mean: interval.mean,
            low: bounded.then_some(interval.low),
            high: bounded.then_some(interval.high),
            n: values.len(),
        })
    }

    /// Whether `x` lies inside the interval (`None` without one).
    fn contains(&self, x: f64) -> Option<bool> {
        Some(self.low? <= x && x <= self.high?)
    }
}

/// One variant of one run: its replicates' records and metrics.
pub struct VariantRun<'a> {
    pub run: &'a RunRecord,
    pub name: &'a str,
    pub replicates: Vec<&'a VariantRecord>,
    /// Each replicate's metrics: from the record, or — for a format-1
    /// record — read from its artifacts while the cache holds them.
    pub metrics: Vec<Option<Metrics>>,
}

impl<'a> VariantRun<'a> {
    /// Every variant of `run`, in the record's order.
    pub fn all(out: &Path, run: &'a RunRecord) -> Vec<VariantRun<'a>> {
        let mut names: Vec<&str> = run.variants.iter().map(|v| v.name.as_str()).collect();
        names.dedup();
        names
            .into_iter()
            .map(|n| VariantRun::of(out, run, n))
            .collect()
    }

    /// The variant `name` of `run`.
    pub fn of(out: &Path, run: &'a RunRecord, name: &'a str) -> VariantRun<'a> {
        let replicates: Vec<&VariantRecord> =
            run.variants.iter().filter(|v| v.name == name).collect();
        let metrics = replicates
            .iter()
            .map(|v| {
                // A format-1 record's, from its artifacts while the cache holds them.
                v.metrics
                    .clone()
                    .or_else(|| records::read_metrics(v, |a| records::locate(out, a)).ok())
            })
            .collect();
        VariantRun {
            run,
            name,
            replicates,
            metrics,
        }
    }

    /// The variant's resolved parameters (its first replicate's).
    pub fn parameters(&self) -> &BTreeMap<String, String> {
        &self.replicates[0].parameters
    }

    /// The figure `name` across the replicates.
    pub fn figure(&self, name: &str) -> Option<Figure> {
        let values: Vec<f64> = self
            .metrics
            .iter()
            .filter_map(|m| m.as_ref()?.values.get(name).copied())
            .collect();
        Figure::of(&values)
    }

    /// Every figure name any replicate has.
    pub fn figure_names(&self) -> Vec<&str> {
        let mut names: Vec<&str> = self
            .metrics
            .iter()
            .flatten()
            .flat_map(|m| m.values.keys().map(String::as_str))
            .collect();
        names.sort_unstable();
        names.dedup();
        names
    }

    /// The rows the figures are over (`held-out` or `all`).
    pub fn rows(&self) -> Option<&str> {
        self.metrics
            .iter()
            .flatten()
            .map(|m| m.rows.as_str())
            .next()
    }

    /// How many of the variant's artifact files the cache still holds, of
    /// how many.
    pub fn cached(&self, out: &Path) -> (usize, usize) {
        let files: Vec<_> = self
            .replicates
            .iter()
            .flat_map(|v| v.artifacts.values())
            .collect();
        let present = files
            .iter()
            .filter(|a| records::locate(out, a).is_some())
            .count();
        (present, files.len())
    }

    /// Whether the variant's parameters satisfy every `KEY=VALUE` filter.
    pub fn matches(&self, filters: &[Filter]) -> bool {
        filters
            .iter()
            .all(|f| self.parameters().get(&f.key).is_some_and(|v| f.accepts(v)))
    }
}

/// A `--where KEY=VALUE` filter on a variant's parameters: numbers compare
/// as numbers (`train.vote=3` accepts `3`, `dt=0.001` accepts `1e-3`), any
/// other value as text.
#[derive(Clone, Debug, PartialEq)]
pub struct Filter {
    pub key: String,
    pub value: String,
}

impl Filter {
    /// Whether a parameter's `value` is the filter's.
    fn accepts(&self, value: &str) -> bool {
        match (value.parse::<f64>(), self.value.parse::<f64>()) {
            (Ok(a), Ok(b)) => a == b,
            _ => value == self.value,
        }
    }
}

impl std::str::FromStr for Filter {
    type Err = String;

    fn from_str(text: &str) -> std::result::Result<Filter, String> {
        match text.split_once('=') {
            Some((key, value)) if !key.trim().is_empty() => Ok(Filter {
                key: key.trim().to_string(),
                value: value.trim().to_string(),
            }),
            _ => Err(format!(
                "`{text}` is not KEY=VALUE (a parameter's dotted key, as `alnlab runs show` \
                 lists them: `train.vote=3`)"
            )),
        }
    }
}

/// The runs `runs list` shows: every run under `out` (of `experiment`, if
/// given) with the variants that pass the filters.
pub fn list<'a>(
    out: &Path,
    runs: &'a [Stored],
    experiment: Option<&str>,
    filters: &[Filter],
) -> Vec<VariantRun<'a>> {
    runs.iter()
        .filter(|s| experiment.is_none_or(|e| s.record.experiment == e))
        .flat_map(|s| VariantRun::all(out, &s.record))
        .filter(|v| v.matches(filters))
        .collect()
}

/// One parameter that differs between two variants.
#[derive(Debug, PartialEq, Serialize)]
pub struct ParameterChange {
    pub key: String,
    /// Its value in A and in B (`None`: not set there).
    pub a: Option<String>,
    pub b: Option<String>,
}

/// One metric of two variants side by side.
#[derive(Debug, PartialEq, Serialize)]
pub struct MetricChange {
    pub name: String,
    pub a: Option<Figure>,
    pub b: Option<Figure>,
    /// B's mean minus A's.
    pub change: Option<f64>,
    /// The change relative to A's mean.
    pub relative: Option<f64>,
    /// With replicates on both sides: whether each mean lies outside the
    /// other's 95% interval.
    pub outside_both_intervals: Option<bool>,
}

impl MetricChange {
    /// Whether the metric differs (or is on one side only).
    pub fn changed(&self) -> bool {
        match (self.a, self.b) {
            (Some(a), Some(b)) => a.mean != b.mean,
            (None, None) => false,
            _ => true,
        }
    }
}

/// Two variants compared.
#[derive(Debug, Serialize)]
pub struct Diff {
    /// The parameters that differ (the replicate seed aside: it follows
    /// from `experiment.seed`).
    pub parameters: Vec<ParameterChange>,
    /// How many parameters the two have between them.
    pub parameters_compared: usize,
    pub metrics: Vec<MetricChange>,
}

/// Variant A against variant B.
pub fn diff(a: &VariantRun, b: &VariantRun) -> Diff {
    let (pa, pb) = (a.parameters(), b.parameters());
    let mut keys: Vec<&String> = pa.keys().chain(pb.keys()).collect();
    keys.sort_unstable();
    keys.dedup();
    let parameters = keys
        .iter()
        .filter(|k| pa.get(**k) != pb.get(**k))
        .map(|k| ParameterChange {
            key: k.to_string(),
            a: pa.get(*k).cloned(),
            b: pb.get(*k).cloned(),
        })
        .collect();
    let mut names = a.figure_names();
    names.extend(b.figure_names());
    names.sort_unstable();
    names.dedup();
    let metrics = names
        .into_iter()
        .map(|name| {
            let (fa, fb) = (a.figure(name), b.figure(name));
            let both = fa.zip(fb);
            let change = both.map(|(x, y)| y.mean - x.mean);
            MetricChange {
                name: name.to_string(),
                a: fa,
                b: fb,
                change,
                relative: both
                    .filter(|(x, _)| x.mean != 0.0)
                    .map(|(x, y)| (y.mean - x.mean) / x.mean.abs()),
                outside_both_intervals: both
                    .and_then(|(x, y)| Some(!x.contains(y.mean)? && !y.contains(x.mean)?)),
            }
        })
        .collect();
    Diff {
        parameters,
        parameters_compared: keys.len(),
        metrics,
    }
}

/// The variants of two runs to compare: the ones named, or — when neither
/// names one — the variants both runs have, by name (an error when they
/// share none).
pub fn pairs<'a>(
    out: &Path,
    (a, va): (&'a RunRecord, Option<&'a str>),
    (b, vb): (&'a RunRecord, Option<&'a str>),
) -> Result<Vec<(VariantRun<'a>, VariantRun<'a>)>> {
    let only = |run: &'a RunRecord| -> Result<&'a str> {
        let all = VariantRun::all(out, run);
        match all.as_slice() {
            [one] => Ok(one.name),
            _ => Err(Error::Invalid(format!(
                "run {} ({}) has {} variants: name one, as `{}:{}`",
                run.id,
                run.experiment,
                all.len(),
                run.id,
                all.first().map_or("", |v| v.name)
            ))),
        }
    };
    match (va, vb) {
        (None, None) => {
            let pairs: Vec<_> = VariantRun::all(out, a)
                .into_iter()
                .filter_map(|x| {
                    let name = b.variants.iter().find(|v| v.name == x.name)?;
                    Some((
                        VariantRun::of(out, a, x.name),
                        VariantRun::of(out, b, &name.name),
                    ))
                })
                .collect();
            if pairs.is_empty() {
                // No shared names: two one-variant runs still compare.
                return Ok(vec![(
                    VariantRun::of(out, a, only(a)?),
                    VariantRun::of(out, b, only(b)?),
                )]);
            }
            Ok(pairs)
        }
        (va, vb) => {
            let na = match va {
                Some(name) => name,
                None => only(a)?,
            };
            let nb = match vb {
                Some(name) => name,
                None => only(b)?,
            };
            Ok(vec![(
                VariantRun::of(out, a, na),
                VariantRun::of(out, b, nb),
            )])
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn filters_compare_numbers_as_numbers() {
        let f: Filter = "train.vote=3".parse().unwrap();
        assert_eq!((f.key.as_str(), f.value.as_str()), ("train.vote", "3"));
        assert!(f.accepts("3") && f.accepts("3.0") && !f.accepts("5"));
        let dt: Filter = "simulate.scene.0.dt=1e-3".parse().unwrap();
        assert!(dt.accepts("0.001"));
        let code: Filter = "quantize.code = gray".parse().unwrap();
        assert!(code.accepts("gray") && !code.accepts("walk"));
        assert!("train.vote".parse::<Filter>().is_err());
        assert!("=3".parse::<Filter>().is_err());
    }

    #[test]
    fn figures_carry_intervals_only_across_replicates() {
        let one = Figure::of(&[0.5]).unwrap();
        assert_eq!((one.mean, one.low, one.n), (0.5, None, 1));
        assert_eq!(one.contains(0.4), None);
        // 1, 2, 3: mean 2 ± t(0.975, 2)·1/√3 = 2 ± 2.484.
        let three = Figure::of(&[1.0, 2.0, 3.0]).unwrap();
        assert!((three.low.unwrap() - (2.0 - 2.4841)).abs() < 1e-3);
        assert_eq!(three.contains(4.0), Some(true));
        assert_eq!(three.contains(4.5), Some(false));
    }
}
