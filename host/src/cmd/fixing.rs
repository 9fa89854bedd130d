//! Command-line description of fixed sets: `--fix-box` (repeatable) and `--fix-nodes`.

use anyhow::{Context, Result, bail};
use fem::elasticity::FixedSet;
use fem::mesh::TetMesh;
use std::path::{Path, PathBuf};

/// Fixed-set options shared by commands.
#[derive(clap::Args, Debug, Clone)]
pub struct FixArgs {
    /// Fix the nodes inside a closed box `xmin,ymin,zmin,xmax,ymax,zmax` (metres). Append
    /// `:xyz`-style axes to fix only those components, e.g. `...,0.01:z` for a slide-only
    /// support. May repeat.
    #[arg(
        long = "fix-box",
        value_name = "BOX[:AXES]",
        allow_hyphen_values = true
    )]
    pub boxes: Vec<String>,
    /// File with one node id per line (0-based, file node order; `#` starts a comment):
    /// all three components of those nodes are fixed.
    #[arg(long = "fix-nodes", value_name = "FILE")]
    pub nodes_file: Option<PathBuf>,
}

impl FixArgs {
    /// Builds the fixed set; errors name the offending option or file line.
    pub fn build(&self, mesh: &TetMesh) -> Result<FixedSet> {
        let mut fixed = FixedSet::none(mesh.nodes.len());
        for spec in &self.boxes {
            let (bounds, axes) = parse_box(spec).with_context(|| format!("--fix-box {spec}"))?;
            fixed
                .fix_box(mesh, bounds, axes)
                .with_context(|| format!("--fix-box {spec}"))?;
        }
        if let Some(path) = &self.nodes_file {
            for (line, node) in read_node_list(path)? {
                fixed
                    .fix_node(node)
                    .with_context(|| format!("{}:{line}", path.display()))?;
            }
        }
        if fixed.count() == 0 {
            bail!("nothing is fixed: give --fix-box or --fix-nodes (the body would float freely)");
        }
        Ok(fixed)
    }
}

fn parse_box(spec: &str) -> Result<([f64; 6], [bool; 3])> {
    let (numbers, axes) = match spec.split_once(':') {
        Some((n, a)) => (n, Some(a)),
        None => (spec, None),
    };
    let values = parse_list::<f64>(numbers)?;
    let Ok(bounds) = <[f64; 6]>::try_from(values.as_slice()) else {
        bail!(
            "expected 6 numbers xmin,ymin,zmin,xmax,ymax,zmax, got {}",
            values.len()
        );
    };
    if bounds.iter().any(|v| !v.is_finite()) || (0..3).any(|a| bounds[a] > bounds[a + 3]) {
        bail!("box bounds must be finite with min <= max on every axis");
    }
    let axes = match axes {
        None => [true; 3],
        Some(a) => FixedSet::parse_axes(a).map_err(anyhow::Error::msg)?,
    };
    Ok((bounds, axes))
}

/// Parses `a,b,c`; the error names the bad item.
pub fn parse_list<T: std::str::FromStr>(s: &str) -> Result<Vec<T>>
where
    T::Err: std::fmt::Display,
{
    s.split(',')
        .map(|item| {
            let item = item.trim();
            item.parse::<T>()
                .map_err(|e| anyhow::anyhow!("{item:?} is not a valid number: {e}"))
        })
        .collect()
}

/// Reads node ids, one per line; returns `(line number, id)`.
fn read_node_list(path: &Path) -> Result<Vec<(usize, usize)>> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("cannot read node list {}", path.display()))?;
    let mut out = Vec::new();
    for (i, raw) in text.lines().enumerate() {
        let line = raw.split('#').next().unwrap_or("").trim();
        if line.is_empty() {
            continue;
        }
        let id = line.parse::<usize>().map_err(|_| {
            anyhow::anyhow!("{}:{}: {line:?} is not a node id", path.display(), i + 1)
        })?;
        out.push((i + 1, id));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn boxes_parse_with_and_without_axes() {
        let (b, a) = parse_box("0,0,0,1,2,3").unwrap();
        assert_eq!(b, [0.0, 0.0, 0.0, 1.0, 2.0, 3.0]);
        assert_eq!(a, [true; 3]);
        let (_, a) = parse_box("0,0,0,1,2,3:zx").unwrap();
        assert_eq!(a, [true, false, true]);
        assert!(parse_box("0,0,0,1,2").is_err());
        assert!(parse_box("0,0,0,1,2,x").is_err());
        assert!(parse_box("1,0,0,0,2,3").is_err());
        assert!(parse_box("0,0,0,1,2,3:w").is_err());
    }
}
