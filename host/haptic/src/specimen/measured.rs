//! Measured marker positions (`--measured`) and the prediction's error against them.
//!
//! **Layout**: one CSV file with a header row naming the columns `x`, `y` and `z` (in the
//! markers' units; other columns ignored, `#` lines are comments), one row per marker and
//! level, level by level in the order of the strains, within a level the markers in the order
//! of the markers file: row `l * markers + i` is marker `i` at strain `l`. The row count must be
//! markers x levels.
//!
//! **Error**: a marker's error is the distance between its predicted and measured positions;
//! per level the RMS over the markers (`sqrt(mean |p - m|^2)`) and the largest, with the
//! marker it is at.

use super::Level;
use crate::calibrate::csv;
use anyhow::{Result, bail};
use serde::Serialize;
use std::path::Path;

/// Measured positions, per level.
#[derive(Debug, Clone, PartialEq)]
pub struct Measured {
    /// The file, as named in errors and in the output.
    pub file: String,
    /// `positions[level][marker]`, in the markers' units.
    pub positions: Vec<Vec<[f64; 3]>>,
    /// The 1-based line of each position in the file, same indexing.
    pub lines: Vec<Vec<u64>>,
}

/// Parses measured positions (the module's layout) for `markers` markers at `levels` levels;
/// `file` names the text in errors. A bad number names its line and column; a wrong row count
/// says how many rows the layout needs.
pub fn parse(file: &str, text: &str, markers: usize, levels: usize) -> Result<Measured> {
    let table = csv::parse(file, text, &["x", "y", "z"])?;
    let need = markers * levels;
    if table.len() != need {
        bail!(
            "{file}: {} data rows, need {markers} markers x {levels} levels = {need}: one row \
             per marker and level, level by level in the --strain order, the markers in the \
             markers file's order",
            table.len()
        );
    }
    let cols = [table.numbers(0)?, table.numbers(1)?, table.numbers(2)?];
    let chunk = |l: usize| l * markers..(l + 1) * markers;
    Ok(Measured {
        file: file.to_string(),
        positions: (0..levels)
            .map(|l| {
                chunk(l)
                    .map(|i| [cols[0][i], cols[1][i], cols[2][i]])
                    .collect()
            })
            .collect(),
        lines: (0..levels)
            .map(|l| table.lines[chunk(l)].to_vec())
            .collect(),
    })
}

/// Reads measured positions from `path` ([`parse`]).
pub fn read(path: &Path, markers: usize, levels: usize) -> Result<Measured> {
    let text = std::fs::read_to_string(path)
        .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", path.display()))?;
    parse(&path.display().to_string(), &text, markers, levels)
}

/// One level's errors.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LevelError {
    /// Nominal strain.
    pub strain: f64,
    /// RMS marker error, in the markers' units.
    pub rms: f64,
    /// Largest marker error, in the markers' units.
    pub max: f64,
    /// RMS marker error, m.
    pub rms_m: f64,
    /// Largest marker error, m.
    pub max_m: f64,
    /// The marker with the largest error (1-based, in the markers file's order).
    pub max_marker: usize,
    /// Its line in the measured file.
    pub max_line: u64,
    /// Every marker's error, in the markers' units, in the markers file's order.
    pub errors: Vec<f64>,
}

/// The prediction against the measured positions.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Comparison {
    /// The measured file.
    pub file: String,
    /// Units of `rms`, `max` and `errors`.
    pub units: &'static str,
    /// One entry per level, in the order of the strains.
    pub levels: Vec<LevelError>,
}

/// The errors of the predicted `levels` (a [`super::SpecimenReport`]'s) against `measured`
/// (read for the same markers and levels); `units` names the markers' units and `to_metres`
/// converts them to metres.
pub fn compare(
    levels: &[Level],
    units: &'static str,
    measured: &Measured,
    to_metres: f64,
) -> Comparison {
    let levels = levels
        .iter()
        .zip(&measured.positions)
        .zip(&measured.lines)
        .map(|((level, m), lines)| {
            let errors: Vec<f64> = level
                .markers
                .iter()
                .zip(m)
                .map(|(p, q)| distance(*p, *q))
                .collect();
            let rms =
                (errors.iter().map(|e| e * e).sum::<f64>() / errors.len().max(1) as f64).sqrt();
            let (at, max) = errors
                .iter()
                .copied()
                .enumerate()
                .fold((0, 0.0), |b, (i, e)| if e > b.1 { (i, e) } else { b });
            LevelError {
                strain: level.strain,
                rms,
                max,
                rms_m: rms * to_metres,
                max_m: max * to_metres,
                max_marker: at + 1,
                max_line: lines.get(at).copied().unwrap_or(0),
                errors,
            }
        })
        .collect();
    Comparison {
        file: measured.file.clone(),
        units,
        levels,
    }
}

/// Euclidean distance.
pub fn distance(a: [f64; 3], b: [f64; 3]) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    const TWO_BY_TWO: &str = "# two markers at two strains\nx,y,z\n0,0,1\n1,0,1\n0,0,0.5\n\
                              1,0,0.25\n";

    #[test]
    fn rows_are_level_by_level_with_their_lines() {
        let m = parse("m.csv", TWO_BY_TWO, 2, 2).unwrap();
        assert_eq!(
            m.positions,
            vec![
                vec![[0.0, 0.0, 1.0], [1.0, 0.0, 1.0]],
                vec![[0.0, 0.0, 0.5], [1.0, 0.0, 0.25]]
            ]
        );
        assert_eq!(m.lines, vec![vec![3, 4], vec![5, 6]]);
    }

    #[test]
    fn a_bad_file_names_the_line_or_the_count() {
        let e = |text: &str, markers, levels| {
            format!("{:#}", parse("m.csv", text, markers, levels).unwrap_err())
        };
        let msg = e(TWO_BY_TWO, 2, 3);
        assert!(
            msg.contains("m.csv: 4 data rows, need 2 markers x 3 levels = 6"),
            "{msg}"
        );
        let msg = e(&TWO_BY_TWO.replace("1,0,0.25", "1,nan,0.25"), 2, 2);
        assert!(msg.contains("m.csv:6") && msg.contains("\"y\""), "{msg}");
        let msg = e(&TWO_BY_TWO.replace("x,y,z", "x,y,w"), 2, 2);
        assert!(msg.contains("missing column \"z\""), "{msg}");
    }

    /// Errors by hand: at the first level marker 2 is off by (0, 3, 4) (5 units), marker 1
    /// exact: RMS sqrt(25 / 2), largest 5 at marker 2 (line 4).
    #[test]
    fn level_errors_are_the_rms_and_largest_distance() {
        let m = parse("m.csv", TWO_BY_TWO, 2, 2).unwrap();
        let level = |strain, markers| Level {
            strain,
            markers,
            platen_force_n: 0.0,
        };
        let levels = [
            level(0.1, vec![[0.0, 0.0, 1.0], [1.0, 3.0, 5.0]]),
            level(0.2, vec![[0.0, 0.0, 0.5], [1.0, 0.0, 0.25]]),
        ];
        let c = compare(&levels, "mm", &m, 1e-3);
        let l = &c.levels[0];
        assert_eq!(l.errors, vec![0.0, 5.0]);
        assert!((l.rms - 12.5f64.sqrt()).abs() < 1e-15);
        assert_eq!((l.max, l.max_marker, l.max_line), (5.0, 2, 4));
        assert!((l.max_m - 5e-3).abs() < 1e-18 && (l.rms_m - 12.5f64.sqrt() * 1e-3).abs() < 1e-18);
        assert_eq!((c.levels[1].rms, c.levels[1].max), (0.0, 0.0));
    }
}
