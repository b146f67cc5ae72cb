//! MATLAB MAT v5 files (what `save -v7` and `scipy.io.savemat` write): each
//! numeric variable becomes a channel. Written here rather than with the
//! `matfile` crate: that crate inflates compressed variables without bound
//! and reports every malformed file as the same opaque parse error; a v5
//! file is a flat list of tagged elements, read here with every length
//! checked against the bytes present. v7.3 files are HDF5 and are refused
//! with the way out named.

use std::io::Read;

use crate::import::columns::Channel;

/// Bytes of the text header plus subsystem offset, version and endianness.
const HEADER_BYTES: usize = 128;
const MI_INT8: u32 = 1;
const MI_UINT8: u32 = 2;
const MI_INT16: u32 = 3;
const MI_UINT16: u32 = 4;
const MI_INT32: u32 = 5;
const MI_UINT32: u32 = 6;
const MI_SINGLE: u32 = 7;
const MI_DOUBLE: u32 = 9;
const MI_INT64: u32 = 12;
const MI_UINT64: u32 = 13;
const MI_MATRIX: u32 = 14;
const MI_COMPRESSED: u32 = 15;
/// Numeric array classes (mxDOUBLE_CLASS … mxUINT64_CLASS).
const NUMERIC_CLASSES: std::ops::RangeInclusive<u8> = 6..=15;
/// Inflated bytes allowed per compressed variable beyond 16 × its size.
const INFLATE_ALLOWANCE: u64 = 64 << 20;

/// Whether `head` starts a MAT file (v5 or v7.3).
pub fn is_mat(head: &[u8]) -> bool {
    head.starts_with(b"MATLAB ")
}

/// Every numeric variable of a MAT v5 file, by name (a scalar is a channel
/// of one value), and the variables not read, each with its class (a
/// struct, a cell array, text), so that a signal looked for in vain names them.
pub fn read(bytes: &[u8]) -> Result<(Vec<Channel>, Vec<String>), String> {
    if bytes.len() < HEADER_BYTES || !is_mat(bytes) {
        return Err("not a MAT file (no `MATLAB` header)".into());
    }
    let text = String::from_utf8_lossy(&bytes[..116]);
    if text.starts_with("MATLAB 7.3") || bytes.get(512..516) == Some(b"\x89HDF") {
        return Err(
            "a MATLAB v7.3 file (HDF5) is not read: save it as v7 (`save(file, '-v7')`) or with scipy.io.savemat"
                .into(),
        );
    }
    let big = match &bytes[126..128] {
        b"IM" => false,
        b"MI" => true,
        _ => return Err("MAT header: no endian indicator (`IM`/`MI`) at byte 126".into()),
    };
    let version = u16_at(&bytes[124..126], big);
    if version != 0x0100 {
        return Err(format!(
            "MAT header: version {version:#06x}, expected 0x0100 (MAT v5); a v7.3 file is HDF5: save it as v7"
        ));
    }
    let mut out = Vars::default();
    elements(&bytes[HEADER_BYTES..], big, HEADER_BYTES, &mut out, true)?;
    Ok((out.channels, out.skipped))
}

#[derive(Default)]
struct Vars {
    channels: Vec<Channel>,
    skipped: Vec<String>,
}

/// A variable: a numeric vector, or another class (named for the message).
enum Var {
    Numeric(Channel),
    Other { name: String, class: &'static str },
}

/// mxSINGLE_CLASS: 32-bit floats, whatever type the data element uses.
const SINGLE_CLASS: u8 = 7;

fn class_name(class: u8) -> &'static str {
    match class {
        1 => "a cell array",
        2 => "a struct: save its fields as variables of their own",
        3 => "an object",
        4 => "text",
        5 => "a sparse matrix",
        _ => "not numeric",
    }
}

fn u16_at(b: &[u8], big: bool) -> u16 {
    let a = [b[0], b[1]];
    if big {
        u16::from_be_bytes(a)
    } else {
        u16::from_le_bytes(a)
    }
}

fn u32_at(b: &[u8], big: bool) -> u32 {
    let a = [b[0], b[1], b[2], b[3]];
    if big {
        u32::from_be_bytes(a)
    } else {
        u32::from_le_bytes(a)
    }
}

/// One tagged element: (type, data, bytes taken including padding).
fn element(b: &[u8], big: bool, at: usize) -> Result<(u32, &[u8], usize), String> {
    if b.len() < 8 {
        return Err(format!("byte {at}: a data element cut short ({} bytes left)", b.len()));
    }
    let first = u32_at(&b[0..4], big);
    if first >> 16 != 0 {
        // Small data element: type and size in one word, data in the next.
        let (ty, n) = (first & 0xffff, (first >> 16) as usize);
        if n > 4 {
            return Err(format!("byte {at}: a small data element claims {n} bytes (at most 4)"));
        }
        return Ok((ty, &b[4..4 + n], 8));
    }
    let n = u32_at(&b[4..8], big) as usize;
    if n > b.len() - 8 {
        return Err(format!(
            "byte {at}: a data element claims {n} bytes, {} remain in the file",
            b.len() - 8
        ));
    }
    let ty = first;
    // Compressed elements are not padded; the rest are to 8 bytes.
    let padded = if ty == MI_COMPRESSED { n } else { n.div_ceil(8) * 8 };
    Ok((ty, &b[8..8 + n], 8 + padded.min(b.len() - 8)))
}

fn elements(mut b: &[u8], big: bool, mut at: usize, out: &mut Vars, top: bool) -> Result<(), String> {
    while !b.is_empty() {
        let (ty, data, taken) = element(b, big, at)?;
        match ty {
            MI_MATRIX => match matrix(data, big, at + 8)? {
                Var::Numeric(c) => out.channels.push(c),
                Var::Other { name, class } => out.skipped.push(format!("`{name}` ({class})")),
            },
            MI_COMPRESSED if top => {
                let limit = INFLATE_ALLOWANCE + 16 * data.len() as u64;
                let mut inflated = Vec::new();
                flate2::read::ZlibDecoder::new(data)
                    .take(limit + 1)
                    .read_to_end(&mut inflated)
                    .map_err(|e| format!("byte {at}: a compressed variable does not inflate: {e}"))?;
                if inflated.len() as u64 > limit {
                    return Err(format!(
                        "byte {at}: a compressed variable inflates beyond {limit} bytes (16 × its size + 64 MiB)"
                    ));
                }
                elements(&inflated, big, 0, out, false)?;
            }
            _ => {}
        }
        at += taken;
        b = &b[taken.min(b.len())..];
    }
    Ok(())
}

/// A numeric matrix as a channel (column-major values, any shape with one
/// non-singleton dimension); other classes (cell, struct, char) are named,
/// not read.
fn matrix(b: &[u8], big: bool, at: usize) -> Result<Var, String> {
    let (ty, flags, n1) = element(b, big, at)?;
    if ty != MI_UINT32 || flags.len() < 8 {
        return Err(format!("byte {at}: a matrix without its array flags"));
    }
    let class = (u32_at(&flags[0..4], big) & 0xff) as u8;
    let complex = u32_at(&flags[0..4], big) & 0x0800 != 0;
    let rest = &b[n1..];
    let (ty, dims, n2) = element(rest, big, at + n1)?;
    if ty != MI_INT32 || dims.len() < 8 || dims.len() % 4 != 0 {
        return Err(format!("byte {at}: a matrix without its dimensions"));
    }
    let dims: Vec<u64> = dims.chunks(4).map(|c| u32_at(c, big) as u64).collect();
    let count = dims.iter().try_fold(1u64, |a, &d| a.checked_mul(d));
    let rest = &rest[n2..];
    let (ty, name, n3) = element(rest, big, at + n1 + n2)?;
    if ty != MI_INT8 && ty != MI_UINT8 {
        return Err(format!("byte {at}: a matrix without its name"));
    }
    let name = String::from_utf8_lossy(name).into_owned();
    if !NUMERIC_CLASSES.contains(&class) {
        return Ok(Var::Other {
            name,
            class: class_name(class),
        });
    }
    let rest = &rest[n3..];
    let (ty, real, _) = element(rest, big, at + n1 + n2 + n3)?;
    if complex {
        return Err(format!("variable `{name}`: complex values; a signal is real"));
    }
    let values = numbers(ty, real, big).ok_or_else(|| format!("variable `{name}`: data type {ty} is not numeric"))?;
    if count != Some(values.len() as u64) {
        return Err(format!(
            "variable `{name}`: dimensions {dims:?} do not match its {} values",
            values.len()
        ));
    }
    if dims.iter().filter(|&&d| d > 1).count() > 1 {
        return Err(format!(
            "variable `{name}`: a {dims:?} matrix; a signal is a vector (one variable per channel)"
        ));
    }
    let mut c = Channel::new(name, values);
    c.float32 = class == SINGLE_CLASS;
    Ok(Var::Numeric(c))
}

fn numbers(ty: u32, b: &[u8], big: bool) -> Option<Vec<f64>> {
    macro_rules! conv {
        ($t:ty, $n:expr) => {
            b.chunks_exact($n)
                .map(|c| {
                    let a: [u8; $n] = c.try_into().unwrap_or([0; $n]);
                    (if big {
                        <$t>::from_be_bytes(a)
                    } else {
                        <$t>::from_le_bytes(a)
                    }) as f64
                })
                .collect()
        };
    }
    Some(match ty {
        MI_INT8 => conv!(i8, 1),
        MI_UINT8 => conv!(u8, 1),
        MI_INT16 => conv!(i16, 2),
        MI_UINT16 => conv!(u16, 2),
        MI_INT32 => conv!(i32, 4),
        MI_UINT32 => conv!(u32, 4),
        MI_SINGLE => conv!(f32, 4),
        MI_DOUBLE => conv!(f64, 8),
        MI_INT64 => conv!(i64, 8),
        MI_UINT64 => conv!(u64, 8),
        _ => return None,
    })
}
