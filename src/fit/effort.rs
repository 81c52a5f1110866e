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
/// iterations of each level. Chosen on LOL eval15's normal-light images at 1 bpp
/// (BENCHMARKS.md, session 8): a half-resolution start wins at equal time up to about
/// 13 s there and loses beyond, so the upper levels add full-resolution steps. With the
/// rates of session 10 ([`super::LEARNING_RATES`]) the fastest level is the one that
/// keeps within 1 dB of the fit before levels (400 steps at the old rates) on 8 of those
/// images: 160 steps are 0.70 dB under it, 120 steps 1.30 dB (session 10). Level 5, 400
/// full-resolution steps, stays the default: the level above it would not fit a 12 MP
/// photograph in 5 minutes.
const LEVELS: [(u32, f32, u32); 9] = [
    (160, 0.5, 8),
    (200, 0.5, 10),
    (300, 0.5, 10),
    (400, 0.5, 10),
    (400, 0.0, 10),
    (600, 0.0, 10),
    (800, 0.0, 10),
    (1200, 0.0, 10),
    (1600, 0.0, 10),
];

impl Effort {
    pub const FASTEST: Effort = Effort(1);
    pub const DEFAULT: Effort = Effort(5);
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
