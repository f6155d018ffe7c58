//! `fpga.parquet`, the circuit stage's place-and-route table: its writer
//! and its reader. One row per learned variable: lookup tables, their
//! levels, logic cells used (or needed) and available, the critical path
//! in ns (none when the variable does not fit), the test rows on which the
//! mapped netlist equalled the software, the device, nextpnr's seed and
//! the tools; no rows when the stage placed nothing (`[circuit] fpga`
//! unset).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};

use crate::fpga::{Device, Placed, State};

/// What the stage placed and routed, and the test rows its mapped netlist
/// was simulated equal to the software on.
#[derive(Clone, Debug, PartialEq)]
pub struct Routed {
    /// Every variable on the part.
    pub state: State,
    /// The test rows simulated, every mapped netlist equal on each.
    pub rows_equal: u64,
}

/// Writes `routed` (none: an empty table) to `path`.
pub fn write(path: &Path, routed: Option<&Routed>, provenance: &Provenance) -> Result<()> {
    let placed: &[Placed] = routed.map_or(&[], |r| &r.state.variables);
    let each = |value: String| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(placed.iter().map(|_| &value)))
    };
    let wide = |f: fn(&Placed) -> u64| -> Arc<dyn Array> {
        Arc::new(UInt64Array::from_iter_values(placed.iter().map(f)))
    };
    let (device, seed, tools, equal) = routed.map_or_else(Default::default, |r| {
        (
            r.state.device.name().to_string(),
            r.state.seed,
            r.state.tools.clone(),
            r.rows_equal,
        )
    });
    let batch = table::batch(vec![
        (
            "variable",
            Arc::new(StringArray::from_iter_values(
                placed.iter().map(|p| &p.variable),
            )),
        ),
        ("luts", wide(|p| p.luts)),
        (
            "lut_levels",
            Arc::new(UInt32Array::from_iter_values(
                placed.iter().map(|p| p.lut_levels),
            )),
        ),
        ("logic_cells", wide(|p| p.logic_cells)),
        ("available", wide(|p| p.available)),
        (
            "critical_ns",
            Arc::new(Float64Array::from_iter(
                placed.iter().map(|p| p.critical_ns),
            )),
        ),
        (
            "rows_equal",
            Arc::new(UInt64Array::from_iter_values(placed.iter().map(|_| equal))),
        ),
        ("device", each(device)),
        (
            "seed",
            Arc::new(UInt64Array::from_iter_values(placed.iter().map(|_| seed))),
        ),
        ("tools", each(tools)),
    ]);
    table::write_parquet(path, &batch, provenance)
}

/// Reads `fpga.parquet`; none when the stage placed nothing.
pub fn read(path: &Path) -> Result<Option<Routed>> {
    let table = Table::read(path)?;
    if table.num_rows() == 0 {
        return Ok(None);
    }
    let device = table.strings("device")?.swap_remove(0);
    let device = Device::named(&device).ok_or_else(|| {
        Error::bad_file(
            path,
            format!("device `{device}`, expected one of ice40-hx8k"),
        )
    })?;
    let luts = table.column::<UInt64Array>("luts")?.values();
    let levels = table.column::<UInt32Array>("lut_levels")?.values();
    let cells = table.column::<UInt64Array>("logic_cells")?.values();
    let available = table.column::<UInt64Array>("available")?.values();
    let critical = table.column::<Float64Array>("critical_ns")?;
    let variables = table
        .strings("variable")?
        .into_iter()
        .enumerate()
        .map(|(r, variable)| Placed {
            variable,
            luts: luts[r],
            lut_levels: levels[r],
            logic_cells: cells[r],
            available: available[r],
            critical_ns: critical.is_valid(r).then(|| critical.value(r)),
        })
        .collect();
    Ok(Some(Routed {
        state: State {
            device,
            seed: table.column::<UInt64Array>("seed")?.value(0),
            tools: table.strings("tools")?.swap_remove(0),
            variables,
        },
        rows_equal: table.column::<UInt64Array>("rows_equal")?.value(0),
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_routed_state_reads_back_as_written_and_none_as_none() {
        let placed = |name: &str, ns: Option<f64>| Placed {
            variable: name.into(),
            luts: 900,
            lut_levels: 7,
            logic_cells: 950,
            available: 7680,
            critical_ns: ns,
        };
        let routed = Routed {
            state: State {
                device: Device::Ice40Hx8k,
                seed: 1991,
                tools: "Yosys 0.x; nextpnr-ice40 0.4".into(),
                variables: vec![placed("v.1.x", Some(11.05)), placed("g.0.z", None)],
            },
            rows_equal: 9000,
        };
        let provenance = Provenance {
            stage: "circuit".into(),
            params: serde_json::Value::Null,
            inputs: Default::default(),
        };
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("fpga.parquet");
        write(&path, Some(&routed), &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), Some(routed));
        write(&path, None, &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), None);
    }
}
