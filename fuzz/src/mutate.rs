//! Byte-level mutations, as libFuzzer and AFL's havoc stage make them, plus a
//! per-target dictionary of tokens (delimiters, keywords, edge numbers) so
//! that text formats get past their tokenizers.

/// xorshift64*: deterministic, fast, good enough to pick mutations.
#[derive(Debug, Clone)]
pub struct Rng(u64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// Uniform in `0..n` (`n > 0`).
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n as u64) as usize
    }

    pub fn chance(&mut self, one_in: usize) -> bool {
        self.below(one_in) == 0
    }
}

const INTERESTING: [u8; 10] = [0x00, 0x01, 0x7f, 0x80, 0xff, b'\n', b',', b'0', b'-', b'.'];

/// Longest input a mutation may produce: the targets' limits (a frame is 400
/// bytes, a line 64 KiB) are reached by far smaller inputs' structure.
pub const MAX_INPUT: usize = 16 * 1024;

/// Applies 1–8 random mutations to `data`; `other` is a second corpus entry
/// to splice from, `dict` the target's tokens.
pub fn mutate(rng: &mut Rng, data: &mut Vec<u8>, other: &[u8], dict: &[&[u8]]) {
    let rounds = 1 + rng.below(8);
    for _ in 0..rounds {
        let len = data.len();
        match rng.below(11) {
            0 if len > 0 => {
                let i = rng.below(len);
                data[i] ^= 1 << rng.below(8);
            }
            1 if len > 0 => {
                let i = rng.below(len);
                data[i] = rng.next_u64() as u8;
            }
            2 if len > 0 => {
                let i = rng.below(len);
                data[i] = INTERESTING[rng.below(INTERESTING.len())];
            }
            3 => {
                let i = rng.below(len + 1);
                let n = 1 + rng.below(8);
                let bytes: Vec<u8> = (0..n).map(|_| rng.next_u64() as u8).collect();
                data.splice(i..i, bytes);
            }
            4 if len > 0 => {
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(32));
                data.drain(i..i + n);
            }
            5 if len > 0 => {
                // Duplicate a chunk: repeated frames, rows, tables.
                let i = rng.below(len);
                let n = 1 + rng.below((len - i).min(64));
                let chunk = data[i..i + n].to_vec();
                let at = rng.below(len + 1);
                data.splice(at..at, chunk);
            }
            6 if !other.is_empty() => {
                // Splice: this input's head with another's tail.
                let cut = rng.below(len + 1);
                let from = rng.below(other.len());
                data.truncate(cut);
                data.extend_from_slice(&other[from..]);
            }
            7 if len > 0 => {
                data.truncate(rng.below(len));
            }
            8 | 9 if !dict.is_empty() => {
                let token = dict[rng.below(dict.len())];
                let i = rng.below(len + 1);
                if rng.chance(2) && len > 0 {
                    // Overwrite rather than insert.
                    let end = (i + token.len()).min(len);
                    data.splice(i..end, token.iter().copied());
                } else {
                    data.splice(i..i, token.iter().copied());
                }
            }
            _ if len > 1 => {
                // Arithmetic on a byte, as AFL does.
                let i = rng.below(len);
                let d = 1 + rng.below(16) as u8;
                data[i] = if rng.chance(2) {
                    data[i].wrapping_add(d)
                } else {
                    data[i].wrapping_sub(d)
                };
            }
            _ => data.push(rng.next_u64() as u8),
        }
    }
    data.truncate(MAX_INPUT);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mutations_are_deterministic_and_bounded() {
        let run = |seed| {
            let mut rng = Rng::new(seed);
            let mut d = b"t_s,p_rear_pa\n0,1\n".to_vec();
            for _ in 0..10_000 {
                mutate(&mut rng, &mut d, b"other,input\n", &[b"nan", b","]);
                assert!(d.len() <= MAX_INPUT);
            }
            d
        };
        assert_eq!(run(1), run(1));
        assert_ne!(run(1), run(2));
    }
}
