//! The log–log charts of a study (`study`'s error against h, k and wall time, and the
//! cost of a kernel's tolerance): data curves with their points marked and labelled,
//! reference slopes dashed; and the linear chart of a run's force history
//! (`plot --history`, `history_chart.rs`).

use super::{draw_err, register_fonts, trim_float, FONT, PALETTE};
use crate::Result;
use plotters::coord::combinators::WithKeyPoints;
use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
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

/// The ticks of a log axis over `lo..hi`: the powers of ten when there are three or more,
/// else 1, 2, 5 × 10^k, else 1, 2, …, 9 × 10^k, else three values between, rounded to two
/// digits: a study of two levels spans less than a decade, where plotters' own ticks (the
/// powers of ten) left the y axis without a label and the x axis with one (issue 49).
fn log_ticks(lo: f64, hi: f64) -> Vec<f64> {
    let decades = lo.log10().floor() as i32..=hi.log10().ceil() as i32;
    let mantissas: [&[f64]; 3] = [
        &[1.0],
        &[1.0, 2.0, 5.0],
        &[1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0, 8.0, 9.0],
    ];
    for m in mantissas {
        let ticks: Vec<f64> = decades
            .clone()
            .flat_map(|e| m.iter().map(move |m| m * 10f64.powi(e)))
            .filter(|v| (lo..=hi).contains(v))
            .collect();
        if ticks.len() >= 3 {
            return ticks;
        }
    }
    (1..=3)
        .map(|i| {
            let v = lo * (hi / lo).powf(f64::from(i) / 4.0);
            format!("{v:.1e}").parse().unwrap_or(v)
        })
        .collect()
}

/// `lo..hi` of a log axis grown at its top (`top`) or bottom by the room of a legend of
/// `rows` entries, so that the legend sits beside the data and hides no point.
fn with_legend_room((lo, hi): (f64, f64), rows: usize, top: bool) -> (f64, f64) {
    // The legend's share of the plot's height (about 560 pixels): 22 pixels a row.
    let share = ((22 * rows + 20) as f64 / 560.0).min(0.6);
    let grow = (hi / lo).powf(share / (1.0 - share));
    if top {
        (lo, hi * grow)
    } else {
        (lo / grow, hi)
    }
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
    let position = legend_position(curves);
    let (x0, x1) = log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.0)));
    let (y0, y1) = with_legend_room(
        log_range(curves.iter().flat_map(|c| c.points.iter().map(|p| p.1))),
        curves.len(),
        matches!(position, SeriesLabelPosition::UpperLeft),
    );
    let axes = (
        (x0..x1).log_scale().with_key_points(log_ticks(x0, x1)),
        (y0..y1).log_scale().with_key_points(log_ticks(y0, y1)),
    );
    let frame = Frame {
        path,
        title,
        desc: [x_desc, y_desc],
        position,
    };
    frame.draw(axes, |chart| {
        curves.iter().try_for_each(|c| draw_curve(chart, c, path))
    })
}

/// A chart of `curves` on linear axes as a PNG at `path` (1000 × 700): lines without point
/// markers, for series of many points (`plot --history`).
pub fn line_chart(
    path: &Path,
    title: &str,
    x_desc: &str,
    y_desc: &str,
    curves: &[Curve],
) -> Result<()> {
    let points = || curves.iter().flat_map(|c| c.points.iter());
    let (x0, x1) = linear_range(points().map(|p| p.0));
    let (y0, y1) = linear_range(points().map(|p| p.1));
    let frame = Frame {
        path,
        title,
        desc: [x_desc, y_desc],
        position: SeriesLabelPosition::UpperLeft,
    };
    frame.draw((x0..x1, y0..y1), |chart| {
        for c in curves {
            let color = PALETTE[c.color % PALETTE.len()];
            let style = color.stroke_width(2);
            chart
                .draw_series(LineSeries::new(c.points.clone(), style))
                .map_err(draw_err(path))?
                .label(c.label.clone())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
        }
        Ok(())
    })
}

/// What a chart's PNG has around its curves: title, axes' descriptions, the legend's place.
struct Frame<'a> {
    path: &'a Path,
    title: &'a str,
    desc: [&'a str; 2],
    position: SeriesLabelPosition,
}

impl Frame<'_> {
    /// The chart on the axes `(x, y)`: grid and labels, the curves drawn by `curves`, then
    /// the legend, written to the PNG.
    fn draw<X, Y>(
        self,
        (x, y): (X, Y),
        curves: impl for<'c> FnOnce(
            &mut ChartContext<
                'c,
                BitMapBackend<'c>,
                Cartesian2d<X::CoordDescType, Y::CoordDescType>,
            >,
        ) -> Result<()>,
    ) -> Result<()>
    where
        X: AsRangedCoord<Value = f64>,
        Y: AsRangedCoord<Value = f64>,
        X::CoordDescType: ValueFormatter<f64>,
        Y::CoordDescType: ValueFormatter<f64>,
    {
        register_fonts();
        let err = draw_err(self.path);
        let root = BitMapBackend::new(self.path, (1000, 700)).into_drawing_area();
        root.fill(&WHITE).map_err(&err)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(self.title, (FONT, 26))
            .margin(20)
            .x_label_area_size(50)
            .y_label_area_size(80)
            .build_cartesian_2d(x, y)
            .map_err(&err)?;
        chart
            .configure_mesh()
            .x_desc(self.desc[0])
            .y_desc(self.desc[1])
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
        curves(&mut chart)?;
        chart
            .configure_series_labels()
            .position(self.position)
            .label_font((FONT, 16))
            .background_style(WHITE.mix(0.9))
            .border_style(RGBColor(160, 160, 160))
            .draw()
            .map_err(&err)?;
        root.present().map_err(&err)?;
        Ok(())
    }
}

/// `lo..hi` of the finite values, widened by 5 % on each side (±1 around a single value).
fn linear_range(values: impl Iterator<Item = f64>) -> (f64, f64) {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(v), b.max(v))
        });
    if !lo.is_finite() {
        return (-1.0, 1.0);
    }
    let pad = match hi > lo {
        true => 0.05 * (hi - lo),
        false => lo.abs().max(1.0),
    };
    (lo - pad, hi + pad)
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

/// A log axis with the ticks of [`log_ticks`].
type LogAxis = WithKeyPoints<LogCoord<f64>>;

/// One curve of a log–log chart: a reference line dashed and grey, a measured one in its
/// colour with its points marked and labelled.
fn draw_curve<'a>(
    chart: &mut ChartContext<'a, BitMapBackend<'a>, Cartesian2d<LogAxis, LogAxis>>,
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
        // A straight line on log-log axes: its ends alone, so that the dashes run evenly
        // (one dashed piece per level restarted the pattern at every point: jagged).
        let ends = [c.points.first(), c.points.last()];
        let ends: Vec<(f64, f64)> = ends.into_iter().flatten().copied().collect();
        chart
            .draw_series(DashedLineSeries::new(ends, dash, 5, style))
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

    /// Issue 49: a two-level study's axes, within a decade, get three ticks or more.
    #[test]
    fn a_log_axis_within_a_decade_has_ticks() {
        assert_eq!(log_ticks(1e-4, 1.0), vec![1e-4, 1e-3, 1e-2, 0.1, 1.0]);
        assert_eq!(
            log_ticks(0.05, 0.15),
            vec![0.05, 0.06, 0.07, 0.08, 0.09, 0.1]
        );
        assert_eq!(log_ticks(0.04, 0.3), vec![0.05, 0.1, 0.2]);
        let close = log_ticks(0.21, 0.25);
        assert_eq!(close.len(), 3);
        assert!(close.iter().all(|t| (0.21..=0.25).contains(t)), "{close:?}");
    }

    /// The legend's room above the data: the data keep their place below it.
    #[test]
    fn the_legend_gets_room_beside_the_data() {
        let (lo, hi) = with_legend_room((1e-3, 1e-1), 4, true);
        assert_eq!(lo, 1e-3);
        // 108 of 560 pixels: the data's two decades take the other 452.
        let data_share = 2.0 / (hi / lo).log10();
        assert!((data_share - 452.0 / 560.0).abs() < 1e-9, "{data_share}");
    }

    #[test]
    fn axis_labels() {
        assert_eq!(sci(1e-3), "1e-3");
        assert_eq!(sci(200.0), "200");
        assert_eq!(sci(0.05), "0.05");
    }
}
