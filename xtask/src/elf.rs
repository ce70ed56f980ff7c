//! Flash and RAM use of a firmware ELF, read from its section headers.

use object::{Object, ObjectSection, SectionFlags};
use std::fmt;
use std::path::Path;

/// Budgets of the release application image (issue 6): what the firmware may use of the
/// STM32F405RG, leaving room for the core's controller and estimators and for a bootloader.
pub const FLASH_BUDGET: u64 = 96 * 1024;
pub const RAM_BUDGET: u64 = 24 * 1024;

/// STM32F405RG memory map (must match `memory.x`).
const FLASH: (u64, u64) = (0x0800_0000, 1024 * 1024);
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
    /// Fails if the image exceeds [`FLASH_BUDGET`] or [`RAM_BUDGET`].
    pub fn check_budget(&self) -> Result<(), String> {
        let (f, r) = (self.flash_bytes(), self.ram_bytes());
        println!(
            "  budget: flash {f} B <= {FLASH_BUDGET} B, static RAM {r} B <= {RAM_BUDGET} B: {}",
            if f <= FLASH_BUDGET && r <= RAM_BUDGET {
                "ok"
            } else {
                "EXCEEDED"
            }
        );
        if f > FLASH_BUDGET || r > RAM_BUDGET {
            return Err(format!(
                "{} exceeds its budget (flash {f} B of {FLASH_BUDGET} B, static RAM {r} B of {RAM_BUDGET} B)",
                self.name
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

/// The largest flash symbols of an ELF (`cargo bloat`-style) and the flash bytes per crate
/// (first path segment of the demangled name; `?` for symbols without one).
pub fn top_symbols(path: &Path, n: usize) -> Result<String, String> {
    use object::{ObjectSymbol, SymbolKind};
    use std::collections::BTreeMap;
    let data = std::fs::read(path).map_err(|e| format!("read {}: {e}", path.display()))?;
    let file = object::File::parse(&*data).map_err(|e| format!("parse ELF: {e}"))?;
    let mut syms: Vec<(u64, String)> = file
        .symbols()
        .filter(|s| matches!(s.kind(), SymbolKind::Text | SymbolKind::Data))
        .filter(|s| within(s.address() & !1, FLASH) && s.size() > 0)
        .map(|s| {
            let name = s.name().unwrap_or("?");
            (s.size(), format!("{:#}", rustc_demangle::demangle(name)))
        })
        .collect();
    syms.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    syms.dedup();
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

/// Crate of a demangled symbol: `<impl ...>` names use the type's path; compiler builtins
/// (`__aeabi_*`, `__adddf3`, ...) are the soft-float library.
fn crate_of(name: &str) -> String {
    let s = name.trim_start_matches('<').trim_start_matches('&');
    let s = s.strip_prefix("mut ").unwrap_or(s);
    if s.starts_with("__") {
        return "compiler_builtins (soft-float, mem*)".into();
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
    fn budgets_pass_at_the_limit_and_fail_one_byte_over() {
        assert!(report(FLASH_BUDGET, RAM_BUDGET).check_budget().is_ok());
        assert!(report(FLASH_BUDGET + 1, 0).check_budget().is_err());
        assert!(report(0, RAM_BUDGET + 1).check_budget().is_err());
    }
}
