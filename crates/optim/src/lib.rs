//! What both fitting stages share: [`optim`], the one Adam (its GPU twin is
//! `shaders/fit/adam.wgsl`), and [`rng`], the one random generator, so that every seeded
//! choice in gsi is reproducible across platforms and dependency upgrades.

pub mod optim;
pub mod rng;
