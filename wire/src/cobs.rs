//! Consistent Overhead Byte Stuffing: removes every 0x00 from a payload so
//! 0x00 can delimit frames.

/// Worst-case encoded length of `n` bytes (without the delimiter).
pub const fn max_encoded_len(n: usize) -> usize {
    n + n / 254 + 1
}

/// Encodes `src` into `dst`; returns the encoded length, or `None` if `dst` is too small.
pub fn encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    if dst.len() < max_encoded_len(src.len()) {
        return None;
    }
    let mut code_pos = 0;
    let mut out = 1;
    let mut code: u8 = 1;
    for &b in src {
        if b == 0 {
            dst[code_pos] = code;
            code_pos = out;
            out += 1;
            code = 1;
        } else {
            dst[out] = b;
            out += 1;
            code += 1;
            if code == 0xFF {
                dst[code_pos] = code;
                code_pos = out;
                out += 1;
                code = 1;
            }
        }
    }
    dst[code_pos] = code;
    Some(out)
}

/// Decodes in place; returns the decoded length, or `None` for a malformed block.
pub fn decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let mut read = 0;
    let mut write = 0;
    while read < buf.len() {
        let code = buf[read];
        if code == 0 {
            return None;
        }
        read += 1;
        let end = read + code as usize - 1;
        if end > buf.len() {
            return None;
        }
        while read < end {
            if buf[read] == 0 {
                return None;
            }
            buf[write] = buf[read];
            write += 1;
            read += 1;
        }
        if code != 0xFF && read < buf.len() {
            buf[write] = 0;
            write += 1;
        }
    }
    Some(write)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(data: &[u8]) {
        let mut enc = [0u8; 1200];
        let n = encode(data, &mut enc).unwrap();
        assert!(!enc[..n].contains(&0), "no zero in {:?}", &enc[..n]);
        let mut buf = enc[..n].to_vec();
        let m = decode_in_place(&mut buf).unwrap();
        assert_eq!(&buf[..m], data);
    }

    #[test]
    fn known_vectors_and_round_trips() {
        let mut enc = [0u8; 16];
        let n = encode(&[0x11, 0x22, 0x00, 0x33], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        let n = encode(&[0x00], &mut enc).unwrap();
        assert_eq!(&enc[..n], &[0x01, 0x01]);
        round_trip(&[]);
        round_trip(&[0, 0, 0]);
        let long: [u8; 600] = core::array::from_fn(|i| (i % 7) as u8);
        round_trip(&long);
        let no_zero: [u8; 600] = core::array::from_fn(|i| (i % 250 + 1) as u8);
        round_trip(&no_zero);
    }

    #[test]
    fn malformed_input_is_rejected_not_panicked() {
        assert_eq!(decode_in_place(&mut [0x05, 1, 2]), None);
        assert_eq!(decode_in_place(&mut [0x02, 0]), None);
        assert_eq!(decode_in_place(&mut [0x00]), None);
    }
}
