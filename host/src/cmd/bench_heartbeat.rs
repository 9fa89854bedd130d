//! `host bench heartbeat`: how regularly the host's link thread sends heartbeats, as a device
//! sees them ([`haptic::link::heartbeat_intervals`]), with an optional CPU load; the figures the
//! firmware's link timeout (`[device] link_timeout_ms`) is chosen from.

use anyhow::{Result, bail};
use std::time::Duration;

/// Arguments of `host bench heartbeat`.
#[derive(clap::Args, Debug)]
pub struct HeartbeatArgs {
    /// Seconds to run.
    #[arg(long, default_value_t = 10.0)]
    seconds: f64,
    /// Threads that spin meanwhile (e.g. one per core to load the machine).
    #[arg(long, default_value_t = 0)]
    load: usize,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
}

/// Runs the link against the stand-in device and prints the interval distribution.
pub fn run(args: HeartbeatArgs) -> Result<()> {
    if !(args.seconds > 0.0 && args.seconds <= 3600.0) {
        bail!("--seconds must be in (0, 3600], not {}", args.seconds);
    }
    let run = haptic::link::heartbeat_intervals(Duration::from_secs_f64(args.seconds), args.load)?;
    let ms = |q: f64| run.quantile(q).map_or(f64::NAN, |d| d.as_secs_f64() * 1e3);
    let over = |limit_ms: u64| run.longer_than(Duration::from_millis(limit_ms));
    if args.json {
        let v = serde_json::json!({
            "seconds": args.seconds,
            "load_threads": run.load_threads,
            "stand_in_realtime": run.stand_in_realtime,
            "link_realtime": run.link_realtime,
            "intervals": run.intervals.len(),
            "median_ms": ms(0.5),
            "p99_ms": ms(0.99),
            "p999_ms": ms(0.999),
            "max_ms": ms(1.0),
            "over_5_ms": over(5),
            "over_10_ms": over(10),
            "over_20_ms": over(20),
            "over_50_ms": over(50),
            "over_100_ms": over(100),
        });
        println!("{v}");
        return Ok(());
    }
    let rt = |yes| if yes { "real-time" } else { "normal priority" };
    println!(
        "heartbeats over {:.1} s with {} busy threads: {} intervals (link thread {}, stand-in \
         device {})",
        args.seconds,
        run.load_threads,
        run.intervals.len(),
        rt(run.link_realtime),
        rt(run.stand_in_realtime),
    );
    println!(
        "interval ms: median {:.3}, p99 {:.3}, p99.9 {:.3}, max {:.3}",
        ms(0.5),
        ms(0.99),
        ms(0.999),
        ms(1.0)
    );
    println!(
        "longer than 5 ms: {}, 10 ms: {}, 20 ms: {}, 50 ms: {}, 100 ms: {}",
        over(5),
        over(10),
        over(20),
        over(50),
        over(100)
    );
    Ok(())
}
