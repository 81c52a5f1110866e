//! One knob from fast to thorough (`gsi encode --effort`), as `cwebp -m` or `cjxl -e` give.
//!
//! Each level is a measured choice of the steps, how many of them fit a reduced copy of the
//! image first ([`Coarse`]) and how long the colour solves run, chosen on LOL eval15's
//! normal-light images and reported on Kodak (BENCHMARKS.md, sessions 8 and 10).
//! `--iterations` stays an expert override of the level's steps.

use super::{Coarse, EncodeOptions};

/// An effort level, 1 (fastest) to 9 (most thorough).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Effort(u8);

/// Steps, coarse steps' share (at half resolution; 0 for none) and colour-solve
/// iterations of each level, chosen on LOL eval15's 15 normal-light images at 1 bpp (not
/// Kodak, which the report scores). Since the optimizer's state carries over from the
/// coarse steps to the full-resolution ones, a half-resolution first half
/// wins at every length tried: 600 steps so scored +0.09 dB over 600 at full resolution
/// in 31 % less time, 1200 steps +0.04 dB over a quarter coarse; before, a fresh optimizer
/// at full resolution lost the coarse start's lead past about 13 s. The
/// fastest level is the fewest steps that stay within 1 dB of the fit before levels (400
/// full-resolution steps at the old rates, 32.59 dB there): 120 steps are 0.65 dB under
/// it, 100 steps 1.01 dB. Level 5, 600 steps, gains at least 1 dB over that fit (+1.16
/// dB) in the time its 400 full-resolution steps took. The default is level 6, 800
/// steps, by the same rule: the most thorough level that takes no longer than the default
/// before it, level 5 as it ran before the fit's forward pass was vectorized
/// (BENCHMARKS.md, the default effort). On the validation sets, against that level 5, it
/// scored +0.21 dB on photos12 at 1 bpp, +0.18 at 0.5 bpp and +0.11 on eval15's
/// normal-light images at 1 bpp, in 0.95 to 1.00 times the CPU time (median over the
/// images); level 7 scored +0.22, +0.28 and +0.22 in 1.15 to 1.21 times. The final
/// colour solve lifted every level (validation: effort 1 −0.52 dB,
/// the default +1.51 dB from the same reference). The levels were left as they were: 100
/// steps would now pass the 1 dB rule too (−0.90 dB), but with less than half effort 1's
/// margin, and on Kodak effort 1 has sat further below the reference than here (−0.80 dB
/// against −0.65 before the final solve, −0.70 dB against −0.52 with it).
const LEVELS: [(u32, f32, u32); 9] = [
    (120, 0.5, 8),
    (200, 0.5, 10),
    (300, 0.5, 10),
    (400, 0.5, 10),
    (600, 0.5, 10),
    (800, 0.5, 10),
    (1000, 0.5, 10),
    (1200, 0.5, 10),
    (1600, 0.5, 10),
];

impl Effort {
    pub const FASTEST: Effort = Effort(1);
    pub const DEFAULT: Effort = Effort(6);
    pub const MOST: Effort = Effort(9);

    /// The level `level`, or `None` outside `1..=9`.
    pub fn new(level: u8) -> Option<Effort> {
        (1..=9).contains(&level).then_some(Effort(level))
    }

    pub fn level(self) -> u8 {
        self.0
    }

    /// Set this level's steps, coarse start and colour solves in `opts`, leaving the rest.
    pub fn apply(self, opts: &mut EncodeOptions) {
        let (iterations, fraction, solve) = LEVELS[usize::from(self.0 - 1)];
        opts.iterations = iterations;
        opts.coarse = (fraction > 0.0).then_some(Coarse {
            factor: 2,
            fraction,
        });
        opts.color_solve = solve;
    }
}

impl Default for Effort {
    fn default() -> Self {
        Effort::DEFAULT
    }
}
