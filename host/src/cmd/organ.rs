//! The organ the benchmarks measure (`host bench compliance`, `host bench refinement`): the
//! shipped livers and their material, resting on a bed.

use std::path::{Path, PathBuf};

/// The benchmarks' organ: the shipped livers' material, resting on a bed.
#[derive(clap::Args, Debug)]
pub struct OrganArgs {
    /// Young's modulus in Pa.
    #[arg(long, default_value_t = 3.0e3)]
    pub young: f64,
    /// Poisson's ratio.
    #[arg(long, default_value_t = 0.45)]
    pub poisson: f64,
    /// The organ rests on a bed: nodes less than this height (m) above its lowest point are
    /// fixed (the peer script's `--fix-box -1,-1,-1,1,1,0.01` for the shipped livers).
    #[arg(long, default_value_t = 0.01)]
    pub bed: f64,
}

/// The shipped livers, coarse to fine, and the generated 100k one when present.
pub fn default_meshes() -> Vec<PathBuf> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("meshes");
    let mut v = vec![dir.join("liver-1k4.msh"), dir.join("liver-10k.msh")];
    let big = dir.join("generated/liver-100k.msh");
    if big.exists() {
        v.push(big);
    } else {
        eprintln!(
            "note: {} not found; generate it with `python3 scripts/gen_meshes.py --only liver-100k`",
            big.display()
        );
    }
    v
}
