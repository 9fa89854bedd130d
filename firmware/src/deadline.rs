//! The tick's deadline on a free-running, wrapping cycle counter (the board's DWT `CYCCNT`):
//! whether a tick overran its period, and how long the whole tick took, for
//! [`crate::app::App::tick`]'s `overrun` and [`crate::app::App::record_tick_cycles`].
//!
//! Tick `k` is due one period after tick `k - 1` was due, whatever happened in between, so a
//! tick that woke late is measured from when it was due, not from when it ran (a periodic
//! timer that fell behind runs its missed ticks back to back, each still due at its own time,
//! and each of them is an overrun until the schedule is caught up). A tick overran when it
//! ended more than one period after it was due, i.e. after the next tick was due. The first
//! tick sets the schedule; a tick that begins before its computed due time (the first one
//! woke later than usual) moves the schedule to it, so the schedule settles on the earliest
//! wake-up seen and wake-up latency counts in the whole-tick figure.
//!
//! All arithmetic wraps: at 168 MHz the counter wraps every 25.6 s, and differences stay right
//! as long as a tick ends less than 2^31 cycles (12.8 s) after it was due.

/// Watches a periodic tick against its schedule.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickWatch {
    period: u32,
    /// When the current tick was due (counter value), once a tick has begun.
    due: Option<u32>,
}

/// How one tick went against its schedule.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TickTiming {
    /// Counter cycles from when the tick was due to its end (wake-up latency included).
    pub cycles: u32,
    /// The tick ended after the next tick was due.
    pub overrun: bool,
}

impl TickWatch {
    /// A watch for a tick every `period_cycles` counter cycles (168,000 at 168 MHz and 1 kHz).
    pub const fn new(period_cycles: u32) -> TickWatch {
        TickWatch {
            period: period_cycles,
            due: None,
        }
    }

    /// The period, in counter cycles.
    pub fn period(&self) -> u32 {
        self.period
    }

    /// A tick begins; the counter reads `now`.
    pub fn begin(&mut self, now: u32) {
        let due = match self.due {
            None => now,
            Some(prev) => {
                let expected = prev.wrapping_add(self.period);
                // Woke before the computed due time: the schedule's phase was late.
                if (now.wrapping_sub(expected) as i32) < 0 {
                    now
                } else {
                    expected
                }
            }
        };
        self.due = Some(due);
    }

    /// The tick that began last ends; the counter reads `now`.
    pub fn end(&self, now: u32) -> TickTiming {
        let due = self.due.unwrap_or(now);
        let late = now.wrapping_sub(due) as i32;
        let cycles = u32::try_from(late).unwrap_or(0);
        TickTiming {
            cycles,
            overrun: cycles > self.period,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const P: u32 = 168_000;

    #[test]
    fn ticks_on_time_never_overrun_and_measure_from_due() {
        let mut w = TickWatch::new(P);
        assert_eq!(w.period(), P);
        // Due at 1,000 + k P; each wakes 50 cycles late (except the first, which sets the
        // schedule) and runs 30,000 cycles.
        for k in 0..100u32 {
            let due = 1_000 + k * P;
            let wake = if k == 0 { due } else { due + 50 };
            w.begin(wake);
            let t = w.end(wake + 30_000);
            assert!(!t.overrun);
            assert_eq!(t.cycles, wake + 30_000 - due);
        }
    }

    #[test]
    fn a_long_tick_overruns_and_the_back_to_back_catch_up_ticks_too() {
        let mut w = TickWatch::new(P);
        w.begin(0);
        assert!(
            !w.end(P).overrun,
            "ending exactly when the next is due is in time"
        );
        // Tick 1 (due P) runs 2.5 periods.
        w.begin(P);
        let t = w.end(P + 5 * P / 2);
        assert!(t.overrun);
        assert_eq!(t.cycles, 5 * P / 2);
        // Ticks 2 and 3 were due at 2P and 3P: they run back to back from 3.5P, 1,000
        // cycles each; 2 ends more than a period after it was due, 3 does not.
        let t2 = {
            w.begin(7 * P / 2);
            w.end(7 * P / 2 + 1_000)
        };
        let t3 = {
            w.begin(7 * P / 2 + 1_000);
            w.end(7 * P / 2 + 2_000)
        };
        assert!(t2.overrun && t2.cycles == 3 * P / 2 + 1_000);
        assert!(!t3.overrun && t3.cycles == P / 2 + 2_000);
        // Back on schedule.
        w.begin(4 * P + 10);
        assert_eq!(w.end(4 * P + 20_010).cycles, 20_010);
    }

    #[test]
    fn a_late_wake_counts_against_the_deadline() {
        let mut w = TickWatch::new(P);
        w.begin(0);
        let _ = w.end(10);
        // Tick 1 is due at P but wakes 0.9 P late (a long critical section) and runs 0.2 P.
        w.begin(P + 9 * P / 10);
        assert!(w.end(P + 11 * P / 10).overrun);
    }

    #[test]
    fn the_schedule_settles_on_the_earliest_wake() {
        let mut w = TickWatch::new(P);
        // The first wake was 400 cycles later than later ones.
        w.begin(400);
        let _ = w.end(1_000);
        w.begin(P);
        assert_eq!(w.end(P + 1_000).cycles, 1_000);
        w.begin(2 * P + 30);
        assert_eq!(w.end(2 * P + 1_000).cycles, 1_000);
    }

    #[test]
    fn wraps_of_the_counter_are_not_overruns() {
        let mut w = TickWatch::new(P);
        let start = u32::MAX - P / 2;
        for k in 0..4u32 {
            let due = start.wrapping_add(k.wrapping_mul(P));
            w.begin(due);
            let t = w.end(due.wrapping_add(1_234));
            assert_eq!(
                t,
                TickTiming {
                    cycles: 1_234,
                    overrun: false
                },
                "tick {k}"
            );
        }
        // And an overrun across the wrap is still one.
        let due = start.wrapping_add(4 * P);
        w.begin(due);
        assert!(w.end(due.wrapping_add(P + 1)).overrun);
    }

    #[test]
    fn end_without_begin_is_an_empty_tick() {
        let w = TickWatch::new(P);
        assert_eq!(
            w.end(77),
            TickTiming {
                cycles: 0,
                overrun: false
            }
        );
    }
}
