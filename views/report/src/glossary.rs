//! The glossary of variable names: what `v.1.y` means.

use std::fmt::Write as _;

use alnlab_codes::unit_of;

use super::Loaded;
use super::format::{Align, MdTable};

/// The paper's quantities (§4.1) and a robot's joint quantities, by a
/// variable name's first part.
const QUANTITIES: [(&str, &str); 13] = [
    ("v", "velocity of the link's hinge"),
    ("a", "acceleration of the link's hinge"),
    ("omega", "angular velocity of the link (ω)"),
    (
        "omega_dot",
        "rate of change of ω's components in the link's frame (ω̇)",
    ),
    ("g", "control torque the link exerts on its parent"),
    ("f_E", "external (contact) force at the link's hinge"),
    ("g_E", "external (contact) torque about the link's hinge"),
    ("roll", "roll angle of the link's hinge (group R)"),
    ("pitch", "pitch angle of the link's hinge (group R)"),
    (
        "q",
        "a robot joint's position (angle, or travel of a prismatic joint)",
    ),
    ("qd", "a robot joint's velocity"),
    ("qdd", "a robot joint's acceleration"),
    (
        "tau",
        "control effort on a robot joint, parent on child (clamped to its limit)",
    ),
];

/// Writes the glossary of the variables the report names.
pub(super) fn section(md: &mut String, variants: &[Loaded]) {
    let mut names: Vec<&str> = variants
        .iter()
        .flat_map(|v| v.summary.iter().map(|r| r.variable.as_str()))
        .chain(
            variants
                .iter()
                .flat_map(|v| v.not_learned.iter().map(|(n, _)| n.as_str())),
        )
        .collect();
    names.sort_unstable();
    names.dedup();
    if names.is_empty() {
        return;
    }
    let _ = writeln!(
        md,
        "## Glossary of variables\n\nA variable is named `<quantity>.<link>[.<axis>]`: links are \
         numbered from 1 at the root of the body's tree (a robot's links and joints go by their \
         URDF names); x, y and z are components in the link's own frame (fixed to the link, \
         origin at its hinge). Errors are in quantization levels of each variable's own range; \
         a level's size in SI units is in each variant's table by group.\n"
    );
    let mut table = MdTable::new(&["quantity"])
        .column("what it is", Align::Left)
        .column("unit", Align::Left)
        .column("links", Align::Left)
        .column("axes", Align::Left);
    for (quantity, meaning) in QUANTITIES {
        let of: Vec<Vec<&str>> = names
            .iter()
            .map(|n| n.split('.').collect::<Vec<_>>())
            .filter(|parts| parts[0] == quantity)
            .collect();
        if of.is_empty() {
            continue;
        }
        // Numbered links in order, then named ones (a robot's) by name.
        let mut links: Vec<(u32, &str)> = of
            .iter()
            .filter_map(|p| p.get(1).map(|l| (l.parse().unwrap_or(u32::MAX), *l)))
            .collect();
        links.sort_unstable();
        links.dedup();
        let mut axes: Vec<&str> = of.iter().filter_map(|p| p.get(2).copied()).collect();
        axes.sort_unstable();
        axes.dedup();
        let links: Vec<String> = links.iter().map(|(_, l)| l.to_string()).collect();
        table.row(vec![
            format!("`{quantity}`"),
            meaning.into(),
            unit_of(quantity).into(),
            links.join(", "),
            if axes.is_empty() {
                "—".into()
            } else {
                axes.join(", ")
            },
        ]);
    }
    table.write(md);
}
