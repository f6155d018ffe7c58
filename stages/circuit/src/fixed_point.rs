//! `fixed.parquet`, the circuit stage's table of a piecewise-linear model
//! in fixed point: its writer and its reader. One row per output: its word
//! widths (input and weight bits, and their fractional bits, chosen on the
//! training rows or given), the bits of a piece's value, its pieces and
//! inputs, the mean difference in levels from the floating-point model on
//! the training and the test rows, and on the test rows both models' and
//! persistence's error in levels against the next level, and those rows
//! (every one simulated equal by its circuits as written); no rows for a bit-forest or
//! when the stage measured nothing.

use std::path::Path;
use std::sync::Arc;

use alnlab_aln::pwl::fixed::Widths;
use alnlab_common::table::{self, Table};
use alnlab_common::{Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};

use crate::piecewise::OutputFigures;

/// Writes one row per output of `outputs` to `path`.
pub fn write(path: &Path, outputs: &[OutputFigures], provenance: &Provenance) -> Result<()> {
    let narrow = |f: fn(&OutputFigures) -> u32| -> Arc<dyn Array> {
        Arc::new(UInt32Array::from_iter_values(outputs.iter().map(f)))
    };
    let real = |f: fn(&OutputFigures) -> f64| -> Arc<dyn Array> {
        Arc::new(Float64Array::from_iter_values(outputs.iter().map(f)))
    };
    let batch = table::batch(vec![
        (
            "variable",
            Arc::new(StringArray::from_iter_values(
                outputs.iter().map(|o| &o.variable),
            )),
        ),
        ("input_bits", narrow(|o| o.widths.input_bits)),
        ("input_frac", narrow(|o| o.input_frac)),
        ("weight_bits", narrow(|o| o.widths.weight_bits)),
        ("weight_frac", narrow(|o| o.weight_frac)),
        ("piece_bits", narrow(|o| o.piece_bits)),
        ("pieces", narrow(|o| o.pieces)),
        ("inputs", narrow(|o| o.inputs)),
        ("train_difference", real(|o| o.train_difference)),
        ("test_difference", real(|o| o.test_difference)),
        ("fixed_error", real(|o| o.fixed_error)),
        ("float_error", real(|o| o.float_error)),
        ("persistence_error", real(|o| o.persistence_error)),
        (
            "rows",
            Arc::new(UInt64Array::from_iter_values(
                outputs.iter().map(|o| o.rows),
            )),
        ),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads `fixed.parquet`: its outputs, none for a bit-forest.
pub fn read(path: &Path) -> Result<Vec<OutputFigures>> {
    let table = Table::read(path)?;
    let narrow = |name| {
        table
            .column::<UInt32Array>(name)
            .map(|c| c.values().to_vec())
    };
    let real = |name| {
        table
            .column::<Float64Array>(name)
            .map(|c| c.values().to_vec())
    };
    let (input_bits, input_frac) = (narrow("input_bits")?, narrow("input_frac")?);
    let (weight_bits, weight_frac) = (narrow("weight_bits")?, narrow("weight_frac")?);
    let (piece_bits, pieces, inputs) =
        (narrow("piece_bits")?, narrow("pieces")?, narrow("inputs")?);
    let (train_difference, test_difference) = (real("train_difference")?, real("test_difference")?);
    let (fixed_error, float_error) = (real("fixed_error")?, real("float_error")?);
    let persistence_error = real("persistence_error")?;
    let rows = table.column::<UInt64Array>("rows")?.values().to_vec();
    Ok(table
        .strings("variable")?
        .into_iter()
        .enumerate()
        .map(|(r, variable)| OutputFigures {
            variable,
            widths: Widths {
                input_bits: input_bits[r],
                weight_bits: weight_bits[r],
            },
            input_frac: input_frac[r],
            weight_frac: weight_frac[r],
            piece_bits: piece_bits[r],
            pieces: pieces[r],
            inputs: inputs[r],
            train_difference: train_difference[r],
            test_difference: test_difference[r],
            fixed_error: fixed_error[r],
            float_error: float_error[r],
            persistence_error: persistence_error[r],
            rows: rows[r],
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_read_back_as_written() {
        let output = OutputFigures {
            variable: "v.1.x".into(),
            widths: Widths {
                input_bits: 13,
                weight_bits: 9,
            },
            input_frac: 4,
            weight_frac: 7,
            piece_bits: 21,
            pieces: 16,
            inputs: 5,
            train_difference: 0.004,
            test_difference: 0.006,
            fixed_error: 0.975,
            float_error: 0.972,
            persistence_error: 1.24,
            rows: 9000,
        };
        let provenance = Provenance {
            stage: "circuit".into(),
            params: serde_json::Value::Null,
            inputs: Default::default(),
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fixed.parquet");
        write(&path, std::slice::from_ref(&output), &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), vec![output]);
        write(&path, &[], &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), vec![]);
    }
}
