//! How the report writes numbers and tables: three significant figures
//! throughout, times in µs, intervals with one number of decimals for all
//! three figures, and tables of at most [`MAX_COLUMNS`] columns.

use std::fmt::Write as _;

/// The most columns a table may have: wider ones are split, their key
/// columns repeated in each part.
pub const MAX_COLUMNS: usize = 9;

/// Decimals that give `x` three significant figures (none for ≥ 100).
fn decimals_for(x: f64) -> usize {
    if x == 0.0 || !x.is_finite() {
        return 2;
    }
    (2 - x.abs().log10().floor() as i32).max(0) as usize
}

/// Three significant figures: 1.87, 0.0835, 81.9, 5470 (from 100 up
/// written whole); a whole number (a count, a median of whole errors) as
/// itself: 2, 17.
pub fn sig3(x: f64) -> String {
    if x.is_nan() {
        return "—".into();
    }
    // Beyond seven digits a number is read by its exponent (a prediction
    // that blew up, an enormous count).
    if x.abs() >= 1e7 || x.abs() < 1e-3 && x != 0.0 {
        return format!("{x:.2e}");
    }
    if x.fract() == 0.0 {
        return format!("{x:.0}");
    }
    // Round first: 9.996 has three figures as 10.0.
    let rounded: f64 = format!("{x:.2e}").parse().unwrap_or(x);
    format!("{rounded:.*}", decimals_for(rounded))
}

/// [`sig3`] with its sign: "+21.6", "-0.104".
pub fn signed(x: f64) -> String {
    if x > 0.0 {
        format!("+{}", sig3(x))
    } else {
        sig3(x)
    }
}

/// A mean and its interval, each to the decimals that give the largest of
/// them three significant figures, signed: "+0.517 [+0.495, +0.540]".
pub fn interval(mean: f64, low: f64, high: f64) -> String {
    let largest = mean.abs().max(low.abs()).max(high.abs());
    if tiny(largest) {
        return format!("{mean:+.2e} [{low:+.2e}, {high:+.2e}]");
    }
    let d = decimals_for(largest);
    format!("{mean:+.d$} [{low:+.d$}, {high:+.d$}]")
}

/// Below 10⁻³ fixed decimals would run long: such figures (a simulator's
/// round-off) are written with exponents.
fn tiny(largest: f64) -> bool {
    largest > 0.0 && largest < 1e-3
}

/// A mean and its unsigned interval: "1.91 [1.66, 2.16]".
pub fn estimate(mean: f64, low: f64, high: f64) -> String {
    let largest = mean.abs().max(low.abs()).max(high.abs());
    if tiny(largest) {
        return format!("{mean:.2e} [{low:.2e}, {high:.2e}]");
    }
    let d = decimals_for(largest);
    format!("{mean:.d$} [{low:.d$}, {high:.d$}]")
}

/// A time per state given in ns, in µs: "5.50 µs".
/// "a", "a and b", "a, b and c".
pub fn and_list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

pub fn micros(ns: f64) -> String {
    format!("{} µs", sig3(ns / 1000.0))
}

/// A measured time in µs with its range, to the precision the range
/// supports: three significant figures while the range spans under 10% of
/// the median, two under 100%, one beyond — "2.64 µs (2.62–2.71)", "2.8 µs
/// (2.6–3.0)"; the same decimals for all three.
pub fn timing(ns: f64, ns_min: f64, ns_max: f64) -> String {
    let (median, low, high) = (ns / 1000.0, ns_min / 1000.0, ns_max / 1000.0);
    let spread = (high - low) / median;
    let figures = if !(spread.is_finite() && spread > 0.0) {
        3
    } else {
        (1 - spread.log10().floor() as i32).clamp(1, 3)
    };
    if !(median.is_finite() && median > 0.0) {
        return format!("{} µs", sig3(median));
    }
    let decimals = (figures - 1 - median.log10().floor() as i32).max(0) as usize;
    format!("{median:.decimals$} µs ({low:.decimals$}–{high:.decimals$})")
}

/// A column's alignment.
#[derive(Clone, Copy)]
pub enum Align {
    Left,
    Right,
}

/// A Markdown table: key columns that name a row, and value columns.
pub struct MdTable {
    keys: Vec<(String, Align)>,
    values: Vec<(String, Align)>,
    rows: Vec<Vec<String>>,
}

impl MdTable {
    /// A table with these key columns (left-aligned).
    pub fn new(keys: &[&str]) -> MdTable {
        MdTable {
            keys: keys.iter().map(|k| (k.to_string(), Align::Left)).collect(),
            values: Vec::new(),
            rows: Vec::new(),
        }
    }

    /// Adds a value column.
    pub fn column(mut self, name: &str, align: Align) -> MdTable {
        self.values.push((name.to_string(), align));
        self
    }

    /// Adds value columns, right-aligned (numbers).
    pub fn numbers<S: AsRef<str>>(mut self, names: &[S]) -> MdTable {
        for n in names {
            self.values.push((n.as_ref().to_string(), Align::Right));
        }
        self
    }

    /// Adds a row: its keys, then its values.
    pub fn row(&mut self, cells: Vec<String>) {
        debug_assert_eq!(cells.len(), self.keys.len() + self.values.len());
        self.rows.push(cells);
    }

    /// Writes the table, split into parts of at most [`MAX_COLUMNS`]
    /// columns when wider.
    pub fn write(&self, md: &mut String) {
        let per_part = (MAX_COLUMNS - self.keys.len()).max(1);
        let parts = self.values.len().div_ceil(per_part).max(1);
        // Spread the values evenly over the parts.
        let size = self.values.len().div_ceil(parts).max(1);
        let k = self.keys.len();
        for part in 0..parts {
            let columns: Vec<usize> = (0..k)
                .chain((k + part * size..k + ((part + 1) * size).min(self.values.len())).take(size))
                .collect();
            let header = |c: usize| {
                if c < k {
                    &self.keys[c]
                } else {
                    &self.values[c - k]
                }
            };
            md.push('|');
            for &c in &columns {
                let _ = write!(md, " {} |", header(c).0);
            }
            md.push_str("\n|");
            for &c in &columns {
                md.push_str(match header(c).1 {
                    Align::Left => "---|",
                    Align::Right => "---:|",
                });
            }
            md.push('\n');
            for row in &self.rows {
                md.push('|');
                for &c in &columns {
                    let _ = write!(md, " {} |", row[c]);
                }
                md.push('\n');
            }
            md.push('\n');
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_timing_is_written_to_the_precision_of_its_range() {
        assert_eq!(timing(2640.0, 2620.0, 2710.0), "2.64 µs (2.62–2.71)");
        assert_eq!(timing(2800.0, 2620.0, 2970.0), "2.8 µs (2.6–3.0)");
        assert_eq!(timing(2800.0, 1000.0, 5000.0), "3 µs (1–5)");
        assert_eq!(timing(252_000.0, 251_000.0, 252_600.0), "252 µs (251–253)");
        assert_eq!(timing(479.0, 479.0, 479.0), "0.479 µs (0.479–0.479)");
    }

    #[test]
    fn three_significant_figures() {
        let cases = [
            (1.8738, "1.87"),
            (0.08349, "0.0835"),
            (81.94, "81.9"),
            (0.19, "0.190"),
            (213.0, "213"),
            (5472.6, "5470"),
            (9.996, "10.0"),
            (-0.0380, "-0.0380"),
            (0.0, "0"),
            (2.0, "2"),
            (17.0, "17"),
            (87_912.4, "87900"),
            (2.87e18, "2.87e18"),
            (-12_345_678.0, "-1.23e7"),
            (3.05e-17, "3.05e-17"),
        ];
        for (x, s) in cases {
            assert_eq!(sig3(x), s, "{x}");
        }
        assert_eq!(interval(0.517, 0.495, 0.540), "+0.517 [+0.495, +0.540]");
        assert_eq!(
            interval(-0.038, -0.068, -0.007),
            "-0.0380 [-0.0680, -0.0070]"
        );
        assert_eq!(micros(5472.0), "5.47 µs");
        // Round-off-sized figures in exponent form.
        assert_eq!(
            estimate(2.7e-6, -4.7e-6, 1.01e-5),
            "2.70e-6 [-4.70e-6, 1.01e-5]"
        );
        assert_eq!(
            interval(-2.7e-6, -4.7e-6, 0.0),
            "-2.70e-6 [-4.70e-6, +0.00e0]"
        );
        assert_eq!(signed(21.43), "+21.4");
    }

    #[test]
    fn wide_tables_split_repeating_their_keys() {
        let names: Vec<String> = (0..12).map(|i| format!("v{i}")).collect();
        let mut t = MdTable::new(&["model"]).numbers(&names);
        let mut cells = vec!["aln".to_string()];
        cells.extend((0..12).map(|i| i.to_string()));
        t.row(cells);
        let mut md = String::new();
        t.write(&mut md);
        let headers: Vec<&str> = md.lines().filter(|l| l.starts_with("| model")).collect();
        assert_eq!(headers.len(), 2, "{md}");
        for h in &headers {
            assert!(h.matches('|').count() - 1 <= MAX_COLUMNS, "{h}");
        }
        assert!(
            md.contains("| aln | 0 |") && md.contains("| aln | 6 |"),
            "{md}"
        );
    }
}
