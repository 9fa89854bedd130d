//! The figures file (`figures.md`): the numbers a `host report` run measured that the user guide
//! quotes, as Markdown tables, written beside `report.json`. `scripts/gen-figures.sh` copies it
//! to `docs/figures.md`; `host/tests/report.rs` checks the committed copy against the report it
//! runs with [`compare`], each figure to its stated tolerance: bytes and node counts exactly,
//! loop-body instructions under QEMU to 2 %, whole-tick and link instructions (which vary with
//! the link bytes that land in a tick) to 30 %, the rest (forces, errors, fits) to 5 %, and
//! rounding errors of exact solutions only below 1e-9, the display's wall times (the
//! `mesh-display` knob, which vary with the machine's load) only against a budget. Other
//! wall-clock times are not in the file, and labels drop what varies from run to run (see
//! `stable`). The `pareto` knob's points are keyed by their combination and carry a third
//! figure, the combination's worst loop-body instructions (from its label); its front series
//! is left out (its points are the combinations' own, picked by instruction counts that may
//! swap places between runs).

use std::collections::BTreeMap;

use super::{Knob, Report, pareto};

/// How closely a fresh measurement must agree with the committed figure.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Tolerance {
    /// Equal (integers: bytes, nodes).
    Exact,
    /// Within this fraction of the larger magnitude, or `abs` (for values near zero).
    Relative { rel: f64, abs: f64 },
    /// Both below 1e-9: a rounding error (an exact solution's), whose digits are noise.
    Roundoff,
    /// Both at most this budget: a wall time on this machine, whose value varies with the
    /// machine's load (only a slowdown past the budget is a change).
    Budget(f64),
}

impl Tolerance {
    const BODY: Tolerance = Tolerance::Relative {
        rel: 0.02,
        abs: 10.0,
    };
    const TICK: Tolerance = Tolerance::Relative {
        rel: 0.30,
        abs: 10.0,
    };
    const COMPUTED: Tolerance = Tolerance::Relative {
        rel: 0.05,
        abs: 1e-12,
    };
    /// A display frame's wall time, ms: one frame at 60 frames/s.
    const FRAME_MS: Tolerance = Tolerance::Budget(16.7);
    /// A new contact node's display columns, ms: while they are solved the display shows a
    /// nearby node's (`docs/demo.md`); a second is about five times the worst the quick
    /// report's meshes took on a loaded 2-core machine (210 ms), and what a slower solve (a
    /// refactorisation, a dense solve) would exceed.
    const COLUMNS_MS: Tolerance = Tolerance::Budget(1000.0);

    /// As the table's last column writes it: `exact`, `5 %`, `2 % or 10`.
    pub fn text(self) -> String {
        match self {
            Tolerance::Exact => "exact".into(),
            Tolerance::Roundoff => "below 1e-9".into(),
            Tolerance::Relative { rel, abs } if abs >= 1.0 => {
                format!("{:.0} % or {abs:.0}", rel * 100.0)
            }
            Tolerance::Relative { rel, .. } => format!("{:.0} %", rel * 100.0),
            Tolerance::Budget(limit) => format!("under {limit}"),
        }
    }

    /// The inverse of [`Tolerance::text`].
    pub fn from_text(s: &str) -> Option<Tolerance> {
        match s {
            "exact" => return Some(Tolerance::Exact),
            "below 1e-9" => return Some(Tolerance::Roundoff),
            _ => {}
        }
        if let Some(limit) = s.strip_prefix("under ") {
            return limit.parse().ok().map(Tolerance::Budget);
        }
        let (rel, abs) = match s.split_once(" % or ") {
            Some((r, a)) => (r, a.parse().ok()?),
            None => (s.strip_suffix(" %")?, 1e-12),
        };
        Some(Tolerance::Relative {
            rel: rel.parse::<f64>().ok()? / 100.0,
            abs,
        })
    }

    /// Whether `fresh` agrees with `committed`.
    pub fn holds(self, committed: f64, fresh: f64) -> bool {
        match self {
            Tolerance::Exact => committed == fresh,
            Tolerance::Roundoff => committed.abs() < 1e-9 && fresh.abs() < 1e-9,
            Tolerance::Budget(limit) => committed <= limit && fresh <= limit,
            Tolerance::Relative { rel, abs } => {
                (committed - fresh).abs() <= rel * committed.abs().max(fresh.abs()) + abs
            }
        }
    }
}

/// The knobs the file carries, with the tolerance of each axis per series (by the series
/// name): `None` leaves that axis out (its value is a position, not a measurement).
type AxisRule = fn(&str) -> Option<Tolerance>;

fn knob_rules(id: &str) -> Option<(AxisRule, AxisRule)> {
    fn exact(_: &str) -> Option<Tolerance> {
        Some(Tolerance::Exact)
    }
    fn computed(_: &str) -> Option<Tolerance> {
        Some(Tolerance::COMPUTED)
    }
    fn none(_: &str) -> Option<Tolerance> {
        None
    }
    fn instructions(series: &str) -> Option<Tolerance> {
        if series.contains("whole tick") || series.contains("link") {
            Some(Tolerance::TICK)
        } else {
            Some(Tolerance::BODY)
        }
    }
    fn wall(series: &str) -> Option<Tolerance> {
        if series.starts_with("frame") {
            Some(Tolerance::FRAME_MS)
        } else {
            Some(Tolerance::COLUMNS_MS)
        }
    }
    Some(match id {
        "element" => (computed, computed),
        "law-degree" => (computed, computed),
        "large-strain" => (exact, computed),
        "f32-vs-f64" => (computed, computed),
        "bank-couplings" => (exact, computed),
        "firmware-phases" => (none, instructions),
        "relaxation-terms" => (none, instructions),
        "contact-refinement" => (exact, computed),
        "mesh-bank" => (exact, exact),
        "mesh-display" => (exact, wall),
        _ => return None,
    })
}

/// The code-phase knob's series are by statistic and its points by phase: the link phase
/// varies like the whole tick.
fn code_phase_rule(point: &str) -> Tolerance {
    if point.starts_with("link") {
        Tolerance::TICK
    } else {
        Tolerance::BODY
    }
}

/// One figure: where it sits in the file, its value and its tolerance.
#[derive(Debug, Clone, PartialEq)]
pub struct Figure {
    /// The knob's id (`hard case` for the hard-case table).
    pub table: String,
    /// The series (for a hard case: the case).
    pub series: String,
    /// The point's label (for a hard case: `value`).
    pub point: String,
    /// `x` or `y` (for a hard case: `-`).
    pub axis: &'static str,
    /// The measured value.
    pub value: f64,
    /// How closely a fresh run must agree.
    pub tolerance: Tolerance,
}

impl Figure {
    /// `table / series / point / axis`: what [`parse`] keys a row by.
    pub fn key(&self) -> String {
        format!(
            "{} / {} / {} / {}",
            self.table, self.series, self.point, self.axis
        )
    }
}

/// A number as the file writes it: integers whole, others to four significant digits.
fn number(v: f64) -> String {
    if v == v.trunc() && v.abs() < 1e12 {
        format!("{v:.0}")
    } else if v != 0.0 && (v.abs() < 1e-2 || v.abs() >= 1e5) {
        format!("{v:.3e}")
    } else {
        let digits = (3 - v.abs().log10().floor() as i32).max(0) as usize;
        format!("{v:.digits$}")
    }
}

/// Text as a table cell: no `|`, no line break.
fn cell(s: &str) -> String {
    s.replace('|', "/").replace('\n', " ")
}

/// A label without what varies from run to run: wall times (`, built in 1.1 s`) and tick
/// counts of the QEMU runs (` (2930 ticks)`: a link command can land a tick later, which
/// moves a contact's phases by a tick). Keys are made of stable labels only.
fn stable(label: &str) -> String {
    let mut s = label.to_string();
    while let Some(at) = s.find(", built in ") {
        let end = s[at..].find(" s").map_or(s.len(), |e| at + e + 2);
        s.replace_range(at..end, "");
    }
    while let Some(at) = s.find(" (") {
        let Some(len) = s[at..].find(')') else { break };
        let inner = &s[at + 2..at + len];
        let ticks = inner
            .strip_suffix(" ticks")
            .is_some_and(|n| !n.is_empty() && n.bytes().all(|b| b.is_ascii_digit()));
        if !ticks {
            break;
        }
        s.replace_range(at..at + len + 1, "");
    }
    s
}

/// Every figure of `report` that the file carries, in file order (a label repeated within a
/// series gets ` (2)`, ` (3)`, ... so that every row has its own key).
pub fn figures(report: &Report) -> Vec<Figure> {
    let mut out: Vec<Figure> = Vec::new();
    let mut seen = std::collections::HashSet::new();
    let mut push = |mut f: Figure| {
        let base = f.point.clone();
        let mut n = 1;
        while !seen.insert(f.key()) {
            n += 1;
            f.point = format!("{base} ({n})");
        }
        out.push(f);
    };
    for knob in &report.knobs {
        for (series, point, axis, value, tolerance) in knob_points(knob) {
            push(Figure {
                table: knob.id.clone(),
                series: cell(&stable(&series)),
                point: cell(&stable(&point)),
                axis,
                value,
                tolerance,
            });
        }
    }
    for h in &report.hard_cases {
        if let Some(value) = h.value {
            push(Figure {
                table: "hard case".into(),
                series: cell(&h.case),
                point: "value".into(),
                axis: "-",
                value,
                tolerance: if h.case.contains("tick on the MCU") {
                    Tolerance::TICK
                } else if value != 0.0 && value.abs() < 1e-9 {
                    Tolerance::Roundoff
                } else {
                    Tolerance::COMPUTED
                },
            });
        }
    }
    out
}

type Row = (String, String, &'static str, f64, Tolerance);

/// The series name of a knob's chosen point.
const CHOSEN: &str = "the scene's choice";

/// The axis of the `pareto` knob's third figure: the worst loop-body instructions per tick of
/// the combination on the QEMU image (its point label carries them).
const INSTRUCTIONS_AXIS: &str = "instructions";

fn knob_points(knob: &Knob) -> Vec<Row> {
    let mut rows = Vec::new();
    if knob.id == "pareto" {
        // The front is left out: its points are the combinations' own.
        let points = knob
            .series
            .iter()
            .filter(|s| s.name != pareto::FRONT)
            .flat_map(|s| s.points.iter().map(|p| (s.name.as_str(), p)));
        let chosen = knob.chosen.iter().map(|c| (CHOSEN, c));
        for (series, p) in points.chain(chosen) {
            let (label, instructions) = match pareto::split_instructions(&p.label) {
                Some((label, n)) => (label, Some(n)),
                None => (p.label.as_str(), None),
            };
            let row = |axis, value, t| (series.to_string(), label.to_string(), axis, value, t);
            rows.push(row("x", p.x, Tolerance::Exact));
            rows.push(row("y", p.y, Tolerance::COMPUTED));
            if let Some(n) = instructions {
                rows.push(row(INSTRUCTIONS_AXIS, n, Tolerance::BODY));
            }
        }
        return rows;
    }
    if knob.id == "firmware-code-phases" {
        for s in &knob.series {
            for p in &s.points {
                rows.push((
                    s.name.clone(),
                    p.label.clone(),
                    "y",
                    p.y,
                    code_phase_rule(&p.label),
                ));
            }
        }
        return rows;
    }
    let Some((x_rule, y_rule)) = knob_rules(&knob.id) else {
        return rows;
    };
    for s in &knob.series {
        for p in &s.points {
            if let Some(t) = x_rule(&s.name) {
                rows.push((s.name.clone(), p.label.clone(), "x", p.x, t));
            }
            if let Some(t) = y_rule(&s.name) {
                rows.push((s.name.clone(), p.label.clone(), "y", p.y, t));
            }
        }
    }
    if let Some(c) = &knob.chosen {
        if let Some(t) = x_rule("chosen") {
            rows.push((CHOSEN.into(), c.label.clone(), "x", c.x, t));
        }
        if let Some(t) = y_rule("chosen") {
            rows.push((CHOSEN.into(), c.label.clone(), "y", c.y, t));
        }
    }
    rows
}

const TABLE_HEAD: &str =
    "| series | point | axis | value | checked to |\n| --- | --- | --- | ---: | --- |\n";

/// The file's text: a header saying where it comes from, one table per knob, the hard cases.
pub fn markdown(report: &Report) -> String {
    let mut s = String::new();
    s.push_str("# Figures measured by `host report`\n\n");
    s.push_str(
        "Generated, not typed: `scripts/gen-figures.sh` runs the report and copies the \
         `figures.md` it writes here; do not edit by hand. `host/tests/report.rs` runs the same \
         report and checks every figure below against this file, to the tolerance in the \
         table's last column: bytes and node counts exactly; loop-body instructions under QEMU \
         2 %; whole-tick and link instructions, which vary with the link bytes that land in a \
         tick, 30 %; forces, errors and fits 5 %; rounding errors of exact solutions only below 1e-9; \
         the display's wall times (ms, on the machine that ran it, loaded or not) only \
         against a budget (`under` it: 16.7 ms for a frame, 1 s for a new contact node's \
         columns). Other wall-clock times and the QEMU runs' tick counts are left out of the \
         keys: they vary from run to run. What each knob and hard case is: \
         [the report](report.md).\n\n",
    );
    s.push_str(&format!(
        "Report: `host report{} --scene {}`.\n",
        if report.quick { " --quick" } else { "" },
        report.scene
    ));
    let all = figures(report);
    let mut table: Option<&str> = None;
    for f in &all {
        if table != Some(f.table.as_str()) {
            table = Some(f.table.as_str());
            match report.knobs.iter().find(|k| k.id == f.table) {
                Some(knob) => s.push_str(&format!(
                    "\n## {} (`{}`)\n\nx: {}; y: {}{}.\n\n",
                    cell(&knob.title),
                    knob.id,
                    cell(&knob.x_label),
                    cell(&knob.y_label),
                    if all
                        .iter()
                        .any(|g| g.table == f.table && g.axis == INSTRUCTIONS_AXIS)
                    {
                        "; instructions: the worst loop-body instructions per tick on the QEMU \
                         image"
                    } else {
                        ""
                    }
                )),
                None => s.push_str(&format!("\n## Hard cases (`{}`)\n\n", f.table)),
            }
            s.push_str(TABLE_HEAD);
        }
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} |\n",
            f.series,
            f.point,
            f.axis,
            number(f.value),
            f.tolerance.text()
        ));
    }
    s
}

/// The figures of a figures file, by key (`table / series / point / axis`), each with its
/// tolerance: the tables' rows under each `## ... (`table`)` heading.
pub fn parse(text: &str) -> BTreeMap<String, (f64, Tolerance)> {
    let mut out = BTreeMap::new();
    let mut table: Option<String> = None;
    for line in text.lines() {
        if let Some(h) = line.strip_prefix("## ") {
            table = h
                .rsplit_once("(`")
                .and_then(|(_, rest)| rest.strip_suffix("`)"))
                .map(str::to_owned);
            continue;
        }
        let Some(table) = &table else { continue };
        let cells: Vec<&str> = line
            .trim()
            .trim_matches('|')
            .split('|')
            .map(str::trim)
            .collect();
        if cells.len() != 5 {
            continue;
        }
        let (Ok(value), Some(tolerance)) =
            (cells[3].parse::<f64>(), Tolerance::from_text(cells[4]))
        else {
            continue;
        };
        out.insert(
            format!(
                "{table} / {} / {} / {}",
                stable(cells[0]),
                stable(cells[1]),
                cells[2]
            ),
            (value, tolerance),
        );
    }
    out
}

/// A committed figures file against a fresh one (the tolerances are the fresh file's, the
/// code's): every figure of either that the other lacks, and every value outside its
/// tolerance, one line each (empty: they agree).
pub fn compare(committed: &str, fresh: &str) -> Vec<String> {
    let old = parse(committed);
    let new = parse(fresh);
    let mut problems = Vec::new();
    for (key, &(value, tolerance)) in &new {
        match old.get(key) {
            None => problems.push(format!(
                "{key}: measured {}, not in the file",
                number(value)
            )),
            Some(&(v, _)) if !tolerance.holds(v, value) => problems.push(format!(
                "{key}: the file says {}, measured {} (tolerance {})",
                number(v),
                number(value),
                tolerance.text()
            )),
            Some(_) => {}
        }
    }
    for key in old.keys() {
        if !new.contains_key(key) {
            problems.push(format!("{key}: in the file, no longer measured"));
        }
    }
    problems
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{HardCase, Point, Series, Verdict};

    fn report(bytes: f64, body: f64, error: f64) -> Report {
        Report {
            scene: "host/scenes/liver-nodal.toml".into(),
            quick: true,
            knobs: vec![
                Knob {
                    id: "mesh-bank".into(),
                    title: "Mesh size against bank size".into(),
                    x_label: "mesh nodes".into(),
                    y_label: "bank bytes".into(),
                    log_x: false,
                    log_y: false,
                    series: vec![Series {
                        name: "bank".into(),
                        points: vec![Point {
                            x: 1393.0,
                            y: bytes,
                            label: "liver-1k4 | R = 261".into(),
                        }],
                    }],
                    chosen: None,
                    finding: String::new(),
                },
                Knob {
                    id: "firmware-phases".into(),
                    title: "Firmware".into(),
                    x_label: "phase".into(),
                    y_label: "instructions".into(),
                    log_x: false,
                    log_y: false,
                    series: vec![Series {
                        name: "loop body, worst".into(),
                        points: vec![Point {
                            x: 0.0,
                            y: body,
                            label: "free motion".into(),
                        }],
                    }],
                    chosen: None,
                    finding: String::new(),
                },
                Knob {
                    id: "mesh-size".into(),
                    title: "precompute times, left out".into(),
                    x_label: String::new(),
                    y_label: String::new(),
                    log_x: false,
                    log_y: false,
                    series: vec![Series {
                        name: "frame".into(),
                        points: vec![Point {
                            x: 1.0,
                            y: 0.02,
                            label: "a".into(),
                        }],
                    }],
                    chosen: None,
                    finding: String::new(),
                },
            ],
            hard_cases: vec![HardCase {
                case: "f32 force error".into(),
                measurement: String::new(),
                reference: String::new(),
                verdict: Verdict::MatchesReference,
                value: Some(error),
                reference_value: Some(1e-4),
            }],
            not_measured: Vec::new(),
        }
    }

    #[test]
    fn a_file_agrees_with_its_own_report_and_round_trips() {
        let r = report(120_056.0, 2_639.0, 8.8e-7);
        let text = markdown(&r);
        assert!(!text.contains("precompute times"), "{text}");
        let parsed = parse(&text);
        assert_eq!(parsed.len(), 4, "{parsed:?}");
        assert_eq!(
            parsed["mesh-bank / bank / liver-1k4 / R = 261 / y"],
            (120_056.0, Tolerance::Exact)
        );
        assert_eq!(parsed["hard case / f32 force error / value / -"].0, 8.8e-7);
        assert_eq!(
            parsed["firmware-phases / loop body, worst / free motion / y"].1,
            Tolerance::BODY
        );
        assert!(
            compare(&text, &text).is_empty(),
            "{:?}",
            compare(&text, &text)
        );
    }

    #[test]
    fn each_figure_is_held_to_its_tolerance() {
        let text = markdown(&report(120_056.0, 2_639.0, 8.8e-7));
        // Within 2 % of the body, within 5 % of the error: agrees.
        assert!(compare(&text, &markdown(&report(120_056.0, 2_680.0, 9.1e-7))).is_empty());
        // One byte more, 3 % more body, 10 % more error: each named.
        let problems = compare(&text, &markdown(&report(120_057.0, 2_720.0, 9.7e-7)));
        assert_eq!(problems.len(), 3, "{problems:?}");
        for what in ["mesh-bank", "loop body", "f32 force error"] {
            assert!(
                problems.iter().any(|p| p.contains(what)),
                "{what}: {problems:?}"
            );
        }
    }

    #[test]
    fn labels_drop_what_varies_between_runs() {
        assert_eq!(
            stable("liver-10k: R = 1407 nodes, built in 13.8 s, too large for the MCU"),
            "liver-10k: R = 1407 nodes, too large for the MCU"
        );
        assert_eq!(stable("free motion (2930 ticks)"), "free motion");
        assert_eq!(stable("link (4497 ticks)"), "link");
        assert_eq!(
            stable("tool patch r = 3.0 mm (paper)"),
            "tool patch r = 3.0 mm (paper)"
        );
        // A committed row with the run's times still finds the fresh row.
        let committed = "## T (`mesh-bank`)\n| bank | a, built in 1.1 s | y | 5 | exact |\n";
        let fresh = "## T (`mesh-bank`)\n| bank | a, built in 9.9 s | y | 5 | exact |\n";
        assert!(
            compare(committed, fresh).is_empty(),
            "{:?}",
            compare(committed, fresh)
        );
        assert_eq!(
            Tolerance::from_text("below 1e-9"),
            Some(Tolerance::Roundoff)
        );
        for t in [Tolerance::FRAME_MS, Tolerance::COLUMNS_MS] {
            assert_eq!(Tolerance::from_text(&t.text()), Some(t));
        }
        assert!(Tolerance::Roundoff.holds(7.4e-13, 3e-12));
        assert!(!Tolerance::Roundoff.holds(7.4e-13, 3e-9));
    }

    fn point(x: f64, y: f64, label: &str) -> Point {
        Point {
            x,
            y,
            label: label.into(),
        }
    }

    /// A report of the two knobs with their own rules: `pareto` with a combination of
    /// `instructions`, a finer mesh and the front; `mesh-display` with a frame of `frame_ms`.
    fn pareto_and_display(instructions: f64, frame_ms: f64) -> Report {
        let combo = point(
            120_056.0,
            0.43,
            &format!("liver / tool patch / tool 12 mm bfp16 bank, {instructions} instructions"),
        );
        let knob = |id: &str, series: Vec<Series>, chosen: Option<Point>| Knob {
            id: id.into(),
            title: id.into(),
            x_label: "x".into(),
            y_label: "y".into(),
            log_x: false,
            log_y: false,
            series,
            chosen,
            finding: String::new(),
        };
        let series = |name: &str, points: Vec<Point>| Series {
            name: name.into(),
            points,
        };
        Report {
            scene: "s".into(),
            quick: true,
            knobs: vec![
                knob(
                    "pareto",
                    vec![
                        series("combinations", vec![combo.clone()]),
                        series("finer", vec![point(1e6, 0.1, "liver-10k / point")]),
                        series(pareto::FRONT, vec![combo.clone()]),
                    ],
                    Some(combo),
                ),
                knob(
                    "mesh-display",
                    vec![series(
                        "frame, mean",
                        vec![point(1393.0, frame_ms, "liver: 620 display nodes")],
                    )],
                    None,
                ),
            ],
            hard_cases: Vec::new(),
            not_measured: Vec::new(),
        }
    }

    #[test]
    fn pareto_points_carry_their_instructions_and_display_times_a_budget() {
        let text = markdown(&pareto_and_display(2_100.0, 0.04));
        let parsed = parse(&text);
        let key = "pareto / combinations / liver / tool patch / tool 12 mm bfp16 bank";
        assert_eq!(
            parsed[&format!("{key} / instructions")],
            (2_100.0, Tolerance::BODY)
        );
        assert_eq!(parsed[&format!("{key} / x")], (120_056.0, Tolerance::Exact));
        assert!(parsed.contains_key("pareto / finer / liver-10k / point / y"));
        assert!(!text.contains("Pareto front"), "{text}");
        assert_eq!(
            parsed["mesh-display / frame, mean / liver: 620 display nodes / y"],
            (0.04, Tolerance::FRAME_MS)
        );
        // Combination, finer point (x, y each), the chosen point, and the frame's x and y.
        assert_eq!(parsed.len(), 3 + 2 + 3 + 2, "{parsed:?}");
        // Three times the frame time, a few instructions more: within budget and tolerance.
        assert!(compare(&text, &markdown(&pareto_and_display(2_110.0, 0.12))).is_empty());
        // 3 % more instructions (the combination and the chosen point), a frame over budget.
        let problems = compare(&text, &markdown(&pareto_and_display(2_163.0, 17.0)));
        assert_eq!(problems.len(), 3, "{problems:?}");
        assert_eq!(
            split_instructions_of("a / b, 12 instructions"),
            Some(("a / b", 12.0))
        );
        assert_eq!(split_instructions_of("a / b: fits the MCU"), None);
    }

    fn split_instructions_of(label: &str) -> Option<(&str, f64)> {
        pareto::split_instructions(label)
    }

    #[test]
    fn numbers_are_written_to_four_digits_or_whole() {
        assert_eq!(number(120_056.0), "120056");
        assert_eq!(number(8.8e-7), "8.800e-7");
        assert_eq!(number(0.07347), "0.07347");
        assert_eq!(number(21.000241), "21.00");
        assert_eq!(number(307.44117), "307.4");
    }
}
