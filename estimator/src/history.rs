//! The neighbour check: a cycle whose period or stroke contradicts the
//! median of the last valid ones is implausible (a split or merged cycle, a
//! false impact that passed the shock test).

/// Valid cycles kept for the neighbour check.
const HISTORY: usize = 8;
/// A cycle whose period or stroke leaves these bands around the recent
/// median contradicts its neighbours (a supply change moves the period by
/// ~25 % between 4 and 7 bar; a split or merged cycle by 50 % or more).
const PERIOD_BAND: (f32, f32) = (0.6, 1.7);
const STROKE_BAND: (f32, f32) = (0.7, 1.4);
/// Recent valid cycles' periods and strokes, for the neighbour check.
#[derive(Debug, Clone, Copy, Default)]
pub(crate) struct History {
    period_s: [f32; HISTORY],
    stroke_m: [f32; HISTORY],
    len: usize,
    next: usize,
}

impl History {
    pub(crate) fn push(&mut self, period_s: f32, stroke_m: f32) {
        self.period_s[self.next] = period_s;
        self.stroke_m[self.next] = stroke_m;
        self.next = (self.next + 1) % HISTORY;
        self.len = (self.len + 1).min(HISTORY);
    }

    fn median(values: &[f32; HISTORY], len: usize) -> f32 {
        let mut v = [0.0f32; HISTORY];
        v[..len].copy_from_slice(&values[..len]);
        // Insertion sort of at most eight values.
        for i in 1..len {
            let mut j = i;
            while j > 0 && v[j - 1] > v[j] {
                v.swap(j - 1, j);
                j -= 1;
            }
        }
        v[len / 2]
    }

    /// True when the cycle contradicts the recent ones (needs four of them).
    pub(crate) fn contradicts(&self, period_s: f32, stroke_m: f32) -> bool {
        if self.len < 4 {
            return false;
        }
        let p = Self::median(&self.period_s, self.len);
        let x = Self::median(&self.stroke_m, self.len);
        let out = |v: f32, m: f32, (lo, hi): (f32, f32)| !(v >= lo * m && v <= hi * m);
        out(period_s, p, PERIOD_BAND) || out(stroke_m, x, STROKE_BAND)
    }
}
