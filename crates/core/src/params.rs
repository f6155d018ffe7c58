//! Checked parameter types for manifests. Each rejects an out-of-range value
//! while it is being deserialized, so the manifest error points at the value's
//! line and column and says what is allowed.

use std::fmt;

use serde::de::{self, Deserializer, Visitor};
use serde::{Deserialize, Serialize};

/// What a stage's `validate` reports: the key within the stage's table and
/// what is wrong with it.
pub type ParamError = (String, String);

/// A failed parameter check as a user error, `stage.key: message`.
pub fn invalid(stage: &str, (key, message): ParamError) -> crate::Error {
    crate::Error::Invalid(format!("{stage}.{key}: {message}"))
}

/// A whole number ≥ 1 (a count of runs, steps, epochs …).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize)]
#[serde(transparent)]
pub struct Count(pub u64);

impl Count {
    /// The count as `usize`.
    pub fn get(self) -> usize {
        self.0 as usize
    }
}

impl<'de> Deserialize<'de> for Count {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = Count;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a whole number ≥ 1")
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Count, E> {
                if v >= 1 {
                    Ok(Count(v as u64))
                } else {
                    Err(E::custom(format!("expected a whole number ≥ 1, found {v}")))
                }
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Count, E> {
                self.visit_i64(i64::try_from(v).unwrap_or(i64::MAX))
            }
        }
        d.deserialize_i64(V)
    }
}

/// A finite real number > 0 (a duration, a step size, a mass …). Integers
/// are accepted and widened.
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd, Serialize)]
#[serde(transparent)]
pub struct Positive(pub f64);

impl Positive {
    /// The value.
    pub fn get(self) -> f64 {
        self.0
    }
}

impl<'de> Deserialize<'de> for Positive {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl Visitor<'_> for V {
            type Value = Positive;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number > 0")
            }
            fn visit_f64<E: de::Error>(self, v: f64) -> Result<Positive, E> {
                if v.is_finite() && v > 0.0 {
                    Ok(Positive(v))
                } else {
                    Err(E::custom(format!("expected a number > 0, found {v}")))
                }
            }
            fn visit_i64<E: de::Error>(self, v: i64) -> Result<Positive, E> {
                self.visit_f64(v as f64)
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<Positive, E> {
                self.visit_f64(v as f64)
            }
        }
        d.deserialize_f64(V)
    }
}

/// A number strictly between 0 and 1 (a share of rows, …).
#[derive(Clone, Copy, Debug, PartialEq, PartialOrd, Serialize)]
#[serde(transparent)]
pub struct Fraction(pub f64);

impl Fraction {
    /// The value.
    pub fn get(self) -> f64 {
        self.0
    }
}

impl<'de> Deserialize<'de> for Fraction {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let Positive(v) = Positive::deserialize(d)
            .map_err(|_| de::Error::custom("expected a number between 0 and 1 (exclusive)"))?;
        if v < 1.0 {
            Ok(Fraction(v))
        } else {
            Err(de::Error::custom(format!(
                "expected a number between 0 and 1 (exclusive), found {v}"
            )))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Deserialize, Debug)]
    struct T {
        c: Option<Count>,
        p: Option<Positive>,
        f: Option<Fraction>,
    }

    fn parse(s: &str) -> Result<T, String> {
        toml::from_str::<T>(s).map_err(|e| e.to_string())
    }

    #[test]
    fn accepts_in_range() {
        let t = parse("c = 3\np = 2\nf = 0.25").unwrap();
        assert_eq!(t.c, Some(Count(3)));
        assert_eq!(t.p, Some(Positive(2.0)));
        assert_eq!(t.f, Some(Fraction(0.25)));
    }

    #[test]
    fn rejects_out_of_range_with_what_is_allowed() {
        assert!(
            parse("c = 0")
                .unwrap_err()
                .contains("whole number ≥ 1, found 0")
        );
        assert!(parse("c = -4").unwrap_err().contains("found -4"));
        assert!(parse("c = 1.5").unwrap_err().contains("whole number ≥ 1"));
        assert!(parse("p = -1e-3").unwrap_err().contains("number > 0"));
        assert!(parse("p = \"x\"").unwrap_err().contains("number > 0"));
        assert!(parse("f = 1.0").unwrap_err().contains("between 0 and 1"));
    }
}
