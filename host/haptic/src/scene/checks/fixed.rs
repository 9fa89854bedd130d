//! `[fixed]`: the supports, boxes and node ids.

use super::Ctx;
use crate::scene::schema::RawFixed;
use crate::scene::{FixBox, SceneError, line_of};
use fem::elasticity::FixedSet;

/// `[fixed]`: every box finite with min <= max, `axes` default "xyz"; `nodes` default none (line
/// 0); at least one box or node. Returns the boxes, the nodes and the line of the node list.
pub(super) fn parse_fixed(
    ctx: &Ctx,
    fixed: &RawFixed,
) -> Result<(Vec<FixBox>, Vec<usize>, usize), SceneError> {
    let mut fix_boxes = Vec::new();
    for b in &fixed.boxes {
        let key = "fixed.boxes";
        let r = b.get_ref();
        let mut bounds = [0.0; 6];
        bounds[..3].copy_from_slice(&r.min);
        bounds[3..].copy_from_slice(&r.max);
        if bounds.iter().any(|v| !v.is_finite()) || (0..3).any(|a| r.min[a] > r.max[a]) {
            return Err(ctx.err(
                b.span(),
                key,
                "box bounds must be finite with min <= max on every axis",
            ));
        }
        let axes = match &r.axes {
            None => [true; 3],
            Some(s) => {
                FixedSet::parse_axes(s).map_err(|msg| ctx.err(b.span(), "fixed.boxes.axes", msg))?
            }
        };
        fix_boxes.push(FixBox {
            bounds,
            axes,
            line: line_of(ctx.text, b.span().start),
        });
    }
    let (fix_nodes, fix_nodes_line) = match &fixed.nodes {
        Some(n) => (n.get_ref().clone(), line_of(ctx.text, n.span().start)),
        None => (Vec::new(), 0),
    };
    if fix_boxes.is_empty() && fix_nodes.is_empty() {
        return Err(SceneError {
            file: ctx.file.clone(),
            line: Some(line_of(ctx.text, ctx.text.find("[fixed]").unwrap_or(0))),
            key: "fixed".into(),
            message: "nothing is fixed: give boxes and/or nodes (the body would float)".into(),
        });
    }
    Ok((fix_boxes, fix_nodes, fix_nodes_line))
}
