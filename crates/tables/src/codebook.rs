//! `codebook.parquet` (quantize → train, test, plan, circuit, the report):
//! one row per variable — its range, level count, code and the code's
//! parameters — with the [`Codebook`] it holds.

use std::path::Path;
use std::sync::Arc;

use alnlab_codes::codebook::{Entry, Quantizer, group_of};
use alnlab_codes::{Code, Codebook};
use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, BooleanArray, Float64Array, StringArray, UInt64Array};

/// The codebook's file name.
pub const FILE: &str = "codebook.parquet";

/// Reads `codebook.parquet`.
pub fn read(path: &Path) -> Result<Codebook> {
    let t = Table::read(path)?;
    let s = |c| t.column::<StringArray>(c);
    let f = |c| t.f64_column(c);
    let u = |c| t.column::<UInt64Array>(c);
    let (variable, note, code) = (s("variable")?, s("note")?, s("code")?);
    let (min, max) = (f("min")?, f("max")?);
    let (levels, width, step, span, seed, clamped) = (
        u("levels")?,
        u("width")?,
        u("walk_step")?,
        u("walk_span")?,
        u("seed")?,
        u("clamped")?,
    );
    let learned = t.column::<BooleanArray>("learned")?;
    t.require_no_nulls()?;
    let small = |column: &UInt64Array, name: &str, r: usize| {
        u32::try_from(column.value(r)).map_err(|_| {
            Error::bad_file(
                path,
                format!("row {r}: `{name}` is {}, beyond 32 bits", column.value(r)),
            )
        })
    };
    let entries = (0..t.num_rows())
        .map(|r| {
            let (lo, hi, count) = (min.value(r), max.value(r), levels.value(r));
            if learned.value(r) && !(lo.is_finite() && hi.is_finite() && lo < hi) {
                return Err(Error::bad_file(
                    path,
                    format!("row {r}: the range {lo}…{hi} is not a finite interval with min < max"),
                ));
            }
            if learned.value(r) && !(2..=1 << 16).contains(&count) {
                return Err(Error::bad_file(
                    path,
                    format!("row {r}: {count} levels, expected 2 to 65536"),
                ));
            }
            let code: Code = code.value(r).parse().map_err(|_| {
                Error::bad_file(
                    path,
                    format!(
                        "row {r}: unknown code `{}`; expected one of {}",
                        code.value(r),
                        Code::ALL.map(|c| c.to_string()).join(", ")
                    ),
                )
            })?;
            Ok(Entry {
                variable: variable.value(r).to_string(),
                learned: learned.value(r),
                note: note.value(r).to_string(),
                quantizer: Quantizer {
                    min: lo,
                    max: hi,
                    levels: count as usize,
                },
                code,
                width: small(width, "width", r)?,
                walk_step: small(step, "walk_step", r)?,
                walk_span: small(span, "walk_span", r)?,
                seed: seed.value(r),
                clamped: clamped.value(r),
            })
        })
        .collect::<Result<_>>()?;
    Ok(Codebook { entries })
}

/// Writes `codebook.parquet` (with `provenance` as its metadata).
pub fn write(codebook: &Codebook, path: &Path, provenance: &Provenance) -> Result<()> {
    let e = &codebook.entries;
    let strings = |f: fn(&Entry) -> &str| -> Arc<dyn Array> {
        Arc::new(e.iter().map(|x| Some(f(x))).collect::<StringArray>())
    };
    let code_names: Arc<dyn Array> = Arc::new(
        e.iter()
            .map(|x| Some(x.code.to_string()))
            .collect::<StringArray>(),
    );
    let floats = |f: fn(&Entry) -> f64| -> Arc<dyn Array> {
        Arc::new(
            e.iter()
                .map(f)
                .collect::<Vec<_>>()
                .into_iter()
                .collect::<Float64Array>(),
        )
    };
    let counts = |f: fn(&Entry) -> u64| -> Arc<dyn Array> {
        Arc::new(
            e.iter()
                .map(f)
                .collect::<Vec<_>>()
                .into_iter()
                .collect::<UInt64Array>(),
        )
    };
    let batch = table::batch(vec![
        ("variable", strings(|x| &x.variable)),
        ("group", strings(|x| group_of(&x.variable))),
        (
            "learned",
            Arc::new(e.iter().map(|x| Some(x.learned)).collect::<BooleanArray>()),
        ),
        ("note", strings(|x| &x.note)),
        ("min", floats(|x| x.quantizer.min)),
        ("max", floats(|x| x.quantizer.max)),
        ("levels", counts(|x| x.quantizer.levels as u64)),
        ("code", code_names),
        ("width", counts(|x| u64::from(x.width))),
        ("walk_step", counts(|x| u64::from(x.walk_step))),
        ("walk_span", counts(|x| u64::from(x.walk_span))),
        ("seed", counts(|x| x.seed)),
        ("clamped", counts(|x| x.clamped)),
    ]);
    table::write_parquet(path, &batch, provenance)
}
