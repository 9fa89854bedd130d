//! `--script` on the command line (`host demo`, `host sil`): the names of the scripted hand
//! motions, converted to the library's [`Script`].

use haptic::trajectory::Script;

/// A scripted hand motion, repeated for as long as the run lasts (the demo's steering, the SIL
/// plant's hand).
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScriptArg {
    /// Hover above the aim point, press in, hold, release (demo: 8 mm every 3 s; sil: 6 mm
    /// every 2.5 s).
    Press,
    /// Press in, slide sideways and back, release (demo: 6 mm deep, +-0.08 rad in yaw, about
    /// +-9 mm on the organ, every 4 s; sil: 4 mm deep, +-0.05 rad in pitch, every 3 s).
    Slide,
    /// Strike in at the hand's top speed, hold, withdraw (demo: from 20 mm above, 8 mm in,
    /// every 1.5 s; sil: from 10 mm above, 8 mm in, every 1.5 s).
    Strike,
    /// Press 5 mm in over 0.5 s, hold 10 s, release, every 12 s (sil: 11.5 s): what a
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
