//! The `linear-p` model: the linear model's marker displacements with the display law P of the
//! paper (section 3, eq. 4) applied to their radial part.
//!
//! For a compression specimen the constraint's direction is the compression axis: a marker's
//! linear displacement `u` splits into its axial component `u^t` (kept, linear) and its
//! component orthogonal to the axis `u^r` (the radial part), whose amplitude becomes
//! [`DisplayLaw::radial`]`(|u^r|) = max(P(|u^r|) - P(0), 0)`, its direction kept: the display's
//! rule ([`crate::display::law`]) on the specimen's markers. A P that is the identity to f32
//! rounding is no correction ([`DisplayLaw::new`]): `linear-p` then gives exactly `linear`.
//!
//! P comes from a scene's `[display_law]` table or from a file holding that table alone
//! ([`read`]).

use super::Axis;
use crate::display::law::DisplayLaw;
use anyhow::{Context, Result, bail};
use bank_format::TissueLaw;
use serde::Deserialize;
use std::path::Path;

/// A `--display-law` file: the `[display_law]` table of a scene, alone.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DisplayLawFile {
    display_law: DisplayLawTable,
}

/// The keys of `[display_law]`, as in a scene.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct DisplayLawTable {
    kind: String,
    coeffs: Vec<f64>,
    domain_m: [f64; 2],
}

/// Parses the text of a display-law file (`file` names it in errors): one `[display_law]`
/// table with the scene's keys, `kind = "chebyshev"`, `coeffs` (m) and `domain_m` (m), and
/// nothing else; the law must be what [`TissueLaw::chebyshev`] accepts (an increasing series).
pub fn parse(file: &str, text: &str) -> Result<TissueLaw> {
    let raw: DisplayLawFile = toml::from_str(text).with_context(|| {
        format!(
            "{file}: not a display-law file (a [display_law] table with kind, coeffs and \
             domain_m, as in a scene)"
        )
    })?;
    let t = raw.display_law;
    if t.kind != "chebyshev" {
        bail!(
            "{file}: display_law.kind: unknown law {:?} (use \"chebyshev\")",
            t.kind
        );
    }
    let coeffs: Vec<f32> = t.coeffs.iter().map(|&v| v as f32).collect();
    TissueLaw::chebyshev(&coeffs, t.domain_m.map(|v| v as f32))
        .map_err(|e| anyhow::anyhow!("{file}: display_law: {e}"))
}

/// Reads a display-law file ([`parse`]).
pub fn read(path: &Path) -> Result<TissueLaw> {
    let text = std::fs::read_to_string(path)
        .with_context(|| format!("{}: cannot read the display law", path.display()))?;
    parse(&path.display().to_string(), &text)
}

/// A marker's displayed displacement (m) for its linear one `u` (m): the component along
/// `axis` kept, the amplitude of the other two through `p` (module notes).
pub fn apply(p: &DisplayLaw, axis: Axis, u: [f64; 3]) -> [f64; 3] {
    let a = axis.index();
    let lateral = [(a + 1) % 3, (a + 2) % 3];
    let len = u[lateral[0]].hypot(u[lateral[1]]);
    if len == 0.0 {
        return u;
    }
    let k = f64::from(p.radial(len as f32)) / len;
    let mut out = u;
    for c in lateral {
        out[c] = k * u[c];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    const TABLE: &str = "[display_law]\nkind = \"chebyshev\"\ncoeffs = [2.0e-3, 2.0e-3, \
                         1.5e-4]\ndomain_m = [0.0, 0.004]\n";

    /// The file's law is the series it writes: `P(x) = c0 + c1 t + c2 (2 t^2 - 1)`,
    /// `t = (2 x - 0.004) / 0.004`, evaluated here by hand at three points.
    #[test]
    fn a_display_law_file_is_the_scene_table() {
        let law = parse("p.toml", TABLE).unwrap();
        for (x, want) in [
            (0.0f64, 2.0e-3 - 2.0e-3 + 1.5e-4),
            (0.002, 2.0e-3 - 1.5e-4),
            (0.004, 2.0e-3 + 2.0e-3 + 1.5e-4),
        ] {
            let got = f64::from(law.eval(x as f32));
            assert!((got - want).abs() < 2e-9, "P({x}) = {got}, want {want}");
        }
    }

    #[test]
    fn bad_display_law_files_name_the_file_and_key() {
        let e = |text: &str| format!("{:#}", parse("p.toml", text).unwrap_err());
        let msg = e(&TABLE.replace("chebyshev", "spline"));
        assert!(
            msg.contains("p.toml") && msg.contains("display_law.kind"),
            "{msg}"
        );
        // A decreasing law is refused by the law's own validation.
        let msg = e(&TABLE.replace("2.0e-3, 2.0e-3", "2.0e-3, -2.0e-3"));
        assert!(msg.contains("p.toml: display_law"), "{msg}");
        // Another table, a missing key, a typo: not a display-law file, with TOML's line.
        for text in [
            format!("{TABLE}[law]\nkind = \"linear\"\n"),
            TABLE.replace("domain_m = [0.0, 0.004]\n", ""),
            TABLE.replace("coeffs", "coefs"),
        ] {
            let msg = e(&text);
            assert!(
                msg.contains("p.toml: not a display-law file") && msg.contains("line"),
                "{msg}"
            );
        }
    }

    /// `P(x) = 2 x` on the axis z: the x and y components double, z stays bit for bit; a purely
    /// axial displacement is unchanged.
    #[test]
    fn the_radial_part_follows_p_and_the_axial_part_stays() {
        let law = TissueLaw::chebyshev(&[0.002, 0.002], [0.0, 0.002]).unwrap();
        let p = DisplayLaw::new(law).unwrap();
        let u = [3e-4, -4e-4, -1.7e-3];
        let d = apply(&p, Axis::Z, u);
        assert_eq!(d[2], u[2]);
        for c in 0..2 {
            assert!((d[c] - 2.0 * u[c]).abs() < 1e-6 * u[c].abs(), "{d:?}");
        }
        assert_eq!(apply(&p, Axis::X, [1e-3, 0.0, 0.0]), [1e-3, 0.0, 0.0]);
        // Along x the radial part is (y, z).
        let d = apply(&p, Axis::X, [1e-3, 3e-4, 4e-4]);
        assert_eq!(d[0], 1e-3);
        assert!(
            (d[1] - 6e-4).abs() < 1e-9 && (d[2] - 8e-4).abs() < 1e-9,
            "{d:?}"
        );
    }
}
