//! Every committed report's first screen says what its record says: each
//! figure of the results table (mean error, persistence's, the difference
//! from persistence, with their intervals across replicates) agrees, to the
//! digits shown, with the same figure in the report's `replicates.csv` —
//! the file the interop check recomputes from the stages' tables with
//! numpy and scipy; the abstract quotes the table; `reports/README.md`
//! quotes no number its report's first screen does not; and every "In
//! hardware" sentence — a bit-forest's or a piecewise-linear model's in
//! fixed point — quotes its hardware table and judges by it.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use crate::common::committed_reports;

fn reports_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("reports")
}

/// The Markdown before the appendix: abstract, figure, table, caption.
fn first_screen(report: &str) -> &str {
    report.split("\n## Appendix").next().unwrap()
}

/// A figure of `replicates.csv`: its mean and 95% interval, and its
/// verdict when it is a difference.
#[derive(Clone, Copy, Debug)]
struct Figure {
    mean: f64,
    low: f64,
    high: f64,
    verdict: Option<&'static str>,
}

/// `replicates.csv` by (variant, figure).
fn figures(dir: &Path) -> BTreeMap<(String, String), Figure> {
    let mut reader = csv::Reader::from_path(dir.join("replicates.csv")).unwrap();
    let headers = reader.headers().unwrap().clone();
    let column = |name: &str| headers.iter().position(|h| h == name).unwrap();
    let (variant, figure, mean, low, high, verdict) = (
        column("variant"),
        column("figure"),
        column("mean"),
        column("ci_low"),
        column("ci_high"),
        column("verdict"),
    );
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            let number = |k: usize| r[k].parse::<f64>().unwrap();
            (
                (r[variant].to_string(), r[figure].to_string()),
                Figure {
                    mean: number(mean),
                    low: number(low),
                    high: number(high),
                    verdict: ["lower", "higher", "indistinguishable", "tied"]
                        .into_iter()
                        .find(|v| *v == &r[verdict]),
                },
            )
        })
        .collect()
}

/// The numbers of a cell ("0.682 [0.381, 0.983]", "+0.0438 [+0.0068,
/// +0.0808]", "-0.231", "3.2e-5"), each with the decimals its mantissa was
/// written to (`None` in exponent form).
fn numbers(cell: &str) -> Vec<(f64, Option<usize>)> {
    cell.replace('−', "-")
        .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == '+' || c == 'e'))
        .filter(|t| t.chars().any(|c| c.is_ascii_digit()))
        .map(|t| {
            let decimals = (!t.contains('e')).then(|| t.split('.').nth(1).map_or(0, str::len));
            (
                t.parse::<f64>()
                    .unwrap_or_else(|_| panic!("{t:?} in {cell:?}")),
                decimals,
            )
        })
        .collect()
}

/// Whether `cell` writes `figure` (mean, then its interval when the cell
/// has one) to the digits shown.
fn agrees(cell: &str, figure: Figure) -> bool {
    let shown = numbers(cell);
    let expected = [figure.mean, figure.low, figure.high];
    !shown.is_empty()
        && shown.len() <= 3
        && shown.iter().zip(expected).all(|(&(x, decimals), value)| {
            let tolerance = match decimals {
                Some(d) => 0.5 * 10f64.powi(-(d as i32)) + 1e-9,
                // Three significant figures in exponent form.
                None => 5e-3 * value.abs(),
            };
            (x - value).abs() <= tolerance
        })
}

/// The results table of a first screen: header cells and rows of cells.
fn results_table(screen: &str) -> (Vec<String>, Vec<Vec<String>>) {
    let cells = |line: &str| -> Vec<String> {
        line.trim()
            .trim_matches('|')
            .split('|')
            .map(|c| c.trim().to_string())
            .collect()
    };
    let mut lines = screen.lines().skip_while(|l| !l.starts_with("| model |"));
    let header = cells(lines.next().expect("a results table"));
    let rows = lines
        .skip(1)
        .take_while(|l| l.starts_with('|'))
        .map(cells)
        .collect();
    (header, rows)
}

#[test]
fn cells_are_read_with_their_precision() {
    assert_eq!(
        numbers("+0.0438 [+0.0068, -0.0808]"),
        [(0.0438, Some(4)), (0.0068, Some(4)), (-0.0808, Some(4))]
    );
    assert_eq!(numbers("−0.231"), [(-0.231, Some(3))]);
    assert_eq!(numbers("3.18e-17"), [(3.18e-17, None)]);
    let figure = Figure {
        mean: 0.68202,
        low: 0.38098,
        high: 0.98306,
        verdict: None,
    };
    assert!(agrees("0.682 [0.381, 0.983]", figure));
    assert!(!agrees("0.682 [0.381, 0.984]", figure));
    assert!(!agrees("0.683", figure));
}

#[test]
fn every_first_screen_table_agrees_with_its_replicates() {
    for dir in committed_reports() {
        let name = dir.file_name().unwrap().to_string_lossy().to_string();
        let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
        let screen = first_screen(&report);
        assert!(
            screen.lines().count() <= 250,
            "{name}: {} lines before the appendix",
            screen.lines().count()
        );
        let figures = figures(&dir);
        let variants: Vec<&String> = figures.keys().map(|(v, _)| v).collect();
        let (header, rows) = results_table(screen);
        let column = |title: &str| {
            header
                .iter()
                .position(|h| h.starts_with(title))
                .unwrap_or_else(|| panic!("{name}: no column {title:?} in {header:?}"))
        };
        let (error, persistence, gap) = (
            column("mean error"),
            column("persistence's"),
            column("− persistence"),
        );
        assert!(!rows.is_empty() && rows.len() <= 10, "{name}: {rows:?}");
        // Baselines are the best (first) ALN's variant's, but where another
        // variant's form of one errs less on the same rows: `linear `v``.
        let variant_of = |label: &str| -> String {
            match label.strip_prefix("ALN `") {
                Some(rest) => rest.trim_end_matches('`').to_string(),
                None => variants[0].clone(),
            }
        };
        let best = variant_of(&rows[0][0]);
        let mut checked = 0;
        for row in &rows {
            let label = &row[0];
            let (variant, model) = if label.starts_with("ALN") {
                (variant_of(label), "aln".to_string())
            } else if let Some((model, variant)) = label.split_once(" `") {
                (variant.trim_end_matches('`').to_string(), model.to_string())
            } else {
                (best.clone(), label.clone())
            };
            let figure = |f: &str| {
                *figures
                    .get(&(variant.clone(), f.to_string()))
                    .unwrap_or_else(|| panic!("{name}: no `{variant},{f}` in replicates.csv"))
            };
            let mut check = |cell: &str, f: &str| {
                let expected = figure(f);
                assert!(
                    agrees(cell, expected),
                    "{name}, row {label}: {cell:?} is not {f} = {expected:?}"
                );
                checked += 1;
            };
            check(&row[error], &format!("{model} mean"));
            if model != "persistence" {
                check(&row[persistence], "persistence mean");
                let difference = if model == "aln" {
                    "aln - persistence".to_string()
                } else {
                    format!("{model} mean - persistence mean")
                };
                check(&row[gap], &difference);
            }
        }
        // The abstract quotes the best ALN's row.
        let abstract_ = screen
            .lines()
            .find(|l| l.starts_with("**Abstract.**"))
            .unwrap_or_else(|| panic!("{name}: no abstract"));
        let quoted = abstract_
            .split(" errs ")
            .nth(1)
            .and_then(|rest| rest.split(" levels").next())
            .unwrap_or_else(|| panic!("{name}: the abstract quotes no error"));
        assert_eq!(quoted, rows[0][error], "{name}: abstract against table");
        assert!(
            abstract_.contains(&format!("({}", rows[0][gap])),
            "{name}: the abstract does not quote {:?}",
            rows[0][gap]
        );
        assert!(checked >= 5, "{name}: {checked} figures checked");
        // The most accurate of every model one frame ahead is the table's
        // row of lowest error (reports rendered before the abstract said
        // so have no such sentence).
        if let Some(rest) = abstract_
            .split(" Of every model, the most accurate one frame ahead is ")
            .nth(1)
        {
            let (model, rest) = rest.split_once(" at ").unwrap();
            let cell = rest.split(" levels").next().unwrap();
            let label = model.strip_prefix("the ").unwrap_or(model);
            let row = rows
                .iter()
                .find(|r| r[0] == label)
                .unwrap_or_else(|| panic!("{name}: {label} is not in the results table"));
            assert_eq!(row[error], cell, "{name}: the most accurate, {label}");
            let least = rows
                .iter()
                .map(|r| numbers(&r[error])[0].0)
                .fold(f64::INFINITY, f64::min);
            assert_eq!(
                numbers(cell)[0].0,
                least,
                "{name}: {label} is not the most accurate"
            );
        }
        // The abstract's planning sentence repeats the deadline verdicts:
        // each of its deadlines' intervals is the deadline paragraph's.
        if let Some(planning) = abstract_.split(" Planning, each model at ").nth(1) {
            let (_, tasks) = planning.split_once("): `").unwrap();
            for said in tasks.split("; `") {
                let (task, said) = said.split_once('`').unwrap();
                let paragraph = screen
                    .lines()
                    .find(|l| l.starts_with(&format!("**`{task}` at each deadline**")))
                    .unwrap_or_else(|| panic!("{name}: no deadline paragraph of {task}"));
                for (at, _) in said.match_indices(" ms (") {
                    let deadline = said[..at].rsplit(' ').next().unwrap();
                    let rest = &said[at + " ms (".len()..];
                    let figure = &rest[..=rest.find(']').unwrap()];
                    let at_deadline = paragraph
                        .split(&format!("at {deadline} ms, "))
                        .nth(1)
                        .and_then(|r| r.split("; at ").next())
                        .unwrap_or_else(|| panic!("{name}: {task} has no {deadline} ms verdict"));
                    assert!(
                        at_deadline.contains(&format!(": {figure}")),
                        "{name}: the abstract's {task} at {deadline} ms, {figure}, is not the \
                         paragraph's: {at_deadline}"
                    );
                }
                // The last deadline's pick against the feedback loop, as
                // the paragraph on the controls engineer's first try says.
                if let Some((_, against)) = said.split_once(", and at ") {
                    let (_, rest) = against.split_once(" ms ").unwrap();
                    let (pick, rest) = rest.split_once(" is ").unwrap();
                    let word = rest.split(' ').next().unwrap();
                    let (_, figure) = rest.rsplit_once(" (").unwrap();
                    let figure = &figure[..=figure.find(']').unwrap()];
                    let first_try = screen
                        .lines()
                        .skip_while(|l| *l != paragraph)
                        .find(|l| l.starts_with("**Against the controls engineer's first try**"))
                        .unwrap_or_else(|| panic!("{name}: {task} has no loop paragraph"));
                    assert!(
                        first_try.contains(&format!("{pick} {word}: {figure}")),
                        "{name}: the abstract's {task} loop, {pick} {word}: {figure}, is not \
                         the paragraph's: {first_try}"
                    );
                }
            }
            continue;
        }
        if screen.contains("Planning with it") {
            continue;
        }
        check_frontier(&name, abstract_, &header, &rows, &best, &figures);
    }
}

/// The simulator on the first screen: every setting the best variant
/// measured has a row, and the abstract sets the ALN's one-at-a-time speed
/// against the cheapest setting at least as accurate (one the ALN is not
/// better than, by `replicates.csv`), quoting its paired difference.
fn check_frontier(
    name: &str,
    abstract_: &str,
    header: &[String],
    rows: &[Vec<String>],
    best: &str,
    figures: &BTreeMap<(String, String), Figure>,
) {
    let measured: Vec<String> = figures
        .keys()
        .filter(|(v, f)| v == best && f.starts_with("simulator@") && f.ends_with("/frame mean"))
        .map(|(_, f)| f.trim_end_matches(" mean").to_string())
        .collect();
    if measured.is_empty() {
        return;
    }
    let one_at_a_time = header
        .iter()
        .position(|h| h == "µs per state, one at a time")
        .unwrap_or_else(|| panic!("{name}: no one-at-a-time column in {header:?}"));
    let median = |model: &str| -> f64 {
        let row = rows
            .iter()
            .find(|r| r[0] == model)
            .unwrap_or_else(|| panic!("{name}: {model} measured, but not in the results table"));
        numbers(&row[one_at_a_time])[0].0
    };
    let as_accurate: Vec<&String> = measured
        .iter()
        .filter(|m| {
            let f = figures[&(best.to_string(), format!("aln - {m}"))];
            f.verdict != Some("lower")
        })
        .collect();
    // Cheapest is fewest steps a frame (every step costs the same); the
    // measured medians of neighbouring settings swap under load.
    let steps = |model: &str| -> u32 {
        model
            .trim_start_matches("simulator@")
            .trim_end_matches("/frame")
            .parse()
            .unwrap_or_else(|_| panic!("{name}: {model} names no steps"))
    };
    let Some(cheapest) = as_accurate.iter().min_by_key(|m| steps(m)) else {
        return;
    };
    // Each measured setting has its row in the results table.
    for m in &measured {
        median(m);
    }
    let claim = format!(
        "{cheapest}, the cheapest simulator setting at least as accurate as the ALN (the ALN is "
    );
    let rest = abstract_
        .split(&claim)
        .nth(1)
        .unwrap_or_else(|| panic!("{name}: the abstract does not name {cheapest}: {abstract_}"));
    let figure = figures[&(best.to_string(), format!("aln - {cheapest}"))];
    let word = match figure.verdict {
        Some("higher") => "worse than",
        Some("indistinguishable") => "indistinguishable from",
        Some("tied") => "tied with",
        other => panic!("{name}: {cheapest} is not as accurate ({other:?})"),
    };
    assert!(rest.starts_with(word), "{name}: {word:?} expected: {rest}");
    let cell = rest[word.len()..]
        .trim_start_matches(" it, ")
        .split(" across")
        .next()
        .unwrap();
    assert!(
        agrees(cell, figure),
        "{name}: the abstract's {cell:?} is not aln - {cheapest} = {figure:?}"
    );
}

#[test]
fn the_reports_index_quotes_only_first_screen_figures() {
    let index = std::fs::read_to_string(reports_root().join("README.md")).unwrap();
    let normal = |s: &str| s.replace('−', "-");
    let mut lines = 0;
    // The index's table (`| [name](…) | finding |`) and the synthesis
    // above it (`- [name](…): finding`): each line's figures are its
    // report's.
    for line in index
        .lines()
        .filter(|l| l.starts_with("| [") || l.starts_with("- ["))
    {
        let name = line[3..].split(']').next().unwrap();
        let report = std::fs::read_to_string(reports_root().join(name).join("report.md")).unwrap();
        let screen = normal(first_screen(&report));
        let finding = if line.starts_with("| [") {
            normal(line.rsplit(" | ").next().unwrap())
        } else {
            normal(line.split_once("): ").unwrap().1)
        };
        for token in finding
            .split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == '+' || c == '×'))
        {
            let token = token.trim_matches(['.', '-']);
            if token.chars().any(|c| c.is_ascii_digit()) {
                assert!(
                    screen.contains(token),
                    "reports/README.md, {name}: {token:?} is not on the report's first screen"
                );
            }
        }
        lines += 1;
    }
    assert!(lines >= 10, "{lines} report lines");
}

/// Each report's `frontier.csv` — the first screen's models, unrounded,
/// which the synthesis chart draws — holds the errors of its
/// `replicates.csv`.
#[test]
fn every_frontier_agrees_with_its_replicates() {
    for dir in committed_reports() {
        let name = dir.file_name().unwrap().to_string_lossy().to_string();
        let figures = figures(&dir);
        let mut reader = csv::Reader::from_path(dir.join("frontier.csv"))
            .unwrap_or_else(|e| panic!("{name}: frontier.csv: {e}"));
        let headers = reader.headers().unwrap().clone();
        let column = |title: &str| headers.iter().position(|h| h == title).unwrap();
        let (model, variant, error) = (column("model"), column("variant"), column("error"));
        let mut checked = 0;
        for record in reader.records() {
            let record = record.unwrap();
            let key = (
                record[variant].to_string(),
                format!("{} mean", &record[model]),
            );
            let expected = figures
                .get(&key)
                .unwrap_or_else(|| panic!("{name}: no {key:?} in replicates.csv"));
            let found: f64 = record[error].parse().unwrap();
            assert!(
                (found - expected.mean).abs() <= 1e-12 * expected.mean.abs().max(1.0),
                "{name}: frontier.csv {key:?} {found} against {}",
                expected.mean
            );
            checked += 1;
        }
        assert!(checked >= 3, "{name}: {checked} rows");
    }
}

/// The chart at the top of `reports/README.md` is what `alnlab synthesis`
/// draws from the committed reports' `frontier.csv` files, byte for byte.
#[test]
fn the_synthesis_chart_is_drawn_from_the_reports() {
    let tmp = tempfile::tempdir().unwrap();
    for dir in committed_reports() {
        let to = tmp.path().join(dir.file_name().unwrap());
        std::fs::create_dir_all(&to).unwrap();
        std::fs::copy(dir.join("frontier.csv"), to.join("frontier.csv")).unwrap();
    }
    let out = crate::common::alnlab(tmp.path(), &["synthesis", "."]);
    assert!(out.status.success(), "{}", crate::common::stderr(&out));
    assert_eq!(
        std::fs::read(tmp.path().join("synthesis.svg")).unwrap(),
        std::fs::read(reports_root().join("synthesis.svg")).unwrap(),
        "reports/synthesis.svg is not what `alnlab synthesis reports` draws: run it again"
    );
}

/// The number after `before` in `text`, up to the next space or bracket.
fn number_after(text: &str, before: &str) -> Option<f64> {
    let rest = &text[text.find(before)? + before.len()..];
    let end = rest
        .find(|c: char| !(c.is_ascii_digit() || c == '.'))
        .unwrap_or(rest.len());
    rest[..end].parse().ok()
}

/// The cells of the appendix table row that starts with `start`.
fn row<'a>(report: &'a str, start: &str) -> Option<Vec<&'a str>> {
    report
        .lines()
        .find(|l| l.starts_with(start))
        .map(|l| l.split('|').map(str::trim).collect())
}

/// A report's "In hardware" sentences agree with its hardware tables: the
/// ns per state (and, for a piecewise-linear model, the pipeline's states
/// per second, the fixed-point error and persistence's) are the table's,
/// and the verdicts follow from them — "nanoseconds" confirmed under a
/// microsecond, "errs less than persistence" when its error is below
/// persistence's. How many sentences it checked.
fn check_hardware(name: &str, report: &str) -> usize {
    let screen = first_screen(report);
    let mut checked = 0;
    for line in screen
        .lines()
        .filter(|l| l.starts_with("**In hardware** (§5)"))
    {
        let ns = number_after(line, "predicts a state in ").expect("a state's ns");
        if line.contains("piecewise-linear model in fixed point") {
            let combinational = row(report, "| fixed point, combinational, on the ")
                .unwrap_or_else(|| panic!("{name}: no combinational row"));
            let pipelined = row(report, "| fixed point, pipelined (")
                .unwrap_or_else(|| panic!("{name}: no pipelined row"));
            let persistence = row(report, "| persistence (no change) |").unwrap();
            assert_eq!(
                combinational[4].parse::<f64>().unwrap(),
                ns,
                "{name}: {line}"
            );
            if pipelined[4] == "—" {
                // A pipelined state with a variable unmeasured has no rate,
                // and says so.
                assert!(line.contains("so it has no rate"), "{name}: {line}");
                assert_eq!(pipelined[5], "—", "{name}");
            } else {
                let rate = number_after(line, " ns) ").expect("states a second");
                let latency = number_after(line, "clocks, a state in ").expect("a latency");
                assert_eq!(pipelined[4].parse::<f64>().unwrap(), latency, "{name}");
                let table_rate: f64 = pipelined[5].trim_end_matches(" million").parse().unwrap();
                assert_eq!(table_rate, rate, "{name}");
            }
            let error = number_after(line, "in fixed point it errs ").unwrap();
            let persists = number_after(line, "and persistence's ").unwrap();
            assert_eq!(combinational[2].parse::<f64>().unwrap(), error, "{name}");
            assert_eq!(persistence[2].parse::<f64>().unwrap(), persists, "{name}");
            let beats = line.contains("for a model that errs less than persistence");
            assert_eq!(beats, error < persists, "{name}: {line}");
        } else {
            let forest = row(report, "| this forest on the ")
                .unwrap_or_else(|| panic!("{name}: no FPGA row"));
            assert_eq!(forest[4].parse::<f64>().unwrap(), ns, "{name}: {line}");
        }
        assert_eq!(
            line.contains("confirmed (under a microsecond)"),
            ns < 1000.0,
            "{name}: {line}"
        );
        checked += 1;
    }
    checked
}

#[test]
fn every_hardware_sentence_agrees_with_its_table() {
    let mut checked = 0;
    for dir in committed_reports() {
        let name = dir.file_name().unwrap().to_string_lossy().to_string();
        let report = std::fs::read_to_string(dir.join("report.md")).unwrap();
        checked += check_hardware(&name, &report);
    }
    assert!(
        checked >= 1,
        "no committed report measures its model in hardware"
    );
    // A piecewise-linear model's sentence, and a wrong one caught.
    let report = "**In hardware** (§5): `p`'s piecewise-linear model in fixed point (replicate \
                  1), each of its 2 variables placed and routed on a Lattice iCE40 HX8K of its \
                  own, predicts a state in 110 ns as a combinational circuit between registers \
                  (nextpnr's timing analysis), and pipelined (at most 20 \
                  clocks, a state in 120 ns) 167 million states a second; in fixed point it errs 0.750 levels against the \
                  floating-point model's 0.750 and persistence's 1.20, …: the paper's \
                  \"nanoseconds\", for a model that errs less than persistence on these rows, confirmed \
                  (under a microsecond).\n\n## Appendix\n\n\
                  | fixed point, combinational, on the Lattice iCE40 HX8K | 0.750 | 501 | 110 | 9.09 million |\n\
                  | fixed point, pipelined (at most 20 clocks) | 0.750 | 501 | 120 | 167 million |\n\
                  | persistence (no change) | 1.20 | — | — | — |\n";
    assert_eq!(check_hardware("synthetic", report), 1);
    let wrong = report.replace("| 110 | 9.09", "| 111 | 9.01");
    assert!(std::panic::catch_unwind(|| check_hardware("wrong", &wrong)).is_err());
    // A pipelined state without a rate must say it has none.
    let unrated = report.replace("| 501 | 120 | 167 million |", "| 501 | — | — |");
    assert!(std::panic::catch_unwind(|| check_hardware("unrated", &unrated)).is_err());
    let said = unrated.replace(
        ", and pipelined (at most 20 clocks, a state in 120 ns) 167 million states a second",
        "; pipelined, 1 of its variables are too large for the part, so it has no rate",
    );
    assert_eq!(check_hardware("said", &said), 1);
}
