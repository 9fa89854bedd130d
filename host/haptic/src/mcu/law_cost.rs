//! What evaluating a fitted law costs on the MCU, counted on the cross-compiled disassembly of
//! [`bank_format::TissueLaw::eval`] (thumbv7em, `llvm-objdump -d`): [`measure`] builds
//! `bank-format` for the MCU ([`super::build_rlib`]), disassembles it ([`super::objdump`]) and
//! counts.
//!
//! The evaluation is straight-line code (the Clenshaw recurrence runs in passes of a fixed
//! number of coefficients over a zero-padded copy, each pass laid out in full; a pass is
//! skipped by one compare and branch). So every path from the entry to a return is one way
//! through the function, and its multiply-accumulates (`vmla`/`vfma`) say which: an
//! in-domain evaluation of a degree-`d` law runs the path with the fewest multiply-accumulates
//! that is at least `d + 1` (one per padded coefficient, one for the final step). Its length is
//! the instruction count; where several paths tie, the longest is taken (an upper bound).
//! A loop in the function (a back edge) is reported as an error rather than guessed at.

use anyhow::{Context, bail};
use std::collections::HashMap;
use std::path::PathBuf;
use std::process::Command;

/// One decoded instruction.
#[derive(Debug, Clone, PartialEq)]
pub struct Insn {
    /// Address.
    pub addr: u64,
    /// Mnemonic, e.g. `vmla.f32`.
    pub mnemonic: String,
    /// Operands as printed.
    pub operands: String,
}

/// One way through the function.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub struct PathCost {
    /// Multiply-accumulates on the path.
    pub macs: usize,
    /// Instructions on the path (the longest such path).
    pub instructions: usize,
}

/// The count.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct EvalCost {
    /// Instructions in the function.
    pub instructions: usize,
    /// Entry-to-return paths by multiply-accumulate count (longest path per count), ascending.
    pub paths: Vec<PathCost>,
}

impl EvalCost {
    /// Instructions of one in-domain evaluation of a degree-`degree` law: the path with the
    /// fewest multiply-accumulates that is at least `degree + 1`.
    pub fn instructions_for_degree(&self, degree: usize) -> Option<usize> {
        self.paths
            .iter()
            .find(|p| p.macs > degree)
            .map(|p| p.instructions)
    }
}

/// Instructions of the first function whose (demangled) name contains `symbol` in
/// `llvm-objdump -d -C --no-show-raw-insn` output; data words (`.word`) are skipped.
pub fn function(disassembly: &str, symbol: &str) -> Vec<Insn> {
    let mut out = Vec::new();
    let mut inside = false;
    for line in disassembly.lines() {
        if line.ends_with(">:") {
            if inside {
                break;
            }
            inside = line.contains(symbol);
            continue;
        }
        if !inside {
            continue;
        }
        let Some((addr, rest)) = line.trim().split_once(':') else {
            continue;
        };
        let Ok(addr) = u64::from_str_radix(addr.trim(), 16) else {
            continue;
        };
        let rest = rest.trim();
        if rest.contains(".word") || rest.contains(".short") || rest.is_empty() {
            continue;
        }
        let (mnemonic, operands) = rest
            .split_once(char::is_whitespace)
            .map_or((rest, ""), |(m, o)| (m, o.trim()));
        out.push(Insn {
            addr,
            mnemonic: mnemonic.to_string(),
            operands: operands.to_string(),
        });
    }
    out
}

const CONDITIONS: [&str; 16] = [
    "eq", "ne", "cs", "cc", "hs", "lo", "mi", "pl", "vs", "vc", "hi", "ls", "ge", "lt", "gt", "le",
];

/// How control leaves an instruction.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Flow {
    Next,
    Jump(u64),
    Branch(u64),
    Return,
    ReturnIf,
}

fn flow(insn: &Insn) -> Flow {
    let m = insn.mnemonic.trim_end_matches(".w").trim_end_matches(".n");
    let target = || {
        let s = insn.operands.split("0x").nth(1)?;
        let hex: String = s.chars().take_while(char::is_ascii_hexdigit).collect();
        u64::from_str_radix(&hex, 16).ok()
    };
    let is_pc_pop = m == "pop" && insn.operands.contains("pc");
    if (m == "bx" && insn.operands.starts_with("lr")) || is_pc_pop {
        return Flow::Return;
    }
    if let Some(c) = m.strip_prefix("bx")
        && CONDITIONS.contains(&c)
    {
        return Flow::ReturnIf;
    }
    if m == "b" {
        return target().map_or(Flow::Next, Flow::Jump);
    }
    let conditional =
        m == "cbz" || m == "cbnz" || m.strip_prefix('b').is_some_and(|c| CONDITIONS.contains(&c));
    if conditional {
        return target().map_or(Flow::Next, Flow::Branch);
    }
    Flow::Next
}

/// Errors of the count.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CostError {
    /// The symbol was not found.
    #[error("function not found in the disassembly")]
    NotFound,
    /// The function loops.
    #[error(
        "the function has a loop (a branch from {from:#x} back to {to:#x}): the count expects straight-line code"
    )]
    Loop {
        /// Branch address.
        from: u64,
        /// Target address.
        to: u64,
    },
}

/// Counts the paths of the function in `insns` (see the module documentation).
pub fn estimate(insns: &[Insn]) -> Result<EvalCost, CostError> {
    if insns.is_empty() {
        return Err(CostError::NotFound);
    }
    let index: HashMap<u64, usize> = insns.iter().enumerate().map(|(i, x)| (x.addr, i)).collect();
    let n = insns.len();
    let succ: Vec<Vec<usize>> = (0..n)
        .map(|i| {
            let next = (i + 1 < n).then_some(i + 1);
            match flow(&insns[i]) {
                Flow::Next => next.into_iter().collect(),
                Flow::Jump(t) => index.get(&t).copied().into_iter().collect(),
                Flow::Branch(t) => next.into_iter().chain(index.get(&t).copied()).collect(),
                Flow::Return => vec![],
                Flow::ReturnIf => next.into_iter().collect(),
            }
        })
        .collect();
    let is_mac = |i: usize| {
        let m = &insns[i].mnemonic;
        usize::from(m.starts_with("vmla") || m.starts_with("vfma"))
    };
    // Depth-first enumeration of the paths from the entry; an edge back onto the current
    // path is a loop.
    let mut best: HashMap<usize, usize> = HashMap::new();
    let mut on_path = vec![false; n];
    // (node, next successor to try, instructions so far, macs so far)
    let mut stack = vec![(0usize, 0usize, 1usize, is_mac(0))];
    on_path[0] = true;
    while let Some(&mut (node, ref mut next, len, macs)) = stack.last_mut() {
        if succ[node].is_empty() {
            let e = best.entry(macs).or_insert(0);
            *e = (*e).max(len);
        }
        match succ[node].get(*next) {
            Some(&to) => {
                *next += 1;
                if on_path[to] {
                    return Err(CostError::Loop {
                        from: insns[node].addr,
                        to: insns[to].addr,
                    });
                }
                on_path[to] = true;
                stack.push((to, 0, len + 1, macs + is_mac(to)));
            }
            None => {
                on_path[node] = false;
                stack.pop();
            }
        }
    }
    let mut paths: Vec<PathCost> = best
        .into_iter()
        .map(|(macs, instructions)| PathCost { macs, instructions })
        .collect();
    paths.sort_by_key(|p| p.macs);
    Ok(EvalCost {
        instructions: n,
        paths,
    })
}

/// The cost model of `TissueLaw::eval` from the thumbv7em disassembly: `rlib` (default: build
/// bank-format for the MCU) read by `objdump` (default: rustup's llvm-tools). Returns the rlib
/// read and the cost.
pub fn measure(
    rlib: Option<PathBuf>,
    objdump: Option<PathBuf>,
) -> anyhow::Result<(PathBuf, EvalCost)> {
    let rlib = match rlib {
        Some(p) => p,
        None => super::build_rlib("bank-format")?,
    };
    let objdump = match objdump {
        Some(p) => p,
        None => super::objdump()?,
    };
    let out = Command::new(&objdump)
        .args(["-d", "-C", "--no-show-raw-insn"])
        .arg(&rlib)
        .output()
        .with_context(|| format!("running {}", objdump.display()))?;
    if !out.status.success() {
        bail!(
            "{} failed on {}: {}",
            objdump.display(),
            rlib.display(),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    let text = String::from_utf8_lossy(&out.stdout);
    let insns = function(&text, "TissueLaw::eval");
    let c = estimate(&insns).with_context(|| format!("TissueLaw::eval in {}", rlib.display()))?;
    Ok((rlib, c))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-made function: an early return, then passes of 2 multiply-accumulates that a
    /// compare skips, and a final step.
    const TOY: &str = "\
00000000 <other>:
       0:      \tnop
00000000 <crate::Law::eval::h1>:
       0:      \tcmp\tr1, #0x1
       2:      \tbne\t0x6 <crate::Law::eval::h1+0x6> @ imm = #0x2
       4:      \tbx\tlr
       6:      \tcmp\tr2, #0x0
       8:      \tbeq\t0x1a <crate::Law::eval::h1+0x1a> @ imm = #0x10
       a:      \tvmla.f32\ts4, s2, s6
       e:      \tvmla.f32\ts8, s2, s4
      12:      \tcmp\tr2, #0x1
      14:      \tbeq\t0x1a <crate::Law::eval::h1+0x1a> @ imm = #0x2
      16:      \tvmla.f32\ts4, s2, s8
      18:      \tvmla.f32\ts8, s2, s4
      1a:      \tvmla.f32\ts0, s2, s8
      1e:      \tpop\t{r7, pc}
      20: 00 00 00 00  \t.word\t0x00000000
00000000 <next>:
       0:      \tnop
";

    #[test]
    fn toy_function_paths() {
        let f = function(TOY, "Law::eval");
        assert_eq!(f.len(), 13);
        let c = estimate(&f).unwrap();
        let p = |macs, instructions| PathCost { macs, instructions };
        // Early return (3, no MAC), no pass (6), one pass (10), two passes (12).
        assert_eq!(c.paths, vec![p(0, 3), p(1, 6), p(3, 10), p(5, 12)]);
        assert_eq!(c.instructions_for_degree(1), Some(10));
        assert_eq!(c.instructions_for_degree(2), Some(10));
        assert_eq!(c.instructions_for_degree(3), Some(12));
        assert_eq!(c.instructions_for_degree(5), None);
    }

    #[test]
    fn loops_are_refused() {
        let looped = TOY.replace(
            "beq\t0x1a <crate::Law::eval::h1+0x1a> @ imm = #0x2",
            "beq\t0xa <x>",
        );
        let e = estimate(&function(&looped, "Law::eval")).unwrap_err();
        assert_eq!(
            e,
            CostError::Loop {
                from: 0x14,
                to: 0xa
            }
        );
    }
}
