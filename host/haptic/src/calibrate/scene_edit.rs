//! Writes calibration results into a scene file's text, keeping its comments, key order and
//! layout (`toml_edit`): a replaced value keeps the comment after it, keys that no longer apply
//! are removed, new keys and tables are appended. The result is validated as a whole
//! ([`Scene::parse`]) before it is returned, so a caller never writes a scene the tools would
//! refuse.

use crate::scene::{Scene, SceneError};
use std::path::Path;
use toml_edit::{Array, DocumentMut, Item, Table, Value};

/// Scene-edit errors.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum EditError {
    /// The scene text is not TOML.
    #[error("{file}: not a TOML document: {message}")]
    Syntax {
        /// The scene file.
        file: String,
        /// Parser message.
        message: String,
    },
    /// A table the edit needs is missing or not a table.
    #[error("{file}: [{table}] must be a table")]
    NotATable {
        /// The scene file.
        file: String,
        /// Its name.
        table: String,
    },
    /// The edited scene does not validate.
    #[error("the calibrated scene would be invalid: {0}")]
    Invalid(#[from] SceneError),
}

/// Which law a fit goes to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Law {
    /// Tissue force law Q: table `[law]`, domain key `domain_n` (N).
    Q,
    /// Display (radial displacement) law P: table `[display_law]`, domain key `domain_m` (m).
    P,
}

impl Law {
    /// The scene table.
    pub fn table(self) -> &'static str {
        match self {
            Law::Q => "law",
            Law::P => "display_law",
        }
    }

    /// The domain key (its unit is in the name).
    pub fn domain_key(self) -> &'static str {
        match self {
            Law::Q => "domain_n",
            Law::P => "domain_m",
        }
    }
}

/// `v` to 9 significant digits (enough for f32, short in the file).
fn short(v: f64) -> f64 {
    format!("{v:.8e}").parse().unwrap_or(v)
}

fn array(values: impl IntoIterator<Item = f64>) -> Value {
    Value::Array(Array::from_iter(values.into_iter().map(short)))
}

/// Sets `key` to `new`, keeping the old value's surrounding whitespace and trailing comment.
fn set(table: &mut Table, key: &str, mut new: Value) {
    match table.get_mut(key) {
        // Replacing the item in place keeps the key and the comments above it.
        Some(item) => {
            if let Some(old) = item.as_value() {
                *new.decor_mut() = old.decor().clone();
            }
            *item = Item::Value(new);
        }
        None => {
            table.insert(key, Item::Value(new));
        }
    }
}

fn parse(path: &Path, text: &str) -> Result<DocumentMut, EditError> {
    text.parse::<DocumentMut>().map_err(|e| EditError::Syntax {
        file: path.display().to_string(),
        message: e.to_string(),
    })
}

fn table<'d>(
    path: &Path,
    doc: &'d mut DocumentMut,
    name: &str,
    create_with: Option<&str>,
) -> Result<&'d mut Table, EditError> {
    if doc.get(name).is_none()
        && let Some(comment) = create_with
    {
        let mut t = Table::new();
        t.decor_mut().set_prefix(comment);
        doc.insert(name, Item::Table(t));
    }
    doc.get_mut(name)
        .and_then(Item::as_table_mut)
        .ok_or_else(|| EditError::NotATable {
            file: path.display().to_string(),
            table: name.to_string(),
        })
}

fn validated(path: &Path, doc: &DocumentMut) -> Result<String, EditError> {
    let text = doc.to_string();
    Scene::parse(path, &text)?;
    Ok(text)
}

/// The scene text with `law` set to the Chebyshev series `coeffs` on `domain`; `source` (e.g.
/// the bench file and degree) goes into a comment.
pub fn set_law(
    path: &Path,
    text: &str,
    law: Law,
    coeffs: &[f64],
    domain: [f64; 2],
    source: &str,
) -> Result<String, EditError> {
    let mut doc = parse(path, text)?;
    let new_table = "\n# Display law P (paper, eq. 4): the length of each displayed node's displacement\n\
                     # orthogonal to the tool's imposed displacement, P(|u_r|) for the linear |u_r|\n\
                     # (m). Chebyshev series on domain_m = [min, max] (m), increasing, continued\n\
                     # linearly outside. Written by `host calibrate tissue --law P`.\n";
    let t = table(
        path,
        &mut doc,
        law.table(),
        (law == Law::P).then_some(new_table),
    )?;
    for stale in ["gain", "offset_n"] {
        t.remove(stale);
    }
    set(t, "kind", Value::from("chebyshev"));
    set(t, "coeffs", array(coeffs.iter().copied()));
    set(t, law.domain_key(), array(domain));
    if let Some(mut key) = t.key_mut("coeffs") {
        key.leaf_decor_mut()
            .set_prefix(format!("# fitted by `host calibrate tissue`: {source}\n"));
    }
    validated(path, &doc)
}

/// The scene text with the fitted axes' torque constants (`Some`) and friction offsets set in
/// `[device]`; other axes keep their values (friction offsets default to 0).
pub fn set_motor(
    path: &Path,
    text: &str,
    torque_constant_nm_per_a: [Option<f64>; 3],
    friction: [Option<f64>; 3],
) -> Result<String, EditError> {
    let mut doc = parse(path, text)?;
    let t = table(path, &mut doc, "device", None)?;
    let current = |t: &Table, key: &str, default: f64| -> [f64; 3] {
        let a = t.get(key).and_then(Item::as_array);
        std::array::from_fn(|i| {
            a.and_then(|a| a.get(i))
                .and_then(|v| v.as_float().or_else(|| v.as_integer().map(|n| n as f64)))
                .unwrap_or(default)
        })
    };
    let kt_old = current(t, "torque_constant_nm_per_a", 0.0);
    let fr_old = current(t, "friction_offset", 0.0);
    let merge = |old: [f64; 3], new: [Option<f64>; 3]| -> [f64; 3] {
        std::array::from_fn(|i| new[i].unwrap_or(old[i]))
    };
    set(
        t,
        "torque_constant_nm_per_a",
        array(merge(kt_old, torque_constant_nm_per_a)),
    );
    let had_friction = t.contains_key("friction_offset");
    set(t, "friction_offset", array(merge(fr_old, friction)));
    if !had_friction && let Some(mut key) = t.key_mut("friction_offset") {
        key.leaf_decor_mut().set_prefix(
            "# friction offsets from `host calibrate motor` (pitch, yaw: N m; insertion: N)\n",
        );
    }
    validated(path, &doc)
}

/// The scene text with `[gravity] coeffs` set to a gravity fit (`bank-format` `SPEC.md`,
/// "gravity"); `source` (the CSV and its residual) goes into a comment.
pub fn set_gravity(
    path: &Path,
    text: &str,
    coeffs: &[f64; bank_format::GRAVITY_COEFFS],
    source: &str,
) -> Result<String, EditError> {
    let mut doc = parse(path, text)?;
    let new_table = "\n# Gravity compensation of the instrument's weight: tau_g(q) = dV/dq with\n\
                     # V = -(a_c + s b_c) cp cy - (a_s + s b_s) cp sy - (a_p + s b_p) sp - d_c cy - d_s sy,\n\
                     # coeffs = [a_c, a_s, a_p, b_c, b_s, b_p, d_c, d_s] (N m, N m, N m, N, N, N, N m, N m).\n\
                     # The bank carries it and the firmware adds it in every armed mode. Written by\n\
                     # `host calibrate gravity`; delete the table to switch compensation off.\n";
    let t = table(path, &mut doc, "gravity", Some(new_table))?;
    set(t, "coeffs", array(coeffs.iter().copied()));
    if let Some(mut key) = t.key_mut("coeffs") {
        key.leaf_decor_mut()
            .set_prefix(format!("# fitted by `host calibrate gravity`: {source}\n"));
    }
    validated(path, &doc)
}

/// The scene text with `[viscoelastic] g, tau_s` set to a relaxation fit (`bank-format`
/// `SPEC.md`, "viscoelastic relaxation"); `source` (the CSV and its residual) goes into a
/// comment.
pub fn set_viscoelastic(
    path: &Path,
    text: &str,
    g: &[f64],
    tau_s: &[f64],
    source: &str,
) -> Result<String, EditError> {
    let mut doc = parse(path, text)?;
    let new_table = "\n# Viscoelastic relaxation (Fung's QLV): the rendered force is the elastic force\n\
                     # convolved with G(t) = g_inf + sum_k g_k exp(-t / tau_k), G(0) = 1 (tau_s in s).\n\
                     # The bank carries it and the firmware renders it (firmware::relax). Written by\n\
                     # `host calibrate relaxation`; delete the table for an elastic tissue.\n";
    let t = table(path, &mut doc, "viscoelastic", Some(new_table))?;
    set(t, "g", array(g.iter().copied()));
    set(t, "tau_s", array(tau_s.iter().copied()));
    if let Some(mut key) = t.key_mut("g") {
        key.leaf_decor_mut().set_prefix(format!(
            "# fitted by `host calibrate relaxation`: {source}\n"
        ));
    }
    validated(path, &doc)
}
