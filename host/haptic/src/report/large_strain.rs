//! The linear model at large strain: marker RMS error against nominal strain for `linear`,
//! `linear-p` and `large` ([`crate::specimen`]) on the synthetic gel-cube markers of
//! `host/data/` (the large-deformation reference's positions plus a 0.3 mm CT voxel's noise,
//! `scripts/gen_specimen_markers.py`).
//!
//! The material's parameters are the truth's (E = 5 kPa, nu = 0.49), as its characterisation
//! would give them, never fitted to the markers checked. `linear-p`'s P is fitted by the
//! project's fitter ([`fit::fit_law`]) to a **separate characterisation specimen**: a
//! 30 x 30 x 15 mm slab (the shape of the paper's brain sample, not the 40 mm cube), bonded,
//! compressed along z at 2 to 24 % strain, its radial bulge at the middle of a side face
//! (`large`, the material's "measured" curve) against the linear model's there: P maps the
//! linear radial amplitude to the measured one, as `host calibrate tissue --law P` does for a
//! bench curve.
//!
//! The generator and this section use the same mesh (4 cells along the solved eighth's side), so `large` with the
//! truth parameters differs from the data by the noise alone: its RMS is the noise's,
//! expected `sqrt(3) x 0.3 mm / sqrt(12) = 0.150 mm`.

use super::{HardCase, Knob, Point, Series, Verdict};
use crate::calibrate::fit;
use crate::specimen::measured::{self, Comparison};
use crate::specimen::{self, Axis, End, Geometry, Model, Platens, SpecimenConfig};
use crate::units::Units;
use anyhow::{Context, Result};
use bank_format::TissueLaw;
use std::io::Write;
use std::path::Path;

/// The markers' rest positions (mm).
const MARKERS: &str = include_str!("../../../data/specimen-gel-cube-markers.csv");
/// Their synthetic measured positions (mm), level by level.
const MEASURED: &str = include_str!("../../../data/specimen-gel-cube-measured.csv");
const MEASURED_NAME: &str = "host/data/specimen-gel-cube-measured.csv";

/// The nominal strains of the data.
pub const STRAINS: [f64; 4] = [0.05, 0.10, 0.15, 0.20];
/// The CT voxel of the data's noise, mm (uniform within +-half a voxel per coordinate).
pub const VOXEL_MM: f64 = 0.3;
/// The noise's expected RMS marker error, mm: three coordinates of standard deviation
/// `voxel / sqrt(12)`.
pub fn noise_rms_mm() -> f64 {
    (3.0f64).sqrt() * VOXEL_MM / 12.0f64.sqrt()
}
/// A model recovers the data when its RMS error is within this factor of the noise's.
pub const RECOVERED: f64 = 1.5;

/// The characterisation specimen's strains.
const CHARACTERISATION_STRAINS: [f64; 12] = [
    0.02, 0.04, 0.06, 0.08, 0.10, 0.12, 0.14, 0.16, 0.18, 0.20, 0.22, 0.24,
];

/// The gel cube of the data (the generator's case), for `model` with `markers` at `path`.
pub fn gel_cube(markers: &Path, model: Model, display_law: Option<TissueLaw>) -> SpecimenConfig {
    SpecimenConfig {
        geometry: Geometry::Box {
            lo: [0.0; 3],
            hi: [40.0; 3],
        },
        units: Units::Mm,
        cells: Some(4),
        tolerance: None,
        symmetry: true,
        young_pa: 5000.0,
        poisson: 0.49,
        axis: Axis::Z,
        moving: End::Max,
        platens: Platens::Bonded,
        strains: STRAINS.to_vec(),
        markers: markers.to_path_buf(),
        model,
        display_law,
    }
}

/// P fitted to the characterisation slab (module notes): returns the law and the fit's RMS
/// error relative to full scale.
pub fn characterised_p() -> Result<(TissueLaw, f64)> {
    let mut file = tempfile::NamedTempFile::new().context("a temporary markers file")?;
    // The middle of the side face x = 30 mm.
    writeln!(file, "x,y,z\n30,15,7.5").context("writing the markers file")?;
    let mut config = gel_cube(file.path(), Model::Linear, None);
    config.geometry = Geometry::Box {
        lo: [0.0; 3],
        hi: [30.0, 30.0, 15.0],
    };
    config.strains = CHARACTERISATION_STRAINS.to_vec();
    let mut bulge_m = |model: Model| -> Result<Vec<f64>> {
        config.model = model;
        let r = specimen::run(&config)?;
        Ok(r.levels
            .iter()
            .map(|l| 1e-3 * (l.markers[0][0] - 30.0).hypot(l.markers[0][1] - 15.0))
            .collect())
    };
    let x = bulge_m(Model::Linear)?;
    let y = bulge_m(Model::Large)?;
    let (f, law, _) = fit::fit_law(&x, &y, None, fit::DEFAULT_TARGET_RMS)
        .context("fitting P to the characterisation slab's bulge")?;
    Ok((law, f.errors(&x, &y).rms_rel))
}

/// One model's errors against the data.
#[derive(Debug, Clone)]
pub struct ModelErrors {
    /// `linear`, `linear-p` or `large`.
    pub name: &'static str,
    /// The comparison, one level per strain.
    pub comparison: Comparison,
}

/// Every model's errors against the synthetic data, and P's fit error on the slab.
pub fn measure(step: &dyn Fn(&str)) -> Result<(Vec<ModelErrors>, f64)> {
    let mut file = tempfile::NamedTempFile::new().context("a temporary markers file")?;
    file.write_all(MARKERS.as_bytes())
        .context("writing the markers file")?;
    let points = specimen::markers::read(file.path())?.points;
    let data = measured::parse(MEASURED_NAME, MEASURED, points.len(), STRAINS.len())?;
    step("large strain: P fitted to the characterisation slab");
    let (p, p_rms) = characterised_p()?;
    let mut out = Vec::new();
    for (name, model, law) in [
        ("linear", Model::Linear, None),
        ("linear-p", Model::LinearP, Some(p)),
        ("large", Model::Large, None),
    ] {
        step(&format!("large strain: the gel cube's markers, {name}"));
        let r = specimen::run(&gel_cube(file.path(), model, law))?;
        out.push(ModelErrors {
            name,
            comparison: measured::compare(&r.levels, r.units, &data, 1e-3),
        });
    }
    Ok((out, p_rms))
}

/// The knob (RMS error against strain, per model, with the noise's expected RMS) and the hard
/// cases (each model at each strain against the noise).
pub fn section(models: &[ModelErrors], p_rms: f64) -> (Knob, Vec<HardCase>) {
    let noise = noise_rms_mm();
    let mut series: Vec<Series> = models
        .iter()
        .map(|m| Series {
            name: m.name.into(),
            points: m
                .comparison
                .levels
                .iter()
                .map(|l| Point {
                    x: 100.0 * l.strain,
                    y: l.rms,
                    label: format!("{:.0} %", 100.0 * l.strain),
                })
                .collect(),
        })
        .collect();
    series.push(Series {
        name: "CT noise (expected RMS)".into(),
        points: STRAINS
            .iter()
            .map(|&s| Point {
                x: 100.0 * s,
                y: noise,
                label: format!("{:.0} %", 100.0 * s),
            })
            .collect(),
    });
    let mut cases = Vec::new();
    for m in models {
        for l in &m.comparison.levels {
            let ratio = l.rms / noise;
            let verdict = if ratio <= RECOVERED {
                Verdict::MatchesReference
            } else {
                Verdict::Weakness
            };
            cases.push(HardCase {
                case: format!(
                    "{} on the gel cube's markers, strain {:.0} %",
                    m.name,
                    100.0 * l.strain
                ),
                measurement: format!(
                    "marker RMS error {:.3} mm = {ratio:.2} x the noise's, largest {:.3} mm \
                     (marker {})",
                    l.rms, l.max, l.max_marker
                ),
                reference: format!(
                    "the data's CT noise, expected RMS {noise:.3} mm (0.3 mm voxel); \
                     recovered within {RECOVERED} x"
                ),
                verdict,
                value: Some(l.rms_m),
                reference_value: Some(noise * 1e-3),
            });
        }
    }
    let at = |name: &str| {
        models
            .iter()
            .find(|m| m.name == name)
            .and_then(|m| m.comparison.levels.last())
            .map_or(f64::NAN, |l| l.rms)
    };
    let knob = Knob {
        id: "large-strain".into(),
        title: "The linear model at large strain".into(),
        x_label: "nominal strain, %".into(),
        y_label: "marker RMS error against the synthetic CT data, mm".into(),
        log_x: false,
        log_y: false,
        series,
        chosen: None,
        finding: format!(
            "at {:.0} % strain the marker RMS error is {:.3} mm linear, {:.3} mm with P (fitted \
             to a separate slab, {:.2} % RMS), {:.3} mm large, against the noise's {noise:.3} mm",
            100.0 * STRAINS[STRAINS.len() - 1],
            at("linear"),
            at("linear-p"),
            100.0 * p_rms,
            at("large"),
        ),
    };
    (knob, cases)
}
