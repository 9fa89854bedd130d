//! `--plot FILE.svg`: arrows of the predicted and the measured displacement of the markers on
//! a slice through the compression axis, one panel per level.
//!
//! The slice is the plane through the axis spanned by it and the first lateral axis (for a
//! compression along z, the x-z plane; along x, y-x; along y, z-y), placed at the middle of the
//! markers' spread along the second lateral axis; the markers drawn are those within
//! [`SLICE_BAND`] of that spread from it (at least the nearest layer). Each marker's rest
//! position is a dot; its predicted displacement an arrow in blue, its measured one in red,
//! both at true scale in the markers' units.

use super::Axis;
use super::Level;
use super::measured::Measured;
use std::fmt::Write;

/// Half-width of the slice, as a fraction of the markers' spread normal to it.
pub const SLICE_BAND: f64 = 0.1;

/// Side of a panel, px.
const PANEL: f64 = 320.0;
/// Margin around a panel, px.
const MARGIN: f64 = 40.0;

/// The indices of the markers on the slice (module notes) through `axis`.
pub fn slice(points: &[[f64; 3]], axis: Axis) -> Vec<usize> {
    let normal = (axis.index() + 2) % 3;
    let (lo, hi) = points
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p[normal]), hi.max(p[normal]))
        });
    let mid = 0.5 * (lo + hi);
    let nearest = points
        .iter()
        .map(|p| (p[normal] - mid).abs())
        .fold(f64::INFINITY, f64::min);
    let band = (SLICE_BAND * (hi - lo)).max(nearest + 1e-9 * (hi - lo));
    (0..points.len())
        .filter(|&i| (points[i][normal] - mid).abs() <= band)
        .collect()
}

/// The SVG of the slice for the rest positions `points`, the predicted `levels` and the
/// `measured` positions, in `units`.
pub fn svg(
    points: &[[f64; 3]],
    levels: &[Level],
    measured: &Measured,
    axis: Axis,
    units: &str,
) -> String {
    let a = axis.index();
    let h = (a + 1) % 3;
    let on = slice(points, axis);
    // The drawing's extent: every rest, predicted and measured position on the slice.
    let all = on.iter().flat_map(|&i| {
        std::iter::once(points[i])
            .chain(levels.iter().map(move |l| l.markers[i]))
            .chain(measured.positions.iter().map(move |m| m[i]))
    });
    let (lo, hi) = all.fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[h]), lo[1].min(p[a])],
                [hi[0].max(p[h]), hi[1].max(p[a])],
            )
        },
    );
    let span = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(f64::MIN_POSITIVE);
    let k = PANEL / span;
    let names = ["x", "y", "z"];
    let width = levels.len() as f64 * (PANEL + 2.0 * MARGIN);
    let height = PANEL + 2.0 * MARGIN + 30.0;
    let mut s = String::new();
    let _ = writeln!(
        s,
        r##"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" font-family="sans-serif" font-size="12">"##
    );
    s.push_str(
        r##"<defs><marker id="p" viewBox="0 0 6 6" refX="6" refY="3" markerWidth="6" markerHeight="6" orient="auto"><path d="M0,0 L6,3 L0,6 z" fill="#1f5fbf"/></marker><marker id="m" viewBox="0 0 6 6" refX="6" refY="3" markerWidth="6" markerHeight="6" orient="auto"><path d="M0,0 L6,3 L0,6 z" fill="#c8302c"/></marker></defs>
"##,
    );
    let _ = writeln!(
        s,
        r##"<text x="10" y="{:.0}">slice {}-{} through the axis ({} markers); blue: predicted, red: measured displacement, true scale, {units}</text>"##,
        height - 8.0,
        names[h],
        names[a],
        on.len()
    );
    for (n, (level, m)) in levels.iter().zip(&measured.positions).enumerate() {
        let x0 = n as f64 * (PANEL + 2.0 * MARGIN) + MARGIN;
        let to = |p: [f64; 3]| (x0 + k * (p[h] - lo[0]), MARGIN + PANEL - k * (p[a] - lo[1]));
        let _ = writeln!(
            s,
            r##"<text x="{x0:.1}" y="{:.1}">strain {:.1} %</text><rect x="{x0:.1}" y="{MARGIN:.1}" width="{PANEL:.1}" height="{PANEL:.1}" fill="none" stroke="#bbb"/>"##,
            MARGIN - 12.0,
            100.0 * level.strain
        );
        for &i in &on {
            let (x, y) = to(points[i]);
            let _ = writeln!(s, r##"<circle cx="{x:.2}" cy="{y:.2}" r="1.5"/>"##);
            for (end, colour, head) in [(level.markers[i], "#1f5fbf", "p"), (m[i], "#c8302c", "m")]
            {
                let (u, v) = to(end);
                let _ = writeln!(
                    s,
                    r##"<line x1="{x:.2}" y1="{y:.2}" x2="{u:.2}" y2="{v:.2}" stroke="{colour}" stroke-width="1.2" marker-end="url(#{head})"/>"##
                );
            }
        }
        let _ = writeln!(
            s,
            r##"<text x="{:.1}" y="{:.1}" text-anchor="end">{} ({units}) right, {} up</text>"##,
            x0 + PANEL,
            MARGIN + PANEL + 16.0,
            names[h],
            names[a]
        );
    }
    s.push_str("</svg>\n");
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 3 x 3 x 3 grid compressed along z: the slice is the x-z plane at the middle y (the
    /// nine markers with y = 1); along x it is the y-x plane at the middle z.
    #[test]
    fn the_slice_is_the_middle_layer_through_the_axis() {
        let mut points = Vec::new();
        for i in 0..3 {
            for j in 0..3 {
                for k in 0..3 {
                    points.push([i as f64, j as f64, k as f64]);
                }
            }
        }
        let on = slice(&points, Axis::Z);
        assert_eq!(on.len(), 9);
        assert!(on.iter().all(|&i| points[i][1] == 1.0));
        let on = slice(&points, Axis::X);
        assert_eq!(on.len(), 9);
        assert!(on.iter().all(|&i| points[i][2] == 1.0));
    }
}
