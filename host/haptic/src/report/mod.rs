//! `host report`: what each knob of the simulator costs and what it buys, measured by the
//! command itself, on one generated page (`index.html`, inline SVG) with every plotted number
//! in `report.json`.
//!
//! The measurements are sections of this module, each returning [`Knob`]s (a plot of error
//! against cost, one series per variant) and [`HardCase`] rows (a measurement with a
//! verdict). [`html`] renders them; [`pipeline`] runs every section on a scene and writes the
//! page. Sections:
//!
//! - [`couplings`]: the bank's couplings (truncation rule and radius) against force error and
//!   bytes;
//! - [`locking`]: the element (P1, ANP) under near-incompressibility, against 10-node
//!   tetrahedra on the same mesh (the punch of `fem::reference`);
//! - [`precompute_cost`]: precompute time and factor size against mesh size, per element;
//! - [`law`]: the tissue law's degree, held-out fit error against MCU instructions per
//!   evaluation;
//! - [`hard`]: the hard cases that are a refusal or an exact reference;
//! - [`precision`]: f32 on the MCU against f64 on the host, and the near-incompressible
//!   condition numbers;
//! - [`tick_cost`]: instructions per tick of the QEMU image over the SIL scripts;
//! - [`scale`]: contact models under refinement, bank size and display cost per mesh;
//! - [`loops`]: the force loop's hard cases, through the firmware's own code;
//! - [`pareto`]: the combinations no other beats on error, bytes and instructions;
//! - [`sampled`]: the sampled patch compliance's FEM and sample spacing against the converged
//!   reference, with the nodal bank on the same axis and their Pareto front;
//! - [`large_strain`]: the linear model at large strain, marker errors of `linear`,
//!   `linear-p` and `large` against synthetic CT markers of a compressed gel cube;
//! - [`surface`]: on a sampled scene, presses along the organ's (FEM surface's) own normal at
//!   random sites of it, the collision normal's angle to the organ's and R's shortfall there;
//! - [`relaxation`]: viscoelastic relaxation: `press-hold` on the QLV scene, the
//!   image's force against the analytic QLV response, and instructions per tick against the
//!   number of Prony terms;
//! - [`large_press`]: large presses and pulls at study sites, the linear model (with and without
//!   Q) against the neo-Hookean reference.

pub mod couplings;
pub mod figures;
pub mod hard;
pub mod html;
pub mod large_press;
pub mod large_strain;
pub mod law;
pub mod locking;
pub mod loops;
pub mod pareto;
pub mod pipeline;
pub mod precision;
pub mod precompute_cost;
pub mod relaxation;
pub mod sampled;
pub mod scale;
pub mod surface;
pub mod tick_cost;

use serde::Serialize;

/// One plotted point, with the label shown beside it (e.g. the knob's value).
#[derive(Debug, Clone, Serialize)]
pub struct Point {
    /// Cost axis value.
    pub x: f64,
    /// Error (or benefit) axis value.
    pub y: f64,
    /// What the point is, e.g. `nu = 0.49`.
    pub label: String,
}

/// A curve of one variant of a knob.
#[derive(Debug, Clone, Serialize)]
pub struct Series {
    /// Variant name, e.g. `p1`.
    pub name: String,
    /// Its points, in knob order.
    pub points: Vec<Point>,
}

/// One knob: error against cost.
#[derive(Debug, Clone, Serialize)]
pub struct Knob {
    /// Stable identifier (`report.json` key, HTML id).
    pub id: String,
    /// Title of the plot.
    pub title: String,
    /// The cost axis.
    pub x_label: String,
    /// The error axis.
    pub y_label: String,
    /// Logarithmic axes.
    pub log_x: bool,
    /// Logarithmic error axis.
    pub log_y: bool,
    /// The variants.
    pub series: Vec<Series>,
    /// The scene's own choice, marked on the plot.
    pub chosen: Option<Point>,
    /// What the measurement says, in a sentence or two.
    pub finding: String,
}

/// How a hard case came out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Verdict {
    /// Within its reference's tolerance.
    MatchesReference,
    /// Finite and within the stated bound.
    Bounded,
    /// Refused with a clear error, as it should be.
    Refused,
    /// A real weakness of the method, stated plainly.
    Weakness,
}

impl Verdict {
    /// Short text for the table.
    pub fn text(self) -> &'static str {
        match self {
            Verdict::MatchesReference => "matches reference",
            Verdict::Bounded => "finite and bounded",
            Verdict::Refused => "clear refusal",
            Verdict::Weakness => "weakness",
        }
    }
}

/// One row of the hard-case table.
#[derive(Debug, Clone, Serialize)]
pub struct HardCase {
    /// The case, e.g. `nu = 0.499, P1`.
    pub case: String,
    /// What was measured.
    pub measurement: String,
    /// What it is compared with.
    pub reference: String,
    /// The outcome.
    pub verdict: Verdict,
    /// The measured number, where the row has one (SI, or relative for errors).
    pub value: Option<f64>,
    /// The reference's number, where it has one.
    pub reference_value: Option<f64>,
}

/// Everything the page shows.
#[derive(Debug, Clone, Serialize)]
pub struct Report {
    /// The scene the knobs were measured for.
    pub scene: String,
    /// Coarse sweeps (`--quick`).
    pub quick: bool,
    /// The knobs, in page order.
    pub knobs: Vec<Knob>,
    /// The hard-case table.
    pub hard_cases: Vec<HardCase>,
    /// What the report does not measure yet, said on the page.
    pub not_measured: Vec<String>,
}

impl Report {
    /// The lines printed on stdout: one per knob and a count of verdicts.
    pub fn summary(&self) -> Vec<String> {
        let mut lines: Vec<String> = self
            .knobs
            .iter()
            .map(|k| format!("{}: {}", k.title, k.finding))
            .collect();
        let count = |v: Verdict| self.hard_cases.iter().filter(|h| h.verdict == v).count();
        lines.push(format!(
            "hard cases: {} match their reference, {} bounded, {} refused, {} weaknesses",
            count(Verdict::MatchesReference),
            count(Verdict::Bounded),
            count(Verdict::Refused),
            count(Verdict::Weakness)
        ));
        lines
    }

    /// Every plotted number is finite (the report refuses to write a page that is not).
    pub fn check_finite(&self) -> Result<(), String> {
        for k in &self.knobs {
            for s in &k.series {
                for p in &s.points {
                    if !(p.x.is_finite() && p.y.is_finite()) {
                        return Err(format!(
                            "{} / {} / {}: non-finite point ({}, {})",
                            k.id, s.name, p.label, p.x, p.y
                        ));
                    }
                }
            }
        }
        for h in &self.hard_cases {
            if h.value.is_some_and(|v| !v.is_finite())
                || h.reference_value.is_some_and(|v| !v.is_finite())
            {
                return Err(format!("hard case {}: non-finite value", h.case));
            }
        }
        Ok(())
    }
}
