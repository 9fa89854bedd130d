//! `--units` on the command line (`host demo`, `host mesh`, `host scene new`): the length
//! units of a mesh file, converted to the library's [`Units`].

use haptic::units::Units;

/// Length units of a surface or tetrahedral mesh file.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum UnitsArg {
    /// Metres.
    M,
    /// Centimetres.
    Cm,
    /// Millimetres.
    Mm,
}

impl From<UnitsArg> for Units {
    fn from(u: UnitsArg) -> Units {
        match u {
            UnitsArg::M => Units::M,
            UnitsArg::Cm => Units::Cm,
            UnitsArg::Mm => Units::Mm,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::ValueEnum;

    /// Each name on the command line is the library's name of the same unit.
    #[test]
    fn the_cli_names_are_the_librarys() {
        for u in UnitsArg::value_variants() {
            let name = u.to_possible_value().unwrap().get_name().to_string();
            assert_eq!(name.parse::<Units>().unwrap(), Units::from(*u));
        }
    }
}
