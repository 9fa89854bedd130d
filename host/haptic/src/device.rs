//! A bring-up session with a device on a serial port (`host device`): the bank it must run,
//! the link opened and checked against it, and the steps a person at the bench takes: watch
//! the telemetry, home the encoders (`ZeroEncoders`), arm in a mode. [`Session::arm`] returns
//! an [`Armed`] guard: [`Armed::disarm`] disarms and checks that the device confirmed it, and
//! dropping the guard without it (an early return, an error) sends `Disarm` all the same.

use crate::display::source::{Sample, SerialSource, Source};
use crate::kinematics::Workspace;
use anyhow::{Context, Result, anyhow, bail};
use bank_format::{AlignedBytes, Bank, DeviceCalibration, FaultReason, HostToDevice, Mode, State};
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How long a session waits for the device to confirm a command.
pub const CONFIRM: Duration = Duration::from_secs(1);

/// Where the bank the device should run comes from.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum BankSource {
    /// The bank of a scene file, built in memory (as `host bank build` does).
    Scene(PathBuf),
    /// A bank file.
    File(PathBuf),
}

/// The bank the device should run: its calibration, its CRC and a name for messages.
#[derive(Clone, Debug)]
pub struct ExpectedBank {
    /// The bank's device calibration.
    pub calibration: DeviceCalibration,
    /// The bank's CRC, which the device's `Hello` must report.
    pub crc: u32,
    /// The bank in messages: "the bank of" and the scene's path, or the bank file's path.
    pub name: String,
}

impl ExpectedBank {
    /// Builds or reads the bank of `source` and parses it.
    pub fn load(source: &BankSource) -> Result<ExpectedBank> {
        let (bytes, name) = match source {
            BankSource::Scene(scene) => (
                crate::bank::scene_bank(scene)?,
                format!("the bank of {}", scene.display()),
            ),
            BankSource::File(bank) => (
                std::fs::read(bank)
                    .with_context(|| format!("cannot read the bank {}", bank.display()))?,
                bank.display().to_string(),
            ),
        };
        let aligned = AlignedBytes::new(&bytes);
        let bank = Bank::parse(&aligned).map_err(|e| anyhow!("{name}: invalid bank: {e}"))?;
        Ok(ExpectedBank {
            calibration: *bank.device(),
            crc: bank.crc(),
            name,
        })
    }

    /// The tip at the calibration's home joints (where the device's tip reads after
    /// `ZeroEncoders`), m.
    pub fn home_tip(&self) -> [f64; 3] {
        let cal = &self.calibration;
        Workspace::from_device(cal).tip(
            f64::from(cal.home_joint[0]),
            f64::from(cal.home_joint[1]),
            f64::from(cal.home_joint[2]),
        )
    }
}

/// An open link to a device whose identity matched the expected bank.
pub struct Session {
    source: SerialSource,
    port: String,
}

impl Session {
    /// Opens `port` at `baud` and checks that the device runs `bank` (the error says what to
    /// reflash otherwise; [`SerialSource::open`]).
    pub fn open(port: &str, baud: u32, bank: &ExpectedBank) -> Result<Session> {
        Ok(Session {
            source: SerialSource::open(port, baud, bank.crc, &bank.name)?,
            port: port.to_string(),
        })
    }

    /// The port's name.
    pub fn port(&self) -> &str {
        &self.port
    }

    /// The link's telemetry and commands, for watching the device without arming it.
    pub fn source(&mut self) -> &mut SerialSource {
        &mut self.source
    }

    /// Waits up to [`CONFIRM`] for a sample satisfying `ok`, returning it, or the newest
    /// sample seen (`None` if none came).
    fn await_sample(
        &mut self,
        ok: impl Fn(&Sample) -> bool,
    ) -> Result<std::result::Result<Sample, Option<Sample>>> {
        let end = Instant::now() + CONFIRM;
        let mut newest = None;
        while Instant::now() < end {
            if let Some(s) = self.source.latest(Duration::from_millis(20))? {
                if ok(&s) {
                    return Ok(Ok(s));
                }
                newest = Some(s);
            }
        }
        Ok(Err(newest))
    }

    /// The first telemetry sample, an error when none comes within [`CONFIRM`].
    fn first_sample(&mut self) -> Result<Sample> {
        let port = self.port.clone();
        self.await_sample(|_| true)?
            .map_err(|_| anyhow!("{port}: no telemetry from the device within 1 s"))
    }

    /// Makes sure the device can be armed: refuses one that is armed already, or in a fault
    /// unless `clear_fault` (then sends `ClearFault` and waits for it to disarm).
    pub fn ready_to_arm(&mut self, clear_fault: bool) -> Result<()> {
        let first = self.first_sample()?;
        let port = self.port.clone();
        match first.state {
            State::Armed => bail!(
                "{port}: the device is armed already (another host, or a previous run still \
                 holding it): disarm it first"
            ),
            State::Fault if !clear_fault => bail!(
                "{port}: the device is in a fault ({:?}): fix its cause and rerun with \
                 --clear-fault{}",
                first.fault,
                fault_hint(first.fault)
            ),
            State::Fault => {
                self.source.command(HostToDevice::ClearFault)?;
                self.await_sample(|s| s.state == State::Disarmed)?
                    .map_err(|seen| {
                        anyhow!(
                            "{port}: the fault did not clear (its cause remains?): {}",
                            describe(&seen)
                        )
                    })?;
                Ok(())
            }
            State::Disarmed => Ok(()),
        }
    }

    /// Selects `mode` and arms the device, waiting for its telemetry to say it is armed in
    /// that mode; if it does not, sends `Disarm` and says why (the device's fault, with the
    /// fix an operator makes outside it). The guard returned disarms when dropped.
    pub fn arm(&mut self, mode: Mode) -> Result<Armed<'_>> {
        self.source.command(HostToDevice::SetMode(mode))?;
        self.source.command(HostToDevice::Arm)?;
        // The first telemetry after Arm that is not Disarmed: armed in the mode, or why not.
        let seen = match self.await_sample(|s| s.state != State::Disarmed)? {
            Ok(s) if s.state == State::Armed && s.mode == mode => None,
            Ok(s) => Some(Some(s)),
            Err(seen) => Some(seen),
        };
        if let Some(seen) = seen {
            let _ = self.source.command(HostToDevice::Disarm);
            let hint = fault_hint(seen.as_ref().and_then(|s| s.fault));
            bail!(
                "{}: the device did not arm in mode {mode:?}: {}{hint}",
                self.port,
                describe(&seen)
            );
        }
        Ok(Armed {
            session: self,
            left: None,
            disarmed: false,
        })
    }

    /// Refuses to zero an armed device (its tip would jump), from its first telemetry.
    pub fn ready_to_zero(&mut self) -> Result<()> {
        if self.first_sample()?.state == State::Armed {
            bail!(
                "{}: the device is armed; zeroing would make the tip jump: disarm it first",
                self.port
            );
        }
        Ok(())
    }

    /// Sends `ZeroEncoders` and waits for the device's tip to read `home` (m, the bank's
    /// [`ExpectedBank::home_tip`]): that says the device applied it, nothing of the pose the
    /// instrument stands in.
    pub fn zero(&mut self, home: [f64; 3]) -> Result<()> {
        // The tip goes through f32 (a ~0.1 m vector): 10 um is far below any pose change.
        let at_home = |s: &Sample| {
            s.tip_m
                .iter()
                .zip(home)
                .all(|(&x, h)| (f64::from(x) - h).abs() < 1e-5)
        };
        self.source.command(HostToDevice::ZeroEncoders)?;
        match self.await_sample(at_home)? {
            Ok(_) => Ok(()),
            Err(seen) => bail!(
                "{}: the device did not apply ZeroEncoders within 1 s: its tip did not move to \
                 the home pose ({}; tip {:?} m)",
                self.port,
                describe(&seen),
                seen.map(|s| s.tip_m)
            ),
        }
    }
}

/// An armed device. [`Armed::disarm`] disarms it and checks the device's answer; dropping the
/// guard without it sends `Disarm` (best effort: errors are ignored) and waits up to
/// [`CONFIRM`] for telemetry that is not armed, so the command leaves before the link closes.
pub struct Armed<'a> {
    session: &'a mut Session,
    /// What the device reported when it left the armed state on its own.
    left: Option<String>,
    disarmed: bool,
}

impl Armed<'_> {
    /// The newest telemetry sample, waiting up to `timeout`: `None` when none came, or when
    /// the device left the armed state (a fault; then [`Armed::is_armed`] is false and
    /// [`Armed::disarm`] reports it).
    pub fn latest(&mut self, timeout: Duration) -> Result<Option<Sample>> {
        let Some(s) = self.session.source.latest(timeout)? else {
            return Ok(None);
        };
        if s.state != State::Armed {
            self.left = Some(describe(&Some(s)));
            return Ok(None);
        }
        Ok(Some(s))
    }

    /// Whether the device stayed armed in every sample [`Armed::latest`] returned.
    pub fn is_armed(&self) -> bool {
        self.left.is_none()
    }

    /// Sends `Disarm` and waits up to [`CONFIRM`] for the device to confirm it: an error when
    /// the device had left the armed state on its own (its fault), or when it does not confirm.
    pub fn disarm(mut self) -> Result<()> {
        self.disarmed = true;
        let session = &mut *self.session;
        session.source.command(HostToDevice::Disarm)?;
        let disarmed = session.await_sample(|s| s.state != State::Armed)?;
        let port = &session.port;
        if let Some(f) = &self.left {
            bail!("{port}: the device left the armed state: {f}");
        }
        match disarmed {
            Ok(s) if s.state == State::Disarmed => Ok(()),
            Ok(s) => bail!("{port}: after Disarm the device is {}", describe(&Some(s))),
            Err(seen) => bail!(
                "{port}: the device did not confirm Disarm within 1 s ({}); it faults \
                 LinkSilent once this host stops",
                describe(&seen)
            ),
        }
    }
}

impl Drop for Armed<'_> {
    fn drop(&mut self) {
        if !self.disarmed && self.session.source.command(HostToDevice::Disarm).is_ok() {
            let _ = self.session.await_sample(|s| s.state != State::Armed);
        }
    }
}

/// What a sample says of the device's state, for messages.
fn describe(s: &Option<Sample>) -> String {
    match s {
        None => "no telemetry".into(),
        Some(s) => match s.fault {
            Some(f) => format!("{:?} ({f:?}), mode {:?}", s.state, s.mode),
            None => format!("{:?}, mode {:?}", s.state, s.mode),
        },
    }
}

/// What to do about the faults an operator fixes outside the device (appended to a message).
fn fault_hint(fault: Option<FaultReason>) -> &'static str {
    match fault {
        Some(FaultReason::NotReferenced) => {
            "; it has not been homed since it started: put the instrument in its home \
             fixture, run `host device zero`, then arm again with --clear-fault"
        }
        Some(FaultReason::BrownOutLevel) => {
            "; its brown-out reset is below level 3 (FLASH_OPTCR's BOR_LEV is not 00), so it \
             could run on below the 2.7 V its 168 MHz clock needs: run `host flash --set-bor` \
             (it programs BOR level 3 in the option bytes), then arm again"
        }
        _ => "",
    }
}
