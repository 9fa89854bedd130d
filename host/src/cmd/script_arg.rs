//! `--script` on the command line (`host demo`, `host sil`): the names of the scripted hand
//! motions, converted to the library's [`Script`].

use host::trajectory::Script;

/// A scripted hand motion, repeated for as long as the run lasts (the demo's steering, the SIL
/// plant's hand).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScriptArg {
    /// Every 3 s: hover 5 mm above the aim point, press 8 mm in over 1 s, hold, release.
    Press,
    /// Every 4 s: press 6 mm in, slide +-0.08 rad in yaw (about +-9 mm on the organ) and back,
    /// release.
    Slide,
    /// Every 1.5 s: from 20 mm above, strike 8 mm in at the hand's top speed, hold 0.25 s,
    /// withdraw.
    Strike,
    /// Every 12 s: from 5 mm above, press 5 mm in over 0.5 s, hold 10 s, release: what a
    /// viscoelastic tissue's relaxation shows (`[viscoelastic]`, `firmware::relax`).
    #[value(name = "press-hold")]
    PressHold,
}

impl From<ScriptArg> for Script {
    fn from(s: ScriptArg) -> Script {
        match s {
            ScriptArg::Press => Script::Press,
            ScriptArg::Slide => Script::Slide,
            ScriptArg::Strike => Script::Strike,
            ScriptArg::PressHold => Script::PressHold,
        }
    }
}
