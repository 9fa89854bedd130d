//! Quadrature encoders on 16-bit timers: the hardware counter wraps every 65,536 counts, the
//! loop wants a position. [`Extender`] turns successive 16-bit readings into an `i32` count:
//! the difference from the previous reading, taken modulo 2^16 as a signed 16-bit number, is
//! the motion since then. So a wrap in either direction is motion, never a jump, as long as an
//! encoder moves less than 32,768 counts between two readings (at 1 kHz and 4,096 counts per
//! motor turn: 8 turns per millisecond, far beyond any motor).

/// Extends one 16-bit counter to `i32` counts (wrapping at the `i32` range, which at 4,096
/// counts per motor turn is half a million turns away).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Extender {
    last: u16,
    count: i32,
}

impl Extender {
    /// Starts at count 0 on the counter's current reading `raw`.
    pub const fn new(raw: u16) -> Extender {
        Extender {
            last: raw,
            count: 0,
        }
    }

    /// The count after the counter reads `raw`.
    pub fn update(&mut self, raw: u16) -> i32 {
        let step = raw.wrapping_sub(self.last) as i16;
        self.last = raw;
        self.count = self.count.wrapping_add(i32::from(step));
        self.count
    }

    /// The count at the last reading.
    pub fn count(&self) -> i32 {
        self.count
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use bank_format::fixtures::SplitMix64;

    #[test]
    fn matches_an_i64_reference_over_a_million_steps_with_wraps() {
        let mut rng = SplitMix64::new(0x9e37_79b9_7f4a_7c15);
        let start: i64 = 40_000;
        let mut position = start;
        let mut enc = Extender::new(start as u16);
        let (mut wraps, mut max) = (0u32, 0i64);
        for i in 0..1_000_000 {
            // Mostly small steps, some near the largest legal one (+-32,767), both ways.
            let r = rng.next_u64();
            let step = if i % 100 == 0 {
                (r % 65_535) as i64 - 32_767
            } else {
                (r % 2_001) as i64 - 1_000
            };
            let before = position.div_euclid(65_536);
            position += step;
            if position.div_euclid(65_536) != before {
                wraps += 1;
            }
            max = max.max((position - start).abs());
            let raw = position.rem_euclid(65_536) as u16;
            assert_eq!(i64::from(enc.update(raw)), position - start, "step {i}");
        }
        assert_eq!(i64::from(enc.count()), position - start);
        assert!(wraps > 5_000, "only {wraps} wraps");
        assert!(max > 100_000, "the walk stayed within {max} counts");
    }

    #[test]
    fn wraps_both_ways_are_motion() {
        let mut enc = Extender::new(65_530);
        assert_eq!(enc.update(4), 10); // up through 65,535 -> 0
        assert_eq!(enc.update(65_534), 4); // back down through 0
        assert_eq!(enc.update(65_534), 4); // still
        // The largest legal step down: 65,534 -> 32,767 is -32,767 counts.
        assert_eq!(enc.update(32_767), 4 - 32_767);
    }
}
