//! Flash and RAM use of a firmware ELF, read from its section headers.

use object::{Object, ObjectSection, SectionFlags};
use std::fmt;
use std::path::Path;

/// The application's share of the code region (flash sectors 0-7, 512 KiB; `memory.x`) once a
/// field-update bootloader is in: the bootloader in sectors 0-3 (64 KiB), the running image's
/// slot in sectors 4-5 (64 + 128 KiB) and the download slot in sectors 6-7 (256 KiB, of which
/// the image may use as much as the smaller slot). An image must fit the smaller slot: 192 KiB.
pub const APP_SLOT_BYTES: u64 = 192 * 1024;

/// Headroom every image keeps in its slot, per cent: room for field fixes and features without
/// a round of byte-shaving first.
pub const FLASH_HEADROOM_PERCENT: u64 = 15;

/// The flash budget of every image: the slot less its headroom (167,116 B).
pub const FLASH_BUDGET: u64 = APP_SLOT_BYTES * (100 - FLASH_HEADROOM_PERCENT) / 100;

/// Static RAM (data + bss) of every image: 24 KiB of the 128 KiB SRAM, so the stack and its
/// guard keep the rest (the worst stack use is measured by `cargo xtask bench`).
pub const RAM_BUDGET: u64 = 24 * 1024;

/// The flash and static-RAM budget of one firmware image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Budget {
    /// Which image (for messages).
    pub image: &'static str,
    /// Flash, bytes.
    pub flash: u64,
    /// Static RAM, bytes.
    pub ram: u64,
}

/// The car image's budget ([`FLASH_BUDGET`], [`RAM_BUDGET`]).
pub const CAR_BUDGET: Budget = Budget {
    image: "the car image",
    flash: FLASH_BUDGET,
    ram: RAM_BUDGET,
};

/// The truck image's budget (cargo feature `model-truck`): the same slot and headroom as the
/// car's.
pub const TRUCK_BUDGET: Budget = Budget {
    image: "the truck image",
    flash: FLASH_BUDGET,
    ram: RAM_BUDGET,
};

/// STM32F405RG memory map (must match `memory.x`): code in flash sectors 0-7 (the store owns
/// sectors 8-11).
const FLASH: (u64, u64) = (0x0800_0000, 512 * 1024);
const RAM: (u64, u64) = (0x2000_0000, 128 * 1024);

pub struct MemoryReport {
    name: String,
    /// (section, address, size, counts in flash, counts in RAM)
    sections: Vec<(String, u64, u64, bool, bool)>,
}

impl MemoryReport {
    pub fn read(path: &Path) -> Result<Self, String> {
        let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
        let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
        let mut sections = Vec::new();
        for s in file.sections() {
            let alloc = matches!(s.flags(), SectionFlags::Elf { sh_flags } if sh_flags & u64::from(object::elf::SHF_ALLOC) != 0);
            if !alloc || s.size() == 0 {
                continue;
            }
            let name = s.name().unwrap_or("?").to_string();
            let in_flash = within(s.address(), FLASH);
            let in_ram = within(s.address(), RAM);
            // Initialised data lives in RAM and is copied there from flash at boot.
            let loaded_from_flash = in_ram && name == ".data";
            sections.push((
                name,
                s.address(),
                s.size(),
                in_flash || loaded_from_flash,
                in_ram,
            ));
        }
        let name = path
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_default();
        Ok(MemoryReport { name, sections })
    }

    pub fn flash_bytes(&self) -> u64 {
        self.sections.iter().filter(|s| s.3).map(|s| s.2).sum()
    }

    /// Statically allocated RAM (data + bss + uninit); the stack takes what is left.
    pub fn ram_bytes(&self) -> u64 {
        self.sections.iter().filter(|s| s.4).map(|s| s.2).sum()
    }

    pub fn one_line(&self) -> String {
        format!(
            "flash {} B, static RAM {} B",
            self.flash_bytes(),
            self.ram_bytes()
        )
    }

    pub fn check_fits(&self) -> Result<(), String> {
        if self.flash_bytes() > FLASH.1 || self.ram_bytes() > RAM.1 {
            return Err(format!(
                "{} does not fit the STM32F405RG: {}",
                self.name,
                self.one_line()
            ));
        }
        Ok(())
    }
}

impl MemoryReport {
    /// Fails if the image exceeds `budget`.
    pub fn check_budget(&self, budget: &Budget) -> Result<(), String> {
        let (f, r) = (self.flash_bytes(), self.ram_bytes());
        let (fb, rb) = (budget.flash, budget.ram);
        println!(
            "  budget of {}: flash {f} B <= {fb} B, static RAM {r} B <= {rb} B: {}",
            budget.image,
            if f <= fb && r <= rb { "ok" } else { "EXCEEDED" }
        );
        if f > fb || r > rb {
            return Err(format!(
                "{} exceeds the budget of {} (flash {f} B of {fb} B, static RAM {r} B of {rb} B)",
                self.name, budget.image
            ));
        }
        Ok(())
    }
}

fn within(addr: u64, (origin, len): (u64, u64)) -> bool {
    addr >= origin && addr < origin + len
}

impl fmt::Display for MemoryReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(f, "memory use of {}", self.name)?;
        writeln!(
            f,
            "  {:<16} {:>12} {:>10}  region",
            "section", "address", "bytes"
        )?;
        for (name, addr, size, flash, ram) in &self.sections {
            let region = match (flash, ram) {
                (true, true) => "RAM (+ flash image)",
                (true, false) => "flash",
                (false, true) => "RAM",
                _ => "-",
            };
            writeln!(f, "  {name:<16} {addr:#012x} {size:>10}  {region}")?;
        }
        let pct = |used: u64, total: u64| 100.0 * used as f64 / total as f64;
        writeln!(
            f,
            "  flash {:>8} B of {} KiB ({:.1} %)",
            self.flash_bytes(),
            FLASH.1 / 1024,
            pct(self.flash_bytes(), FLASH.1)
        )?;
        write!(
            f,
            "  RAM   {:>8} B of {} KiB ({:.1} %) static; the stack uses the rest",
            self.ram_bytes(),
            RAM.1 / 1024,
            pct(self.ram_bytes(), RAM.1)
        )
    }
}

/// Whether `name` is one of the soft-float f64 helpers of the ARM EABI (`__aeabi_dadd`,
/// `__aeabi_f2d`, ...): the M4F's FPU is single precision, every f64 operation is a call.
fn is_soft_f64(name: &str) -> bool {
    let Some(op) = name.strip_prefix("__aeabi_") else {
        return false;
    };
    op.starts_with('d') || ["f2d", "i2d", "ui2d", "l2d", "ul2d"].contains(&op)
}

/// The target of a Thumb-2 `BL` at `addr` made of the halfwords `hw1`, `hw2` (encoding T1),
/// or `None` when they are not one.
fn bl_target(addr: u64, hw1: u16, hw2: u16) -> Option<u64> {
    if hw1 & 0xF800 != 0xF000 || hw2 & 0xD000 != 0xD000 {
        return None;
    }
    let s = u32::from(hw1 >> 10) & 1;
    let (j1, j2) = (u32::from(hw2 >> 13) & 1, u32::from(hw2 >> 11) & 1);
    let (i1, i2) = (!(j1 ^ s) & 1, !(j2 ^ s) & 1);
    let imm = (s << 24)
        | (i1 << 23)
        | (i2 << 22)
        | (u32::from(hw1 & 0x3FF) << 12)
        | (u32::from(hw2 & 0x7FF) << 1);
    // sign-extend the 25-bit offset
    let offset = i64::from(((imm << 7) as i32) >> 7);
    Some((addr as i64 + 4 + offset) as u64)
}

/// Calls to the soft-float f64 helpers ([`is_soft_f64`]) in the image's code, per calling
/// function, most first (a `BL` scan of every sized code symbol): how much f64 arithmetic is
/// left for the single-precision FPU to not do.
pub fn soft_f64_calls(path: &Path) -> Result<Vec<(String, usize)>, String> {
    use object::{ObjectSymbol, SymbolKind};
    use std::collections::{BTreeMap, BTreeSet};
    let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
    let code: Vec<(u64, u64, String)> = file
        .symbols()
        .filter(|s| s.kind() == SymbolKind::Text && s.size() > 0)
        .map(|s| located_symbol(&s))
        .filter(|(a, _, _)| within(*a, FLASH))
        .collect();
    let helpers: BTreeSet<u64> = code
        .iter()
        .filter(|(_, _, n)| is_soft_f64(n))
        .map(|(a, _, _)| *a)
        .collect();
    let text = file
        .section_by_name(".text")
        .ok_or("the ELF has no .text section")?;
    let bytes = text.data().map_err(|e| format!(".text: {e}"))?;
    let base = text.address();
    let halfword = |a: u64| -> Option<u16> {
        let i = usize::try_from(a.checked_sub(base)?).ok()?;
        Some(u16::from_le_bytes([*bytes.get(i)?, *bytes.get(i + 1)?]))
    };
    let mut calls: BTreeMap<String, usize> = BTreeMap::new();
    for (addr, size, name) in &code {
        let mut a = *addr;
        while a + 4 <= addr + size {
            let hit = match (halfword(a), halfword(a + 2)) {
                (Some(h1), Some(h2)) => bl_target(a, h1, h2).filter(|t| helpers.contains(t)),
                _ => None,
            };
            if hit.is_some() {
                *calls.entry(name.clone()).or_default() += 1;
                a += 4;
            } else {
                a += 2;
            }
        }
    }
    let mut out: Vec<(String, usize)> = calls.into_iter().collect();
    out.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    Ok(out)
}

/// The `cargo xtask size` lines of [`soft_f64_calls`]: the total and the `n` largest callers.
pub fn soft_f64_table(path: &Path, n: usize) -> Result<String, String> {
    let calls = soft_f64_calls(path)?;
    let total: usize = calls.iter().map(|c| c.1).sum();
    let mut out = format!("soft-float f64 call sites: {total} (largest callers)\n");
    for (name, k) in calls.iter().take(n) {
        // the end of a long name: its method
        let skip = name.chars().count().saturating_sub(100);
        let short: String = name.chars().skip(skip).collect();
        let more = if skip > 0 { "..." } else { "" };
        out.push_str(&format!("  {k:>6}  {more}{short}\n"));
    }
    Ok(out)
}

/// The largest flash symbols of an ELF (`cargo bloat`-style) and the flash bytes per crate
/// (first path segment of the demangled name; `?` for symbols without one).
pub fn top_symbols(path: &Path, n: usize) -> Result<String, String> {
    use object::{ObjectSymbol, SymbolKind};
    use std::collections::BTreeMap;
    let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
    let mut located: Vec<(u64, u64, String)> = file
        .symbols()
        .filter(|s| matches!(s.kind(), SymbolKind::Text | SymbolKind::Data))
        .filter(|s| within(s.address() & !1, FLASH) && s.size() > 0)
        .map(|s| located_symbol(&s))
        .collect();
    // Aliases (several names for one address) count once.
    located.sort();
    located.dedup_by_key(|s| (s.0, s.1));
    let mut syms: Vec<(u64, String)> = located.into_iter().map(|s| (s.1, s.2)).collect();
    syms.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    let mut by_crate: BTreeMap<String, u64> = BTreeMap::new();
    for (size, name) in &syms {
        let krate = crate_of(name);
        *by_crate.entry(krate).or_default() += size;
    }
    let total: u64 = syms.iter().map(|s| s.0).sum();
    let mut out = format!("flash by crate (sized symbols, {total} B):\n");
    let mut crates: Vec<_> = by_crate.into_iter().collect();
    crates.sort_by_key(|c| std::cmp::Reverse(c.1));
    for (k, v) in crates.iter().take(12) {
        out.push_str(&format!("  {v:>8} B  {k}\n"));
    }
    out.push_str(&format!("largest {n} flash symbols:\n"));
    for (size, name) in syms.iter().take(n) {
        let short: String = name.chars().take(110).collect();
        out.push_str(&format!("  {size:>8} B  {short}\n"));
    }
    Ok(out)
}

/// Code the image once linked and was cut out of it (each entry: a piece of the demangled name,
/// what it cost, what pulls it in): [`check_unwanted`] fails `cargo xtask size` when one is
/// back, so a cut cannot be undone unnoticed (the row swaps of eigen's LU brought `memmove`
/// back once, in a revert).
pub const UNWANTED: &[(&str, &str)] = &[
    (
        "compiler_builtins::mem::memmove",
        "1.4 KB: an overlapping copy, e.g. `slice::swap` of whole rows or `Vec::insert`; swap entry by entry",
    ),
    (
        "rem_pio2_large",
        "libm's huge-argument reduction, 3.5 KB: an f32 sin/cos/tan from libm instead of `core::trig`",
    ),
    (
        "core::fmt::float",
        "float formatting, ~9 KB: a panic message or `Debug` that formats a float (e.g. `f64::clamp`)",
    ),
];

/// `Err` naming every [`UNWANTED`] entry that one of `names` (demangled symbols) contains.
pub fn unwanted_in<'a>(names: impl IntoIterator<Item = &'a str>) -> Result<(), String> {
    let names: Vec<&str> = names.into_iter().collect();
    let found: Vec<String> = UNWANTED
        .iter()
        .filter_map(|(piece, why)| {
            let hit = names.iter().find(|n| n.contains(piece))?;
            Some(format!("`{hit}` is linked again ({why})"))
        })
        .collect();
    if found.is_empty() {
        Ok(())
    } else {
        Err(found.join("; "))
    }
}

/// [`unwanted_in`] for the symbols of the ELF at `path`.
pub fn check_unwanted(path: &Path) -> Result<(), String> {
    let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
    let names: Vec<String> = file.symbols().map(|s| located_symbol(&s).2).collect();
    unwanted_in(names.iter().map(String::as_str)).map_err(|e| format!("{}: {e}", path.display()))
}

/// (address with the Thumb bit cleared, size, demangled name) of an ELF symbol.
fn located_symbol<'d, S: object::ObjectSymbol<'d>>(s: &S) -> (u64, u64, String) {
    let name = s.name().unwrap_or("?");
    (
        s.address() & !1,
        s.size(),
        format!("{:#}", rustc_demangle::demangle(name)),
    )
}

/// Where the flash bytes go that the symbol table does not size: per flash section, the bytes
/// covered by sized symbols (union of their address ranges, so aliases count once), alignment
/// padding (gaps of at most 3 B) and the rest, each span of the rest named by the symbol that
/// starts it or precedes it (ARM mapping symbols `$t`/`$d` say whether it is code or data).
pub fn attribution(path: &Path, n_spans: usize) -> Result<String, String> {
    use object::ObjectSymbol;
    let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
    // (address, size, name) of every symbol, thumb bit cleared
    let mut syms: Vec<(u64, u64, String)> = file
        .symbols()
        .filter(|s| s.address() != 0)
        .map(|s| located_symbol(&s))
        .collect();
    syms.sort();
    let mut out = String::from(
        "flash attribution (section = sized symbols + alignment padding + unattributed):\n",
    );
    out.push_str(&format!(
        "  {:<16} {:>8} {:>14} {:>9} {:>14}\n",
        "section", "bytes", "sized symbols", "padding", "unattributed"
    ));
    let mut spans: Vec<(u64, u64, String, String)> = Vec::new();
    let (mut tot_sec, mut tot_sym, mut tot_pad, mut tot_un) = (0, 0, 0, 0);
    for sec in file.sections() {
        let alloc = matches!(sec.flags(), SectionFlags::Elf { sh_flags } if sh_flags & u64::from(object::elf::SHF_ALLOC) != 0);
        let name = sec.name().unwrap_or("?").to_string();
        let in_flash =
            within(sec.address(), FLASH) || (within(sec.address(), RAM) && name == ".data");
        if !alloc || sec.size() == 0 || !in_flash {
            continue;
        }
        let (lo, hi) = (sec.address(), sec.address() + sec.size());
        // covered intervals of the sized symbols inside the section, merged
        let mut covered: Vec<(u64, u64)> = Vec::new();
        for (a, sz, _) in syms
            .iter()
            .filter(|(a, sz, _)| *sz > 0 && *a >= lo && *a < hi)
        {
            let end = (a + sz).min(hi);
            match covered.last_mut() {
                Some(last) if *a <= last.1 => last.1 = last.1.max(end),
                _ => covered.push((*a, end)),
            }
        }
        let in_syms: u64 = covered.iter().map(|(a, b)| b - a).sum();
        let mut gaps = Vec::new();
        let mut at = lo;
        for (a, b) in &covered {
            if *a > at {
                gaps.push((at, *a));
            }
            at = at.max(*b);
        }
        if hi > at {
            gaps.push((at, hi));
        }
        let (mut pad, mut un) = (0, 0);
        for (a, b) in gaps {
            if b - a <= 3 {
                pad += b - a;
                continue;
            }
            un += b - a;
            // the symbol that starts the span, else the last one before it
            let before: Vec<&(u64, u64, String)> = syms.iter().filter(|s| s.0 <= a).collect();
            let label = before
                .iter()
                .rev()
                .find(|s| !s.2.starts_with('$'))
                .map(|s| {
                    if s.0 == a {
                        format!("at {}", s.2)
                    } else {
                        format!("{} B after {}", a - s.0, s.2)
                    }
                })
                .unwrap_or_else(|| "section start".into());
            // text with NULs (file names of panic locations, messages) or code/data by the ARM
            // mapping symbol in front of it
            let bytes = sec.data_range(a, b - a).ok().flatten().unwrap_or_default();
            let texty = !bytes.is_empty()
                && bytes
                    .iter()
                    .filter(|c| c.is_ascii_graphic() || **c == b' ' || **c == 0)
                    .count()
                    * 10
                    >= bytes.len() * 9;
            let kind = match before.iter().rev().find(|s| s.2.starts_with('$')) {
                _ if texty => "strings",
                Some(m) if m.2.starts_with("$d") => "data",
                Some(m) if m.2.starts_with("$t") || m.2.starts_with("$a") => "code",
                _ => "?",
            };
            spans.push((b - a, a, format!("{name} {kind}"), label));
        }
        out.push_str(&format!(
            "  {name:<16} {:>8} {in_syms:>14} {pad:>9} {un:>14}\n",
            sec.size()
        ));
        tot_sec += sec.size();
        tot_sym += in_syms;
        tot_pad += pad;
        tot_un += un;
    }
    out.push_str(&format!(
        "  {:<16} {tot_sec:>8} {tot_sym:>14} {tot_pad:>9} {tot_un:>14}\n",
        "total"
    ));
    spans.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    out.push_str(&format!("largest {n_spans} unattributed spans:\n"));
    for (size, addr, kind, label) in spans.iter().take(n_spans) {
        let short: String = label.chars().take(90).collect();
        out.push_str(&format!(
            "  {size:>8} B  {addr:#010x}  {kind:<14} {short}\n"
        ));
    }
    Ok(out)
}

/// Code bytes by the source they were compiled from, inlined code included: every 2-byte step
/// of each sized code symbol goes to the innermost frame of its inline chain (the image's DWARF)
/// whose file is not the Rust standard library, so an f32 add of `core::ops` inlined into the
/// estimator counts for the estimator. Grouped by crate for dependencies and by module for this
/// workspace (`core/estimator`, `firmware/store`, ...); what only the standard library explains
/// (mem*, soft-float, core::fmt) is `std`. The symbol table alone puts inlined code under the
/// function it landed in (an RTIC task, `__rtic_init_resources`).
pub fn by_source(path: &Path) -> Result<Vec<(String, u64)>, String> {
    use object::{ObjectSymbol, SymbolKind};
    use std::collections::BTreeMap;
    let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
    let dwarf = gimli::Dwarf::load(|id| -> Result<_, String> {
        let bytes = file
            .section_by_name(id.name())
            .and_then(|s| s.data().ok())
            .unwrap_or(&[]);
        Ok(gimli::EndianSlice::new(bytes, gimli::LittleEndian))
    })?;
    let ctx = addr2line::Context::from_dwarf(dwarf).map_err(|e| format!("DWARF: {e}"))?;
    let mut code: Vec<(u64, u64)> = file
        .symbols()
        .filter(|s| s.kind() == SymbolKind::Text && s.size() > 0)
        .map(|s| (s.address() & !1, s.size()))
        .filter(|(a, _)| within(*a, FLASH))
        .collect();
    code.sort();
    code.dedup();
    let mut groups: BTreeMap<String, u64> = BTreeMap::new();
    let mut done = 0; // end of the ranges counted so far (aliases and overlaps count once)
    for (addr, size) in code {
        for at in (addr.max(done)..addr + size).step_by(2) {
            let step = 2.min(addr + size - at);
            *groups.entry(source_of(&ctx, at)).or_default() += step;
        }
        done = done.max(addr + size);
    }
    let mut out: Vec<(String, u64)> = groups.into_iter().collect();
    out.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    Ok(out)
}

/// The source group of the code at `addr` (see [`by_source`]).
fn source_of<R: gimli::Reader>(ctx: &addr2line::Context<R>, addr: u64) -> String {
    let mut std_only = false;
    if let Ok(mut frames) = ctx.find_frames(addr).skip_all_loads() {
        while let Ok(Some(frame)) = frames.next() {
            let Some(file) = frame.location.and_then(|l| l.file) else {
                continue;
            };
            match source_group(file) {
                Some(group) => return group,
                None => std_only = true,
            }
        }
    }
    if std_only { "std" } else { "? (no line info)" }.into()
}

/// `None` for the standard library; a dependency's crate name; `crate/module` for this
/// workspace's sources.
fn source_group(file: &str) -> Option<String> {
    if file.contains("/rustc/") || file.contains("/rustlib/") {
        return None;
    }
    if let Some((_, rest)) = file.split_once("/registry/src/") {
        // index.crates.io-<hash>/<name>-<version>/src/...
        let dir = rest.split('/').nth(1).unwrap_or(rest);
        let name = match dir.rsplit_once('-') {
            Some((n, v)) if v.starts_with(|c: char| c.is_ascii_digit()) => n,
            _ => dir,
        };
        // a version with a dash (1.0.0-rc.1): cut at the first dash before a digit
        let name = name
            .match_indices('-')
            .find(|(i, _)| name[i + 1..].starts_with(|c: char| c.is_ascii_digit()))
            .map_or(name, |(i, _)| &name[..i]);
        return Some(name.to_string());
    }
    let root = crate::root();
    let rel = Path::new(file)
        .strip_prefix(&root)
        .map(|p| p.to_string_lossy().into_owned())
        .unwrap_or_else(|_| file.to_string());
    let parts: Vec<&str> = rel.split('/').collect();
    match parts.as_slice() {
        [krate, "src", module, ..] => Some(format!(
            "{krate}/{}",
            module.strip_suffix(".rs").unwrap_or(module)
        )),
        _ => Some(rel),
    }
}

/// The flash that the flash store and the host link add (issues 23 and 24), from
/// [`by_source`]: their code with the dependencies only they use, and the core's vehicle record
/// (field table, ranges, rules, record encoding), which both need.
pub const STORE_SOURCES: &[&str] = &[
    "firmware/store",
    "sequential-storage",
    "embedded-storage",
    "embedded-storage-async",
];
/// See [`STORE_SOURCES`].
pub const LINK_SOURCES: &[&str] = &[
    "firmware/link",
    "link/device",
    "link/frame",
    "link/log",
    "link/wire",
    "link/lib",
    "postcard",
    "cobs",
    "crc",
    "crc-catalog",
    "serde",
    "serde_core",
];

/// The `cargo xtask size` table of [`by_source`], with the store's and the link's parts summed.
pub fn source_table(path: &Path, n: usize) -> Result<String, String> {
    let groups = by_source(path)?;
    let total: u64 = groups.iter().map(|g| g.1).sum();
    let mut out = format!("code by source, inlined code included (DWARF; {total} B):\n");
    for (name, bytes) in groups.iter().take(n) {
        out.push_str(&format!("  {bytes:>8} B  {name}\n"));
    }
    let rest: u64 = groups.iter().skip(n).map(|g| g.1).sum();
    out.push_str(&format!(
        "  {rest:>8} B  ({} more)\n",
        groups.len().saturating_sub(n)
    ));
    let sum = |names: &[&str]| -> u64 {
        groups
            .iter()
            .filter(|(g, _)| names.contains(&g.as_str()))
            .map(|g| g.1)
            .sum()
    };
    for (part, names) in [
        ("flash store", STORE_SOURCES),
        ("host link", LINK_SOURCES),
        ("vehicle record", &["core/vehicle"][..]),
    ] {
        out.push_str(&format!(
            "  part {part:<15} {:>8} B  ({})\n",
            sum(names),
            names.join(", ")
        ));
    }
    out.pop();
    Ok(out)
}

/// Crate of a demangled symbol: `<impl ...>` names use the type's path. Unmangled names get
/// what they are: compiler builtins (`__aeabi_*`, `__adddf3`, ...) are the soft-float library;
/// interrupt handlers (`TIM2`, `EXTI1`: upper-case vector names) are the RTIC tasks with the
/// code they inline (the control task's supervisor and controller, the meter task's pipeline);
/// `Reset`, `main` and the vector tables are cortex-m-rt's; `_defmt_*` the log transport;
/// `.Lanon.*` / `.Lswitch.table.*` anonymous constants (string and float literals, jump
/// tables).
fn crate_of(name: &str) -> String {
    let s = name.strip_prefix(".hidden ").unwrap_or(name);
    let s = s.trim_start_matches('<').trim_start_matches('&');
    let s = s.strip_prefix("mut ").unwrap_or(s);
    if s.starts_with("__INTERRUPTS") || s.starts_with("__EXCEPTIONS") || s.starts_with("__RESET") {
        return "cortex-m-rt (vectors, reset)".into();
    }
    if s.starts_with("__") {
        return "compiler_builtins (soft-float, mem*)".into();
    }
    if s.starts_with(".Lanon") || s.starts_with(".Lswitch") {
        return "anonymous constants (literals, jump tables)".into();
    }
    if s.starts_with("_defmt_") {
        return "defmt (transport)".into();
    }
    if matches!(
        s,
        "Reset" | "main" | "DefaultHandler" | "HardFault" | "HardFault_"
    ) {
        return "cortex-m-rt (vectors, reset)".into();
    }
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_uppercase() || c.is_ascii_digit() || c == '_')
    {
        return "interrupt handlers (RTIC tasks, inlined code)".into();
    }
    match s.split_once("::") {
        Some((k, _)) if !k.contains(' ') => k.to_string(),
        _ => "?".into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(flash: u64, bss: u64) -> MemoryReport {
        MemoryReport {
            name: "test.elf".into(),
            sections: vec![
                (".text".into(), FLASH.0, flash, true, false),
                (".bss".into(), RAM.0, bss, false, true),
            ],
        }
    }

    #[test]
    fn source_groups_name_the_crate_or_the_workspace_module() {
        let reg = "/root/.cargo/registry/src/index.crates.io-1949cf8c6b5b557f";
        assert_eq!(
            source_group(&format!("{reg}/sequential-storage-8.0.2/src/map.rs")).as_deref(),
            Some("sequential-storage")
        );
        assert_eq!(
            source_group(&format!(
                "{reg}/embedded-storage-async-0.4.2/src/nor_flash.rs"
            ))
            .as_deref(),
            Some("embedded-storage-async")
        );
        let root = crate::root();
        let ws = |rel: &str| root.join(rel).to_string_lossy().into_owned();
        assert_eq!(
            source_group(&ws("firmware/src/store/storage.rs")).as_deref(),
            Some("firmware/store")
        );
        assert_eq!(
            source_group(&ws("core/src/vehicle.rs")).as_deref(),
            Some("core/vehicle")
        );
        assert_eq!(
            source_group("/rustc/88d9e12a/library/core/src/ops/arith.rs"),
            None
        );
    }

    #[test]
    fn budgets_pass_at_the_limit_and_fail_one_byte_over() {
        for b in [CAR_BUDGET, TRUCK_BUDGET] {
            assert!(report(b.flash, b.ram).check_budget(&b).is_ok());
            assert!(report(b.flash + 1, 0).check_budget(&b).is_err());
            assert!(report(0, b.ram + 1).check_budget(&b).is_err());
        }
    }

    #[test]
    fn thumb_bl_targets_decode_both_ways() {
        // BL from 0x0800_8000 to 0x0800_8100: offset 0xFC (S = 0, J1 = J2 = 1)
        assert_eq!(bl_target(0x0800_8000, 0xF000, 0xF87E), Some(0x0800_8100));
        // and back to 0x0800_7F00: offset -0x104 (S = 1, J1 = J2 = 1, imm10 = 0x3FF)
        assert_eq!(bl_target(0x0800_8000, 0xF7FF, 0xFF7E), Some(0x0800_7F00));
        // a 16-bit instruction pair is not a BL
        assert_eq!(bl_target(0x0800_8000, 0x4770, 0xBF00), None);
        assert!(is_soft_f64("__aeabi_dadd") && is_soft_f64("__aeabi_f2d"));
        assert!(!is_soft_f64("__aeabi_memcpy") && !is_soft_f64("__aeabi_fadd"));
    }

    #[test]
    fn an_unwanted_symbol_fails_and_is_named() {
        let clean = [
            "shimmy_core::eigen::inverse_iteration::<f32, 10>",
            "__aeabi_memcpy4",
        ];
        assert!(unwanted_in(clean).is_ok());
        let back = [
            "compiler_builtins::mem::memmove",
            "compiler_builtins::mem::memcpy",
        ];
        let e = unwanted_in(back).unwrap_err();
        assert!(
            e.contains("`compiler_builtins::mem::memmove` is linked again"),
            "{e}"
        );
        assert!(!e.contains("rem_pio2_large"), "{e}");
    }
}
