//! The host and the firmware agree on units and the tick period.

#[test]
fn firmware_and_bank_agree_on_si_units_and_1khz() {
    assert!(bank_format::UNITS.starts_with("SI"));
    assert_eq!(firmware::TICK_PERIOD_S, 1.0e-3);
}
