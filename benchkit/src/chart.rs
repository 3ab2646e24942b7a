//! Line charts with points, written as SVG: the step-time-against-error and
//! bytes-against-error charts of the benches.

use std::ops::Range;
use std::path::Path;

use plotters::coord::ranged1d::{AsRangedCoord, ValueFormatter};
use plotters::coord::Shift;
use plotters::prelude::*;

/// What drawing a chart can fail with (the SVG file cannot be written).
pub type ChartError = DrawingAreaErrorKind<std::io::Error>;

/// Sizes and weights of a chart's marks.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChartStyle {
    /// Width of the y axis's label area (pixels).
    pub y_label_area_px: u32,
    /// Width of a series' line (pixels).
    pub line_width_px: u32,
    /// Radius of a point (pixels).
    pub point_radius_px: i32,
    /// Length of a legend entry's line (pixels).
    pub legend_line_px: i32,
    /// Opacity of the legend's white background.
    pub legend_opacity: f64,
    /// Font size of notes at points (pixels).
    pub note_font_px: u32,
}

impl ChartStyle {
    /// Thin lines and a see-through legend, for charts set side by side (the network
    /// benches).
    pub const PANEL: ChartStyle = ChartStyle {
        y_label_area_px: 50,
        line_width_px: 1,
        point_radius_px: 3,
        legend_line_px: 16,
        legend_opacity: 0.8,
        note_font_px: 11,
    };

    /// Bold lines and larger points, for a chart on its own (the soft-body benches).
    pub const FIGURE: ChartStyle = ChartStyle {
        y_label_area_px: 56,
        line_width_px: 2,
        point_radius_px: 4,
        legend_line_px: 18,
        legend_opacity: 1.0,
        note_font_px: 13,
    };
}

/// One line through points, with a legend entry and optional notes written at points.
#[derive(Clone, Debug)]
pub struct Series {
    /// Legend text.
    pub label: String,
    /// Line, point and legend colour.
    pub color: RGBColor,
    /// The points, joined in this order.
    pub points: Vec<(f64, f64)>,
    /// Texts drawn at positions, after the series' points.
    pub notes: Vec<(String, (f64, f64))>,
}

impl Series {
    /// A series without notes.
    pub fn new(label: impl Into<String>, color: RGBColor, points: Vec<(f64, f64)>) -> Series {
        Series {
            label: label.into(),
            color,
            points,
            notes: Vec::new(),
        }
    }
}

/// A titled chart of series over given axis ranges.
#[derive(Clone, Debug)]
pub struct LineChart {
    /// Caption above the chart.
    pub title: String,
    /// What the x axis measures.
    pub x_desc: String,
    /// What the y axis measures.
    pub y_desc: String,
    /// The x axis's range.
    pub x_range: Range<f64>,
    /// A logarithmic x axis.
    pub x_log: bool,
    /// The y axis's range.
    pub y_range: Range<f64>,
    /// The lines, drawn in order.
    pub series: Vec<Series>,
    /// Mark sizes.
    pub style: ChartStyle,
}

impl LineChart {
    /// Draws the chart on `area`.
    pub fn draw(&self, area: &DrawingArea<SVGBackend<'_>, Shift>) -> Result<(), ChartError> {
        if self.x_log {
            self.draw_over(area, self.x_range.clone().log_scale())
        } else {
            self.draw_over(area, self.x_range.clone())
        }
    }

    fn draw_over<X>(
        &self,
        area: &DrawingArea<SVGBackend<'_>, Shift>,
        x: X,
    ) -> Result<(), ChartError>
    where
        X: AsRangedCoord<Value = f64>,
        X::CoordDescType: ValueFormatter<f64>,
    {
        let style = self.style;
        let mut c = ChartBuilder::on(area)
            .caption(&self.title, ("sans-serif", 18))
            .margin(12)
            .x_label_area_size(40)
            .y_label_area_size(style.y_label_area_px)
            .build_cartesian_2d(x, self.y_range.clone())?;
        c.configure_mesh()
            .x_desc(&self.x_desc)
            .y_desc(&self.y_desc)
            .draw()?;
        for s in &self.series {
            let color = s.color;
            let legend_px = style.legend_line_px;
            c.draw_series(LineSeries::new(
                s.points.iter().copied(),
                color.stroke_width(style.line_width_px),
            ))?
            .label(s.label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + legend_px, y)], color));
            c.draw_series(
                s.points
                    .iter()
                    .map(|p| Circle::new(*p, style.point_radius_px, color.filled())),
            )?;
            for (text, at) in &s.notes {
                c.draw_series(std::iter::once(Text::new(
                    text.clone(),
                    *at,
                    ("sans-serif", style.note_font_px),
                )))?;
            }
        }
        c.configure_series_labels()
            .border_style(BLACK)
            .background_style(WHITE.mix(style.legend_opacity))
            .draw()?;
        Ok(())
    }
}

/// Writes `charts` side by side, in equal widths, to one SVG file of `size_px` (width,
/// height) on a white background.
pub fn write_svg(
    path: impl AsRef<Path>,
    size_px: (u32, u32),
    charts: &[LineChart],
) -> Result<(), ChartError> {
    let root = SVGBackend::new(path.as_ref(), size_px).into_drawing_area();
    root.fill(&WHITE)?;
    for (area, chart) in root
        .split_evenly((1, charts.len().max(1)))
        .iter()
        .zip(charts)
    {
        chart.draw(area)?;
    }
    root.present()?;
    Ok(())
}
