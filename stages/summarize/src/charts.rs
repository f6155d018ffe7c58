//! The report's charts, as SVG text (plotters' SVG backend: text stays text,
//! no fonts needed).

use plotters::coord::ranged1d::{IntoSegmentedCoord, SegmentValue};
use plotters::prelude::*;

use crate::stats::HISTOGRAM_BINS;

type DrawResult = std::result::Result<(), Box<dyn std::error::Error>>;

const SIZE: (u32, u32) = (720, 420);
const PALETTE: [RGBColor; 10] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(148, 103, 189),
    RGBColor(140, 86, 75),
    RGBColor(227, 119, 194),
    RGBColor(127, 127, 127),
    RGBColor(188, 189, 34),
    RGBColor(23, 190, 207),
];

/// Draws into an SVG string; a drawing error (which plotters reports only for
/// degenerate ranges) leaves a chart that says so rather than no file.
fn svg(
    draw: impl FnOnce(&DrawingArea<SVGBackend, plotters::coord::Shift>) -> DrawResult,
) -> String {
    let mut text = String::new();
    {
        let root = SVGBackend::with_string(&mut text, SIZE).into_drawing_area();
        if let Err(e) = root
            .fill(&WHITE)
            .map_err(Into::into)
            .and_then(|()| draw(&root))
        {
            let _ = root.fill(&WHITE);
            let _ = root.draw_text(
                &format!("chart not drawn: {e}"),
                &("sans-serif", 16).into_text_style(&root),
                (20, 20),
            );
        }
        let _ = root.present();
    }
    text
}

/// The §4.5 view: errors of 0 … 9 levels and of 10 or more.
pub fn histogram(title: &str, counts: &[u64; HISTOGRAM_BINS]) -> String {
    svg(|root| {
        let top = counts.iter().copied().max().unwrap_or(0).max(1) as f64 * 1.1;
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((0u32..HISTOGRAM_BINS as u32).into_segmented(), 0f64..top)?;
        chart
            .configure_mesh()
            .disable_x_mesh()
            .x_desc("error (levels)")
            .y_desc("count")
            .x_label_formatter(&|v| match v {
                SegmentValue::CenterOf(b) if *b as usize + 1 == HISTOGRAM_BINS => "10+".into(),
                SegmentValue::CenterOf(b) => b.to_string(),
                _ => String::new(),
            })
            .draw()?;
        chart.draw_series(counts.iter().enumerate().map(|(bin, &count)| {
            let bin = bin as u32;
            let mut bar = Rectangle::new(
                [
                    (SegmentValue::Exact(bin), 0.0),
                    (SegmentValue::Exact(bin + 1), count as f64),
                ],
                PALETTE[0].filled(),
            );
            bar.set_margin(0, 0, 4, 4);
            bar
        }))?;
        Ok(())
    })
}

/// Lines, one per named series of (x, y) points.
pub fn lines(
    title: &str,
    x_desc: &str,
    y_desc: &str,
    series: &[(String, Vec<(f64, f64)>)],
) -> String {
    svg(|root| {
        let points = series.iter().flat_map(|(_, p)| p);
        let (x_max, y_max) = points.fold((1f64, 0f64), |(x, y), p| (x.max(p.0), y.max(p.1)));
        let mut chart = ChartBuilder::on(root)
            .caption(title, ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d(0f64..x_max, 0f64..(y_max * 1.1).max(1e-9))?;
        chart
            .configure_mesh()
            .x_desc(x_desc)
            .y_desc(y_desc)
            .draw()?;
        for (k, (name, points)) in series.iter().enumerate() {
            let color = PALETTE[k % PALETTE.len()];
            chart
                .draw_series(LineSeries::new(
                    points.iter().copied(),
                    color.stroke_width(2),
                ))?
                .label(name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], color));
        }
        chart
            .configure_series_labels()
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
        Ok(())
    })
}

/// One point of the speed chart.
pub struct SpeedPoint {
    pub label: String,
    pub ns_per_state: f64,
    pub mean: f64,
    pub p95: f64,
}

/// Speed against error: ns per predicted state (log scale) against mean
/// error (filled) and 95th-percentile error (hollow), one colour per label.
pub fn speed(points: &[SpeedPoint]) -> String {
    svg(|root| {
        let (lo, hi) = points.iter().fold((f64::MAX, f64::MIN), |(lo, hi), p| {
            (lo.min(p.ns_per_state), hi.max(p.ns_per_state))
        });
        let (lo, hi) = if lo <= hi {
            (lo / 2.0, hi * 2.0)
        } else {
            (1.0, 1e6)
        };
        let y_max = points
            .iter()
            .map(|p| p.p95.max(p.mean))
            .fold(0f64, f64::max)
            * 1.15;
        let mut chart = ChartBuilder::on(root)
            .caption("speed against error", ("sans-serif", 20))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(60)
            .build_cartesian_2d((lo.max(1e-3)..hi).log_scale(), 0f64..y_max.max(1.0))?;
        chart
            .configure_mesh()
            .x_desc("ns per predicted state (log)")
            .y_desc("error (levels): mean ●, 95th percentile ○")
            .draw()?;
        for (k, p) in points.iter().enumerate() {
            let color = PALETTE[k % PALETTE.len()];
            chart
                .draw_series([Circle::new((p.ns_per_state, p.mean), 6, color.filled())])?
                .label(p.label.as_str())
                .legend(move |(x, y)| Circle::new((x + 10, y), 5, color.filled()));
            chart.draw_series([Circle::new(
                (p.ns_per_state, p.p95),
                6,
                color.stroke_width(2),
            )])?;
        }
        chart
            .configure_series_labels()
            .position(SeriesLabelPosition::UpperRight)
            .background_style(WHITE.mix(0.8))
            .border_style(BLACK)
            .draw()?;
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
        let h = histogram("worst", &[5, 3, 2, 1, 0, 0, 0, 0, 0, 0, 4]);
        well_formed(&h);
        assert!(h.contains("10+"));
        let l = lines(
            "training",
            "epoch",
            "errors",
            &[("v".into(), vec![(1.0, 3.0), (2.0, 1.0)])],
        );
        well_formed(&l);
        let s = speed(&[SpeedPoint {
            label: "aln batched".into(),
            ns_per_state: 1500.0,
            mean: 1.2,
            p95: 4.0,
        }]);
        well_formed(&s);
        assert!(s.contains("aln batched"));
    }
}
