//! `circuit.parquet`, the circuit stage's table: its writer and its reader.
//! Three rows per learned variable (its trees, votes and decoder: gates,
//! inverters, depth in gate levels), each with the test rows on which the
//! simulated circuit equalled the software and the tools and gate library
//! that measured it; no rows when the stage measured nothing (`[circuit]
//! synthesize` off, or a threshold model).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, StringArray, UInt32Array, UInt64Array};

use crate::synth::{Figures, Part, VariableFigures};

/// What the stage measured: the synthesized circuit and the test rows
/// simulated equal to the software.
#[derive(Clone, Debug, PartialEq)]
pub struct Measured {
    pub figures: Figures,
    pub rows_equal: u64,
}

/// The parts of a variable, in row order.
const PARTS: [&str; 3] = ["trees", "votes", "decode"];

/// Writes `measured` (none: an empty table) to `path`.
pub fn write(path: &Path, measured: Option<&Measured>, provenance: &Provenance) -> Result<()> {
    let mut rows: Vec<(&str, &str, Part)> = Vec::new();
    if let Some(m) = measured {
        for v in &m.figures.variables {
            for (part, figures) in PARTS.into_iter().zip([v.trees, v.votes, v.decode]) {
                rows.push((&v.variable, part, figures));
            }
        }
    }
    let (tools, library, equal) = measured.map_or(("", "", 0), |m| {
        (
            m.figures.tools.as_str(),
            m.figures.library.as_str(),
            m.rows_equal,
        )
    });
    let text = |f: &dyn Fn(&(&str, &str, Part)) -> String| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(rows.iter().map(f)))
    };
    let wide = |f: fn(&Part) -> u64| -> Arc<dyn Array> {
        Arc::new(UInt64Array::from_iter_values(rows.iter().map(|r| f(&r.2))))
    };
    let batch = table::batch(vec![
        ("variable", text(&|r| r.0.to_string())),
        ("part", text(&|r| r.1.to_string())),
        ("cells", wide(|p| p.cells)),
        ("inverters", wide(|p| p.inverters)),
        (
            "depth",
            Arc::new(UInt32Array::from_iter_values(
                rows.iter().map(|r| r.2.depth),
            )),
        ),
        (
            "rows_equal",
            Arc::new(UInt64Array::from_iter_values(rows.iter().map(|_| equal))),
        ),
        ("tools", text(&|_| tools.to_string())),
        ("library", text(&|_| library.to_string())),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads `circuit.parquet`; none when the stage measured nothing.
pub fn read(path: &Path) -> Result<Option<Measured>> {
    let table = Table::read(path)?;
    if table.num_rows() == 0 {
        return Ok(None);
    }
    let (variables, parts) = (table.strings("variable")?, table.strings("part")?);
    let cells = table.column::<UInt64Array>("cells")?.values();
    let inverters = table.column::<UInt64Array>("inverters")?.values();
    let depths = table.column::<UInt32Array>("depth")?.values();
    let mut figures = Figures {
        tools: table.strings("tools")?.swap_remove(0),
        library: table.strings("library")?.swap_remove(0),
        variables: Vec::new(),
    };
    for (r, variable) in variables.into_iter().enumerate() {
        let k = r % PARTS.len();
        if parts[r] != PARTS[k] {
            return Err(Error::bad_file(
                path,
                format!("row {r}: part `{}`, expected {}", parts[r], PARTS[k]),
            ));
        }
        if k == 0 {
            figures.variables.push(VariableFigures {
                variable: variable.clone(),
                trees: Part::default(),
                votes: Part::default(),
                decode: Part::default(),
            });
        }
        let v = figures.variables.last_mut().expect("pushed at its trees");
        if v.variable != variable {
            return Err(Error::bad_file(
                path,
                format!(
                    "row {r}: variable `{variable}` among `{}`'s parts",
                    v.variable
                ),
            ));
        }
        let part = Part {
            cells: cells[r],
            inverters: inverters[r],
            depth: depths[r],
        };
        *[&mut v.trees, &mut v.votes, &mut v.decode][k] = part;
    }
    if table.num_rows() % PARTS.len() != 0 {
        return Err(Error::bad_file(
            path,
            format!(
                "{} rows: three per variable (trees, votes, decode) expected",
                table.num_rows()
            ),
        ));
    }
    let rows_equal = table.column::<UInt64Array>("rows_equal")?.value(0);
    Ok(Some(Measured {
        figures,
        rows_equal,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn provenance() -> Provenance {
        Provenance {
            stage: "circuit".into(),
            params: serde_json::Value::Null,
            inputs: Default::default(),
        }
    }

    #[test]
    fn a_measured_circuit_reads_back_as_written_and_none_as_none() {
        let part = |cells, depth| Part {
            cells,
            inverters: cells / 4,
            depth,
        };
        let variable = |name: &str| VariableFigures {
            variable: name.into(),
            trees: part(100, 9),
            votes: part(8, 3),
            decode: part(12, 4),
        };
        let measured = Measured {
            figures: Figures {
                tools: "Yosys 0.x".into(),
                library: "two-input gates".into(),
                variables: vec![variable("v.1.x"), variable("a.2.y")],
            },
            rows_equal: 9000,
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("circuit.parquet");
        write(&path, Some(&measured), &provenance()).unwrap();
        assert_eq!(read(&path).unwrap(), Some(measured));
        write(&path, None, &provenance()).unwrap();
        assert_eq!(read(&path).unwrap(), None);
    }
}
