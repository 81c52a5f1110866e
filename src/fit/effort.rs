//! One knob from fast to thorough (`gsi encode --effort`), as `cwebp -m` or `cjxl -e` give.
//!
//! Each level is a measured choice of the steps, how many of them fit a reduced copy of the
//! image first ([`Coarse`]) and how long the colour solves run, chosen on LOL eval15's
//! normal-light images and reported on Kodak (BENCHMARKS.md, session 8).
//! `--iterations` stays an expert override of the level's steps.

use super::{Coarse, EncodeOptions};

/// An effort level, 1 (fastest) to 9 (most thorough).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Effort(u8);

/// Steps, coarse steps' share (at half resolution; 0 for none) and colour-solve
/// iterations of each level. Chosen on 4 of LOL eval15's normal-light images at 1 bpp
/// (BENCHMARKS.md, session 8): a half-resolution start wins at equal time up to about
/// 13 s there (60 steps: +0.8 dB over 40 full ones in less time; 200: +0.4 dB), and loses
/// beyond (800 steps half coarse: 31.81 dB in 25.5 s, 400 full ones: 31.90 dB in 20.0 s),
/// so the upper levels add full-resolution steps. Level 5 is the fit before levels, and
/// the default: no level reached more PSNR in its time.
const LEVELS: [(u32, f32, u32); 9] = [
    (60, 0.5, 4),
    (100, 0.5, 6),
    (200, 0.5, 10),
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
