//! An FMU's zip, unpacked into a private directory the instances load
//! from (their `resources/` URI points there). Stored and deflated entries,
//! as the tools write them; names that would leave the directory refused.

use std::io::Read;
use std::path::{Component, Path, PathBuf};
use std::sync::atomic::{AtomicU32, Ordering};

/// A directory removed when dropped.
#[derive(Debug)]
pub struct Unpacked {
    pub dir: PathBuf,
}

impl Drop for Unpacked {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn u16_at(b: &[u8], at: usize) -> Option<u16> {
    Some(u16::from_le_bytes(b.get(at..at + 2)?.try_into().ok()?))
}

fn u32_at(b: &[u8], at: usize) -> Option<u32> {
    Some(u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?))
}

/// The entries of a zip: (name, bytes). Errors say what is wrong, never
/// quote the file.
pub fn entries(zip: &[u8]) -> Result<Vec<(String, Vec<u8>)>, String> {
    const EOCD: u32 = 0x0605_4b50;
    let not_zip = || "not a zip file (no end of central directory)".to_string();
    if zip.len() < 22 {
        return Err(not_zip());
    }
    let lowest = zip.len().saturating_sub(22 + 0xffff);
    let eocd = (lowest..=zip.len() - 22)
        .rev()
        .find(|&i| u32_at(zip, i) == Some(EOCD))
        .ok_or_else(not_zip)?;
    let count = u16_at(zip, eocd + 10).ok_or_else(not_zip)? as usize;
    let mut at = u32_at(zip, eocd + 16).ok_or_else(not_zip)? as usize;
    let bad = |what: &str| format!("a damaged zip ({what})");
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        if u32_at(zip, at) != Some(0x0201_4b50) {
            return Err(bad("central directory"));
        }
        let method = u16_at(zip, at + 10).ok_or_else(|| bad("entry"))?;
        let packed = u32_at(zip, at + 20).ok_or_else(|| bad("entry"))? as usize;
        let size = u32_at(zip, at + 24).ok_or_else(|| bad("entry"))? as usize;
        let name_len = u16_at(zip, at + 28).ok_or_else(|| bad("entry"))? as usize;
        let extra = u16_at(zip, at + 30).ok_or_else(|| bad("entry"))? as usize;
        let comment = u16_at(zip, at + 32).ok_or_else(|| bad("entry"))? as usize;
        let local = u32_at(zip, at + 42).ok_or_else(|| bad("entry"))? as usize;
        let name = zip.get(at + 46..at + 46 + name_len).ok_or_else(|| bad("entry name"))?;
        let name = String::from_utf8_lossy(name).into_owned();
        at += 46 + name_len + extra + comment;
        if u32_at(zip, local) != Some(0x0403_4b50) {
            return Err(bad("local header"));
        }
        let l_name = u16_at(zip, local + 26).ok_or_else(|| bad("local header"))? as usize;
        let l_extra = u16_at(zip, local + 28).ok_or_else(|| bad("local header"))? as usize;
        let start = local + 30 + l_name + l_extra;
        let data = zip
            .get(start..start + packed)
            .ok_or_else(|| bad("entry past the end"))?;
        let bytes = match method {
            0 => data.to_vec(),
            8 => {
                let mut v = Vec::with_capacity(size);
                flate2::read::DeflateDecoder::new(data)
                    .take(size as u64 + 1)
                    .read_to_end(&mut v)
                    .map_err(|_| bad("deflate"))?;
                v
            }
            m => {
                return Err(format!(
                    "zip entry {name} uses compression method {m} (stored or deflate only)"
                ))
            }
        };
        if bytes.len() != size {
            return Err(bad("entry size"));
        }
        out.push((name, bytes));
    }
    Ok(out)
}

static UNPACKED: AtomicU32 = AtomicU32::new(0);

/// Unpacks the FMU at `fmu` into a new directory under the temporary one.
pub fn unpack(fmu: &Path) -> Result<Unpacked, String> {
    let bytes = std::fs::read(fmu).map_err(|e| e.to_string())?;
    let files = entries(&bytes)?;
    let n = UNPACKED.fetch_add(1, Ordering::Relaxed);
    let dir = std::env::temp_dir().join(format!("hammer-fmu-{}-{n}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let unpacked = Unpacked { dir };
    for (name, data) in files {
        let rel = Path::new(&name);
        if rel.components().any(|c| !matches!(c, Component::Normal(_))) {
            return Err(format!("zip entry {name} would leave the FMU's directory"));
        }
        let path = unpacked.dir.join(rel);
        if name.ends_with('/') {
            std::fs::create_dir_all(&path).map_err(|e| format!("{}: {e}", path.display()))?;
            continue;
        }
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent).map_err(|e| format!("{}: {e}", parent.display()))?;
        }
        std::fs::write(&path, data).map_err(|e| format!("{}: {e}", path.display()))?;
    }
    Ok(unpacked)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_and_deflated_entries_read_and_damage_is_named() {
        use std::io::Write;
        let files = vec![("a/b.txt".to_string(), b"hello".to_vec())];
        let zip = crate::package::zip_stored(&files);
        assert_eq!(entries(&zip).unwrap(), files);
        // The same entry deflated: method 8, packed size, data.
        let mut enc = flate2::write::DeflateEncoder::new(Vec::new(), flate2::Compression::default());
        enc.write_all(b"hello").unwrap();
        let packed = enc.finish().unwrap();
        let mut z = Vec::new();
        let mut local = zip[..30].to_vec();
        local[8..10].copy_from_slice(&8u16.to_le_bytes());
        local[18..22].copy_from_slice(&(packed.len() as u32).to_le_bytes());
        z.extend(&local);
        z.extend(b"a/b.txt");
        z.extend(&packed);
        let cd_at = z.len();
        let cd_start = 30 + 7 + 5;
        let mut central = zip[cd_start..cd_start + 46 + 7].to_vec();
        central[10..12].copy_from_slice(&8u16.to_le_bytes());
        central[20..24].copy_from_slice(&(packed.len() as u32).to_le_bytes());
        z.extend(&central);
        let mut eocd = zip[zip.len() - 22..].to_vec();
        eocd[16..20].copy_from_slice(&(cd_at as u32).to_le_bytes());
        z.extend(&eocd);
        assert_eq!(entries(&z).unwrap(), files);
        assert!(entries(b"not a zip at all, just some text")
            .unwrap_err()
            .contains("not a zip"));
        let mut cut = zip.clone();
        cut.truncate(zip.len() - 30);
        assert!(entries(&cut).is_err());
    }
}
