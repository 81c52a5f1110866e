//! Stage 1: fitting Gaussians to an image ([`fit`], whose front door is [`fit::encode`]),
//! with its CPU kernels and their wgpu twin side by side. The `gsi` crate re-exports it
//! under feature `encode`.

pub mod fit;
