//! Writing the firmware image and the bank to the STM32F405 through a debug probe, with
//! [probe-rs](https://probe.rs) 0.32 as a library.
//!
//! The flash map of the workspace's `memory.x` ([`bank_format::region`]: firmware in sectors
//! 0-5, the bank from sector 6 at `0x0804_0000`) is checked at run time against probe-rs's own
//! description of [`CHIP`] ([`Layout::new`]): both regions inside the chip's flash and no
//! sector shared by them, so that rewriting the bank never erases firmware and vice versa.
//! [`Layout::plan`] turns the parts to write into the erase/program plan with probe-rs's
//! [`FlashLoader`] (which refuses data outside the target's memory map or overlapping) and
//! the sector geometry of the target's flash algorithm; [`flash`] runs that plan in one probe
//! session (erase of the planned sectors only, program, verify, reset).
//!
//! [`set_bor_level3`] programs the option bytes' brown-out reset level 3 (the firmware refuses
//! to arm below it, `firmware::brownout`), the word computed by [`bor_level3`].
//!
//! What needs no probe ([`Layout`], [`Layout::plan`], [`firmware_segments`], [`check_bank`],
//! [`bor_level3`]) is what the tests cover; [`flash`], [`set_bor_level3`] and [`list_probes`]
//! need a probe for anything but the "no probe" error.

use bank_format::region::{BANK_LEN, BANK_ORIGIN, FIRMWARE_LEN, FIRMWARE_ORIGIN};
use bank_format::{AlignedBytes, Bank};
pub use probe_rs::config::Target;
use probe_rs::config::{MemoryRegion, Registry};
use probe_rs::flashing::{
    DownloadOptions, FlashAlgorithm, FlashLoader, FlashProgress, ProgressEvent, ProgressOperation,
};
pub use probe_rs::probe::DebugProbeSelector;
use probe_rs::probe::list::{Accessibility, Lister};
use probe_rs::{MemoryInterface, Permissions};
use std::ops::Range;

/// The chip of the board, by its name in probe-rs's target registry.
pub const CHIP: &str = "STM32F405RGTx";
/// `DBGMCU_IDCODE` (RM0090 §38.6.1): its `DEV_ID` (bits 11:0) names the die.
const DBGMCU_IDCODE: u64 = 0xE004_2000;
/// `DEV_ID` of the STM32F405/407/415/417 die (RM0090 §38.6.1).
const DEV_ID_F405: u32 = 0x413;
/// `FLASH_OPTCR` (RM0090 §3.9.10): the read-protection level `RDP` is bits 15:8.
const FLASH_OPTCR: u64 = 0x4002_3C14;
/// `RDP` byte of level 0 (no read protection); 0xCC is level 2, anything else level 1.
const RDP_LEVEL_0: u32 = 0xAA;
/// `FLASH_OPTKEYR` (RM0090 §3.9.3): the two keys written in turn clear `OPTLOCK`.
const FLASH_OPTKEYR: u64 = 0x4002_3C08;
/// The option-byte unlock keys (RM0090 §3.6.2).
const OPTKEYS: [u32; 2] = [0x0819_2A3B, 0x4C5D_6E7F];
/// `FLASH_SR` (RM0090 §3.9.5): `BSY` (bit 16) and the error flags OPERR (1), WRPERR (4),
/// PGAERR (5), PGPERR (6), PGSERR (7).
const FLASH_SR: u64 = 0x4002_3C0C;
const SR_BSY: u32 = 1 << 16;
const SR_ERRORS: u32 = (1 << 1) | (0b1111 << 4);
/// `FLASH_OPTCR.OPTLOCK` (bit 0) and `OPTSTRT` (bit 1).
const OPTCR_OPTLOCK: u32 = 1;
const OPTCR_OPTSTRT: u32 = 1 << 1;
/// `FLASH_OPTCR.BOR_LEV` (bits 3:2): 00 level 3, 01 level 2, 10 level 1, 11 off.
pub const OPTCR_BOR_LEV: u32 = 0b11 << 2;
/// `FLASH_OPTCR`'s reset value on a chip with factory option bytes (RM0090 §3.9.10): no write
/// protection, `RDP` level 0, the user bits set, BOR off, `OPTLOCK` set.
pub const OPTCR_FACTORY: u32 = 0x0FFF_AAED;
/// `DBGMCU_APB1_FZ` (RM0090 §38.16.4): `DBG_WWDG_STOP` (bit 11) and `DBG_IWDG_STOP` (bit 12)
/// stop the watchdogs while the core is halted, so that none resets the chip in the middle
/// of an option-byte write.
const DBGMCU_APB1_FZ: u64 = 0xE004_2008;
const FREEZE_WATCHDOGS: u32 = (1 << 11) | (1 << 12);

/// What a part of the plan holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum What {
    /// The firmware image (the ELF's loadable segments), in the FIRMWARE region.
    Firmware,
    /// The bank, at the start of the BANK region.
    Bank,
}

impl What {
    /// `"firmware"` or `"bank"`, as the JSON plan names it.
    pub fn name(self) -> &'static str {
        match self {
            What::Firmware => "firmware",
            What::Bank => "bank",
        }
    }
}

/// Bytes to write at a flash address.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Part {
    /// What the bytes are.
    pub what: What,
    /// Flash address of the first byte.
    pub address: u64,
    /// The bytes.
    pub data: Vec<u8>,
}

/// An address range of flash.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Span {
    /// First address.
    pub address: u64,
    /// Bytes.
    pub size: u64,
}

/// A range of flash programmed with one kind of content.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Programmed {
    /// First address.
    pub address: u64,
    /// Bytes.
    pub size: u64,
    /// What they hold.
    pub what: What,
}

/// What one flash session does: the sectors it erases and the ranges it programs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Plan {
    /// The chip, as probe-rs names it.
    pub chip: String,
    /// Sectors erased, ascending, one entry per sector.
    pub erase: Vec<Span>,
    /// Ranges programmed, ascending.
    pub program: Vec<Programmed>,
}

/// Why flashing (or planning it) failed.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The target registry has no such chip.
    #[error("probe-rs has no target description of {chip}: {reason}")]
    NoTarget {
        /// The chip asked for.
        chip: String,
        /// probe-rs's reason.
        reason: String,
    },
    /// memory.x and the chip's flash disagree.
    #[error("memory.x does not fit {chip}'s flash as probe-rs describes it: {reason}")]
    Layout {
        /// The chip.
        chip: String,
        /// What is wrong.
        reason: String,
    },
    /// The ELF is not a firmware image for this flash map.
    #[error("{0}")]
    Elf(String),
    /// The bank would not be accepted by the firmware.
    #[error("{0}")]
    Bank(String),
    /// probe-rs refused the data (outside the memory map, overlapping).
    #[error("probe-rs refuses the plan: {0}")]
    Plan(String),
    /// No probe was found.
    #[error("{0}")]
    NoProbe(String),
    /// Several probes match and none was picked.
    #[error("{count} debug probes are attached ({list}): pick one with --probe VID:PID[:SERIAL]")]
    SeveralProbes {
        /// How many.
        count: usize,
        /// Their selectors.
        list: String,
    },
    /// The probe could not be opened.
    #[error(
        "cannot open the debug probe {probe}: {reason} (is it busy, held by another probe-rs, \
         OpenOCD, GDB server or STM32CubeProgrammer? is its firmware supported?)"
    )]
    ProbeBusy {
        /// The probe's selector.
        probe: String,
        /// probe-rs's reason.
        reason: String,
    },
    /// The probe opened but could not attach to the chip.
    #[error(
        "the probe {probe} cannot attach to {chip}: {reason} (check the SWD wiring: SWDIO, \
         SWCLK, GND and NRST; the board powered; BOOT0 low)"
    )]
    Attach {
        /// The probe's selector.
        probe: String,
        /// The chip.
        chip: String,
        /// probe-rs's reason.
        reason: String,
    },
    /// The attached die is not an STM32F405/407.
    #[error(
        "the attached chip is not an STM32F405: DBGMCU_IDCODE reads {idcode:#010x} (DEV_ID \
         {dev_id:#05x}, want {want:#05x})"
    )]
    WrongChip {
        /// The register value.
        idcode: u32,
        /// Its DEV_ID field.
        dev_id: u32,
        /// The STM32F405's DEV_ID.
        want: u32,
    },
    /// Flash read protection is on.
    #[error(
        "the chip's flash is read-protected (FLASH_OPTCR RDP byte {rdp:#04x}, level {level}): \
         nothing was written; level 1 is removed by an option-byte change to RDP 0xAA (e.g. \
         STM32CubeProgrammer), which mass-erases the flash; level 2 is permanent"
    )]
    ReadProtected {
        /// The RDP byte.
        rdp: u32,
        /// Protection level (1 or 2).
        level: u8,
    },
    /// Read-back after programming differs from what was written.
    #[error(
        "verify failed: the flash read back differs from what was written (a bad SWD \
         connection, unstable supply or worn flash); the device must not be used until a \
         reflash verifies"
    )]
    Verify,
    /// The option bytes did not take the brown-out level written.
    #[error(
        "the option bytes did not take BOR level 3: FLASH_OPTCR was {old:#010x}, {new:#010x} \
         was written, {read:#010x} reads back{when}; the device stays refused to arm \
         (BrownOutLevel): power-cycle the board and run `host flash --set-bor` again"
    )]
    OptionVerify {
        /// The word before.
        old: u32,
        /// The word written.
        new: u32,
        /// The word read back.
        read: u32,
        /// When it was read (after the write, or after the reset).
        when: &'static str,
    },
    /// The flash interface reported an error or stayed busy during the option-byte write.
    #[error(
        "the option-byte write failed: {what} (FLASH_SR {sr:#010x}); FLASH_OPTCR was \
         {old:#010x}: power-cycle the board and run `host flash --set-bor` again (it reads the \
         word and asks before writing) before using the device"
    )]
    OptionWrite {
        /// What went wrong.
        what: &'static str,
        /// `FLASH_SR` at that moment.
        sr: u32,
        /// The word before.
        old: u32,
    },
    /// Another probe-rs failure during the session.
    #[error("{what}: {reason}")]
    Session {
        /// The step that failed.
        what: &'static str,
        /// probe-rs's reason.
        reason: String,
    },
}

/// probe-rs's built-in description of [`CHIP`] (memory map, flash algorithms).
pub fn target() -> Result<Target, Error> {
    Registry::from_builtin_families()
        .get_target_by_name(CHIP)
        .map_err(|e| Error::NoTarget {
            chip: CHIP.into(),
            reason: e.to_string(),
        })
}

/// The chip as probe-rs describes it, checked against memory.x.
pub struct Layout {
    target: Target,
    algorithm: FlashAlgorithm,
    firmware: Range<u64>,
    bank: Range<u64>,
}

impl Layout {
    /// probe-rs's built-in description of [`CHIP`] with memory.x's regions
    /// ([`bank_format::region`]), refused when they do not fit ([`Layout::with_regions`]).
    pub fn new() -> Result<Layout, Error> {
        let target = target()?;
        let firmware = u64::from(FIRMWARE_ORIGIN)..u64::from(FIRMWARE_ORIGIN) + FIRMWARE_LEN as u64;
        let bank = u64::from(BANK_ORIGIN)..u64::from(BANK_ORIGIN) + BANK_LEN as u64;
        Layout::with_regions(target, firmware, bank)
    }

    /// `target` with the firmware and bank regions given: both must lie in one flash (NVM)
    /// region of the target covered by its default flash algorithm, and no sector of that
    /// algorithm may hold bytes of both.
    pub fn with_regions(
        target: Target,
        firmware: Range<u64>,
        bank: Range<u64>,
    ) -> Result<Layout, Error> {
        let bad = |reason: String| Error::Layout {
            chip: target.name.clone(),
            reason,
        };
        for (name, r) in [("FLASH (firmware)", &firmware), ("BANK", &bank)] {
            if r.is_empty() {
                return Err(bad(format!("the {name} region is empty")));
            }
            let nvm = target
                .memory_map
                .iter()
                .filter_map(MemoryRegion::as_nvm_region)
                .find(|n| !n.is_alias && n.range.start <= r.start && r.end <= n.range.end);
            if nvm.is_none() {
                return Err(bad(format!(
                    "the {name} region {:#010x}..{:#010x} is not inside the chip's flash",
                    r.start, r.end
                )));
            }
        }
        let algorithm = default_algorithm(&target, &firmware, &bank).map_err(bad)?;
        let sectors = |r: &Range<u64>| -> Result<Vec<Span>, Error> {
            sectors_of(&algorithm, r).ok_or_else(|| {
                bad(format!(
                    "the flash algorithm has no sector at some address of {:#010x}..{:#010x}",
                    r.start, r.end
                ))
            })
        };
        let (fw, bk) = (sectors(&firmware)?, sectors(&bank)?);
        if let Some(s) = fw.iter().find(|s| bk.contains(s)) {
            return Err(bad(format!(
                "the firmware region {:#010x}..{:#010x} and the bank region {:#010x}..{:#010x} \
                 share the sector {:#010x}..{:#010x}: rewriting one would erase the other",
                firmware.start,
                firmware.end,
                bank.start,
                bank.end,
                s.address,
                s.address + s.size
            )));
        }
        Ok(Layout {
            target,
            algorithm,
            firmware,
            bank,
        })
    }

    /// The chip's name.
    pub fn chip(&self) -> &str {
        &self.target.name
    }

    /// The firmware region.
    pub fn firmware_region(&self) -> Range<u64> {
        self.firmware.clone()
    }

    /// The bank region.
    pub fn bank_region(&self) -> Range<u64> {
        self.bank.clone()
    }

    /// The erase/program plan for `parts`: each part must lie in its region (firmware in
    /// FIRMWARE, bank in BANK); probe-rs's [`FlashLoader`] takes the data (refusing what is
    /// outside the target's memory map or overlaps) and the sectors erased are those of the
    /// target's flash algorithm ([`FlashAlgorithm::sector_info`]) that its data touches.
    pub fn plan(&self, parts: &[Part]) -> Result<Plan, Error> {
        let loader = self.loader(parts)?;
        let mut erase: Vec<Span> = Vec::new();
        let mut program = Vec::new();
        for (address, data) in loader.data() {
            let range = address..address + data.len() as u64;
            for s in sectors_of(&self.algorithm, &range).ok_or_else(|| {
                Error::Plan(format!(
                    "no flash sector at some address of {:#010x}..{:#010x}",
                    range.start, range.end
                ))
            })? {
                if !erase.contains(&s) {
                    erase.push(s);
                }
            }
            // probe-rs merges adjacent data: split it again at the region boundary.
            for (what, region) in [(What::Firmware, &self.firmware), (What::Bank, &self.bank)] {
                let (lo, hi) = (range.start.max(region.start), range.end.min(region.end));
                if lo < hi {
                    program.push(Programmed {
                        address: lo,
                        size: hi - lo,
                        what,
                    });
                }
            }
        }
        erase.sort_by_key(|s| s.address);
        program.sort_by_key(|p| p.address);
        Ok(Plan {
            chip: self.target.name.clone(),
            erase,
            program,
        })
    }

    /// probe-rs's flash loader holding `parts`, each checked to lie in its region.
    fn loader(&self, parts: &[Part]) -> Result<FlashLoader, Error> {
        let mut loader =
            FlashLoader::new(self.target.memory_map.clone(), self.target.source().clone());
        for p in parts {
            let region = match p.what {
                What::Firmware => &self.firmware,
                What::Bank => &self.bank,
            };
            let end = p.address + p.data.len() as u64;
            if p.address < region.start || end > region.end {
                return Err(Error::Plan(format!(
                    "{} bytes {:#010x}..{end:#010x} are outside the {} region {:#010x}..{:#010x}",
                    p.what.name(),
                    p.address,
                    p.what.name(),
                    region.start,
                    region.end
                )));
            }
            loader
                .add_data(p.address, &p.data)
                .map_err(|e| Error::Plan(e.to_string()))?;
        }
        Ok(loader)
    }
}

/// The target's default flash algorithm covering both regions (probe-rs's choice when no
/// algorithm is named: the one marked default among those whose range covers the data).
fn default_algorithm(
    target: &Target,
    firmware: &Range<u64>,
    bank: &Range<u64>,
) -> Result<FlashAlgorithm, String> {
    let covers = |r: &Range<u64>, a: &Range<u64>| a.start <= r.start && r.end <= a.end;
    let candidates: Vec<_> = target
        .flash_algorithms
        .iter()
        .filter(|a| {
            let range = &a.flash_properties.address_range;
            covers(firmware, range) && covers(bank, range)
        })
        .collect();
    let chosen = match candidates.as_slice() {
        [] => return Err("no flash algorithm covers both regions".into()),
        [one] => one,
        many => {
            let mut defaults = many.iter().filter(|a| a.default);
            match (defaults.next(), defaults.next()) {
                (Some(one), None) => *one,
                _ => {
                    return Err(format!(
                        "{} flash algorithms cover the regions and not exactly one is the \
                         default",
                        many.len()
                    ));
                }
            }
        }
    };
    if chosen.flash_properties.sectors.is_empty() {
        return Err(format!(
            "the flash algorithm {} lists no sectors",
            chosen.name
        ));
    }
    Ok(FlashAlgorithm {
        name: chosen.name.clone(),
        flash_properties: chosen.flash_properties.clone(),
        ..FlashAlgorithm::default()
    })
}

/// The sectors of `algorithm` that hold bytes of `range`, ascending; `None` when an address
/// of it is not in the algorithm's flash.
fn sectors_of(algorithm: &FlashAlgorithm, range: &Range<u64>) -> Option<Vec<Span>> {
    let mut out = Vec::new();
    let mut at = range.start;
    while at < range.end {
        let s = algorithm.sector_info(at)?;
        if s.size == 0 {
            return None;
        }
        out.push(Span {
            address: s.base_address,
            size: s.size,
        });
        at = s.base_address + s.size;
    }
    Some(out)
}

/// The loadable bytes of the ELF image `elf`: one [`Part`] per `PT_LOAD` segment with file
/// data, at its physical (load) address, as probe-rs's ELF loader places them. Refused unless
/// it is a 32-bit little-endian ARM executable whose segments all lie in `region` (the
/// FIRMWARE region of memory.x).
pub fn firmware_segments(elf: &[u8], region: &Range<u64>) -> Result<Vec<Part>, Error> {
    use object::elf::{EM_ARM, ET_EXEC, FileHeader32, PT_LOAD};
    use object::read::elf::{FileHeader as _, ProgramHeader as _};
    let bad = |why: &str| Error::Elf(format!("not a firmware image: {why}"));
    let header = FileHeader32::<object::Endianness>::parse(elf)
        .map_err(|e| bad(&format!("not a 32-bit ELF file ({e})")))?;
    let endian = header
        .endian()
        .map_err(|e| bad(&format!("bad ELF header ({e})")))?;
    if endian != object::Endianness::Little
        || header.e_machine.get(endian) != EM_ARM
        || header.e_type.get(endian) != ET_EXEC
    {
        return Err(bad("not a little-endian ARM executable"));
    }
    let headers = header
        .program_headers(endian, elf)
        .map_err(|e| bad(&format!("bad program headers ({e})")))?;
    let mut parts = Vec::new();
    for ph in headers {
        if ph.p_type(endian) != PT_LOAD {
            continue;
        }
        let data = ph
            .data(endian, elf)
            .map_err(|()| bad("a loadable segment lies outside the file"))?;
        if data.is_empty() {
            continue;
        }
        let address = u64::from(ph.p_paddr(endian));
        let end = address + data.len() as u64;
        if address < region.start || end > region.end {
            return Err(Error::Elf(format!(
                "the image's loadable segment {address:#010x}..{end:#010x} ({} bytes) is \
                 outside the firmware region {:#010x}..{:#010x} of memory.x",
                data.len(),
                region.start,
                region.end
            )));
        }
        parts.push(Part {
            what: What::Firmware,
            address,
            data: data.to_vec(),
        });
    }
    if parts.is_empty() {
        return Err(bad("no loadable segments"));
    }
    Ok(parts)
}

/// Checks `bytes` as the firmware will at boot: [`Bank::parse`] (the reader the firmware uses,
/// which also refuses a format major version it does not read) and the size of the BANK
/// region. Returns the bank's CRC (what the device's `Hello` reports once it runs it).
pub fn check_bank(bytes: &[u8], region_len: u64) -> Result<u32, Error> {
    if bytes.len() as u64 > region_len {
        return Err(Error::Bank(format!(
            "the bank is {} bytes, more than the {region_len} bytes of the bank region",
            bytes.len()
        )));
    }
    let aligned = AlignedBytes::new(bytes);
    let bank = Bank::parse(&aligned)
        .map_err(|e| Error::Bank(format!("the bank fails the firmware's validation: {e}")))?;
    Ok(bank.crc())
}

/// Opens the probe (`selector`, or the only one attached) and attaches to `chip`.
fn open_session(
    chip: &str,
    selector: Option<&DebugProbeSelector>,
) -> Result<probe_rs::Session, Error> {
    let lister = Lister::new();
    let found = lister.list_with_access(selector);
    let usable: Vec<_> = found
        .iter()
        .filter(|p| matches!(p.accessibility, Accessibility::Accessible))
        .collect();
    let probe_info = match usable.as_slice() {
        [] if found.is_empty() => {
            let which = selector.map_or_else(
                || "no debug probe found".into(),
                |s| format!("no debug probe {s} found"),
            );
            return Err(Error::NoProbe(format!("{which}: {NO_PROBE_HELP}")));
        }
        [] => {
            let names: Vec<_> = found
                .iter()
                .map(|p| DebugProbeSelector::from(&p.info).to_string())
                .collect();
            return Err(Error::NoProbe(format!(
                "the debug probe(s) {} are attached but this user may not open them (USB \
                 permissions): {NO_PROBE_HELP}",
                names.join(", ")
            )));
        }
        [one] => *one,
        many => {
            return Err(Error::SeveralProbes {
                count: many.len(),
                list: many
                    .iter()
                    .map(|p| DebugProbeSelector::from(&p.info).to_string())
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
    };
    let name = DebugProbeSelector::from(&probe_info.info).to_string();
    let probe = probe_info.info.open().map_err(|e| Error::ProbeBusy {
        probe: name.clone(),
        reason: e.to_string(),
    })?;
    probe
        .attach(chip, Permissions::default())
        .map_err(|e| Error::Attach {
            probe: name,
            chip: chip.into(),
            reason: e.to_string(),
        })
}

/// Reads the word at `address`, naming `what` on failure.
fn read(core: &mut probe_rs::Core<'_>, address: u64, what: &'static str) -> Result<u32, Error> {
    core.read_word_32(address).map_err(|e| Error::Session {
        what,
        reason: e.to_string(),
    })
}

/// Writes `value` at `address`, naming `what` on failure.
fn write(
    core: &mut probe_rs::Core<'_>,
    address: u64,
    value: u32,
    what: &'static str,
) -> Result<(), Error> {
    core.write_word_32(address, value)
        .map_err(|e| Error::Session {
            what,
            reason: e.to_string(),
        })
}

/// Checks the die (`DBGMCU_IDCODE`) and that the flash is not read-protected
/// (`FLASH_OPTCR.RDP`); returns `FLASH_OPTCR`.
fn check_chip(core: &mut probe_rs::Core<'_>) -> Result<u32, Error> {
    let idcode = read(core, DBGMCU_IDCODE, "cannot read DBGMCU_IDCODE")?;
    if idcode & 0xFFF != DEV_ID_F405 {
        return Err(Error::WrongChip {
            idcode,
            dev_id: idcode & 0xFFF,
            want: DEV_ID_F405,
        });
    }
    let optcr = read(core, FLASH_OPTCR, "cannot read FLASH_OPTCR")?;
    check_rdp(optcr)?;
    Ok(optcr)
}

/// Refuses a `FLASH_OPTCR` word whose `RDP` byte (bits 15:8) is not level 0.
fn check_rdp(optcr: u32) -> Result<(), Error> {
    let rdp = (optcr >> 8) & 0xFF;
    if rdp != RDP_LEVEL_0 {
        return Err(Error::ReadProtected {
            rdp,
            level: if rdp == 0xCC { 2 } else { 1 },
        });
    }
    Ok(())
}

/// A change of `FLASH_OPTCR` that sets brown-out reset level 3 ([`bor_level3`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BorChange {
    /// The word read from the chip.
    pub old: u32,
    /// The word once written and locked again.
    pub new: u32,
}

impl BorChange {
    /// Whether the chip is below level 3 (there is something to write).
    pub fn is_needed(&self) -> bool {
        self.old != self.new
    }
}

/// The brown-out level `BOR_LEV` of a `FLASH_OPTCR` word selects, as a person reads it.
pub fn bor_level_name(optcr: u32) -> &'static str {
    match (optcr & OPTCR_BOR_LEV) >> 2 {
        0b00 => "level 3 (reset below about 2.7 V)",
        0b01 => "level 2 (reset below about 2.4 V)",
        0b10 => "level 1 (reset below about 2.1 V)",
        _ => "off (reset only at power-down, about 1.7 V)",
    }
}

/// The `FLASH_OPTCR` word that sets brown-out reset level 3 from the word `old` read from the
/// chip: `BOR_LEV` (bits 3:2) cleared to 00, every other option bit kept as it is (write
/// protection, the read protection `RDP`, the user bits), `OPTSTRT` clear and `OPTLOCK` set,
/// as the register reads once the write is over. Refused unless `RDP` is level 0 (0xAA): the
/// read protection is never written, and a chip at level 1 or 2 is not this tool's to change.
pub fn bor_level3(old: u32) -> Result<BorChange, Error> {
    check_rdp(old)?;
    Ok(BorChange {
        old,
        new: (old & !(OPTCR_BOR_LEV | OPTCR_OPTSTRT)) | OPTCR_OPTLOCK,
    })
}

/// What [`set_bor_level3`] did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BorOutcome {
    /// The chip was at level 3 already (the word read): nothing written.
    AlreadySet(u32),
    /// The change was not confirmed: nothing written.
    Declined(BorChange),
    /// Written, read back after the write and again after a reset of the chip.
    Written(BorChange),
}

/// How long a flash operation may keep `FLASH_SR.BSY` set (an option-byte write takes tens of
/// milliseconds; a sector erase, which a running firmware could have started, up to 2 s).
const BUSY_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(5);

/// Waits until `FLASH_SR.BSY` clears; the status word then.
fn wait_not_busy(core: &mut probe_rs::Core<'_>, old: u32) -> Result<u32, Error> {
    let end = std::time::Instant::now() + BUSY_TIMEOUT;
    loop {
        let sr = read(core, FLASH_SR, "cannot read FLASH_SR")?;
        if sr & SR_BSY == 0 {
            return Ok(sr);
        }
        if std::time::Instant::now() >= end {
            return Err(Error::OptionWrite {
                what: "the flash stayed busy for 5 s",
                sr,
                old,
            });
        }
        std::thread::sleep(std::time::Duration::from_millis(1));
    }
}

/// Programs brown-out reset level 3 into the option bytes in one probe session: opens the
/// probe (`selector`, or the only one attached), attaches to [`CHIP`], resets and halts the
/// core with the watchdogs frozen (so that neither the firmware nor a watchdog reset
/// interrupts the write), checks the die and reads `FLASH_OPTCR`. At level 3 already, nothing
/// is written; else [`bor_level3`] gives the new word (refused unless `RDP` is level 0) and
/// `confirm` sees the change: `false` writes nothing. Confirmed, it unlocks the option bytes
/// (`FLASH_OPTKEYR`), writes the word with `BOR_LEV` = 00, starts the write (`OPTSTRT`),
/// waits for `BSY` to clear, checks the error flags, locks again (`OPTLOCK`), reads the word
/// back, resets the chip (which reloads the option bytes) and reads it again: a mismatch
/// either time is [`Error::OptionVerify`].
pub fn set_bor_level3(
    selector: Option<&DebugProbeSelector>,
    confirm: &mut dyn FnMut(&BorChange) -> bool,
) -> Result<BorOutcome, Error> {
    let mut session = open_session(CHIP, selector)?;
    let mut core = session.core(0).map_err(|e| Error::Session {
        what: "cannot reach the core",
        reason: e.to_string(),
    })?;
    core.reset_and_halt(std::time::Duration::from_millis(500))
        .map_err(|e| Error::Session {
            what: "cannot reset and halt the core",
            reason: e.to_string(),
        })?;
    match write_bor_level3(&mut core, confirm) {
        Ok(BorOutcome::Written(change)) => {
            core.reset().map_err(|e| Error::Session {
                what: "the option bytes are written but the core did not reset (power-cycle \
                       the board, then check with `host flash --set-bor`)",
                reason: e.to_string(),
            })?;
            verify_optcr(&mut core, change, " after a reset of the chip")?;
            Ok(BorOutcome::Written(change))
        }
        other => {
            // Nothing written, or the write failed: the firmware runs again either way (below
            // level 3 it refuses to arm).
            let restarted = core.run().map_err(|e| Error::Session {
                what: "the core did not restart after the option-byte step (power-cycle the \
                       board)",
                reason: e.to_string(),
            });
            let outcome = other?;
            restarted?;
            Ok(outcome)
        }
    }
}

/// [`set_bor_level3`] on the halted core, up to the read-back after the write.
fn write_bor_level3(
    core: &mut probe_rs::Core<'_>,
    confirm: &mut dyn FnMut(&BorChange) -> bool,
) -> Result<BorOutcome, Error> {
    let fz = read(core, DBGMCU_APB1_FZ, "cannot read DBGMCU_APB1_FZ")?;
    write(
        core,
        DBGMCU_APB1_FZ,
        fz | FREEZE_WATCHDOGS,
        "cannot freeze the watchdogs (DBGMCU_APB1_FZ)",
    )?;
    let old = check_chip(core)?;
    let change = bor_level3(old)?;
    if !change.is_needed() {
        return Ok(BorOutcome::AlreadySet(old));
    }
    if !confirm(&change) {
        return Ok(BorOutcome::Declined(change));
    }
    wait_not_busy(core, old)?;
    for key in OPTKEYS {
        write(core, FLASH_OPTKEYR, key, "cannot write FLASH_OPTKEYR")?;
    }
    let unlocked = read(core, FLASH_OPTCR, "cannot read FLASH_OPTCR")?;
    if unlocked & OPTCR_OPTLOCK != 0 {
        let sr = read(core, FLASH_SR, "cannot read FLASH_SR")?;
        return Err(Error::OptionWrite {
            what: "FLASH_OPTCR stayed locked after the unlock keys",
            sr,
            old,
        });
    }
    let word = change.new & !(OPTCR_OPTLOCK | OPTCR_OPTSTRT);
    write(core, FLASH_OPTCR, word, "cannot write FLASH_OPTCR")?;
    write(
        core,
        FLASH_OPTCR,
        word | OPTCR_OPTSTRT,
        "cannot start the option-byte write (OPTSTRT)",
    )?;
    let sr = wait_not_busy(core, old)?;
    if sr & SR_ERRORS != 0 {
        return Err(Error::OptionWrite {
            what: "the flash interface flagged an error",
            sr,
            old,
        });
    }
    write(
        core,
        FLASH_OPTCR,
        word | OPTCR_OPTLOCK,
        "cannot lock FLASH_OPTCR again",
    )?;
    verify_optcr(core, change, " after the write")?;
    Ok(BorOutcome::Written(change))
}

/// Refuses a `FLASH_OPTCR` read back (`when`: after the write, after the reset) that is not
/// the word of `change` (`OPTSTRT` aside, which the hardware clears).
fn verify_optcr(
    core: &mut probe_rs::Core<'_>,
    change: BorChange,
    when: &'static str,
) -> Result<(), Error> {
    let read = read(core, FLASH_OPTCR, "cannot read FLASH_OPTCR back")?;
    if read & !OPTCR_OPTSTRT == change.new {
        Ok(())
    } else {
        Err(Error::OptionVerify {
            old: change.old,
            new: change.new,
            read,
            when,
        })
    }
}

/// One probe found by [`list_probes`].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProbeEntry {
    /// `VID:PID[:SERIAL]`, as `--probe` takes it.
    pub selector: String,
    /// probe-rs's name of the probe.
    pub name: String,
    /// Whether this user may open it (false: USB permissions, udev rules).
    pub accessible: bool,
}

/// The debug probes on USB.
pub fn list_probes() -> Vec<ProbeEntry> {
    Lister::new()
        .list_all_with_access()
        .into_iter()
        .map(|p| ProbeEntry {
            selector: DebugProbeSelector::from(&p.info).to_string(),
            name: p.info.identifier.clone(),
            accessible: matches!(p.accessibility, Accessibility::Accessible),
        })
        .collect()
}

/// The message for "no probe": what a person checks.
const NO_PROBE_HELP: &str = "check that the probe (ST-Link, J-Link or CMSIS-DAP) is plugged in \
     and shows up in `lsusb`, and that this user has the USB permissions to open it: on Linux \
     install probe-rs's udev rules (https://probe.rs/docs/getting-started/probe-setup/), reload them with `udevadm \
     control --reload && udevadm trigger` and replug the probe";

/// A flashing step, for progress bars.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Erasing sectors.
    Erase,
    /// Programming pages.
    Program,
    /// Reading back and comparing.
    Verify,
}

/// A progress report of [`flash`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Progress {
    /// `phase` will process this many bytes.
    Total(Phase, u64),
    /// `phase` processed this many more bytes.
    Advance(Phase, u64),
    /// `phase` is over.
    Done(Phase),
}

/// Writes `parts` to the chip in one probe session: opens the probe (`selector`, or the only
/// one attached), attaches to [`CHIP`], checks the die (`DBGMCU_IDCODE`) and that the flash is
/// not read-protected (`FLASH_OPTCR.RDP`), erases the sectors of [`Layout::plan`] only,
/// programs, verifies by read-back and resets the core. Returns the plan it ran.
pub fn flash(
    layout: &Layout,
    parts: &[Part],
    selector: Option<&DebugProbeSelector>,
    progress: &mut dyn FnMut(Progress),
) -> Result<Plan, Error> {
    let plan = layout.plan(parts)?;
    let loader = layout.loader(parts)?;
    let mut session = open_session(layout.chip(), selector)?;
    {
        let mut core = session.core(0).map_err(|e| Error::Session {
            what: "cannot reach the core",
            reason: e.to_string(),
        })?;
        check_chip(&mut core)?;
    }
    // The sectors probe-rs's flasher lays out (reported once, before it erases).
    let mut laid_out: Vec<Span> = Vec::new();
    let mut options = DownloadOptions::default();
    options.verify = true;
    options.progress = FlashProgress::new(|event| {
        let phase = |op: ProgressOperation| match op {
            ProgressOperation::Erase => Some(Phase::Erase),
            ProgressOperation::Program => Some(Phase::Program),
            ProgressOperation::Verify => Some(Phase::Verify),
            ProgressOperation::Fill => None,
        };
        match event {
            ProgressEvent::FlashLayoutReady { flash_layout } => {
                laid_out.extend(flash_layout.iter().flat_map(|l| {
                    l.sectors().iter().map(|s| Span {
                        address: s.address(),
                        size: s.size(),
                    })
                }));
            }
            ProgressEvent::AddProgressBar {
                operation,
                total: Some(total),
            } => {
                if let Some(p) = phase(operation) {
                    progress(Progress::Total(p, total));
                }
            }
            ProgressEvent::Progress {
                operation, size, ..
            } => {
                if let Some(p) = phase(operation) {
                    progress(Progress::Advance(p, size));
                }
            }
            ProgressEvent::Finished(operation) | ProgressEvent::Failed(operation) => {
                if let Some(p) = phase(operation) {
                    progress(Progress::Done(p));
                }
            }
            _ => {}
        }
    });
    loader.commit(&mut session, options).map_err(|e| match e {
        probe_rs::flashing::FlashError::Verify => Error::Verify,
        e => Error::Session {
            what: "flashing failed",
            reason: e.to_string(),
        },
    })?;
    session
        .core(0)
        .and_then(|mut core| core.reset())
        .map_err(|e| Error::Session {
            what: "the flash is written and verified but the core did not reset (power-cycle \
                   the board)",
            reason: e.to_string(),
        })?;
    Ok(plan)
}
