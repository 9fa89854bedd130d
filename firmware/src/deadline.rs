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
//! **After an overrun the schedule restarts from the tick's end**, and the image restarts its
//! period timer there too (embassy's `Ticker::reset`: the next tick one period from now), so
//! watch and timer agree again. Both images do exactly this (`firmware/board`, `firmware/qemu`:
//! [`TickWatch::end`], then the ticker's reset on an overrun), so one late tick is one overrun.
//! (Before, the watch kept its old schedule while the timer restarted: every later tick was
//! measured against a due time the timer no longer kept, each counted late, and the device
//! faulted `Overrun` as soon as it was armed again, until the 32-bit difference wrapped.)
//! Restarting rather than catching up with the missed ticks back to back keeps the link task,
//! which runs below the tick, the time to report the fault.
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

    /// The tick that began last ends; the counter reads `now`. On an overrun the schedule
    /// restarts from `now` (the next tick is due one period later): the caller restarts its
    /// period timer from now as well.
    pub fn end(&mut self, now: u32) -> TickTiming {
        let due = self.due.unwrap_or(now);
        let late = now.wrapping_sub(due) as i32;
        let cycles = u32::try_from(late).unwrap_or(0);
        let overrun = cycles > self.period;
        if overrun {
            self.due = Some(now);
        }
        TickTiming { cycles, overrun }
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
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
    fn a_long_tick_overruns_once_and_the_schedule_restarts_from_its_end() {
        let mut w = TickWatch::new(P);
        w.begin(0);
        assert!(
            !w.end(P).overrun,
            "ending exactly when the next is due is in time"
        );
        // Tick 1 (due P) runs 2.5 periods: an overrun, and the schedule restarts at its end.
        w.begin(P);
        let t = w.end(P + 5 * P / 2);
        assert!(t.overrun);
        assert_eq!(t.cycles, 5 * P / 2);
        // The image restarted its timer there (3.5 P): the next tick wakes a period later, 50
        // cycles late, and every tick after it is on time again.
        for k in 0..100u32 {
            let due = 9 * P / 2 + k * P;
            w.begin(due + 50);
            let t = w.end(due + 1_050);
            assert!(!t.overrun, "tick {k}");
            assert_eq!(t.cycles, 1_050);
        }
    }

    /// The images' sequence on embassy's `Ticker`, which restarts on an overrun (`reset`: the
    /// next tick a period from now): one wake 1.2 periods late among 10,000 ticks that wake on
    /// time is exactly one overrun.
    #[test]
    fn one_late_wake_with_the_timer_restarted_is_one_overrun() {
        let mut w = TickWatch::new(P);
        // When the ticker's next tick expires.
        let mut expiry = 5_000u32;
        let mut overruns = std::vec::Vec::new();
        for k in 0..10_000u32 {
            let latency = if k == 500 { 6 * P / 5 } else { 40 };
            let wake = expiry.wrapping_add(latency);
            w.begin(wake);
            let end = wake.wrapping_add(20_000);
            expiry = expiry.wrapping_add(P);
            if w.end(end).overrun {
                overruns.push(k);
                // `Ticker::reset` a few cycles after the tick's end.
                expiry = end.wrapping_add(30 + P);
            }
        }
        assert_eq!(overruns, [500]);
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
        let mut w = TickWatch::new(P);
        assert_eq!(
            w.end(77),
            TickTiming {
                cycles: 0,
                overrun: false
            }
        );
    }
}
