//! `fpga.parquet`, the circuit stage's place-and-route table: its writer
//! and its reader. One row per learned variable and form (a bit-forest's
//! combinational circuit; a piecewise-linear model's combinational and
//! pipelined ones): lookup tables, their levels, carry-chain cells,
//! flip-flops, logic cells used (or needed) and available, the critical
//! path in ns (none when the variable does not fit), the clocks from
//! inputs to level (0 when combinational), the test rows on which the
//! mapped netlist equalled the software, the device, the nextpnr seed of
//! the placement routed and the tools; no rows when the stage placed nothing (`[circuit] fpga`
//! unset).

use std::path::Path;
use std::sync::Arc;

use alnlab_common::table::{self, Table};
use alnlab_common::{Error, Provenance, Result};
use arrow_array::{Array, Float64Array, StringArray, UInt32Array, UInt64Array};

use crate::datapath::Form;
use crate::fpga::{Device, Placed, State};

/// What the stage placed and routed, and the test rows its mapped netlist
/// was simulated equal to the software on.
#[derive(Clone, Debug, PartialEq)]
pub struct Routed {
    /// Every variable on the part, combinational between registers.
    pub state: State,
    /// A piecewise-linear model's pipelined circuits (one state a clock).
    pub pipelined: Option<State>,
    /// The test rows simulated, every mapped netlist equal on each.
    pub rows_equal: u64,
}

/// Writes `routed` (none: an empty table) to `path`.
pub fn write(path: &Path, routed: Option<&Routed>, provenance: &Provenance) -> Result<()> {
    let states: Vec<&State> = routed.map_or_else(Vec::new, |r| {
        std::iter::once(&r.state).chain(&r.pipelined).collect()
    });
    let placed: Vec<(&State, &Placed)> = states
        .iter()
        .flat_map(|s| s.variables.iter().map(move |p| (*s, p)))
        .collect();
    let each = |value: String| -> Arc<dyn Array> {
        Arc::new(StringArray::from_iter_values(placed.iter().map(|_| &value)))
    };
    let wide = |f: fn(&Placed) -> u64| -> Arc<dyn Array> {
        Arc::new(UInt64Array::from_iter_values(
            placed.iter().map(|(_, p)| f(p)),
        ))
    };
    let narrow = |f: fn(&Placed) -> u32| -> Arc<dyn Array> {
        Arc::new(UInt32Array::from_iter_values(
            placed.iter().map(|(_, p)| f(p)),
        ))
    };
    let (tools, equal) =
        routed.map_or_else(Default::default, |r| (r.state.tools.clone(), r.rows_equal));
    let batch = table::batch(vec![
        (
            "variable",
            Arc::new(StringArray::from_iter_values(
                placed.iter().map(|(_, p)| &p.variable),
            )),
        ),
        (
            "form",
            Arc::new(StringArray::from_iter_values(
                placed.iter().map(|(s, _)| s.form.name()),
            )),
        ),
        ("luts", wide(|p| p.luts)),
        ("lut_levels", narrow(|p| p.lut_levels)),
        ("carries", wide(|p| p.carries)),
        ("flip_flops", wide(|p| p.flip_flops)),
        ("logic_cells", wide(|p| p.logic_cells)),
        ("available", wide(|p| p.available)),
        (
            "critical_ns",
            Arc::new(Float64Array::from_iter(
                placed.iter().map(|(_, p)| p.critical_ns),
            )),
        ),
        ("latency", narrow(|p| p.latency)),
        (
            "rows_equal",
            Arc::new(UInt64Array::from_iter_values(placed.iter().map(|_| equal))),
        ),
        (
            "device",
            Arc::new(StringArray::from_iter_values(
                placed.iter().map(|(s, _)| s.device.name()),
            )),
        ),
        (
            "seed",
            Arc::new(UInt64Array::from_iter_values(
                placed.iter().map(|(s, _)| s.seed),
            )),
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
    let devices = table.strings("device")?;
    let forms = table.strings("form")?;
    let luts = table.column::<UInt64Array>("luts")?.values();
    let levels = table.column::<UInt32Array>("lut_levels")?.values();
    let carries = table.column::<UInt64Array>("carries")?.values();
    let flip_flops = table.column::<UInt64Array>("flip_flops")?.values();
    let cells = table.column::<UInt64Array>("logic_cells")?.values();
    let available = table.column::<UInt64Array>("available")?.values();
    let critical = table.column::<Float64Array>("critical_ns")?;
    let latency = table.column::<UInt32Array>("latency")?.values();
    let seeds = table.column::<UInt64Array>("seed")?.values();
    let tools = table.strings("tools")?.swap_remove(0);
    let mut states: Vec<State> = Vec::new();
    for (r, variable) in table.strings("variable")?.into_iter().enumerate() {
        let device = Device::named(&devices[r]).ok_or_else(|| {
            Error::bad_file(
                path,
                format!(
                    "row {r}: device `{}`, expected one of ice40-hx8k",
                    devices[r]
                ),
            )
        })?;
        let form = Form::named(&forms[r]).ok_or_else(|| {
            Error::bad_file(
                path,
                format!(
                    "row {r}: form `{}`, expected combinational or pipelined",
                    forms[r]
                ),
            )
        })?;
        if states.last().is_none_or(|s| s.form != form) {
            states.push(State {
                device,
                form,
                // The first variable's seed is the first tried.
                seed: seeds[r],
                tools: tools.clone(),
                variables: Vec::new(),
            });
        }
        states.last_mut().expect("pushed").variables.push(Placed {
            variable,
            luts: luts[r],
            lut_levels: levels[r],
            carries: carries[r],
            flip_flops: flip_flops[r],
            logic_cells: cells[r],
            available: available[r],
            critical_ns: critical.is_valid(r).then(|| critical.value(r)),
            latency: latency[r],
            seed: seeds[r],
        });
    }
    let mut states = states.into_iter();
    let state = states.next().filter(|s| s.form == Form::Combinational);
    let (Some(state), pipelined, None) = (state, states.next(), states.next()) else {
        return Err(Error::bad_file(
            path,
            "expected the combinational rows, then any pipelined ones",
        ));
    };
    Ok(Some(Routed {
        state,
        pipelined,
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
            carries: 40,
            flip_flops: 60,
            latency: 0,
            seed: 1991,
        };
        let state = State {
            device: Device::Ice40Hx8k,
            form: Form::Combinational,
            seed: 1991,
            tools: "Yosys 0.x; nextpnr-ice40 0.4".into(),
            variables: vec![placed("v.1.x", Some(11.05)), placed("g.0.z", None)],
        };
        let mut routed = Routed {
            state: state.clone(),
            pipelined: None,
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
        assert_eq!(read(&path).unwrap(), Some(routed.clone()));
        let mut pipelined = State {
            form: Form::Pipelined,
            ..state
        };
        pipelined.variables[0].latency = 9;
        routed.pipelined = Some(pipelined);
        write(&path, Some(&routed), &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), Some(routed));
        write(&path, None, &provenance).unwrap();
        assert_eq!(read(&path).unwrap(), None);
    }
}
