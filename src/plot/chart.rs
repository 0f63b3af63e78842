//! The log–log charts of a study (`study`'s error against h, k and wall time, and the
//! cost of a kernel's tolerance): data curves with their points marked and labelled,
//! reference slopes dashed.

use super::{draw_err, register_fonts, trim_float, FONT, PALETTE};
use crate::Result;
use plotters::element::DashedPathElement;
use plotters::prelude::*;
use std::path::Path;

/// One curve of a chart: data (coloured, with markers) or a reference line (grey, dashed).
#[derive(Clone, Debug)]
pub struct Curve {
    pub label: String,
    pub points: Vec<(f64, f64)>,
    /// A short label beside each point (empty: none).
    pub point_labels: Vec<String>,
    pub reference: bool,
    pub color: usize,
}

impl Curve {
    pub fn data(color: usize, label: String, points: Vec<(f64, f64)>) -> Self {
        Curve {
            label,
            points,
            point_labels: Vec::new(),
            reference: false,
            color,
        }
    }

    pub fn reference(label: String, points: Vec<(f64, f64)>) -> Self {
        Curve {
            label,
            points,
            point_labels: Vec::new(),
            reference: true,
            color: 0,
        }
    }

    /// With a short label beside each point.
    pub fn with_point_labels(mut self, labels: Vec<String>) -> Self {
        self.point_labels = labels;
        self
    }
}

/// `lo..hi` widened by a factor on each side (log axes).
fn log_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| *v > 0.0 && v.is_finite())
        .fold((f64::INFINITY, 0.0f64), |(a, b), v| (a.min(v), b.max(v)));
    if !lo.is_finite() {
        return (0.1, 10.0);
    }
    let pad = (hi / lo).powf(0.08).max(1.25);
    (lo / pad, hi * pad)
}

/// An axis label: plain for 0.01 ≤ |v| < 10⁴ (`0.05`, `200`), else `2e-3`.
fn sci(v: f64) -> String {
    if v == 0.0 {
        return "0".into();
    }
    if (1e-2..1e4).contains(&v.abs()) {
        return trim_float(format!("{:.3}", v).parse::<f64>().unwrap_or(v));
    }
    let e = v.abs().log10().floor();
    let m = v / 10f64.powf(e);
    if (m - m.round()).abs() < 0.05 {
        format!("{:.0}e{}", m.round(), e)
    } else {
        format!("{m:.1}e{e}")
    }
}

/// A log-log chart of `curves` as a PNG at `path` (1000 × 700).
pub fn log_log_chart(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    curves: &[Curve],
) -> Result<()> {
    register_fonts();
    let err = draw_err(path);
    let root = BitMapBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(&err)?;
    let (x0, x1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
    let (y0, y1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1)));
    let mut chart = ChartBuilder::on(&root)
        .caption(title, (FONT, 26))
        .margin(20)
        .x_label_area_size(50)
        .y_label_area_size(80)
        .build_cartesian_2d((x0..x1).log_scale(), (y0..y1).log_scale())
        .map_err(&err)?;
    chart
        .configure_mesh()
        .x_desc(x_desc)
        .y_desc(y_desc)
        .x_labels(8)
        .y_labels(12)
        .x_label_formatter(&|v| sci(*v))
        .y_label_formatter(&|v| sci(*v))
        .label_style((FONT, 16))
        .axis_desc_style((FONT, 18))
        .light_line_style(RGBColor(235, 235, 235))
        .bold_line_style(RGBColor(205, 205, 205))
        .draw()
        .map_err(&err)?;
    for c in curves {
        draw_curve(&mut chart, c, path)?;
    }
    chart
        .configure_series_labels()
        .position(legend_position(curves))
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.9))
        .border_style(RGBColor(160, 160, 160))
        .draw()
        .map_err(&err)?;
    root.present().map_err(&err)?;
    Ok(())
}

/// Where a chart's legend goes: where the data are not. Rising data leave the upper left
/// corner free, falling data the lower left one.
fn legend_position(curves: &[Curve]) -> SeriesLabelPosition {
    let mut rising = 0i32;
    for c in curves.iter().filter(|c| !c.reference) {
        if let (Some(a), Some(b)) = (c.points.first(), c.points.last()) {
            rising += if (b.1 - a.1) * (b.0 - a.0) > 0.0 {
                1
            } else {
                -1
            };
        }
    }
    if rising > 0 {
        SeriesLabelPosition::UpperLeft
    } else {
        SeriesLabelPosition::LowerLeft
    }
}

/// One curve of a log–log chart: a reference line dashed and grey, a measured one in its
/// colour with its points marked and labelled.
fn draw_curve<'a>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<LogCoord<f64>, LogCoord<f64>>>,
    c: &Curve,
    path: &Path,
) -> Result<()> {
    let err = draw_err(path);
    if c.reference {
        // Successive reference lines: grey, long dashes; lighter, short dashes.
        let (grey, dash) = if c.color.is_multiple_of(2) {
            (110, 8)
        } else {
            (165, 3)
        };
        let style = RGBColor(grey, grey, grey).stroke_width(2);
        chart
            .draw_series(DashedLineSeries::new(c.points.clone(), dash, 5, style))
            .map_err(&err)?
            .label(c.label.clone())
            .legend(move |(x, y)| {
                DashedPathElement::new(vec![(x, y), (x + 24, y)], dash, 4, style)
            });
    } else {
        let color = PALETTE[c.color % PALETTE.len()];
        chart
            .draw_series(LineSeries::new(c.points.clone(), color.stroke_width(2)))
            .map_err(&err)?
            .label(c.label.clone())
            .legend(move |(x, y)| {
                EmptyElement::at((x, y))
                    + PathElement::new(vec![(0, 0), (24, 0)], color.stroke_width(2))
                    + Circle::new((12, 0), 4, color.filled())
            });
        chart
            .draw_series(c.points.iter().map(|&p| Circle::new(p, 5, color.filled())))
            .map_err(&err)?;
        let style = TextStyle::from((FONT, 13).into_font()).color(&color);
        chart
            .draw_series(
                c.points.iter().zip(&c.point_labels).map(|(&p, l)| {
                    EmptyElement::at(p) + Text::new(l.clone(), (7, -16), style.clone())
                }),
            )
            .map_err(&err)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn axis_labels() {
        assert_eq!(sci(1e-3), "1e-3");
        assert_eq!(sci(200.0), "200");
        assert_eq!(sci(0.05), "0.05");
    }
}
