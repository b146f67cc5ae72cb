//! The samples at which a pressure sat at a rail, kept apart from the
//! fit's sums (see [`Left`]); the slow path of the hot loop.

use super::pass::Balance;
use super::{Calibration, CycleAcc, Derived};

/// The samples at which a pressure sat at a rail (a vented chamber's dip
/// that a 0-based transducer clips, or a saturated one): their pressure
/// force is wrong, so they leave the friction fit (friction is a constant
/// per phase: dropping samples costs precision, not truth) and the velocity
/// integral takes the measured acceleration over them. Sums since the last
/// checkpoint, `j` the index from the checkpoint; kept only on the slow path
/// (a piece that touched a rail), so a cycle without rails pays nothing.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub(super) struct Railed {
    pub(super) n: u32,
    pub(super) e: f32,
    pub(super) ee: f32,
    pub(super) r: f32,
    pub(super) re: f32,
    pub(super) rr: f32,
    /// The pressure force: Σ force, Σ force², Σ r·force.
    pub(super) f: f32,
    pub(super) ff: f32,
    pub(super) rf: f32,
    /// Σ j, Σ j·e, Σ j·r.
    pub(super) j: f32,
    pub(super) je: f32,
    pub(super) jr: f32,
}

/// The cycle's totals over the samples that left the fit (j counted from
/// the first kept sample): where the closure puts back the fitted friction
/// and zero shift their measured acceleration held (`estimate`), and what
/// the accelerometer's gain reaches through them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Left {
    pub n: f32,
    /// Σ r and Σ force: Σ m·a over them.
    pub r: f32,
    pub f: f32,
    pub e: f32,
    pub j: f32,
    pub je: f32,
}

impl CycleAcc {
    /// The samples of `piece` at which a pressure sat at a rail, summed
    /// into [`Railed`] (the slow path: only a piece that touched a rail).
    /// The regressor e is recomputed from its value before the piece with
    /// the pass's own arithmetic, so the sums cancel exactly what it added.
    #[inline(never)]
    pub(super) fn leave_fit(
        &mut self,
        d: &Derived,
        cal: &Calibration,
        b: &Balance,
        piece: [&[crate::RawSample]; 2],
        mut e: f32,
    ) {
        // Their pressure sums stay in: the pressures' gain sensitivities are
        // read as phase means, which the clipped few hardly move.
        let at_rail = |c: u16, full: u16| c.wrapping_sub(1) >= full.wrapping_sub(1);
        let x = &mut self.railed;
        for (j, s) in piece[0].iter().chain(piece[1]).enumerate() {
            e *= d.q;
            if at_rail(s.rear, cal.full[0]) || at_rail(s.front, cal.full[1]) {
                let f = b.force(s.rear, s.front);
                let r = b.residual(s.accel, f);
                let j = (self.since_cp as usize + j) as f32;
                x.n += 1;
                x.e += e;
                x.ee += e * e;
                x.r += r;
                x.re += r * e;
                x.rr += r * r;
                x.f += f;
                x.ff += f * f;
                x.rf += r * f;
                x.j += j;
                x.je += j * e;
                x.jr += j * r;
            }
        }
    }
}
