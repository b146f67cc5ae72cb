//! NI TDMS files (LabVIEW, DAQmx loggers, npTDMS): every numeric channel
//! becomes a channel `group/channel`, with `wf_start_offset` and
//! `wf_increment` as its time base. Written here: the TDMS crates served
//! today mis-read interleaved data and allocate by a file's claimed sizes
//! (see `docs/trace-format.md`). Every length is checked against the bytes
//! present before anything is read or allocated, so a corrupt file costs no
//! more memory than its own values. DAQmx raw data (format-changing scalers)
//! and unscaled channels are refused with what to do instead.

use std::collections::BTreeMap;

use crate::import::columns::Channel;

const LEAD_IN_BYTES: usize = 28;
const TOC_META_DATA: u32 = 1 << 1;
const TOC_NEW_OBJ_LIST: u32 = 1 << 2;
const TOC_RAW_DATA: u32 = 1 << 3;
const TOC_INTERLEAVED: u32 = 1 << 5;
const TOC_BIG_ENDIAN: u32 = 1 << 6;
const TOC_DAQMX_RAW_DATA: u32 = 1 << 7;
const NO_RAW_DATA: u32 = 0xFFFF_FFFF;
const SAME_AS_BEFORE: u32 = 0;
const TYPE_STRING: u32 = 0x20;

/// Whether `head` starts a TDMS file.
pub fn is_tdms(head: &[u8]) -> bool {
    head.starts_with(b"TDSm")
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Index {
    data_type: u32,
    values: u64,
}

#[derive(Debug, Default)]
struct Object {
    index: Option<Index>,
    props: BTreeMap<String, Prop>,
    values: Vec<f64>,
    /// The raw data is not a number (timestamps, booleans): kept out of the channels.
    numeric: bool,
    /// Stored as 32-bit floats (see `Channel::float32`).
    float32: bool,
}

#[derive(Debug, Clone, PartialEq)]
enum Prop {
    Num(f64),
    Text(String),
    Other,
}

struct Cursor<'a> {
    b: &'a [u8],
    at: usize,
    big: bool,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        if n > self.b.len() - self.at {
            return Err(format!(
                "byte {}: {n} bytes claimed, {} remain in the segment",
                self.at,
                self.b.len() - self.at
            ));
        }
        let s = &self.b[self.at..self.at + n];
        self.at += n;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32, String> {
        let a: [u8; 4] = self.take(4)?.try_into().map_err(|_| "short read".to_string())?;
        Ok(if self.big {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }
    fn u64(&mut self) -> Result<u64, String> {
        let a: [u8; 8] = self.take(8)?.try_into().map_err(|_| "short read".to_string())?;
        Ok(if self.big {
            u64::from_be_bytes(a)
        } else {
            u64::from_le_bytes(a)
        })
    }
    fn string(&mut self) -> Result<String, String> {
        let n = self.u32()? as usize;
        Ok(String::from_utf8_lossy(self.take(n)?).into_owned())
    }
}

/// Bytes per value of a TDMS data type, and whether it is a number read here.
fn type_size(t: u32) -> Option<(usize, bool)> {
    Some(match t {
        1 | 5 => (1, true),
        2 | 6 => (2, true),
        3 | 7 | 9 | 0x19 => (4, true),
        4 | 8 | 10 | 0x1A => (8, true),
        0x21 => (1, false),
        0x44 => (16, false),
        0x08000c => (8, false),
        0x10000d => (16, false),
        _ => return None,
    })
}

fn number(t: u32, b: &[u8], big: bool) -> f64 {
    macro_rules! conv {
        ($ty:ty, $n:expr) => {{
            let a: [u8; $n] = b[..$n].try_into().unwrap_or([0; $n]);
            (if big {
                <$ty>::from_be_bytes(a)
            } else {
                <$ty>::from_le_bytes(a)
            }) as f64
        }};
    }
    match t {
        1 => conv!(i8, 1),
        2 => conv!(i16, 2),
        3 => conv!(i32, 4),
        4 => conv!(i64, 8),
        5 => conv!(u8, 1),
        6 => conv!(u16, 2),
        7 => conv!(u32, 4),
        8 => conv!(u64, 8),
        9 | 0x19 => conv!(f32, 4),
        10 | 0x1A => conv!(f64, 8),
        _ => f64::NAN,
    }
}

/// `/'Group'/'Channel'` → (group, channel); `''` inside a name is a quote.
fn split_path(path: &str) -> Vec<String> {
    let mut parts = Vec::new();
    let mut chars = path.chars().peekable();
    while let Some(c) = chars.next() {
        if c == '\'' {
            let mut name = String::new();
            while let Some(c) = chars.next() {
                if c == '\'' {
                    if chars.peek() == Some(&'\'') {
                        chars.next();
                        name.push('\'');
                    } else {
                        break;
                    }
                } else {
                    name.push(c);
                }
            }
            parts.push(name);
        }
    }
    parts
}

/// Every numeric channel of the file (in `group` only, when given).
pub fn read(bytes: &[u8], group: Option<&str>) -> Result<Vec<Channel>, String> {
    let mut objects: BTreeMap<String, Object> = BTreeMap::new();
    // Paths in the order of the current segment's object list.
    let mut list: Vec<String> = Vec::new();
    let mut pos = 0usize;
    let mut segment = 0usize;
    while pos < bytes.len() {
        segment += 1;
        let lead = bytes
            .get(pos..pos + LEAD_IN_BYTES)
            .ok_or_else(|| format!("segment {segment} at byte {pos}: lead-in cut short"))?;
        if &lead[0..4] != b"TDSm" {
            return Err(format!("segment {segment} at byte {pos}: no `TDSm` tag"));
        }
        let toc = u32::from_le_bytes([lead[4], lead[5], lead[6], lead[7]]);
        let big = toc & TOC_BIG_ENDIAN != 0;
        let rd = |i: usize| {
            let a: [u8; 8] = lead[i..i + 8].try_into().unwrap_or([0; 8]);
            if big {
                u64::from_be_bytes(a)
            } else {
                u64::from_le_bytes(a)
            }
        };
        let (next, raw_off) = (rd(12), rd(20));
        let body_start = pos + LEAD_IN_BYTES;
        let left = (bytes.len() - body_start) as u64;
        // An unfinished last segment (0xFF…FF, or past the end) runs to the end of the file.
        let body_len = if next > left { left } else { next } as usize;
        if raw_off > body_len as u64 {
            return Err(format!(
                "segment {segment} at byte {pos}: raw data offset {raw_off} beyond the segment's {body_len} bytes"
            ));
        }
        let body = &bytes[body_start..body_start + body_len];
        if toc & TOC_DAQMX_RAW_DATA != 0 {
            return Err(format!(
                "segment {segment}: DAQmx raw data (format-changing scalers) is not read; log the task with scaled data (TDMS logging mode \"log and read\" with scaled values) or export the channels from NI's tools"
            ));
        }
        if toc & TOC_META_DATA != 0 {
            let mut c = Cursor {
                b: &body[..raw_off as usize],
                at: 0,
                big,
            };
            if toc & TOC_NEW_OBJ_LIST != 0 {
                list.clear();
            }
            let n = c.u32()?;
            for _ in 0..n {
                let path = c.string()?;
                let ix = c.u32()?;
                let obj = objects.entry(path.clone()).or_default();
                match ix {
                    NO_RAW_DATA => obj.index = None,
                    SAME_AS_BEFORE => {
                        if obj.index.is_none() {
                            return Err(format!("segment {segment}: `{path}` reuses a raw data index it never had"));
                        }
                    }
                    0x6912_0000..=0x6913_FFFF => {
                        return Err(format!(
                            "segment {segment}: `{path}` holds DAQmx raw data (format-changing scalers), not read; log scaled data instead"
                        ))
                    }
                    _ => {
                        let data_type = c.u32()?;
                        let dim = c.u32()?;
                        let values = c.u64()?;
                        if data_type == TYPE_STRING {
                            return Err(format!("segment {segment}: `{path}` holds strings, not samples"));
                        }
                        if dim != 1 {
                            return Err(format!("segment {segment}: `{path}` has array dimension {dim} (expected 1)"));
                        }
                        let (_, numeric) = type_size(data_type)
                            .ok_or_else(|| format!("segment {segment}: `{path}` has unknown data type {data_type:#x}"))?;
                        obj.index = Some(Index { data_type, values });
                        obj.numeric = numeric;
                        obj.float32 = matches!(data_type, 9 | 0x19);
                    }
                }
                let np = c.u32()?;
                for _ in 0..np {
                    let name = c.string()?;
                    let t = c.u32()?;
                    let v = if t == TYPE_STRING {
                        Prop::Text(c.string()?)
                    } else {
                        let (size, numeric) = type_size(t)
                            .ok_or_else(|| format!("`{path}`: property `{name}` of unknown type {t:#x}"))?;
                        let b = c.take(size)?;
                        if numeric {
                            Prop::Num(number(t, b, big))
                        } else {
                            Prop::Other
                        }
                    };
                    obj.props.insert(name, v);
                }
                if !list.contains(&path) {
                    list.push(path);
                }
            }
        }
        if toc & TOC_RAW_DATA != 0 {
            let raw = &body[raw_off as usize..];
            let active: Vec<(String, Index)> = list
                .iter()
                .filter_map(|p| objects.get(p).and_then(|o| o.index).map(|ix| (p.clone(), ix)))
                .collect();
            let mut chunk: u64 = 0;
            for (p, ix) in &active {
                let (size, _) = type_size(ix.data_type).unwrap_or((1, false));
                chunk = ix
                    .values
                    .checked_mul(size as u64)
                    .and_then(|b| chunk.checked_add(b))
                    .ok_or_else(|| format!("segment {segment}: `{p}` claims more values than a file holds"))?;
            }
            if chunk > 0 {
                if raw.len() as u64 % chunk != 0 {
                    return Err(format!(
                        "segment {segment}: {} bytes of raw data are not a whole number of {chunk}-byte chunks (a truncated file?)",
                        raw.len()
                    ));
                }
                let chunks = raw.len() as u64 / chunk;
                let interleaved = toc & TOC_INTERLEAVED != 0;
                if interleaved && active.windows(2).any(|w| w[0].1.values != w[1].1.values) {
                    return Err(format!("segment {segment}: interleaved channels of different lengths"));
                }
                let mut at = 0usize;
                let stride: usize = active
                    .iter()
                    .map(|(_, ix)| type_size(ix.data_type).map_or(0, |s| s.0))
                    .sum();
                for _ in 0..chunks {
                    if interleaved {
                        let n = active.first().map_or(0, |a| a.1.values) as usize;
                        for k in 0..n {
                            let mut off = at + k * stride;
                            for (p, ix) in &active {
                                let (size, numeric) = type_size(ix.data_type).unwrap_or((1, false));
                                if numeric {
                                    if let Some(o) = objects.get_mut(p) {
                                        o.values.push(number(ix.data_type, &raw[off..off + size], big));
                                    }
                                }
                                off += size;
                            }
                        }
                        at += n * stride;
                    } else {
                        for (p, ix) in &active {
                            let (size, numeric) = type_size(ix.data_type).unwrap_or((1, false));
                            let n = ix.values as usize;
                            if numeric {
                                if let Some(o) = objects.get_mut(p) {
                                    o.values.extend(
                                        raw[at..at + n * size]
                                            .chunks_exact(size)
                                            .map(|b| number(ix.data_type, b, big)),
                                    );
                                }
                            }
                            at += n * size;
                        }
                    }
                }
            }
        }
        pos = body_start + body_len;
    }
    let mut out = Vec::new();
    for (path, o) in objects {
        let parts = split_path(&path);
        if parts.len() != 2 || !o.numeric {
            continue;
        }
        if group.is_some_and(|g| g != parts[0]) {
            continue;
        }
        if o.props.get("NI_Scaling_Status") == Some(&Prop::Text("unscaled".into())) {
            return Err(format!(
                "channel `{}/{}` holds unscaled raw values (NI_Scaling_Status = unscaled); log scaled data",
                parts[0], parts[1]
            ));
        }
        let num = |k: &str| match o.props.get(k) {
            Some(Prop::Num(v)) => Some(*v),
            _ => None,
        };
        let mut c = Channel::new(format!("{}/{}", parts[0], parts[1]), o.values);
        c.float32 = o.float32;
        c.increment_s = num("wf_increment");
        c.start_s = num("wf_start_offset");
        out.push(c);
    }
    if out.is_empty() {
        return Err(match group {
            Some(g) => format!("no numeric channel in group `{g}`"),
            None => "no numeric channel".into(),
        });
    }
    Ok(out)
}
