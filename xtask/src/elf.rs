//! Flash and static RAM of an ARM ELF, from its section headers, and a
//! symbol's address from its symbol table (no external size tool needed on
//! a fresh machine).

use std::path::Path;

const SHF_WRITE: u32 = 0x1;
const SHF_ALLOC: u32 = 0x2;
const SHT_NOBITS: u32 = 8;
const SHT_SYMTAB: u32 = 2;

#[derive(Debug, Default, Clone, Copy)]
pub struct Sizes {
    /// Bytes programmed into flash: code, read-only data, vector table, and
    /// the initial values of `.data`.
    pub flash: u64,
    /// Bytes of RAM allocated statically: `.data`, `.bss`, `.uninit` (stack not included).
    pub ram: u64,
}

fn u16le(b: &[u8], o: usize) -> u16 {
    u16::from_le_bytes([b[o], b[o + 1]])
}
fn u32le(b: &[u8], o: usize) -> u32 {
    u32::from_le_bytes([b[o], b[o + 1], b[o + 2], b[o + 3]])
}

pub fn sizes(path: &Path) -> Result<Sizes, String> {
    let b = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if b.len() < 52 || &b[..4] != b"\x7fELF" || b[4] != 1 {
        return Err(format!("{}: not a 32-bit ELF", path.display()));
    }
    let shoff = u32le(&b, 32) as usize;
    let shentsize = u16le(&b, 46) as usize;
    let shnum = u16le(&b, 48) as usize;
    let mut s = Sizes::default();
    for i in 0..shnum {
        let o = shoff + i * shentsize;
        if o + 40 > b.len() {
            return Err(format!("{}: truncated section table", path.display()));
        }
        let sh_type = u32le(&b, o + 4);
        let flags = u32le(&b, o + 8);
        let size = u32le(&b, o + 20) as u64;
        if flags & SHF_ALLOC == 0 {
            continue;
        }
        if flags & SHF_WRITE != 0 {
            s.ram += size;
            if sh_type != SHT_NOBITS {
                s.flash += size; // .data's initial values live in flash
            }
        } else {
            s.flash += size;
        }
    }
    Ok(s)
}

/// The value (address) of the global or local symbol `name`, if the ELF has it.
pub fn symbol(path: &Path, name: &str) -> Result<Option<u32>, String> {
    let b = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
    if b.len() < 52 || &b[..4] != b"\x7fELF" || b[4] != 1 {
        return Err(format!("{}: not a 32-bit ELF", path.display()));
    }
    let truncated = || format!("{}: truncated ELF", path.display());
    let shoff = u32le(&b, 32) as usize;
    let shentsize = u16le(&b, 46) as usize;
    let shnum = u16le(&b, 48) as usize;
    let section = |i: usize| -> Result<(u32, usize, usize, u32, usize), String> {
        let o = shoff + i * shentsize;
        if o + 40 > b.len() {
            return Err(truncated());
        }
        // (type, offset, size, link, entsize)
        Ok((
            u32le(&b, o + 4),
            u32le(&b, o + 16) as usize,
            u32le(&b, o + 20) as usize,
            u32le(&b, o + 24),
            u32le(&b, o + 36) as usize,
        ))
    };
    for i in 0..shnum {
        let (kind, off, size, link, entsize) = section(i)?;
        if kind != SHT_SYMTAB || entsize < 16 {
            continue;
        }
        let (_, str_off, str_size, _, _) = section(link as usize)?;
        let strings = b.get(str_off..str_off + str_size).ok_or_else(truncated)?;
        let table = b.get(off..off + size).ok_or_else(truncated)?;
        for sym in table.chunks_exact(entsize) {
            let at = u32le(sym, 0) as usize;
            let Some(rest) = strings.get(at..) else { continue };
            let end = rest.iter().position(|&c| c == 0).unwrap_or(rest.len());
            if &rest[..end] == name.as_bytes() {
                return Ok(Some(u32le(sym, 4)));
            }
        }
    }
    Ok(None)
}
