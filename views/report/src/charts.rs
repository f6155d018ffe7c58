//! The report's charts, as SVG text (plotters' SVG backend: text stays text,
//! no fonts needed).
//!
//! Every chart is laid out the same way: the plotting area on the left and
//! the legend in a panel of its own to the right, never over the data;
//! ticks chosen here — whole decades (with 2 and 5 between when the axis
//! spans few) on log axes, whole numbers on integer axes; and each model in
//! one fixed [`Style`] wherever it appears ([`style_of`]).

use std::ops::Range;

use alnlab_common::{ModelId, PolicyId};
use plotters::coord::ranged1d::{DefaultFormatting, KeyPointHint, Ranged};
use plotters::element::DashedPathElement;
use plotters::prelude::*;

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

/// The plotting area (px); the legend panel is added to its right, and
/// the canvas grows taller when the legend needs it.
const PLOT: (u32, u32) = (640, 420);
const FONT: &str = "sans-serif";
/// Font sizes as plotters takes them (its SVG says size / 1.24 px).
const TITLE_SIZE: f64 = 20.0;
const LABEL_SIZE: f64 = 15.0;
/// The legend's rows (px).
const LEGEND_ROW: i32 = 20;
/// Pixels per character of label text, an upper estimate for sans-serif
/// at [`LABEL_SIZE`].
const CHAR_WIDTH: f64 = 7.3;
/// A marker's radius (px).
const MARKER: i32 = 5;

/// Colours of the ALN's series, one per variant: Paul Tol's "bright"
/// scheme and three of his "muted" colours, distinguishable with the
/// common colour-vision deficiencies.
const VARIANT_COLOURS: [RGBColor; 9] = [
    RGBColor(0x44, 0x77, 0xAA),
    RGBColor(0xEE, 0x66, 0x77),
    RGBColor(0x22, 0x88, 0x33),
    RGBColor(0xCC, 0xBB, 0x44),
    RGBColor(0x66, 0xCC, 0xEE),
    RGBColor(0xAA, 0x33, 0x77),
    RGBColor(0x33, 0x22, 0x88),
    RGBColor(0x44, 0xAA, 0x99),
    RGBColor(0x88, 0x22, 0x55),
];
/// The variants' marker shapes, taken in turn once the colours run out.
const VARIANT_MARKERS: [Marker; 4] = [
    Marker::Circle,
    Marker::Square,
    Marker::Triangle,
    Marker::Diamond,
];
/// The baselines keep out of the variants' colours: black and grey for
/// persistence and linear, browns for the simulator — darker the more steps
/// a frame, each step count its own shade and marker.
const PERSISTENCE: RGBColor = RGBColor(0, 0, 0);
const LINEAR: RGBColor = RGBColor(0x77, 0x77, 0x77);
const SIMULATOR: [RGBColor; 5] = [
    RGBColor(0xCC, 0x99, 0x55),
    RGBColor(0xAA, 0x77, 0x33),
    RGBColor(0x88, 0x55, 0x22),
    RGBColor(0x66, 0x3D, 0x14),
    RGBColor(0x44, 0x28, 0x0A),
];
/// The learned peer (gradient-boosted trees): dark teal, dashed like a
/// baseline.
const BOOSTED: RGBColor = RGBColor(0x00, 0x66, 0x66);
/// The hybrids (the nominal simulator plus a learned correction): the
/// learned kind's hue, darker and warmer, dashed.
const LINEAR_NOMINAL: RGBColor = RGBColor(0x88, 0x44, 0x88);
const BOOSTED_NOMINAL: RGBColor = RGBColor(0x22, 0x33, 0x99);
/// The planning reference the random controller.
const RANDOM_TORQUES: RGBColor = RGBColor(0xDD, 0x44, 0x00);
/// The PD and PID loops on the nominal model's gravity compensation: olive,
/// the PID darker.
const GRAVITY_PD: RGBColor = RGBColor(0x88, 0x88, 0x00);
const GRAVITY_PID: RGBColor = RGBColor(0x55, 0x55, 0x00);
/// A plant's own simulator (`plant@k`), the reference no user has: a dark
/// green apart from the simulators' browns.
const PLANT: RGBColor = RGBColor(0x11, 0x55, 0x33);
/// A model trained again after rounds of its planner's own data: its
/// first form's colour, one marker per round.
const ROUND_MARKERS: [Marker; 4] = [Marker::Plus, Marker::Diamond, Marker::Cross, Marker::Square];
/// A reference line across a plot ([`Plot::rules`]): lighter than any
/// series.
const RULE: RGBColor = RGBColor(0xAA, 0xAA, 0xAA);

/// The fill of a signed-log axis's linear band.
const BAND: RGBColor = RGBColor(0xF0, 0xF0, 0xF0);

/// A marker's shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Marker {
    Circle,
    Square,
    Triangle,
    Diamond,
    Cross,
    Plus,
}

/// How one model is drawn, in every chart of every report.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Style {
    pub colour: RGBColor,
    pub marker: Marker,
    /// Baselines are dashed, the ALN solid.
    pub dashed: bool,
}

/// The style of `model`'s series: the ALN by its variant's place among the
/// report's variants (so each variant keeps its style across the report),
/// the baselines by name (the same in every report).
pub fn style_of(model: ModelId, variant: usize) -> Style {
    match model {
        ModelId::Persistence => dashed(PERSISTENCE, Marker::Square),
        ModelId::Linear => dashed(LINEAR, Marker::Triangle),
        ModelId::Boosted => dashed(BOOSTED, Marker::Circle),
        ModelId::LinearNominal => dashed(LINEAR_NOMINAL, Marker::Triangle),
        ModelId::BoostedNominal => dashed(BOOSTED_NOMINAL, Marker::Square),
        ModelId::Simulator { steps } => {
            let (k, marker) = match steps {
                1 => (0, Marker::Diamond),
                2..=3 => (1, Marker::Cross),
                4..=6 => (2, Marker::Plus),
                7..=12 => (3, Marker::Square),
                _ => (4, Marker::Circle),
            };
            dashed(SIMULATOR[k], marker)
        }
        ModelId::Aln => Style {
            colour: VARIANT_COLOURS[variant % VARIANT_COLOURS.len()],
            marker: VARIANT_MARKERS[(variant / VARIANT_COLOURS.len()) % VARIANT_MARKERS.len()],
            dashed: false,
        },
    }
}

/// The style of a planning policy: a forward model's as
/// [`style_of`] draws it (round r of the planner's own data with the r-th
/// round's marker), the plant's own simulator and the references by name —
/// zero torques as persistence, since doing nothing looks the same whether
/// it predicts or controls.
pub fn policy_style(policy: PolicyId, round: u32, variant: usize) -> Style {
    let style = match policy {
        PolicyId::Aln => style_of(ModelId::Aln, variant),
        PolicyId::Linear => style_of(ModelId::Linear, variant),
        PolicyId::Simulator { steps } => style_of(ModelId::Simulator { steps }, variant),
        PolicyId::Plant { .. } => dashed(PLANT, Marker::Circle),
        PolicyId::Zero => dashed(PERSISTENCE, Marker::Square),
        PolicyId::Random => dashed(RANDOM_TORQUES, Marker::Cross),
        PolicyId::GravityPd => dashed(GRAVITY_PD, Marker::Triangle),
        PolicyId::GravityPid => dashed(GRAVITY_PID, Marker::Diamond),
    };
    match round {
        0 => style,
        r => Style {
            marker: ROUND_MARKERS[(r as usize - 1) % ROUND_MARKERS.len()],
            ..style
        },
    }
}

/// A baseline's style: dashed.
fn dashed(colour: RGBColor, marker: Marker) -> Style {
    Style {
        colour,
        marker,
        dashed: true,
    }
}

/// An axis of a [`Plot`].
pub struct Axis {
    pub label: String,
    /// Logarithmic (values ≤ 0 are drawn at the axis floor, and the legend
    /// says so).
    pub log: bool,
    /// Whole numbers only (epochs, steps): ticks at integers.
    pub integer: bool,
    /// A linear axis that starts at zero (errors).
    pub from_zero: bool,
    /// A paired difference: linear, or signed-log where its values span
    /// decades (see [`Axis::difference`]).
    pub difference: bool,
}

impl Axis {
    pub fn linear(label: &str) -> Axis {
        Axis {
            label: label.into(),
            log: false,
            integer: false,
            from_zero: false,
            difference: false,
        }
    }

    /// A paired difference's axis: linear, or, where its values span more
    /// than two and a half decades, signed-log — linear within ± a
    /// thousandth of the largest value's decade, logarithmic beyond on
    /// either side, each decade as wide as that band — so that the
    /// differences near zero, where verdicts are read, are not crushed
    /// under the largest.
    pub fn difference(label: &str) -> Axis {
        Axis {
            difference: true,
            ..Axis::linear(label)
        }
    }

    pub fn log(label: &str) -> Axis {
        Axis {
            log: true,
            ..Axis::linear(label)
        }
    }

    pub fn integer(label: &str) -> Axis {
        Axis {
            integer: true,
            ..Axis::linear(label)
        }
    }

    /// An error axis: log when its values span decades, else from zero.
    pub fn error(label: &str, values: impl IntoIterator<Item = f64>) -> Axis {
        let (lo, hi) = values
            .into_iter()
            .filter(|v| *v > 0.0)
            .fold((f64::MAX, 0f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if hi > 0.0 && hi / lo >= 30.0 {
            Axis::log(&format!("{label} (log)"))
        } else {
            Axis {
                from_zero: true,
                ..Axis::linear(label)
            }
        }
    }
}

/// One point, with an optional range drawn as an error bar on each axis.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    pub x: f64,
    pub y: f64,
    pub x_range: Option<(f64, f64)>,
    pub y_range: Option<(f64, f64)>,
}

impl Point {
    pub fn at(x: f64, y: f64) -> Point {
        Point {
            x,
            y,
            x_range: None,
            y_range: None,
        }
    }
}

/// One named series of a [`Plot`].
pub struct Series {
    pub name: String,
    pub style: Style,
    pub points: Vec<Point>,
    /// Points joined by a line (a curve), or markers alone.
    pub joined: bool,
    /// Markers outlined rather than filled (crosses and pluses ringed).
    pub hollow: bool,
}

/// A chart of series against two axes.
pub struct Plot {
    pub title: String,
    pub x: Axis,
    pub y: Axis,
    pub series: Vec<Series>,
    /// Draw the Pareto front of all points (lower x and lower y are better)
    /// as a staircase under them.
    pub pareto: bool,
    /// Reference lines (zero: persistence; real time), each drawn thin and
    /// grey across the plot and named in the legend — a reference, not data.
    pub rules: Vec<Rule>,
}

/// A reference line of a [`Plot`]: a level of y, or of x when vertical.
pub struct Rule {
    pub at: f64,
    pub name: String,
    pub vertical: bool,
}

impl Rule {
    /// A level of y.
    pub fn horizontal(at: f64, name: &str) -> Rule {
        Rule {
            at,
            name: name.into(),
            vertical: false,
        }
    }

    /// A level of x.
    pub fn vertical(at: f64, name: &str) -> Rule {
        Rule {
            vertical: true,
            ..Rule::horizontal(at, name)
        }
    }
}

/// The points no other point beats on both x and y (lower is better), by
/// increasing x.
pub fn pareto_front(points: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut sorted = points.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
    let mut front: Vec<(f64, f64)> = Vec::new();
    for p in sorted {
        if front.last().is_none_or(|last| p.1 < last.1) {
            front.push(p);
        }
    }
    front
}

/// One axis's range and ticks, in drawing units (log10 of the value on a
/// log axis).
struct Ticks {
    range: (f64, f64),
    /// (position, label)
    ticks: Vec<(f64, String)>,
    log: bool,
    /// On a log axis: where values ≤ 0 are drawn, and whether any was.
    floor: f64,
    clamped: bool,
    /// On a signed-log axis, the half-width of its linear part around zero.
    linear_within: Option<f64>,
}

impl Ticks {
    fn new(axis: &Axis, values: &[f64]) -> Ticks {
        let finite = values.iter().copied().filter(|v| v.is_finite());
        if axis.log {
            let positive: Vec<f64> = finite.clone().filter(|v| *v > 0.0).collect();
            if let Some(lo) = positive.iter().copied().reduce(f64::min) {
                let hi = positive.iter().copied().fold(lo, f64::max);
                let clamped = finite.clone().any(|v| v <= 0.0);
                return Ticks::log(lo.log10(), hi.log10(), clamped);
            }
        }
        if axis.difference
            && let Some(ticks) = Ticks::signed_log(&finite.clone().collect::<Vec<_>>())
        {
            return ticks;
        }
        let (mut lo, mut hi) =
            finite.fold((f64::MAX, f64::MIN), |(lo, hi), v| (lo.min(v), hi.max(v)));
        if lo > hi {
            (lo, hi) = (0.0, 1.0);
        }
        if axis.from_zero {
            lo = lo.min(0.0);
        }
        if hi - lo < 1e-12 {
            hi = lo + if axis.integer { 1.0 } else { lo.abs().max(1.0) };
        }
        let mut step = nice_step((hi - lo) / 6.0);
        if axis.integer {
            step = step.max(1.0).round();
        }
        let first = (lo / step).ceil() as i64;
        let last = (hi / step).floor() as i64;
        let decimals = (-step.log10().floor()).max(0.0) as usize;
        let ticks = (first..=last)
            .map(|k| {
                let v = k as f64 * step;
                (v, format!("{v:.decimals$}"))
            })
            .collect();
        let pad = (hi - lo) * 0.04;
        Ticks {
            range: (lo - pad, hi + pad),
            ticks,
            log: false,
            floor: lo,
            clamped: false,
            linear_within: None,
        }
    }

    /// A signed-log axis over `values`, if they span more than two and a
    /// half decades by magnitude (zero, and round-off below a millionth of
    /// the largest, aside): linear within ± a thousandth of the largest
    /// magnitude's decade, ticked at zero and at ± each decade from there.
    fn signed_log(values: &[f64]) -> Option<Ticks> {
        let big = values.iter().fold(0f64, |m, v| m.max(v.abs()));
        let small = values
            .iter()
            .map(|v| v.abs())
            .filter(|m| *m > 1e-6 * big)
            .fold(f64::INFINITY, f64::min);
        if big == 0.0 || big / small < 10f64.powf(2.5) {
            return None;
        }
        let top = big.log10().floor() as i32;
        let within = 10f64.powi(top - 3);
        let at = |v: f64| signed_log_place(v, within);
        let (lo, hi) = values
            .iter()
            .fold((0f64, 0f64), |(lo, hi), &v| (lo.min(at(v)), hi.max(at(v))));
        let mut ticks = vec![(0.0, "0".to_string())];
        for e in (top - 3)..=top {
            for sign in [1.0, -1.0] {
                let t = at(sign * 10f64.powi(e));
                if (lo - 1e-9..=hi + 1e-9).contains(&t) {
                    let label = log_label(1.0, e);
                    let label = match sign < 0.0 {
                        true => format!("−{label}"),
                        false => label,
                    };
                    ticks.push((t, label));
                }
            }
        }
        ticks.sort_by(|a, b| a.0.total_cmp(&b.0));
        let pad = (hi - lo) * 0.04;
        Some(Ticks {
            range: (lo - pad, hi + pad),
            ticks,
            log: false,
            floor: lo,
            clamped: false,
            linear_within: Some(within),
        })
    }

    /// A log axis over 10^lo … 10^hi.
    fn log(lo: f64, hi: f64, clamped: bool) -> Ticks {
        // Values ≤ 0 sit one step below the smallest.
        let floor = if clamped { lo - 0.3 } else { lo };
        let (lo_decade, hi_decade) = (floor.floor() as i32, hi.ceil() as i32);
        let mut ticks = Vec::new();
        let few = hi - floor < 2.5;
        for e in lo_decade..=hi_decade {
            let multiples: &[f64] = if few { &[1.0, 2.0, 5.0] } else { &[1.0] };
            for &m in multiples {
                let v = m * 10f64.powi(e);
                let t = v.log10();
                if t >= floor - 1e-9 && t <= hi + 1e-9 {
                    ticks.push((t, log_label(m, e)));
                }
            }
        }
        if ticks.len() < 2 {
            // Less than a decade with no 1-2-5 inside: plain steps.
            let (a, b) = (10f64.powf(floor), 10f64.powf(hi));
            let step = nice_step((b - a) / 4.0);
            let decimals = (-step.log10().floor()).max(0.0) as usize;
            ticks = ((a / step).ceil() as i64..=(b / step).floor() as i64)
                .map(|k| k as f64 * step)
                .filter(|v| *v > 0.0)
                .map(|v| (v.log10(), format!("{v:.decimals$}")))
                .collect();
        }
        let span = (hi - floor).max(0.3);
        let pad = span * 0.04;
        Ticks {
            range: (floor - pad, hi.max(floor + 0.3) + pad),
            ticks,
            log: true,
            floor,
            clamped,
            linear_within: None,
        }
    }

    /// A value in drawing units.
    fn place(&self, v: f64) -> f64 {
        if let Some(within) = self.linear_within {
            signed_log_place(v, within)
        } else if !self.log {
            v
        } else if v > 0.0 {
            v.log10().max(self.floor)
        } else {
            self.floor
        }
    }

    /// For the legend, where a signed-log axis turns logarithmic.
    fn scale_note(&self, axis: &str) -> Option<String> {
        self.linear_within.map(|within| {
            let band = log_label(1.0, within.log10().round() as i32);
            format!("{axis} axis: linear within ±{band} (shaded), log beyond")
        })
    }

    fn label(&self, v: f64) -> String {
        self.ticks
            .iter()
            .find(|(t, _)| (t - v).abs() < 1e-9)
            .map_or_else(String::new, |(_, l)| l.clone())
    }
}

/// Where a signed-log axis linear within ±`within` draws `v`: `v / within`
/// there, one unit a decade beyond.
fn signed_log_place(v: f64, within: f64) -> f64 {
    match v.abs() <= within {
        true => v / within,
        false => v.signum() * (1.0 + (v.abs() / within).log10()),
    }
}

/// An axis for plotters: a linear map of drawing units, ticked where
/// [`Ticks`] says.
struct TickedAxis {
    range: (f64, f64),
    ticks: Vec<f64>,
}

impl TickedAxis {
    fn of(ticks: &Ticks) -> TickedAxis {
        TickedAxis {
            range: ticks.range,
            ticks: ticks.ticks.iter().map(|t| t.0).collect(),
        }
    }
}

impl Ranged for TickedAxis {
    type FormatOption = DefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        let (lo, hi) = self.range;
        let share = (value - lo) / (hi - lo);
        limit.0 + (share * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, _hint: Hint) -> Vec<f64> {
        self.ticks.clone()
    }

    fn range(&self) -> Range<f64> {
        self.range.0..self.range.1
    }
}

/// 1, 2 or 5 times a power of ten, at least `raw`.
fn nice_step(raw: f64) -> f64 {
    let raw = raw.max(1e-12);
    let power = 10f64.powf(raw.log10().floor());
    [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * power)
        .find(|s| *s >= raw * 0.999)
        .unwrap_or(10.0 * power)
}

/// The label of m·10^e: plain digits from 0.001 to 9999, else "2·10⁵".
fn log_label(m: f64, e: i32) -> String {
    if (-3..4).contains(&e) {
        let v = m * 10f64.powi(e);
        let decimals = (-e).max(0) as usize;
        format!("{v:.decimals$}")
    } else {
        let superscript: String = e
            .to_string()
            .chars()
            .map(|c| match c {
                '-' => '⁻',
                d => ['⁰', '¹', '²', '³', '⁴', '⁵', '⁶', '⁷', '⁸', '⁹'][d as usize - '0' as usize],
            })
            .collect();
        if m == 1.0 {
            format!("10{superscript}")
        } else {
            format!("{m}·10{superscript}")
        }
    }
}

/// Draws a canvas of `size` into an SVG string; a drawing error (which
/// plotters reports only for degenerate ranges) leaves a chart that says
/// so rather than no file.
fn svg(
    size: (u32, u32),
    draw: impl FnOnce(&DrawingArea<SVGBackend, plotters::coord::Shift>) -> DrawResult,
) -> String {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, size).into_drawing_area();
        if let Err(e) = root
            .fill(&WHITE)
            .map_err(Into::into)
            .and_then(|()| draw(&root))
        {
            let _ = root.fill(&WHITE);
            let _ = root.draw_text(
                &format!("chart not drawn: {e}"),
                &(FONT, LABEL_SIZE).into_text_style(&root),
                (20, 20),
            );
        }
        let _ = root.present();
    }
    text
}

fn text_style(size: f64) -> TextStyle<'static> {
    (FONT, size).into_font().color(&BLACK)
}

/// A marker of `style` centred on pixel `at`.
fn draw_marker<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    marker: Marker,
    (x, y): (i32, i32),
    colour: RGBColor,
    hollow: bool,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let r = MARKER;
    let fill = if hollow {
        colour.stroke_width(2)
    } else {
        colour.filled()
    };
    let outline = |points: Vec<(i32, i32)>| -> DrawResult {
        if hollow {
            let mut closed = points.clone();
            closed.push(points[0]);
            area.draw(&PathElement::new(closed, colour.stroke_width(2)))?;
        } else {
            area.draw(&Polygon::new(points, colour.filled()))?;
        }
        Ok(())
    };
    match marker {
        Marker::Circle => area.draw(&Circle::new((x, y), r, fill))?,
        Marker::Square => outline(vec![
            (x - r + 1, y - r + 1),
            (x + r - 1, y - r + 1),
            (x + r - 1, y + r - 1),
            (x - r + 1, y + r - 1),
        ])?,
        Marker::Triangle => outline(vec![
            (x, y - r - 1),
            (x + r + 1, y + r - 1),
            (x - r - 1, y + r - 1),
        ])?,
        Marker::Diamond => outline(vec![
            (x, y - r - 1),
            (x + r + 1, y),
            (x, y + r + 1),
            (x - r - 1, y),
        ])?,
        Marker::Cross | Marker::Plus => {
            let arms = if marker == Marker::Cross {
                [
                    [(x - r, y - r), (x + r, y + r)],
                    [(x - r, y + r), (x + r, y - r)],
                ]
            } else {
                [
                    [(x - r - 1, y), (x + r + 1, y)],
                    [(x, y - r - 1), (x, y + r + 1)],
                ]
            };
            for arm in arms {
                area.draw(&PathElement::new(arm.to_vec(), colour.stroke_width(2)))?;
            }
            // A cross has no inside to leave empty: hollow ones are ringed.
            if hollow {
                area.draw(&Circle::new((x, y), r + 3, colour.stroke_width(1)))?;
            }
        }
    }
    Ok(())
}

/// A line through pixel points, dashed or solid.
fn draw_line<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    points: Vec<(i32, i32)>,
    colour: RGBColor,
    dashed: bool,
    width: u32,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    if dashed {
        area.draw(&DashedPathElement::new(
            points,
            7,
            4,
            colour.stroke_width(width),
        ))?;
    } else {
        area.draw(&PathElement::new(points, colour.stroke_width(width)))?;
    }
    Ok(())
}

/// An error bar from pixel `a` to `b` (vertical or horizontal), capped at
/// both ends across its direction.
fn draw_error_bar<DB: DrawingBackend>(
    area: &DrawingArea<DB, plotters::coord::Shift>,
    a: (i32, i32),
    b: (i32, i32),
    colour: RGBColor,
) -> DrawResult
where
    DB::ErrorType: 'static,
{
    let style = colour.stroke_width(1);
    area.draw(&PathElement::new(vec![a, b], style))?;
    let vertical = a.0 == b.0;
    for (x, y) in [a, b] {
        let cap = if vertical {
            vec![(x - 4, y), (x + 4, y)]
        } else {
            vec![(x, y - 4), (x, y + 4)]
        };
        area.draw(&PathElement::new(cap, style))?;
    }
    Ok(())
}

/// One row of a legend.
enum Entry<'a> {
    Series(&'a Series),
    Front,
    /// A reference line ([`Plot::rules`]), by name.
    Rule(&'a str),
    Note(&'a str),
}

/// Draws `plot` as SVG.
pub fn plot(plot: &Plot) -> String {
    let points = || plot.series.iter().flat_map(|s| &s.points);
    let xs: Vec<f64> = points()
        .flat_map(|p| {
            let (lo, hi) = p.x_range.unwrap_or((p.x, p.x));
            [p.x, lo, hi]
        })
        .chain(plot.rules.iter().filter(|r| r.vertical).map(|r| r.at))
        .collect();
    let ys: Vec<f64> = points()
        .flat_map(|p| {
            let (lo, hi) = p.y_range.unwrap_or((p.y, p.y));
            [p.y, lo, hi]
        })
        .chain(plot.rules.iter().filter(|r| !r.vertical).map(|r| r.at))
        .collect();
    let x = Ticks::new(&plot.x, &xs);
    let y = Ticks::new(&plot.y, &ys);
    let zero_note = if x.clamped || y.clamped {
        "zero: drawn at the axis floor"
    } else {
        ""
    };
    let mut entries: Vec<Entry> = plot.series.iter().map(Entry::Series).collect();
    // Rules of one name (a set of deadlines) are one entry.
    for rule in &plot.rules {
        if !entries
            .iter()
            .any(|e| matches!(e, Entry::Rule(n) if *n == rule.name))
        {
            entries.push(Entry::Rule(&rule.name));
        }
    }
    if plot.pareto {
        entries.push(Entry::Front);
    }
    if !zero_note.is_empty() {
        entries.push(Entry::Note(zero_note));
    }
    let scale_note = y.scale_note("vertical");
    if let Some(note) = &scale_note {
        entries.push(Entry::Note(note));
    }
    let longest = entries
        .iter()
        .map(|e| match e {
            Entry::Series(s) => s.name.chars().count(),
            Entry::Front => "Pareto front".len(),
            Entry::Rule(n) | Entry::Note(n) => n.chars().count(),
        })
        .max()
        .unwrap_or(0);
    let legend_width = (longest as f64 * CHAR_WIDTH) as u32 + 56;
    let height = PLOT.1.max(60 + entries.len() as u32 * LEGEND_ROW as u32);
    svg((PLOT.0 + legend_width, height), |root| {
        let (left, legend) = root.split_horizontally(PLOT.0);
        let (area, _) = left.split_vertically(PLOT.1);
        let mut chart = ChartBuilder::on(&area)
            .caption(&plot.title, (FONT, TITLE_SIZE))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(TickedAxis::of(&x), TickedAxis::of(&y))?;
        chart
            .configure_mesh()
            .x_desc(plot.x.label.as_str())
            .y_desc(plot.y.label.as_str())
            .label_style(text_style(LABEL_SIZE))
            .axis_desc_style(text_style(LABEL_SIZE))
            .x_label_formatter(&|v| x.label(*v))
            .y_label_formatter(&|v| y.label(*v))
            .light_line_style(WHITE)
            .bold_line_style(BLACK.mix(0.12))
            .draw()?;
        let px = |p: (f64, f64)| chart.backend_coord(&(x.place(p.0), y.place(p.1)));

        // A signed-log axis's linear band, shaded: as tall as a decade, it
        // would otherwise read as one.
        if let Some(within) = y.linear_within {
            // Within the plot: the band may reach past the values drawn.
            let (low, high) = (
                y.place(-within).max(y.range.0),
                y.place(within).min(y.range.1),
            );
            let corners = [
                chart.backend_coord(&(x.range.0, low)),
                chart.backend_coord(&(x.range.1, high)),
            ];
            root.draw(&Rectangle::new(corners, BAND.filled()))?;
        }
        for rule in &plot.rules {
            let ends = if rule.vertical {
                let x_at = x.place(rule.at);
                [(x_at, y.range.0), (x_at, y.range.1)]
            } else {
                let y_at = y.place(rule.at);
                [(x.range.0, y_at), (x.range.1, y_at)]
            };
            let ends = ends.iter().map(|e| chart.backend_coord(e)).collect();
            draw_line(root, ends, RULE, true, 1)?;
        }
        if plot.pareto {
            let all: Vec<(f64, f64)> = plot
                .series
                .iter()
                .flat_map(|s| s.points.iter().map(|p| (p.x, p.y)))
                .collect();
            let front = pareto_front(&all);
            let mut steps = Vec::new();
            for (k, &p) in front.iter().enumerate() {
                if k > 0 {
                    steps.push(px((p.0, front[k - 1].1)));
                }
                steps.push(px(p));
            }
            draw_line(root, steps, RGBColor(0x55, 0x55, 0x55), true, 1)?;
        }
        for s in &plot.series {
            let colour = s.style.colour;
            if s.joined && s.points.len() > 1 {
                let line = s.points.iter().map(|p| px((p.x, p.y))).collect();
                draw_line(root, line, colour, s.style.dashed, 2)?;
            }
            for p in &s.points {
                let at = px((p.x, p.y));
                if let Some((lo, hi)) = p.y_range {
                    draw_error_bar(root, px((p.x, lo)), px((p.x, hi)), colour)?;
                }
                if let Some((lo, hi)) = p.x_range {
                    draw_error_bar(root, px((lo, p.y)), px((hi, p.y)), colour)?;
                }
                draw_marker(root, s.style.marker, at, colour, s.hollow)?;
            }
        }

        // The legend, in its own panel.
        let font = text_style(LABEL_SIZE).pos(plotters::style::text_anchor::Pos::new(
            plotters::style::text_anchor::HPos::Left,
            plotters::style::text_anchor::VPos::Center,
        ));
        for (k, entry) in entries.iter().enumerate() {
            let y0 = 50 + k as i32 * LEGEND_ROW;
            let (name, line): (&str, Option<(RGBColor, bool)>) = match entry {
                Entry::Series(s) => {
                    if s.joined {
                        draw_line(
                            &legend,
                            vec![(4, y0), (32, y0)],
                            s.style.colour,
                            s.style.dashed,
                            2,
                        )?;
                    }
                    draw_marker(&legend, s.style.marker, (18, y0), s.style.colour, s.hollow)?;
                    (&s.name, None)
                }
                Entry::Front => ("Pareto front", Some((RGBColor(0x55, 0x55, 0x55), true))),
                Entry::Rule(name) => (name, Some((RULE, true))),
                Entry::Note(note) => (note, None),
            };
            if let Some((colour, dashed)) = line {
                draw_line(&legend, vec![(4, y0), (32, y0)], colour, dashed, 1)?;
            }
            legend.draw_text(name, &font, (40, y0))?;
        }
        Ok(())
    })
}

/// One bin of a [`histogram`]: errors from `low` to below `high` levels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bin {
    pub low: f64,
    pub high: f64,
    pub count: u64,
}

/// Where an error of `e` levels sits on a histogram's axis: log10(1 + e),
/// so that bins of one level near zero and of fifty in the tail both show.
fn log_place(e: f64) -> f64 {
    (1.0 + e).log10()
}

/// Each bin's share of all errors per decade of its width on the axis
/// (%): a bar's area is its share, whatever its width.
fn densities(bins: &[Bin]) -> Vec<f64> {
    let total = bins.iter().map(|b| b.count).sum::<u64>().max(1) as f64;
    bins.iter()
        .map(|b| 100.0 * b.count as f64 / total / (log_place(b.high) - log_place(b.low)))
        .collect()
}

/// A histogram of errors: bars as wide as their bins on an axis of
/// log10(1 + error) — one level near zero and fifty in the tail both
/// readable — and as high as their share of the errors per decade of that
/// axis, so a bar's area is its share and a wide bin is no false spike; in
/// `colour`, `overlay` (a name and bins) drawn as a black outline over them.
pub fn histogram(
    title: &str,
    bins: &[Bin],
    colour: RGBColor,
    overlay: Option<(&str, &[Bin])>,
) -> String {
    let heights = densities(bins);
    let outline = overlay.map(|(_, o)| (o, densities(o)));
    let axis = Axis {
        from_zero: true,
        ..Axis::linear("share of errors per decade (%)")
    };
    let all_heights: Vec<f64> = heights
        .iter()
        .chain(outline.iter().flat_map(|(_, h)| h))
        .copied()
        .collect();
    let y = Ticks::new(&axis, &all_heights);
    let end = bins
        .iter()
        .chain(overlay.iter().flat_map(|(_, o)| o.iter()))
        .map(|b| b.high)
        .fold(1.0, f64::max);
    let ticks: Vec<(f64, String)> = [0.0, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0]
        .into_iter()
        .filter(|&v| v <= end)
        .map(|v| (log_place(v), format!("{v}")))
        .collect();
    let label = |v: f64| {
        ticks
            .iter()
            .find(|(t, _)| (t - v).abs() < 1e-9)
            .map_or_else(String::new, |(_, l)| l.clone())
    };
    svg((PLOT.0 + 80, PLOT.1), |root| {
        let mut chart = ChartBuilder::on(root)
            .caption(title, (FONT, TITLE_SIZE))
            .margin(14)
            .x_label_area_size(48)
            .y_label_area_size(72)
            .build_cartesian_2d(
                TickedAxis {
                    range: (0.0, log_place(end)),
                    ticks: ticks.iter().map(|t| t.0).collect(),
                },
                TickedAxis {
                    range: (0.0, y.range.1),
                    ticks: y.ticks.iter().map(|t| t.0).collect(),
                },
            )?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc("error (levels; axis log10(1 + error))")
            .y_desc(axis.label.as_str())
            .label_style(text_style(LABEL_SIZE))
            .axis_desc_style(text_style(LABEL_SIZE))
            .x_label_formatter(&|v| label(*v))
            .y_label_formatter(&|v| y.label(*v))
            .light_line_style(WHITE)
            .bold_line_style(BLACK.mix(0.12))
            .draw()?;
        chart.draw_series(bins.iter().zip(&heights).map(|(b, &h)| {
            let (low, high) = (log_place(b.low), log_place(b.high));
            Rectangle::new([(low, 0.0), (high, h)], colour.filled())
        }))?;
        if let Some((o, h)) = &outline {
            // A step outline: up and across each bin, down at the end.
            let mut steps = vec![(o.first().map_or(0.0, |b| log_place(b.low)), 0.0)];
            for (b, &h) in o.iter().zip(h) {
                steps.push((log_place(b.low), h));
                steps.push((log_place(b.high), h));
            }
            steps.push((o.last().map_or(0.0, |b| log_place(b.high)), 0.0));
            chart.draw_series(std::iter::once(PathElement::new(
                steps,
                BLACK.stroke_width(2),
            )))?;
            if let Some((name, _)) = overlay {
                let font = text_style(LABEL_SIZE);
                root.draw_text(
                    &format!("outline: {name}"),
                    &font,
                    (PLOT.0 as i32 - 180, 40),
                )?;
            }
        }
        Ok(())
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn well_formed(svg: &str) {
        assert!(
            svg.starts_with("<svg") && svg.trim_end().ends_with("</svg>"),
            "{svg}"
        );
        assert!(!svg.contains("chart not drawn"), "{svg}");
    }

    #[test]
    fn charts_are_svg_with_their_labels() {
        let bin = |low, high, count| Bin { low, high, count };
        let bins = [bin(0.0, 1.0, 3), bin(1.0, 2.0, 3), bin(10.0, 20.0, 3)];
        // Equal counts: each bar's area (height × width on the axis) is
        // its share, a third.
        let d = densities(&bins);
        for (b, h) in bins.iter().zip(&d) {
            let area = h * (log_place(b.high) - log_place(b.low));
            assert!((area - 100.0 / 3.0).abs() < 1e-9, "{b:?}: {area}");
        }
        let h = histogram(
            "worst",
            &bins,
            VARIANT_COLOURS[0],
            Some(("persistence torques", &bins)),
        );
        well_formed(&h);
        assert!(h.contains("outline: persistence torques"));
        let series = |name: &str, model: ModelId| Series {
            name: name.into(),
            style: style_of(model, 0),
            points: vec![Point::at(1.0, 3.0), Point::at(20.0, 0.0)],
            joined: true,
            hollow: false,
        };
        let p = plot(&Plot {
            title: "t".into(),
            x: Axis::log("x"),
            y: Axis::log("y"),
            series: vec![
                series("aln · walk", ModelId::Aln),
                series("persistence", ModelId::Persistence),
            ],
            pareto: true,
            rules: Vec::new(),
        });
        well_formed(&p);
        assert!(p.contains("aln · walk") && p.contains("Pareto front"));
        assert!(p.contains("zero: drawn at the axis floor"));
    }

    #[test]
    fn styles_are_fixed_and_distinct() {
        let mut seen = Vec::new();
        for k in 0..12 {
            seen.push(style_of(ModelId::Aln, k));
        }
        let simulators = [1, 2, 5, 10].map(|steps| ModelId::Simulator { steps });
        for model in [ModelId::Persistence, ModelId::Linear]
            .into_iter()
            .chain(simulators)
        {
            assert_eq!(style_of(model, 0), style_of(model, 7), "{model}");
            seen.push(style_of(model, 0));
        }
        for policy in [PolicyId::Random, PolicyId::Plant { steps: 1 }] {
            assert_eq!(policy_style(policy, 0, 0), policy_style(policy, 0, 7));
            seen.push(policy_style(policy, 0, 0));
        }
        // Zero torques are drawn as persistence; a forward model as its
        // prediction, round r with the r-th round's marker.
        assert_eq!(
            policy_style(PolicyId::Zero, 0, 3),
            style_of(ModelId::Persistence, 0)
        );
        let simulator = PolicyId::Simulator { steps: 2 };
        assert_eq!(
            policy_style(simulator, 0, 0),
            style_of(ModelId::Simulator { steps: 2 }, 0)
        );
        let round = policy_style(PolicyId::Aln, 2, 1);
        assert_eq!(round.colour, style_of(ModelId::Aln, 1).colour);
        assert_eq!(round.marker, ROUND_MARKERS[1]);
        for (i, a) in seen.iter().enumerate() {
            for b in &seen[..i] {
                assert!(
                    (a.colour, a.marker, a.dashed) != (b.colour, b.marker, b.dashed),
                    "{a:?} twice"
                );
            }
        }
    }

    #[test]
    fn log_ticks_are_decades_with_readable_labels() {
        let t = Ticks::new(&Axis::log("ns"), &[300.0, 2e5]);
        let labels: Vec<&str> = t.ticks.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["1000", "10⁴", "10⁵"]);
        let t = Ticks::new(&Axis::log("e"), &[0.04, 3.0]);
        let labels: Vec<&str> = t.ticks.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["0.05", "0.1", "0.2", "0.5", "1", "2"]);
        let t = Ticks::new(&Axis::integer("epoch"), &[1.0, 3.0]);
        let labels: Vec<&str> = t.ticks.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["1", "2", "3"]);
    }

    /// A paired difference spanning decades (hold's: 20 above the
    /// reference to 0.2 below) is signed-log, linear within ± a thousandth
    /// of the largest decade, monotone through zero; one that does not is
    /// linear.
    #[test]
    fn a_difference_spanning_decades_is_signed_log_and_keeps_its_order() {
        let values = [-0.2, 0.0016, 0.0087, 1.9, 20.0];
        let t = Ticks::new(&Axis::difference("cost"), &values);
        assert_eq!(t.linear_within, Some(0.01));
        let labels: Vec<&str> = t.ticks.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["−0.1", "−0.01", "0", "0.01", "0.1", "1", "10"]);
        let placed: Vec<f64> = values.iter().map(|&v| t.place(v)).collect();
        assert!(placed.windows(2).all(|w| w[0] < w[1]), "{placed:?}");
        // Linear within the band, a unit a decade beyond, either side.
        assert_eq!(t.place(0.0), 0.0);
        assert!((t.place(0.005) - 0.5).abs() < 1e-12);
        assert!((t.place(0.01) - 1.0).abs() < 1e-12);
        assert!((t.place(10.0) - 4.0).abs() < 1e-12);
        assert!((t.place(-0.2) + 1.0 + 20f64.log10()).abs() < 1e-12);
        assert_eq!(
            t.scale_note("vertical").as_deref(),
            Some("vertical axis: linear within ±0.01 (shaded), log beyond")
        );
        // Too narrow a span, or one that only round-off widens, stays
        // linear; so do no values, one, and all zero.
        for values in [
            &[-3.0, 0.5, 12.0][..],
            &[1e-15, 2.0, 30.0],
            &[],
            &[5.0],
            &[0.0, 0.0],
        ] {
            let t = Ticks::new(&Axis::difference("cost"), values);
            assert_eq!(t.linear_within, None, "{values:?}");
            assert_eq!(t.place(12.0), 12.0);
        }
        // The legend says so.
        let svg = plot(&Plot {
            title: "t".into(),
            x: Axis::log("ms"),
            y: Axis::difference("cost"),
            series: vec![Series {
                name: "aln".into(),
                style: style_of(ModelId::Aln, 0),
                points: values
                    .iter()
                    .map(|&v| Point::at(1.0 + v.abs(), v))
                    .collect(),
                joined: true,
                hollow: false,
            }],
            pareto: false,
            rules: Vec::new(),
        });
        well_formed(&svg);
        assert!(svg.contains("vertical axis: linear within ±0.01 (shaded), log beyond"));
        // All below zero: the same, mirrored.
        let t = Ticks::new(&Axis::difference("cost"), &[-20.0, -0.01]);
        let labels: Vec<&str> = t.ticks.iter().map(|(_, l)| l.as_str()).collect();
        assert_eq!(labels, ["−10", "−1", "−0.1", "−0.01", "0"]);
    }

    #[test]
    fn the_pareto_front_keeps_points_nothing_beats() {
        let front = pareto_front(&[(1.0, 5.0), (2.0, 6.0), (3.0, 2.0), (4.0, 2.0), (5.0, 1.0)]);
        assert_eq!(front, [(1.0, 5.0), (3.0, 2.0), (5.0, 1.0)]);
    }
}
