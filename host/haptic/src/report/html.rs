//! The report page: one self-contained HTML file (inline SVG drawn by `plotters`, inline CSS,
//! a few lines of script that check every plot drew something; nothing from the network), and
//! the headline figure as PNG for the guide (`docs/report-headline.png`).

use super::{Knob, Report, Verdict};
use anyhow::{Result, anyhow};
use plotters::coord::Shift;
use plotters::prelude::*;
use std::fmt::Write as _;

const SIZE: (u32, u32) = (760, 460);
const FONT: &str = "sans-serif";
const COLORS: [RGBColor; 6] = [
    RGBColor(200, 30, 30),
    RGBColor(30, 90, 200),
    RGBColor(30, 140, 60),
    RGBColor(150, 60, 170),
    RGBColor(220, 130, 0),
    RGBColor(90, 90, 90),
];

/// Escapes text for HTML.
fn esc(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// Axis value: log10 of `v` on a log axis.
fn axis(v: f64, log: bool) -> f64 {
    if log { v.max(1e-300).log10() } else { v }
}

fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    if !lo.is_finite() {
        return 0.0..1.0;
    }
    let pad = if hi > lo {
        0.08 * (hi - lo)
    } else {
        0.5 * lo.abs().max(1e-3)
    };
    (lo - pad)..(hi + pad)
}

type DrawResult<DB> = Result<(), DrawingAreaErrorKind<<DB as DrawingBackend>::ErrorType>>;

/// Draws one knob: a line with markers per series, the scene's choice ringed.
fn draw<DB: DrawingBackend>(root: &DrawingArea<DB, Shift>, knob: &Knob) -> DrawResult<DB> {
    root.fill(&WHITE)?;
    let points = || knob.series.iter().flat_map(|s| s.points.iter());
    let xr = range(points().map(|p| axis(p.x, knob.log_x)));
    let yr = range(points().map(|p| axis(p.y, knob.log_y)));
    let shown = |v: f64, log: bool| {
        if log {
            // Decades only: a log axis labelled 316.228 says less than 1e2 and 1e3.
            return if (v - v.round()).abs() < 0.02 {
                format!("1e{}", v.round())
            } else {
                String::new()
            };
        }
        if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e5) {
            format!("{v:.0e}")
        } else {
            format!("{v:.3}")
                .trim_end_matches('0')
                .trim_end_matches('.')
                .to_string()
        }
    };
    let mut chart = ChartBuilder::on(root)
        .caption(&knob.title, (FONT, 20))
        .margin(12)
        .x_label_area_size(44)
        .y_label_area_size(70)
        .build_cartesian_2d(xr, yr)?;
    chart
        .configure_mesh()
        .x_desc(&knob.x_label)
        .y_desc(&knob.y_label)
        .x_label_formatter(&|v| shown(*v, knob.log_x))
        .y_label_formatter(&|v| shown(*v, knob.log_y))
        .label_style((FONT, 13))
        .axis_desc_style((FONT, 14))
        .draw()?;
    for (i, s) in knob.series.iter().enumerate() {
        let color = COLORS[i % COLORS.len()];
        let xy: Vec<(f64, f64)> = s
            .points
            .iter()
            .map(|p| (axis(p.x, knob.log_x), axis(p.y, knob.log_y)))
            .collect();
        // A line where the series runs along the cost axis; markers alone where its points
        // share a cost (several values of a knob that does not change the cost).
        if xy.windows(2).all(|w| w[1].0 > w[0].0) {
            chart.draw_series(LineSeries::new(xy.iter().copied(), color.stroke_width(2)))?;
        }
        chart
            .draw_series(
                xy.iter()
                    .map(|&p| Circle::new(p, 4, ShapeStyle::from(&color).filled())),
            )?
            .label(&s.name)
            .legend(move |(x, y)| Circle::new((x + 10, y), 4, ShapeStyle::from(&color).filled()));
        // Each point's knob value beside it (a few per series, so they stay readable).
        if s.points.len() <= 12 {
            chart.draw_series(s.points.iter().zip(&xy).map(|(p, &at)| {
                EmptyElement::at(at) + Text::new(format!(" {}", p.label), (6, -6), (FONT, 11))
            }))?;
        }
    }
    if let Some(c) = &knob.chosen {
        let p = (axis(c.x, knob.log_x), axis(c.y, knob.log_y));
        chart.draw_series([Circle::new(p, 9, BLACK.stroke_width(2))])?;
        chart.draw_series([Text::new(
            format!("scene: {}", c.label),
            p,
            (FONT, 13).into_font(),
        )])?;
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font((FONT, 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()?;
    Ok(())
}

/// The knob as an SVG document.
pub fn svg(knob: &Knob) -> Result<String> {
    crate::calibrate::plot::register_font();
    let mut out = String::new();
    {
        let root = SVGBackend::with_string(&mut out, SIZE).into_drawing_area();
        draw(&root, knob).map_err(|e| anyhow!("plot {}: {e}", knob.id))?;
        root.present()
            .map_err(|e| anyhow!("plot {}: {e}", knob.id))?;
    }
    Ok(out)
}

/// The knob as PNG bytes (the guide's headline figure).
pub fn png(knob: &Knob) -> Result<Vec<u8>> {
    crate::calibrate::plot::register_font();
    let (w, h) = SIZE;
    let mut rgb = vec![0u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut rgb, SIZE).into_drawing_area();
        draw(&root, knob).map_err(|e| anyhow!("plot {}: {e}", knob.id))?;
        root.present()
            .map_err(|e| anyhow!("plot {}: {e}", knob.id))?;
    }
    let mut out = Vec::new();
    {
        let mut enc = png::Encoder::new(&mut out, w, h);
        enc.set_color(png::ColorType::Rgb);
        enc.set_depth(png::BitDepth::Eight);
        let mut writer = enc.write_header()?;
        writer.write_image_data(&rgb)?;
    }
    Ok(out)
}

/// The whole page.
pub fn page(report: &Report) -> Result<String> {
    let mut h = String::new();
    let _ = write!(
        h,
        "<!doctype html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">\
         <title>host report: {scene}</title>\n<style>\
         body{{font-family:sans-serif;max-width:64rem;margin:2rem auto;padding:0 1rem;color:#222}}\
         section{{margin:2rem 0}} .plot svg{{max-width:100%;height:auto;border:1px solid #ddd}}\
         table{{border-collapse:collapse;width:100%;font-size:.9rem}}\
         td,th{{border:1px solid #ccc;padding:.3rem .5rem;text-align:left;vertical-align:top}}\
         tr.weakness{{background:#fde2e2}} tr.refused{{background:#eef}} \
         tr.matches_reference,tr.bounded{{background:#e8f6e8}}\
         </style></head>\n<body>\n<h1>What each knob costs, and what it buys</h1>\n\
         <p>Scene <code>{scene}</code>; {mode}. Every number below was measured by \
         <code>host report</code> in this run; all of them are in <code>report.json</code>.</p>\n",
        scene = esc(&report.scene),
        mode = if report.quick {
            "quick sweeps (<code>--quick</code>)"
        } else {
            "full sweeps"
        }
    );
    for knob in &report.knobs {
        let _ = writeln!(
            h,
            "<section id=\"{id}\"><h2>{title}</h2><p>{finding}</p>\
             <div class=\"plot\" data-knob=\"{id}\">{svg}</div></section>",
            id = esc(&knob.id),
            title = esc(&knob.title),
            finding = esc(&knob.finding),
            svg = svg(knob)?
        );
    }
    h.push_str("<section id=\"hard-cases\"><h2>Hard cases</h2>\n");
    let weak: Vec<String> = report
        .hard_cases
        .iter()
        .filter(|c| c.verdict == Verdict::Weakness)
        .map(|c| esc(&c.case))
        .collect();
    if !weak.is_empty() {
        let _ = writeln!(
            h,
            "<p class=\"weaknesses\"><strong>Weaknesses ({}):</strong> {}. These rows are \
             shaded red below: the method, not the measurement, falls short there.</p>",
            weak.len(),
            weak.join("; ")
        );
    }
    h.push_str(
        "<table><thead><tr><th>case</th>\
         <th>measurement</th><th>reference</th><th>verdict</th></tr></thead><tbody>\n",
    );
    for c in &report.hard_cases {
        let class = match c.verdict {
            Verdict::MatchesReference => "matches_reference",
            Verdict::Bounded => "bounded",
            Verdict::Refused => "refused",
            Verdict::Weakness => "weakness",
        };
        let _ = writeln!(
            h,
            "<tr class=\"{class}\"><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            esc(&c.case),
            esc(&c.measurement),
            esc(&c.reference),
            c.verdict.text()
        );
    }
    h.push_str("</tbody></table></section>\n");
    if !report.not_measured.is_empty() {
        h.push_str("<section id=\"not-measured\"><h2>Not measured by this report yet</h2><ul>\n");
        for n in &report.not_measured {
            let _ = writeln!(h, "<li>{}</li>", esc(n));
        }
        h.push_str("</ul></section>\n");
    }
    // The page checks its own plots: each must hold drawn marks; the count lands on <body>
    // for tests (headless --dump-dom), and an empty plot is a console error.
    h.push_str(
        "<script>\nconst plots = document.querySelectorAll('.plot');\nlet drawn = 0;\n\
         for (const p of plots) {\n  const marks = p.querySelectorAll('svg circle, svg polyline, svg path').length;\n  \
         if (marks > 0) { drawn++; } else { console.error('empty plot: ' + p.dataset.knob); }\n}\n\
         document.body.dataset.plots = plots.length;\ndocument.body.dataset.drawn = drawn;\n</script>\n\
         </body></html>\n",
    );
    Ok(h)
}
