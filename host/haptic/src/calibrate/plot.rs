//! Calibration plots: data and fitted curve on top, residuals below; written as SVG and PNG
//! (`plotters`, text in the embedded DejaVu Sans so the PNG needs no system fonts).

use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::path::{Path, PathBuf};

/// A curve: legend label and points.
pub type Series = (String, Vec<(f64, f64)>);

/// What one plot shows.
#[derive(Debug, Clone)]
pub struct PlotSpec {
    /// Title.
    pub title: String,
    /// x-axis label (shared by both panels).
    pub x_label: String,
    /// y-axis label of the top panel.
    pub y_label: String,
    /// Measured points (markers).
    pub data: Series,
    /// Lines: the fit first, then references (e.g. the linear model).
    pub curves: Vec<Series>,
    /// y-axis label of the residual panel.
    pub residual_label: String,
    /// Residual points.
    pub residuals: Vec<(f64, f64)>,
}

const FONT: &str = "sans-serif";
const COLORS: [RGBColor; 4] = [
    RGBColor(200, 30, 30),
    RGBColor(90, 90, 90),
    RGBColor(30, 120, 30),
    RGBColor(140, 60, 160),
];

/// Registers the embedded DejaVu Sans as plotters' `sans-serif` (once).
pub(crate) fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The embedded font is a valid TrueType file; a failure would only lose the text.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// Writes `<stem>.svg` and `<stem>.png` (1000 x 750 px); returns both paths.
pub fn write(stem: &Path, spec: &PlotSpec) -> Result<[PathBuf; 2]> {
    register_font();
    let svg = stem.with_extension("svg");
    let png = stem.with_extension("png");
    let size = (1000, 750);
    {
        let root = SVGBackend::new(&svg, size).into_drawing_area();
        draw(&root, spec).map_err(|e| anyhow!("{}: {e}", svg.display()))?;
        root.present()
            .map_err(|e| anyhow!("{}: {e}", svg.display()))?;
    }
    {
        let root = BitMapBackend::new(&png, size).into_drawing_area();
        draw(&root, spec).map_err(|e| anyhow!("{}: {e}", png.display()))?;
        root.present()
            .map_err(|e| anyhow!("{}: {e}", png.display()))?;
    }
    Ok([svg, png])
}

fn bounds(points: impl Iterator<Item = (f64, f64)>) -> ([f64; 2], [f64; 2]) {
    let mut x = [f64::INFINITY, f64::NEG_INFINITY];
    let mut y = x;
    for (a, b) in points {
        x = [x[0].min(a), x[1].max(a)];
        y = [y[0].min(b), y[1].max(b)];
    }
    let pad = |r: [f64; 2]| {
        let (lo, hi) = if r[0].is_finite() {
            (r[0], r[1])
        } else {
            (0.0, 1.0)
        };
        let d = if hi > lo {
            0.05 * (hi - lo)
        } else {
            0.5 * lo.abs().max(1e-12)
        };
        [lo - d, hi + d]
    };
    (pad(x), pad(y))
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, spec: &PlotSpec) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let root = root.titled(&spec.title, (FONT, 24))?;
    let (top, bottom) = root.split_vertically(root.dim_in_pixel().1 * 68 / 100);
    let all = spec
        .data
        .1
        .iter()
        .chain(spec.curves.iter().flat_map(|c| c.1.iter()))
        .copied();
    let (xr, yr) = bounds(all);
    let mut chart = ChartBuilder::on(&top)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(xr[0]..xr[1], yr[0]..yr[1])?;
    chart
        .configure_mesh()
        .x_desc(&spec.x_label)
        .y_desc(&spec.y_label)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .draw()?;
    chart
        .draw_series(
            spec.data
                .1
                .iter()
                .map(|&p| Circle::new(p, 3, ShapeStyle::from(&BLUE).filled())),
        )?
        .label(&spec.data.0)
        .legend(|(x, y)| Circle::new((x + 10, y), 4, ShapeStyle::from(&BLUE).filled()));
    for (i, (label, points)) in spec.curves.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        chart
            .draw_series(LineSeries::new(
                points.iter().copied(),
                color.stroke_width(2),
            ))?
            .label(label)
            .legend(move |(x, y)| {
                PathElement::new(vec![(x, y), (x + 20, y)], color.stroke_width(2))
            });
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperLeft)
        .label_font((FONT, 16))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;

    let (_, rr) = bounds(spec.residuals.iter().copied());
    let span = rr[0].abs().max(rr[1].abs());
    let mut res = ChartBuilder::on(&bottom)
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(xr[0]..xr[1], -span..span)?;
    res.configure_mesh()
        .x_desc(&spec.x_label)
        .y_desc(&spec.residual_label)
        .label_style((FONT, 15))
        .axis_desc_style((FONT, 17))
        .draw()?;
    res.draw_series(LineSeries::new(
        [(xr[0], 0.0), (xr[1], 0.0)],
        BLACK.stroke_width(1),
    ))?;
    res.draw_series(
        spec.residuals
            .iter()
            .map(|&p| Circle::new(p, 3, ShapeStyle::from(&BLUE).filled())),
    )?;
    Ok(())
}
